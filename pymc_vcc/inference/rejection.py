"""The paper's ABC rejection sampler: Algorithm 1 for one dataset (pilot phase, then main phase).

Pilot: draw θ from the prior ``n_pilot`` times, simulate, add the learnable output noise, and set
the threshold ε to the ``quantile`` of the distances. Main: draw θ again, up to ``n_main`` times,
and accept every θ whose distance is at most ε, stopping at ``n_desired`` accepted.

θ holds the model parameters γ and, per noisy output j, a noise scale ν_j named ``nu_<output>``:
the simulated outputs become Y + ν·|Y|·Z, Z ~ N(0, 1), before the distance, as in Algorithm 1.

Every simulation has its own random stream, derived from the seed by index
(``SeedSequence(entropy, spawn_key=(..., stream, index))``, what ``SeedSequence.spawn`` gives),
and θ is drawn in the calling process; so the result does not depend on the executor, on
chunking or on completion order, and a run resumed from a checkpoint equals an uninterrupted
one. In the main phase the accepted set is the first ``n_desired`` acceptable draws in draw
order, whatever finished first.
"""

from __future__ import annotations

import json
import time
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime

import numpy as np
import xarray as xr

from pymc_vcc import __version__
from pymc_vcc.execution.executors import Executor, WorkerCrash
from pymc_vcc.execution.options import RunOptions
from pymc_vcc.execution.outcomes import OK, crash_outcome
from pymc_vcc.execution.progress import PhaseProgress, progress_enabled
from pymc_vcc.execution.store import (
    SimulationRecord,
    SimulationStore,
    array_digest,
    describe_callable,
)
from pymc_vcc.inference.distances import BatchDistance, ks_distances
from pymc_vcc.inference.noise import (
    OutputNoise,
    SensorNoise,
    add_output_noise,
    extended_prior,
    is_noise_parameter,
    noise_parameter,
    sensor_parameter,
    with_noise,
)
from pymc_vcc.inference.priors import Prior, check_prior_support
from pymc_vcc.inference.series import ObservedData, OutputData, prepare_observed
from pymc_vcc.inference.simulator import Simulator, SimulatorInfo, check_simulator, run_simulation
from pymc_vcc.physics.failures import FailureKind

PILOT, MAIN = 0, 1
PHASE_NAMES = ("pilot", "main")
_MIN_RUNS_FOR_FAILURE_CHECK = 50


class TooManyFailuresError(RuntimeError):
    """Most simulations of a run failed: the run stops rather than report a meaningless result."""


def simulation_rng(
    entropy: int, spawn_key: tuple[int, ...], stream: int, index: int
) -> np.random.Generator:
    """The random generator of one draw: child ``index`` of child ``stream`` of the seed."""
    return np.random.default_rng(
        np.random.SeedSequence(entropy, spawn_key=(*spawn_key, stream, index))
    )


def prior_stream(phase: int) -> int:
    return 2 * phase


def simulation_stream(phase: int) -> int:
    return 2 * phase + 1


@dataclass(frozen=True)
class SimulationTask:
    """Worker side of the sampler: simulate a chunk of draws, add noise, compute distances.

    Called with a list of ``(phase, index, theta_row)``; returns one
    :class:`~pymc_vcc.execution.store.SimulationRecord` per item. A simulation that kills its worker
    process comes back from the executor as a :class:`~pymc_vcc.execution.executors.WorkerCrash`,
    which :func:`_run_phase` records as a ``worker-crash`` failure.
    """

    simulator: Simulator
    observed: ObservedData
    model_names: tuple[str, ...]
    model_columns: tuple[int, ...]
    noise_columns: tuple[int, ...]
    distance: BatchDistance
    entropy: int
    spawn_key: tuple[int, ...]
    time_limit: float | None
    sensor_noise: OutputNoise | None = None
    sensor_columns: tuple[int, ...] = ()

    def add_noise(
        self, values: np.ndarray, theta: np.ndarray, rng: np.random.Generator
    ) -> np.ndarray:
        """The paper's Y + ν·|Y|·Z (ν per output, 0 without a scale), then the sensor noise."""
        if any(column >= 0 for column in self.noise_columns):
            scales = np.array([theta[c] if c >= 0 else 0.0 for c in self.noise_columns])
            values = add_output_noise(values, scales, rng)
        if self.sensor_noise is not None:
            learned = [theta[c] for c in self.sensor_columns if c >= 0]
            values = self.sensor_noise.sample(values, rng, np.array(learned) if learned else None)
        return values

    def __call__(self, items: list[tuple[int, int, np.ndarray]]) -> list[SimulationRecord]:
        records: list[SimulationRecord | None] = [None] * len(items)
        finished: dict[tuple[int, ...], list[tuple[int, np.ndarray]]] = {}
        for position, (phase, index, theta) in enumerate(items):
            rng = simulation_rng(self.entropy, self.spawn_key, simulation_stream(phase), index)
            parameters = {
                name: float(theta[column])
                for name, column in zip(self.model_names, self.model_columns, strict=True)
            }
            outcome = run_simulation(
                self.simulator, parameters, rng, self.observed, time_limit_s=self.time_limit
            )
            records[position] = SimulationRecord(
                phase, index, np.nan, outcome.status, outcome.reason, outcome.elapsed
            )
            if outcome.ok:
                values = self.add_noise(outcome.values, theta, rng)
                finished.setdefault(values.shape, []).append((position, values))
        for group in finished.values():
            distances = np.asarray(
                self.distance(np.stack([values for _, values in group]), self.observed.values),
                dtype=float,
            )
            if distances.shape != (len(group),):
                raise ValueError(
                    f"distance returned shape {distances.shape} for {len(group)} simulations; "
                    "a batch distance maps (N, n_outputs, m) to (N,)"
                )
            for (position, _), value in zip(group, distances, strict=True):
                record = records[position]
                if np.isfinite(value):
                    records[position] = record._replace(distance=float(value))
                else:
                    records[position] = record._replace(
                        status=FailureKind.NON_FINITE, reason=f"distance is {value}"
                    )
        return records


class PhaseRecords:
    """What is known about the simulations of one phase, by draw index."""

    def __init__(self, size: int) -> None:
        self.distance = np.full(size, np.nan)
        self.status = np.full(size, "", dtype=object)
        self.reason = np.full(size, "", dtype=object)
        self.elapsed = np.zeros(size)
        self.done = np.zeros(size, dtype=bool)
        self.n_done = 0
        self.n_failed = 0

    def add(self, record: SimulationRecord) -> None:
        if not self.done[record.index]:
            self.n_done += 1
            self.n_failed += record.status != OK
        self.done[record.index] = True
        self.distance[record.index] = record.distance
        self.status[record.index] = record.status
        self.reason[record.index] = record.reason
        self.elapsed[record.index] = record.elapsed


class AcceptanceScan:
    """Walks the main phase in draw order; finds where the n_desired-th acceptance happens."""

    def __init__(self, records: PhaseRecords, epsilon: float, n_desired: int) -> None:
        self.records = records
        self.epsilon = epsilon
        self.n_desired = n_desired
        self.position = 0
        self.accepted = 0
        self.stop: int | None = None

    def advance(self) -> bool:
        """Move over every contiguous finished draw; True once the n_desired-th is accepted."""
        records = self.records
        while self.stop is None and self.position < records.done.size:
            if not records.done[self.position]:
                break
            if records.status[self.position] == OK and (
                records.distance[self.position] <= self.epsilon
            ):
                self.accepted += 1
                if self.accepted == self.n_desired:
                    self.stop = self.position
            self.position += 1
        return self.stop is not None


def _check_settings(n_pilot: int, quantile: float, n_main: int, n_desired: int) -> None:
    for name, value in (("n_pilot", n_pilot), ("n_main", n_main), ("n_desired", n_desired)):
        if isinstance(value, bool) or int(value) != value or value < 1:
            raise ValueError(f"{name} must be a positive integer, got {value!r}")
    if not 0.0 < quantile < 1.0:
        raise ValueError(f"quantile must lie in (0, 1), got {quantile}")
    if n_desired > n_main:
        raise ValueError(
            f"n_desired={n_desired} exceeds n_main={n_main}: the main phase cannot accept more "
            "draws than it makes"
        )


def prepare_observed_for(
    info: SimulatorInfo, observed: OutputData, outputs: Sequence[str] | None
) -> ObservedData:
    simulated = info.output_names
    data = prepare_observed(observed, outputs, output_names=simulated)
    if simulated is not None:
        foreign = [name for name in data.names if name not in simulated]
        if foreign:
            raise ValueError(
                f"outputs {foreign} are not produced by the simulator, whose outputs are "
                f"{list(simulated)}"
            )
    return data


def _model_names(info: SimulatorInfo, prior: Prior) -> tuple[str, ...]:
    check_prior_support(info.support, prior.bounds)
    model = tuple(name for name in prior.names if not is_noise_parameter(name))
    expected = info.parameter_names
    if expected is not None and set(expected) != set(model):
        missing = sorted(set(expected) - set(model))
        extra = sorted(set(model) - set(expected))
        raise ValueError(
            f"prior and simulator disagree on parameter names: the prior lacks {missing} and "
            f"has unknown {extra}; the simulator takes {list(expected)}"
        )
    return model


def split_seed(seed: int | np.random.SeedSequence | None) -> tuple[int | None, tuple[int, ...]]:
    """(entropy, spawn_key) of a seed; (None, ()) for None."""
    if seed is None:
        return None, ()
    if isinstance(seed, np.random.SeedSequence):
        return int(seed.entropy), tuple(int(k) for k in seed.spawn_key)
    if isinstance(seed, bool) or int(seed) != seed or seed < 0:
        raise ValueError(f"seed must be a non-negative integer or a SeedSequence, got {seed!r}")
    return int(seed), ()


def _check_failures(records: PhaseRecords, phase: int, size: int, max_rate: float) -> None:
    checked_after = min(size, _MIN_RUNS_FOR_FAILURE_CHECK)
    if records.n_done >= checked_after and records.n_failed > max_rate * records.n_done:
        failed = records.status[records.done & (records.status != OK)]
        kinds, counts = np.unique(failed.astype(str), return_counts=True)
        summary = ", ".join(f"{kind}: {count}" for kind, count in zip(kinds, counts, strict=True))
        example = records.reason[records.done & (records.status != OK)][0]
        raise TooManyFailuresError(
            f"most simulations failed: {records.n_failed} of {records.n_done} in the "
            f"{PHASE_NAMES[phase]} phase ({summary}; e.g. {example!r}), over the allowed "
            f"fraction max_failure_rate={max_rate}; check the prior bounds and the simulator"
        )


def _crash_record(phase: int, index: int, crash: WorkerCrash) -> SimulationRecord:
    outcome = crash_outcome(crash)
    return SimulationRecord(phase, index, np.nan, outcome.status, outcome.reason, outcome.elapsed)


def _run_phase(
    executor: Executor,
    task: SimulationTask,
    phase: int,
    thetas: np.ndarray,
    records: PhaseRecords,
    store: SimulationStore | None,
    bar: PhaseProgress,
    max_failure_rate: float,
    scan: AcceptanceScan | None = None,
) -> None:
    size = thetas.shape[0]
    _check_failures(records, phase, size, max_failure_rate)
    if scan is not None and scan.advance():
        return
    bar.start_phase(f"{PHASE_NAMES[phase]:5s}", size, records.n_done)
    todo = np.flatnonzero(~records.done)
    items = ((phase, int(index), thetas[index]) for index in todo)
    chunks = executor.imap_chunks(task, items, batched=True, time_limit=task.time_limit)
    try:
        for chunk in chunks:
            finished = [
                _crash_record(phase, int(todo[position]), result)
                if isinstance(result, WorkerCrash)
                else result
                for position, result in chunk
            ]
            if store is not None:
                store.append(finished)
            for record in finished:
                records.add(record)
            _check_failures(records, phase, size, max_failure_rate)
            stop = scan is not None and scan.advance()
            bar.update(records.n_done, scan.accepted if scan is not None else 0, records.n_failed)
            if stop:
                break
    finally:
        chunks.close()


def abc_rejection(
    simulator: Simulator,
    prior: Prior,
    observed: OutputData,
    *,
    n_pilot: int = 5000,
    quantile: float = 0.05,
    n_main: int = 80000,
    n_desired: int = 4000,
    noise: Mapping[str, tuple[float, float]] | None = None,
    sensor_noise: SensorNoise | None = None,
    outputs: Sequence[str] | None = None,
    distance: BatchDistance = ks_distances,
    run: RunOptions | None = None,
) -> xr.DataTree:
    """ABC rejection with a pilot-quantile threshold (the paper's Algorithm 1, one dataset).

    Args:
        simulator: ``simulator(theta, rng)`` → Dataset (one variable per output over time) or
            array (outputs, time); picklable for parallel executors.
        prior: distribution of the model parameters (and of the noise scales, if it has them).
        observed: observed outputs, Dataset or array (outputs, time); must be finite.
        n_pilot: pilot draws that set the threshold (Table I: 5000).
        quantile: ζ, the pilot-distance quantile taken as threshold ε, in (0, 1) (Table I: 0.05).
        n_main: most draws of the main phase (Table I: 80000).
        n_desired: accepted draws at which the main phase stops (Table I: 4000).
        noise: output -> (low, high) bounds of its noise scale ν (dimensionless, ≥ 0); ν gets a
            uniform prior unless ``prior`` already holds ``nu_<output>``. None: no noise.
        sensor_noise: sensor noise in engineering units added to every simulation before the
            distance (learnable scales ``sigma_<output>`` if ``sensor_noise.learnable``);
            observed outputs need ``units`` (K, Pa, kg/s, W) or ``sensor_noise.kinds``.
        outputs: outputs compared (default: all observed ones).
        distance: batch distance, (N, n_outputs, m) and (n_outputs, n) → (N,); default: the
            paper's KS distance.
        run: where and how the simulations run (default: every core, fresh entropy, no
            checkpoint); its ``checkpoint`` is an SQLite file persisting finished simulations
            (a run started again with the same arguments resumes there and recomputes nothing
            finished), and more than ``max_failure_rate`` of a phase's simulations failing
            (after its first 50) stops the run with :class:`TooManyFailuresError`.

    Returns:
        An ArviZ DataTree with groups ``posterior`` (accepted θ, chain × draw), ``prior`` (every
        simulated θ), ``observed_data`` and ``sample_stats`` (distances of the accepted draws;
        per simulation: phase, distance, status, failure reason, elapsed time, acceptance; and
        ε, counts, acceptance rate, ``failures`` over every ``failure_kind`` of
        :class:`~pymc_vcc.physics.failures.FailureKind`, wall time).

    Raises:
        ValueError: bad settings or data, before any simulation.
        TooManyFailuresError: most simulations failed.
    """
    started = time.perf_counter()
    run = run or RunOptions()
    _check_settings(n_pilot, quantile, n_main, n_desired)
    info = check_simulator(simulator)
    data = prepare_observed_for(info, observed, outputs)
    full_prior = with_noise(prior, noise, data.names)
    output_noise = None if sensor_noise is None else sensor_noise.resolve(data)
    if sensor_noise is not None:
        full_prior = extended_prior(full_prior, sensor_noise.prior_bounds(data))
    model_names = _model_names(info, full_prior)
    entropy, spawn_key = split_seed(run.seed)
    settings = {
        "sampler": "abc_rejection",
        "n_pilot": int(n_pilot),
        "quantile": float(quantile),
        "n_main": int(n_main),
        "n_desired": int(n_desired),
        "outputs": list(data.names),
        "noise": {key: list(map(float, pair)) for key, pair in (noise or {}).items()},
        "sensor_noise": repr(sensor_noise),
        "parameters": list(full_prior.names),
        "prior": full_prior.kind,
        "prior_digest": array_digest(
            *(v.values for _, v in sorted(full_prior.to_dataset().items()))
        ),
        "observed_digest": array_digest(data.values),
        "simulator": describe_callable(simulator),
        "distance": describe_callable(distance),
        "time_limit": run.time_limit,
        "spawn_key": list(spawn_key),
    }
    store = (
        SimulationStore(run.checkpoint, settings, entropy) if run.checkpoint is not None else None
    )
    try:
        if store is not None:
            entropy = store.entropy
        elif entropy is None:
            entropy = int(np.random.SeedSequence().entropy)
        thetas = {
            phase: full_prior.sample(
                size, simulation_rng(entropy, spawn_key, prior_stream(phase), 0)
            )
            for phase, size in ((PILOT, n_pilot), (MAIN, n_main))
        }
        records = {PILOT: PhaseRecords(n_pilot), MAIN: PhaseRecords(n_main)}
        for record in store.load() if store is not None else []:
            records[record.phase].add(record)
        task = SimulationTask(
            simulator=simulator,
            observed=data,
            model_names=model_names,
            model_columns=tuple(full_prior.names.index(name) for name in model_names),
            noise_columns=tuple(
                full_prior.names.index(noise_parameter(output))
                if noise_parameter(output) in full_prior.names
                else -1
                for output in data.names
            ),
            distance=distance,
            sensor_noise=output_noise,
            sensor_columns=tuple(
                full_prior.names.index(sensor_parameter(output))
                if sensor_parameter(output) in full_prior.names
                else -1
                for output in data.names
            ),
            entropy=entropy,
            spawn_key=spawn_key,
            time_limit=run.time_limit,
        )
        with run.open_executor() as pool, PhaseProgress(progress_enabled(run.progress)) as bar:
            _run_phase(
                pool, task, PILOT, thetas[PILOT], records[PILOT], store, bar, run.max_failure_rate
            )
            pilot_ok = records[PILOT].status == OK
            if not pilot_ok.any():
                raise TooManyFailuresError(
                    f"every one of the {n_pilot} pilot simulations failed; no threshold can be set"
                )
            epsilon = float(np.quantile(records[PILOT].distance[pilot_ok], quantile))
            scan = AcceptanceScan(records[MAIN], epsilon, n_desired)
            _run_phase(
                pool,
                task,
                MAIN,
                thetas[MAIN],
                records[MAIN],
                store,
                bar,
                run.max_failure_rate,
                scan,
            )
    finally:
        if store is not None:
            store.close()
    n_main_run = n_main if scan.stop is None else scan.stop + 1
    if scan.accepted <= len(full_prior.names):
        warnings.warn(
            f"{scan.accepted} accepted draws for {len(full_prior.names)} parameters: too few "
            "to describe a posterior; raise n_main or the quantile",
            RuntimeWarning,
            stacklevel=2,
        )
    return result_tree(
        full_prior.names,
        thetas,
        records,
        n_main_run,
        epsilon,
        data,
        settings | {"entropy": str(entropy)},
        time.perf_counter() - started,
    )


def _chain_draw(values: np.ndarray) -> tuple[tuple[str, str], np.ndarray]:
    return ("chain", "draw"), values[np.newaxis, :]


def _parameters_dataset(names: Sequence[str], thetas: np.ndarray) -> xr.Dataset:
    return xr.Dataset(
        {name: _chain_draw(thetas[:, j]) for j, name in enumerate(names)},
        coords={"chain": [0], "draw": np.arange(thetas.shape[0])},
    )


def result_tree(
    names: Sequence[str],
    thetas: dict[int, np.ndarray],
    records: dict[int, PhaseRecords],
    n_main_run: int,
    epsilon: float,
    data: ObservedData,
    settings: dict,
    wall_time: float,
) -> xr.DataTree:
    pilot, main = records[PILOT], records[MAIN]
    n_pilot = pilot.done.size
    ran = {PILOT: slice(0, n_pilot), MAIN: slice(0, n_main_run)}

    def joined(attribute: str) -> np.ndarray:
        return np.concatenate([getattr(records[p], attribute)[ran[p]] for p in (PILOT, MAIN)])

    status = joined("status").astype(str)
    distance = joined("distance")
    phase = np.repeat(np.array(PHASE_NAMES), [n_pilot, n_main_run])
    accepted = (phase == "main") & (status == OK) & (distance <= epsilon)
    accepted_main = accepted[n_pilot:]
    failed = status != OK
    n_main_ok = int((status[n_pilot:] == OK).sum())
    stats = xr.Dataset(
        {
            "distance": _chain_draw(main.distance[:n_main_run][accepted_main]),
            "sim_phase": ("simulation", phase),
            "sim_index": (
                "simulation",
                np.concatenate([np.arange(n_pilot), np.arange(n_main_run)]),
            ),
            "sim_distance": ("simulation", distance),
            "sim_status": ("simulation", status),
            "sim_failure_reason": ("simulation", joined("reason").astype(str)),
            "sim_elapsed": ("simulation", joined("elapsed"), {"units": "s"}),
            "sim_accepted": ("simulation", accepted),
            "epsilon": ((), epsilon),
            "n_simulations": ((), n_pilot + n_main_run),
            "n_failed": ((), int(failed.sum())),
            "n_accepted": ((), int(accepted.sum())),
            "acceptance_rate": ((), accepted.sum() / n_main_run),
            "acceptance_rate_ok": ((), accepted.sum() / n_main_ok if n_main_ok else 0.0),
            "failures": (
                "failure_kind",
                [int((status == kind.value).sum()) for kind in FailureKind],
            ),
            "wall_time": ((), wall_time, {"units": "s"}),
        },
        coords={
            "chain": [0],
            "draw": np.arange(int(accepted.sum())),
            "simulation": np.arange(n_pilot + n_main_run),
            "failure_kind": [kind.value for kind in FailureKind],
        },
    )
    stats["acceptance_rate"].attrs["long_name"] = "accepted / main-phase simulations run"
    stats["acceptance_rate_ok"].attrs["long_name"] = "accepted / successful main-phase runs"
    attrs = {
        "created_at": datetime.now(UTC).isoformat(),
        "creation_library": "pymc_vcc",
        "creation_library_version": __version__,
        "sampler": "abc_rejection",
        "settings": json.dumps(settings),
    }
    posterior = _parameters_dataset(names, thetas[MAIN][:n_main_run][accepted_main])
    prior = _parameters_dataset(names, np.vstack([thetas[PILOT], thetas[MAIN][:n_main_run]]))
    groups = {
        "posterior": posterior,
        "prior": prior,
        "observed_data": data.dataset.copy(),
        "sample_stats": stats,
    }
    for dataset in groups.values():
        dataset.attrs.update(attrs)
    tree = xr.DataTree.from_dict(groups)
    tree.attrs.update(attrs)
    return tree
