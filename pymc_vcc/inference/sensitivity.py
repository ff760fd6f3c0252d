"""Sobol sensitivity of time-averaged outputs to the calibration parameters (paper's appendix).

Parameter sets come from SALib's Saltelli scheme (first and total order: ``n_base · (D + 2)``
simulations for D parameters); each simulation is reduced to the time average of each output
over a window (the paper: 20 s to 1060 s) and SALib estimates the indices.

Failed simulations are handled without biasing the estimators' structure: Saltelli's rows come
in blocks of ``D + 2`` per base sample (A, the D mixed rows AB_j, B), and the estimators combine
rows of one block only. A block with any failed row is dropped whole, so the indices are those of
the surviving base samples (the parameter region where the model runs), and the drop is counted.

With a ``checkpoint`` file every finished simulation is persisted as its chunk completes, and a
run started again with the same arguments resumes there, recomputing none of them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import xarray as xr
from SALib.analyze import sobol as sobol_analyze
from SALib.sample import sobol as sobol_sample

from pymc_vcc.execution.executors import Executor, WorkerCrash
from pymc_vcc.execution.options import RunOptions
from pymc_vcc.execution.outcomes import crash_outcome
from pymc_vcc.execution.store import ResultRecord, ResultStore
from pymc_vcc.inference.priors import check_prior_support, validate_bounds
from pymc_vcc.inference.series import OutputData, prepare_observed
from pymc_vcc.inference.simulator import Simulator, check_simulator, run_simulation
from pymc_vcc.physics.inputs import CALIBRATION_SECONDS


@dataclass(frozen=True)
class WindowMean:
    """A simulator reduced to the time average of each output over ``window`` (s).

    Returns a (n_outputs, 1) array; a result flagged failed passes through unchanged so that
    its reason is reported. Arrays without a time axis are averaged over all columns.
    """

    simulator: Simulator
    outputs: tuple[str, ...]
    window: tuple[float, float] | None

    def __call__(self, theta: Mapping[str, float], rng: np.random.Generator) -> OutputData:
        result = self.simulator(theta, rng)
        if isinstance(result, xr.Dataset):
            if result.attrs.get("status", "ok") != "ok":
                return result
            if self.window is not None:
                result = result.sel(time=slice(*self.window))
            return np.array([[float(result[name].mean())] for name in self.outputs])
        values = np.asarray(result, dtype=float)
        return values.mean(axis=-1, keepdims=True)


@dataclass(frozen=True)
class _SobolTask:
    """Worker side: simulate one Saltelli row; returns its record (means None if failed)."""

    reduced: WindowMean
    names: tuple[str, ...]
    seed: int
    time_limit: float | None

    def __call__(self, item: tuple[int, np.ndarray]) -> ResultRecord:
        index, row = item
        template = prepare_observed(
            np.zeros((len(self.reduced.outputs), 1)), output_names=self.reduced.outputs
        )
        rng = np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(index,)))
        theta = dict(zip(self.names, map(float, row), strict=True))
        outcome = run_simulation(self.reduced, theta, rng, template, time_limit_s=self.time_limit)
        means = None if outcome.values is None else tuple(map(float, outcome.values[:, 0]))
        return ResultRecord(index, means, outcome.status, outcome.reason, outcome.elapsed)


def _crash_record(index: int, crash: WorkerCrash) -> ResultRecord:
    outcome = crash_outcome(crash)
    return ResultRecord(index, None, outcome.status, outcome.reason, outcome.elapsed)


def _run_rows(
    runner: Executor, task: _SobolTask, rows: np.ndarray, store: ResultStore | None
) -> list[ResultRecord]:
    """Every row's record: from the checkpoint, else simulated (and persisted chunk by chunk)."""
    records = store.load() if store is not None else {}
    todo = [index for index in range(len(rows)) if index not in records]
    chunks = runner.imap_chunks(
        task, ((index, rows[index]) for index in todo), time_limit=task.time_limit
    )
    try:
        for chunk in chunks:
            finished = [
                _crash_record(todo[position], result) if isinstance(result, WorkerCrash) else result
                for position, result in chunk
            ]
            if store is not None:
                store.append(finished)
            records.update((record.index, record) for record in finished)
    finally:
        chunks.close()
    return [records[index] for index in range(len(rows))]


def _integer_seed(seed: int | np.random.SeedSequence | None) -> int | None:
    """The integer a Sobol run is seeded with (one drawn from a SeedSequence); None stays."""
    if isinstance(seed, np.random.SeedSequence):
        return int(seed.generate_state(1)[0])
    if seed is not None and (isinstance(seed, bool) or int(seed) != seed or seed < 0):
        raise ValueError(f"seed must be a non-negative integer or a SeedSequence, got {seed!r}")
    return seed


def sobol_indices(
    simulator: Simulator,
    bounds: Mapping[str, tuple[float, float]],
    outputs: Sequence[str],
    *,
    n_base: int = 1024,
    window: tuple[float, float] | None = (20.0, CALIBRATION_SECONDS),
    n_resamples: int = 100,
    run: RunOptions | None = None,
) -> xr.Dataset:
    """First- and total-order Sobol indices of each output's time average.

    Args:
        simulator: ``simulator(theta, rng) -> outputs``; parameters not in ``bounds`` keep the
            simulator's defaults.
        bounds: ``{name: (low, high)}`` of the varied parameters (SI units).
        outputs: names of the outputs analysed.
        n_base: Saltelli base samples N (a power of 2); ``N · (D + 2)`` simulations run.
        window: time window of the average, s (None: the whole run).
        n_resamples: bootstrap resamples of SALib's confidence intervals.
        run: where and how the simulations run (no progress bar); its ``seed`` seeds the
            scrambled Sobol sequence and the simulations' random streams, and its
            ``checkpoint`` is an SQLite file persisting finished simulations (a run started
            again with the same arguments resumes there and recomputes nothing finished).

    Returns:
        Dataset with ``S1``, ``ST`` and their 95 % half-widths ``S1_conf``, ``ST_conf`` over
        (parameter, output); attrs count simulations, failures and dropped base samples.
    """
    run = run or RunOptions()
    checked = validate_bounds(bounds)
    check_prior_support(check_simulator(simulator).support, checked)
    names = tuple(checked)
    outputs = tuple(outputs)
    if not outputs:
        raise ValueError("outputs is empty; name at least one output to analyse")
    if n_base < 2:
        raise ValueError(f"n_base must be at least 2, got {n_base}")
    if window is not None and not window[0] < window[1]:
        raise ValueError(f"window must be (start, end) with start < end, got {window}")
    problem = {
        "num_vars": len(names),
        "names": list(names),
        "bounds": [list(checked[name]) for name in names],
    }
    settings = {
        "sampler": "sobol_indices",
        "problem": problem,
        "outputs": list(outputs),
        "n_base": int(n_base),
        "window": None if window is None else list(map(float, window)),
        "simulator": f"{type(simulator).__module__}.{type(simulator).__qualname__}",
        "time_limit": run.time_limit,
    }
    seed = _integer_seed(run.seed)
    store = ResultStore(run.checkpoint, settings, seed) if run.checkpoint is not None else None
    if store is not None:
        seed = store.entropy
    elif seed is None:
        seed = int(np.random.SeedSequence().entropy)
    rows = sobol_sample.sample(problem, n_base, calc_second_order=False, seed=seed)
    task = _SobolTask(WindowMean(simulator, outputs, window), names, seed, run.time_limit)
    try:
        with run.open_executor() as runner:
            results = _run_rows(runner, task, rows, store)
    finally:
        if store is not None:
            store.close()

    block = len(names) + 2
    failed = np.array([record.values is None for record in results]).reshape(n_base, block)
    kept_blocks = ~failed.any(axis=1)
    if kept_blocks.sum() < 2:
        raise RuntimeError(
            f"{int(failed.sum())} of {len(rows)} simulations failed, leaving "
            f"{int(kept_blocks.sum())} complete Saltelli block(s); Sobol indices need at least 2"
        )
    kept_rows = np.repeat(kept_blocks, block)
    values = np.array(
        [record.values for record, keep in zip(results, kept_rows, strict=True) if keep]
    )

    indices = {key: np.empty((len(names), len(outputs))) for key in ("S1", "ST")}
    conf = {key: np.empty((len(names), len(outputs))) for key in ("S1_conf", "ST_conf")}
    for j in range(len(outputs)):
        analysis = sobol_analyze.analyze(
            problem,
            values[:, j],
            calc_second_order=False,
            num_resamples=n_resamples,
            seed=seed,
        )
        for key in indices:
            indices[key][:, j] = analysis[key]
        for key in conf:
            conf[key][:, j] = analysis[key]

    reasons: dict[str, int] = {}
    for record in results:
        if record.status != "ok":
            text = f"{record.status}: {record.reason}"
            reasons[text] = reasons.get(text, 0) + 1
    dims = ("parameter", "output")
    return xr.Dataset(
        {key: (dims, value) for key, value in {**indices, **conf}.items()},
        coords={"parameter": list(names), "output": list(outputs)},
        attrs={
            "n_base": n_base,
            "n_simulations": len(rows),
            "n_failed": int(failed.sum()),
            "n_dropped_base_samples": int((~kept_blocks).sum()),
            "failure_reasons": "; ".join(f"{count}× {text}" for text, count in reasons.items()),
            "window": "whole run" if window is None else f"{window[0]} s to {window[1]} s",
        },
    )
