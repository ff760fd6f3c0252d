"""Posterior predictive: simulate posterior draws (e.g. on a longer input profile) and summarise.

The paper's Figs. 6 and 8 show, for each output, the median and an interval of the outputs
simulated with posterior draws over the whole 2120 s profile, of which only the first 1060 s
were used for calibration. :func:`simulate_predictive` runs those simulations in parallel
(one random stream per draw from ``SeedSequence.spawn``, so the result does not depend on the
executor), with the output noise of data if asked (the paper's ν, or a
:class:`~pymc_vcc.inference.noise.SensorNoise` in engineering units), and returns the
posterior's DataTree with ArviZ's standard groups:

``posterior_predictive``
    one variable per output over (chain, draw, time), SI units and long names in its attrs;
    failed runs are NaN (counted in the group's attrs).
``observed_data``
    the reference outputs on the same profile (measured data, or the ground truth), when given;
    ArviZ pairs them with ``posterior_predictive`` by name (``az.plot_ppc_dist``).

(Not named ``sample_posterior_predictive``: PyMC's function of that name takes a model and
draws from its own ``pm.Simulator`` node.) :func:`predictive_bands` derives the median and
central interval of each output over the draws, for figures such as the paper's.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import xarray as xr

from pymc_vcc.execution.executors import WorkerCrash
from pymc_vcc.execution.options import RunOptions
from pymc_vcc.inference.noise import (
    OutputNoise,
    SensorNoise,
    add_output_noise,
    noise_parameter,
    sensor_parameter,
)
from pymc_vcc.inference.series import ObservedData, OutputData, prepare_observed
from pymc_vcc.inference.simulator import Simulator, SimulatorInfo, check_simulator, run_simulation

BANDS = ("lower", "median", "upper")


_DESCRIBING_ATTRS = ("units", "long_name")


@dataclass
class _TimeAndUnits:
    """A simulator wrapper that remembers the time grid, units and long names of the Dataset
    it returns."""

    simulator: Simulator
    time: np.ndarray | None = None
    units: dict[str, dict[str, str]] | None = None

    def __call__(self, theta: Mapping[str, float], rng: np.random.Generator) -> OutputData:
        result = self.simulator(theta, rng)
        if isinstance(result, xr.Dataset):
            if "time" in result.coords:
                self.time = np.asarray(result["time"].values)
            self.units = {
                str(name): {k: str(var.attrs[k]) for k in _DESCRIBING_ATTRS if k in var.attrs}
                for name, var in result.data_vars.items()
            }
        return result


@dataclass(frozen=True)
class PredictiveRun:
    """Worker side: one posterior draw simulated, with its output noise.

    Called with ``(theta, noise_scales, seed)``; returns ``(values | None, status, reason,
    time | None, attrs | None)`` with values (n_outputs, n_time) in ``layout.names`` order and
    attrs output -> its ``units`` and ``long_name``.
    """

    simulator: Simulator
    layout: ObservedData
    time_limit: float | None

    def __call__(self, item: tuple[dict[str, float], np.ndarray, np.random.SeedSequence]):
        theta, scales, seed = item
        rng = np.random.default_rng(seed)
        recorder = _TimeAndUnits(self.simulator)
        outcome = run_simulation(recorder, theta, rng, self.layout, time_limit_s=self.time_limit)
        if not outcome.ok:
            return None, outcome.status, outcome.reason, None, None
        values = outcome.values
        if np.any(scales > 0):
            values = add_output_noise(values, scales, rng)
        return values, outcome.status, "", recorder.time, recorder.units


def _layout(
    info: SimulatorInfo, outputs: Sequence[str] | None, reference: OutputData | None
) -> ObservedData:
    names = info.output_names
    if reference is not None:
        return prepare_observed(reference, outputs, names)
    if names is None:
        raise ValueError(
            "the simulator has no output_names; pass reference= (outputs on the prediction "
            "profile) so that outputs can be named"
        )
    names = tuple(names)
    selected = tuple(names if outputs is None else outputs)
    unknown = [name for name in selected if name not in names]
    if unknown or not selected or isinstance(outputs, str):
        raise ValueError(f"unknown outputs {unknown or outputs!r}; available: {list(names)}")
    return ObservedData(names, selected, np.empty((len(selected), 0)), xr.Dataset())


def _selected_draws(posterior: xr.Dataset, max_draws: int | None) -> xr.Dataset:
    if max_draws is None:
        return posterior
    if int(max_draws) != max_draws or max_draws < 1:
        raise ValueError(f"max_draws must be a positive integer or None, got {max_draws}")
    n_chains, n_draws = posterior.sizes["chain"], posterior.sizes["draw"]
    per_chain = max(1, min(n_draws, int(max_draws) // n_chains))
    keep = np.unique(np.linspace(0, n_draws - 1, per_chain).round().astype(int))
    return posterior.isel(draw=keep)


def simulate_predictive(
    idata: xr.DataTree,
    simulator: Simulator,
    *,
    parameters: Sequence[str] | None = None,
    outputs: Sequence[str] | None = None,
    reference: OutputData | None = None,
    noise: bool = True,
    sensor_noise: SensorNoise | None = None,
    max_draws: int | None = None,
    run: RunOptions | None = None,
) -> xr.DataTree:
    """Simulate posterior draws with ``simulator``: ``idata`` with ``posterior_predictive``.

    Args:
        idata: a result with a ``posterior`` group holding one (chain, draw) variable per
            parameter (from :func:`pymc_vcc.inference.pymc.smc.sample_smc_abc` or the rejection
            sampler).
        simulator: the model on the prediction profile, e.g. ``VCCSimulator(unit, inputs)``
            with the full 2120 s inputs.
        parameters: posterior variables passed to the simulator (default: those it names in
            ``parameter_names``); parameters left out keep the simulator's nominal values.
        outputs: outputs to predict (default: every output of the simulator or reference).
        reference: outputs observed (or true) on the same profile, stored as ``observed_data``
            (in place of the calibration data) for comparison.
        noise: add the output noise (the predictive of data): the paper's ``Y + ν·|Y|·Z`` for
            outputs whose ``nu_<output>`` is in the posterior, and ``sensor_noise`` if given;
            False: predict the noise-free outputs (smooth bands).
        sensor_noise: sensor noise in engineering units added to every draw (with
            ``noise``), its kind per output told by the outputs' ``units``; a learnable
            scale ``sigma_<output>`` in the posterior replaces the fixed scale draw by draw.
        max_draws: simulate at most this many posterior draws, evenly thinned (default: all).
        run: where and how the simulations run (no checkpoint, no progress bar); its
            ``seed`` seeds the simulations' random streams (noise, stochastic simulators).

    Returns:
        A copy of ``idata`` with group ``posterior_predictive`` (its attrs give the draws
        simulated, failed and the failure kinds) and, if ``reference`` is given,
        ``observed_data`` holding it.
    """
    run = run or RunOptions()
    run.refuse_checkpoint("simulate_predictive")
    if "posterior" not in idata.children:
        raise ValueError("idata has no posterior group")
    posterior = _selected_draws(idata["posterior"].to_dataset(), max_draws)
    info = check_simulator(simulator)
    if parameters is None:
        known = info.parameter_names
        if known is None:
            raise ValueError("the simulator has no parameter_names; pass parameters=")
        parameters = [name for name in posterior.data_vars if name in known]
    missing = [name for name in parameters if name not in posterior.data_vars]
    if missing or not parameters:
        raise ValueError(
            f"posterior lacks parameter(s) {missing or parameters}; it has "
            f"{list(posterior.data_vars)}"
        )
    layout = _layout(info, outputs, reference)
    noise_names = [noise_parameter(name) for name in layout.names]
    n_chains, n_draws = posterior.sizes["chain"], posterior.sizes["draw"]
    values = {name: posterior[name].values.reshape(-1) for name in parameters}
    scales = np.column_stack(
        [
            posterior[name].values.reshape(-1)
            if noise and name in posterior.data_vars
            else np.zeros(n_chains * n_draws)
            for name in noise_names
        ]
    )
    seeds = run.seed_sequence().spawn(n_chains * n_draws)
    items = [
        ({name: float(values[name][i]) for name in parameters}, scales[i], seeds[i])
        for i in range(n_chains * n_draws)
    ]
    with run.open_executor() as pool:
        results = [
            (None, result.kind, result.reason, None, None)
            if isinstance(result, WorkerCrash)
            else result
            for result in pool.map(
                PredictiveRun(simulator, layout, run.time_limit), items, time_limit=run.time_limit
            )
        ]

    finished = [r for r in results if r[0] is not None]
    if not finished:
        kinds = Counter(r[1] for r in results)
        raise RuntimeError(
            f"all {len(results)} predictive simulations failed ({dict(kinds)}), e.g. "
            f"{results[0][2]!r}"
        )
    n_time = finished[0][0].shape[1]
    time = finished[0][3] if finished[0][3] is not None else np.arange(n_time)
    units = finished[0][4] or {}
    stacked = np.full((n_chains * n_draws, len(layout.names), n_time), np.nan)
    for index, (simulated, *_rest) in enumerate(results):
        if simulated is not None:
            stacked[index] = simulated
    if noise and sensor_noise is not None:
        given = {name: var.attrs.get("units") for name, var in layout.dataset.data_vars.items()}
        known = {name: units.get(name, {}).get("units") or given.get(name) for name in layout.names}
        learned = np.column_stack(
            [
                posterior[sensor_parameter(name)].values.reshape(-1)
                if sensor_parameter(name) in posterior.data_vars
                else np.full(n_chains * n_draws, np.nan)
                for name in layout.names
            ]
        )
        _add_sensor_noise(stacked, sensor_noise.for_outputs(known), learned, seeds)
    stacked = stacked.reshape(n_chains, n_draws, len(layout.names), n_time)
    coords = {"chain": posterior["chain"].values, "draw": posterior["draw"].values, "time": time}
    predictive = xr.Dataset(
        {
            name: (("chain", "draw", "time"), stacked[:, :, j], units.get(name, {}))
            for j, name in enumerate(layout.names)
        },
        coords=coords,
    )
    predictive["time"].attrs["units"] = "s"
    failures = Counter(r[1] for r in results if r[0] is None)
    predictive.attrs.update(
        {
            "n_draws": int(n_chains * n_draws),
            "n_failed": int(sum(failures.values())),
            "failure_kinds": ", ".join(f"{k}: {n}" for k, n in sorted(failures.items())),
            "noise": int(bool(noise)),
        }
    )
    tree = idata.copy()
    tree["posterior_predictive"] = xr.DataTree(predictive)
    if reference is not None:
        observed = layout.dataset.copy()
        for name in observed.data_vars:
            observed[name].attrs = {**units.get(name, {}), **observed[name].attrs}
        tree["observed_data"] = xr.DataTree(observed)
    return tree


def _add_sensor_noise(
    stacked: np.ndarray,
    noise: OutputNoise,
    learned: np.ndarray,
    seeds: Sequence[np.random.SeedSequence],
) -> None:
    """Add ``noise`` in place to each finished draw of ``stacked`` (draws, outputs, time), from
    a stream spawned off the draw's seed; ``learned`` (draws, outputs) holds the calibrated
    scales, NaN where the fixed scale applies."""
    for index, seed in enumerate(seeds):
        if np.isnan(stacked[index]).any():
            continue
        scales = np.where(np.isnan(learned[index]), noise.scales, learned[index])
        rng = np.random.default_rng(seed.spawn(1)[0])
        stacked[index] = noise.sample(stacked[index], rng, scales)


def predictive_bands(tree: xr.DataTree, interval: float = 0.9) -> xr.Dataset:
    """Median and central interval of every output of ``tree``'s ``posterior_predictive``.

    Args:
        tree: a result with a ``posterior_predictive`` group of (chain, draw, time) outputs.
        interval: probability mass of the central band, in (0, 1) (e.g. 0.9 → 5 %–95 %).

    Returns:
        One variable per output over (band, time), band = lower, median, upper, with the
        output's attrs; draws with any NaN (failed runs) are left out and counted in the attrs
        (``n_draws``, ``n_failed``, ``interval``).
    """
    if "posterior_predictive" not in tree.children:
        raise ValueError("tree has no posterior_predictive group; run simulate_predictive")
    if not 0.0 < interval < 1.0:
        raise ValueError(f"interval must lie in (0, 1), got {interval}")
    predictive = tree["posterior_predictive"].to_dataset()
    names = list(predictive.data_vars)
    stacked = np.stack([predictive[name].values for name in names], axis=2)
    flat = stacked.reshape(-1, *stacked.shape[2:])  # (draws, output, time)
    ok = ~np.isnan(flat).any(axis=(1, 2))
    if not ok.any():
        raise ValueError("every posterior predictive draw failed; no band can be drawn")
    probabilities = [(1 - interval) / 2, 0.5, (1 + interval) / 2]
    quantiles = np.quantile(flat[ok], probabilities, axis=0)  # (band, output, time)
    return xr.Dataset(
        {
            name: (("band", "time"), quantiles[:, j], predictive[name].attrs)
            for j, name in enumerate(names)
        },
        coords={
            "band": list(BANDS),
            "time": predictive["time"],
            "probability": ("band", probabilities),
        },
        attrs={"interval": float(interval), "n_draws": int(ok.size), "n_failed": int((~ok).sum())},
    )


__all__ = ["BANDS", "PredictiveRun", "predictive_bands", "simulate_predictive"]
