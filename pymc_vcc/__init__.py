"""pymc_vcc: Bayesian, likelihood-free calibration of dynamic vapor-compression-cycle models.

The public API is re-exported here and imported lazily on first use, so that worker processes
which only simulate never pay for importing PyMC. The function ``simulate`` lives in the
module of the same name: ``from pymc_vcc.physics.simulate import simulate``. See the README for a
tour.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

_EXPORTS: dict[str, tuple[str, ...]] = {
    "pymc_vcc.physics.refrigerant": ("load_refrigerant", "Refrigerant", "SUPPORTED_FLUIDS"),
    "pymc_vcc.physics.unit": ("load_unit", "Unit"),
    "pymc_vcc.physics.parameters": ("ParameterSpec", "ParameterTable"),
    "pymc_vcc.physics.inputs": (
        "INPUT_IDS",
        "builtin_inputs",
        "constant_inputs",
        "load_inputs_csv",
        "make_inputs",
    ),
    "pymc_vcc.physics.cycles": ("OUTPUT_IDS", "CYCLE_MODELS", "CycleModel"),
    "pymc_vcc.physics.failures": ("FailureKind",),
    "pymc_vcc.physics.simulate": ("VCCSimulator", "operating_point"),
    "pymc_vcc.physics.integration.solver": ("Solver", "get_solver"),
    "pymc_vcc.inference.simulator": ("Simulator", "check_simulator"),
    "pymc_vcc.io.measurements": (
        "load_measurements",
        "load_log",
        "load_column_map",
        "ColumnMap",
        "Measurements",
        "example_log_path",
    ),
    "pymc_vcc.inference.error_model": ("ErrorBudget", "SensorAccuracy"),
    "pymc_vcc.inference.distances": (
        "ks_distance",
        "ks_distances",
        "wasserstein_distances",
        "windowed_distances",
    ),
    "pymc_vcc.inference.noise": ("SensorNoise",),
    "pymc_vcc.inference.likelihood": ("log_likelihood",),
    "pymc_vcc.inference.pymc.likelihood": ("add_likelihood",),
    "pymc_vcc.inference.pymc.laplace": ("fit_reference",),
    "pymc_vcc.inference.pymc.reference": ("GaussianReference",),
    "pymc_vcc.inference.priors": ("Prior", "UniformPrior", "GMMPrior", "load_prior"),
    "pymc_vcc.inference.rejection": ("abc_rejection", "TooManyFailuresError"),
    "pymc_vcc.inference.sequential": ("sequential_calibration", "SequentialResult"),
    "pymc_vcc.execution.executors": ("make_executor", "Executor", "WorkerCrash"),
    "pymc_vcc.execution.options": ("RunOptions",),
    "pymc_vcc.execution.store": ("CheckpointMismatchError",),
    "pymc_vcc.inference.pymc.model": ("add_simulator", "gmm_prior_variable"),
    "pymc_vcc.inference.pymc.smc": ("sample_smc_abc", "ParallelIMH"),
    "pymc_vcc.inference.pymc.layout": ("standard_layout",),
    "pymc_vcc.inference.predictive": ("simulate_predictive", "predictive_bands"),
    "pymc_vcc.inference.sensitivity": ("sobol_indices",),
    "pymc_vcc.inference.identifiability": ("identifiability", "Identifiability"),
    "pymc_vcc.studies": (
        "StudySettings",
        "leak_study",
        "estimation_study",
        "sobol_study",
        "validation_study",
    ),
    "pymc_vcc.studies.unit_log": ("calibrate_record", "record_study"),
    "pymc_vcc.studies.diagnose": ("diagnose",),
    "pymc_vcc.studies.truths": ("generate_truth",),
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}

__all__ = ["__version__", *sorted(_MODULE_OF)]


def __getattr__(name: str) -> Any:
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module 'pymc_vcc' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return __all__
