"""Validation of charge identification on noisy data: methods side by side, coverage.

For one reference charge, ``n_datasets`` measured datasets differ only in their sensor noise
(each drawn with its own seed). Every method calibrates the charge on the same datasets:

* ``ks``: the paper's KS rejection ABC, noise-free simulations against noisy data;
* ``ks-noise``: KS rejection ABC with the sensor noise added to every simulation;
* ``windowed``: rejection ABC with 10 s windowed means (time-aligned), noise simulated;
* ``wasserstein``: rejection ABC with the Wasserstein-1 distance, noise simulated;
* ``likelihood``: the exact likelihood under the sensor noise, PyMC's tempered SMC.

Reported per method: mean |posterior mean − truth|, median posterior sd, the fraction of 95 %
intervals covering the truth, simulations per dataset and median wall time per dataset. Each
finished calibration is appended to ``<out>/runs.jsonl`` as it completes.

With ``reference_table`` the rejection methods share one table of the budget's prior draws
(simulated once, drawn with the first dataset's seed; :mod:`pymc_vcc.inference.reference_table`):
each dataset and method adds its own noise to the stored simulations. Their rows then report the
table rows a dataset used, and :attr:`ValidationResult.table_simulations` the table's size,
simulated once for all of them.
"""

from __future__ import annotations

import json
import statistics
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import xarray as xr

from pymc_vcc.inference.distances import (
    BatchDistance,
    ks_distances,
    wasserstein_distances,
    windowed_distances,
)
from pymc_vcc.inference.noise import SensorNoise
from pymc_vcc.inference.priors import UniformPrior
from pymc_vcc.physics.inputs import CALIBRATION_SECONDS
from pymc_vcc.physics.simulate import VCCSimulator
from pymc_vcc.physics.unit import Unit, load_unit
from pymc_vcc.studies.common import StudySettings, holds_output_folder, write_json, write_text
from pymc_vcc.studies.leak import (
    CHARGE,
    INTERVAL,
    calibrate_charge,
    reference_data,
    shared_table,
)
from pymc_vcc.studies.precision import significant

METHODS: dict[str, tuple[str, bool, BatchDistance]] = {
    "ks": ("rejection", False, ks_distances),
    "ks-noise": ("rejection", True, ks_distances),
    "windowed": ("rejection", True, windowed_distances),
    "wasserstein": ("rejection", True, wasserstein_distances),
    "likelihood": ("likelihood", True, ks_distances),
}
"""Method -> (sampler, whether it accounts for the sensor noise, ABC distance)."""


@dataclass
class ValidationResult:
    """Per method, one row of summary figures; per method and dataset, the raw figures.

    ``table_simulations``: size of the reference table the rejection methods shared (0: none).
    """

    reference_kg: float
    rows: list[dict[str, float | str]]
    runs: list[dict[str, float | str | bool]]
    wall_seconds: float
    table_simulations: int = 0
    files: list[str] = field(default_factory=list)

    def summary(self) -> dict:
        """The JSON summary."""
        return {
            "reference_kg": self.reference_kg,
            "rows": self.rows,
            "runs": self.runs,
            "wall_seconds": round(self.wall_seconds, 1),
            "table_simulations": self.table_simulations,
        }

    def format_table(self) -> str:
        """The comparison as aligned text."""
        lines = [
            f"Charge identification at {self.reference_kg} kg on noisy data",
            f"{'method':>12} {'datasets':>8} {'|error| (kg)':>12} {'sd (kg)':>9} "
            f"{'coverage':>9} {'sims':>6} {'wall (s)':>9}",
        ]
        for row in self.rows:
            lines.append(
                f"{row['method']:>12} {row['datasets']:8d} "
                f"{significant(row['mean_abs_error_kg'], width=12)} "
                f"{significant(row['median_sd_kg'], width=9)} {row['coverage']:9.2f} "
                f"{row['simulations_per_dataset']:6.0f} {row['median_wall_seconds']:9.1f}"
            )
        if self.table_simulations:
            lines.append(
                f"rejection methods: sims are the rows each dataset used of one shared table of "
                f"{self.table_simulations} simulations"
            )
        return "\n".join(lines)


@holds_output_folder("validate")
def validation_study(
    settings: StudySettings | None = None,
    *,
    reference_kg: float = 1.5,
    n_datasets: int = 20,
    methods: Sequence[str] = ("ks", "ks-noise", "windowed", "likelihood"),
    sensor_noise: SensorNoise | None = None,
    unit: Unit | None = None,
    inputs: xr.Dataset | None = None,
    t_calibration: float = CALIBRATION_SECONDS,
    smc_epsilon: float = 0.02,
    reference_table: bool = False,
    smc_draws: int | None = None,
) -> ValidationResult:
    """Calibrate the charge on ``n_datasets`` noisy datasets with each method (see module).

    Args:
        settings: budget (rejection: Table I settings; likelihood: SMC draws), executor, seed.
        reference_kg: the true charge, kg.
        n_datasets: noise realisations.
        methods: names of :data:`METHODS`.
        sensor_noise: noise of the data (default: typical, 0.3 K / 0.5 % / 1 %).
        unit, inputs, t_calibration: the unit, its input profile and calibration window.
        smc_epsilon: kernel width of SMC-ABC methods.
        reference_table: the rejection methods share one table of prior simulations (module).
        smc_draws: particles of the likelihood path (default: the budget's
            ``likelihood_draws``).
    """
    started = time.perf_counter()
    unknown = [name for name in methods if name not in METHODS]
    if unknown or not methods:
        raise ValueError(f"methods must be names of {list(METHODS)}, got {list(methods)}")
    if int(n_datasets) != n_datasets or n_datasets < 1:
        raise ValueError(f"n_datasets must be a positive integer, got {n_datasets}")
    sensor_noise = sensor_noise or SensorNoise.typical()
    unit = unit or load_unit()
    spec = unit.parameters[CHARGE]
    if not spec.low <= reference_kg <= spec.high:
        raise ValueError(
            f"reference_kg must lie in the prior bounds [{spec.low}, {spec.high}] kg, got "
            f"{reference_kg}"
        )
    simulator = VCCSimulator(
        unit, inputs, t_window=(0.0, t_calibration), parameters=[CHARGE], solver=settings.solver
    )
    prior = UniformPrior({CHARGE: (spec.low, spec.high)})
    runs = []
    log = None
    if settings.out is not None:
        settings.out.mkdir(parents=True, exist_ok=True)
        log = settings.out / "runs.jsonl"
        log.write_text("")
    seeds = settings.seeds(int(n_datasets))
    table = None
    with settings.open_executor() as executor:
        for dataset, seed in enumerate(seeds):
            observed = reference_data(
                simulator, reference_kg, sensor_noise, np.random.default_rng(seed.spawn(1)[0])
            )
            wants_table = any(METHODS[method][0] == "rejection" for method in methods)
            if reference_table and wants_table and table is None:
                table = shared_table(
                    simulator, prior, observed, settings, executor, seeds[0], "validate_table"
                )
            for method in methods:
                sampler, aware, distance = METHODS[method]
                begun = time.perf_counter()
                tree, ran = calibrate_charge(
                    sampler,
                    simulator,
                    prior,
                    observed,
                    settings,
                    executor,
                    seed,
                    f"validate_{method}_{dataset}",
                    smc_epsilon,
                    sensor_noise if aware else None,
                    distance,
                    table,
                    smc_draws,
                )
                draws = tree["posterior"][CHARGE].values.ravel()
                low, high = np.quantile(draws, [(1 - INTERVAL) / 2, (1 + INTERVAL) / 2])
                runs.append(
                    {
                        "method": method,
                        "dataset": dataset,
                        "mean_kg": float(draws.mean()),
                        "sd_kg": float(draws.std(ddof=1)),
                        "covered": bool(low <= reference_kg <= high),
                        "simulations": ran,
                        "wall_seconds": time.perf_counter() - begun,
                    }
                )
                if log is not None:
                    with log.open("a") as stream:
                        stream.write(json.dumps(runs[-1]) + "\n")
    rows = [
        _summarise(method, [r for r in runs if r["method"] == method], reference_kg)
        for method in methods
    ]
    result = ValidationResult(
        float(reference_kg),
        rows,
        runs,
        time.perf_counter() - started,
        table.n_simulations if table is not None else 0,
    )
    if settings.out is not None:
        write_text(settings.out / "comparison.txt", result.format_table() + "\n")
        write_json(settings.out / "summary.json", result.summary())
        result.files = [str(settings.out / name) for name in ("runs.jsonl", "comparison.txt")]
        result.files.append(str(settings.out / "summary.json"))
    return result


def _summarise(method: str, runs: list[dict], reference_kg: float) -> dict[str, float | str]:
    return {
        "method": method,
        "datasets": len(runs),
        "mean_abs_error_kg": float(np.mean([abs(r["mean_kg"] - reference_kg) for r in runs])),
        "median_sd_kg": float(statistics.median(r["sd_kg"] for r in runs)),
        "coverage": float(np.mean([r["covered"] for r in runs])),
        "simulations_per_dataset": float(np.mean([r["simulations"] for r in runs])),
        "median_wall_seconds": float(statistics.median(r["wall_seconds"] for r in runs)),
    }
