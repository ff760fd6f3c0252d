"""The exact likelihood of a deterministic simulator under declared sensor noise, in PyMC.

:func:`add_likelihood` adds the calibrated parameters and a ``pm.Simulator`` node whose
random function runs the simulator (noise-free) and whose "distance" is the exact
log-likelihood of :func:`pymc_vcc.inference.likelihood.log_likelihood`: no tolerance ε, no
summary statistic. PyMC's tempered SMC samples it without gradients, with the stock kernel
(``pm.sample_smc``, one simulation after another) or with
:class:`~pymc_vcc.inference.pymc.smc.ParallelIMH` (``sample_smc_abc``), which runs a whole stage
of simulations as one parallel batch.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pymc as pm
import pytensor.tensor as pt
from pytensor.graph.basic import Apply
from pytensor.graph.op import Op

from pymc_vcc.inference.error_model import ErrorBudget
from pymc_vcc.inference.likelihood import innovations, log_likelihood
from pymc_vcc.inference.noise import OutputNoise, SensorNoise
from pymc_vcc.inference.priors import Bounds, Prior, UniformPrior, check_prior_support
from pymc_vcc.inference.pymc.model import (
    SimulatorFunction,
    SimulatorNode,
    prior_variables,
    simulator_bounds,
)
from pymc_vcc.inference.series import OutputData, prepare_observed
from pymc_vcc.inference.simulator import Simulator, check_simulator


class LogLikelihoodKernel(Op):
    """PyTensor op ``(epsilon, observed, simulated) -> [log p(observed | simulated)]``.

    The signature of a ``pm.Simulator`` distance; ``epsilon`` is ignored (the likelihood is
    exact). A failed simulation (non-finite values) gives −inf: zero likelihood.
    """

    __props__ = ("noise",)

    def __init__(self, noise: OutputNoise) -> None:
        self.noise = noise

    def make_node(self, epsilon, observed, simulated) -> Apply:
        inputs = [pt.as_tensor_variable(value) for value in (epsilon, observed, simulated)]
        return Apply(self, inputs, [pt.dvector()])

    def perform(self, node, inputs, output_storage) -> None:
        _, observed, simulated = inputs
        output_storage[0][0] = np.atleast_1d(log_likelihood(observed, simulated, self.noise))

    def residuals(self, observed: np.ndarray, simulated: np.ndarray) -> np.ndarray:
        """The whitened innovations of ``observed`` from ``simulated`` (flat): standard normals
        under the noise model, whose squares sum to −2 log p up to a constant."""
        noise = self.noise
        return innovations((observed - simulated) / noise.std(simulated), noise.correlation).ravel()

    def n_residuals(self, observed: np.ndarray) -> int:
        """How many :meth:`residuals` a simulation of ``observed``'s shape gives."""
        return observed.size


class SummaryLikelihoodKernel(Op):
    """PyTensor op ``(epsilon, observed, simulated) -> [log p(summaries | simulated)]`` under an
    :class:`~pymc_vcc.inference.error_model.ErrorBudget` (which holds the observed summaries);
    −inf for a failed simulation."""

    __props__ = ("budget",)

    def __init__(self, budget: ErrorBudget) -> None:
        self.budget = budget

    def make_node(self, epsilon, observed, simulated) -> Apply:
        inputs = [pt.as_tensor_variable(value) for value in (epsilon, observed, simulated)]
        return Apply(self, inputs, [pt.dvector()])

    def perform(self, node, inputs, output_storage) -> None:
        output_storage[0][0] = np.atleast_1d(self.budget.log_likelihood(inputs[2]))

    def residuals(self, observed: np.ndarray, simulated: np.ndarray) -> np.ndarray:
        """The whitened residual of the budget's summaries (its own observed ones)."""
        return self.budget.whitened(simulated)

    def n_residuals(self, observed: np.ndarray) -> int:
        """How many :meth:`residuals` a simulation gives: one per summary."""
        return self.budget.observed.size


def add_likelihood(
    name: str,
    simulator: Simulator,
    observed: OutputData,
    *,
    sensor_noise: SensorNoise | None = None,
    error_budget: ErrorBudget | None = None,
    prior: Prior | Bounds | None = None,
    parameters: Sequence[str] | None = None,
    outputs: Sequence[str] | None = None,
    time_limit_s: float | None = None,
) -> SimulatorNode:
    """Add the exact likelihood of ``observed`` under ``sensor_noise`` to the current model.

    Args:
        name: name of the observed node (coords ``<name>_output``, ``<name>_time``).
        simulator: a deterministic ``simulator(theta, rng) -> Dataset | array``, picklable,
            on the time grid of ``observed``.
        observed: measured outputs; a Dataset whose variables carry ``units`` (K, Pa, kg/s, W)
            so that each output gets its kind's noise (or name kinds in ``sensor_noise``).
        sensor_noise: the sensors' noise (known scales; correlation and Student-t allowed):
            the likelihood of every sample of a model that is the unit.
        error_budget: instead of ``sensor_noise``, the likelihood of plateau summaries under
            sensor and model errors (:mod:`pymc_vcc.inference.error_model`): for a real unit.
        prior: a :class:`UniformPrior`, a :class:`.GMMPrior` or bounds name -> (low, high)
            (default: uniform on the simulator's bounds).
        parameters: parameters to calibrate (default: those of ``prior``).
        outputs: outputs in the likelihood (default: all of ``observed``).
        time_limit_s: wall-time limit of one simulation, s; a slower run has zero likelihood.

    Returns:
        A :class:`~pymc_vcc.inference.pymc.model.SimulatorNode` (no noise outputs).
    """
    model = pm.modelcontext(None)
    if (sensor_noise is None) == (error_budget is None):
        raise ValueError("add_likelihood takes exactly one of sensor_noise and error_budget")
    if error_budget is not None and not isinstance(error_budget, ErrorBudget):
        raise TypeError(f"error_budget must be an ErrorBudget, got {type(error_budget).__name__}")
    if sensor_noise is not None and not isinstance(sensor_noise, SensorNoise):
        raise TypeError(f"sensor_noise must be a SensorNoise, got {type(sensor_noise).__name__}")
    if sensor_noise is not None and sensor_noise.learnable:
        raise ValueError(
            "add_likelihood takes known noise scales (SensorNoise(learnable=False)); learnable "
            "scales are calibrated by the ABC paths (add_simulator, abc_rejection)"
        )
    info = check_simulator(simulator)
    data = prepare_observed(observed, outputs, info.output_names)
    if error_budget is not None and data.names != error_budget.outputs:
        raise ValueError(
            f"the error budget's outputs {list(error_budget.outputs)} differ from the observed "
            f"outputs {list(data.names)}"
        )
    distance = (
        SummaryLikelihoodKernel(error_budget)
        if error_budget is not None
        else LogLikelihoodKernel(sensor_noise.resolve(data))
    )
    if prior is None:
        prior = UniformPrior(simulator_bounds(simulator, parameters))
    elif not isinstance(prior, Prior):
        prior = UniformPrior(prior)
    if parameters is not None and set(parameters) != set(prior.names):
        raise ValueError(
            f"parameters {list(parameters)} differ from the prior's parameters {list(prior.names)}"
        )
    check_prior_support(info.support, prior.bounds)
    known = info.parameter_names
    unknown = [n for n in prior.names if known is not None and n not in known]
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown}; the simulator has {list(known)}")

    variables = prior_variables(prior, joint_name=f"{name}_theta")
    function = SimulatorFunction(simulator, prior.names, data, time_limit_s=time_limit_s)
    time = data.dataset["time"].values if "time" in data.dataset.coords else None
    model.add_coord(f"{name}_output", list(data.names))
    model.add_coord(f"{name}_time", time if time is not None else np.arange(data.values.shape[1]))
    variable = pm.Simulator(
        name,
        function,
        pt.stack([variables[n] for n in prior.names]),
        distance=distance,
        sum_stat="identity",
        epsilon=1.0,
        signature="(p)->()",
        observed=data.values,
        dims=(f"{name}_output", f"{name}_time"),
    )
    return SimulatorNode(variable, prior, prior.names, (), data, function, variables)


__all__ = ["LogLikelihoodKernel", "SummaryLikelihoodKernel", "add_likelihood"]
