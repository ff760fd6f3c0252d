"""A reference table: noise-free simulations of prior draws, shared by many rejection runs.

Rejection ABC draws from the prior whatever the data. When many datasets (noise seeds, leak
stages) are calibrated against one prior with a deterministic simulator, one table of noise-free
simulations serves them all: per dataset, :func:`table_rejection` draws the sensor noise onto
each stored simulation (cheap), computes the distances and runs Algorithm 1 on the rows.

The table holds the draws :func:`~pymc_vcc.inference.rejection.abc_rejection` would make with
the same seed, ``n_pilot`` and ``n_main`` (same prior streams), and :func:`table_rejection`
draws each row's noise from the random stream ``abc_rejection`` gives that simulation: with the
table's seed and a simulator that does not use its random stream, the posterior equals
``abc_rejection``'s bit for bit. With another seed, only the noise differs; the draws (and
their simulations) are shared, so posteriors of datasets calibrated on one table are not
independent draws of the sampler: count the table's simulations once, as shared.

Checkpoints: each finished chunk of simulations is written atomically to its own ``.npz`` file
in the checkpoint folder, beside ``settings.json``; a build started again with the same
arguments loads them and simulates only the rest.
"""

from __future__ import annotations

import json
import time
import zipfile
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import xarray as xr

from pymc_vcc.execution.executors import WorkerCrash
from pymc_vcc.execution.options import RunOptions
from pymc_vcc.execution.outcomes import OK, crash_outcome
from pymc_vcc.execution.output_folder import atomic_path
from pymc_vcc.execution.progress import PhaseProgress, progress_enabled
from pymc_vcc.execution.store import (
    CheckpointDamagedError,
    CheckpointMismatchError,
    array_digest,
    describe_callable,
)
from pymc_vcc.inference.distances import BatchDistance, ks_distances
from pymc_vcc.inference.noise import SensorNoise, is_noise_parameter
from pymc_vcc.inference.priors import Prior, check_prior_support
from pymc_vcc.inference.rejection import (
    MAIN,
    PHASE_NAMES,
    PILOT,
    AcceptanceScan,
    PhaseRecords,
    prepare_observed_for,
    prior_stream,
    result_tree,
    simulation_rng,
    simulation_stream,
    split_seed,
)
from pymc_vcc.inference.series import ObservedData, OutputData, prepare_observed
from pymc_vcc.inference.simulator import Simulator, check_simulator, run_simulation

SETTINGS_FILE = "settings.json"


@dataclass(frozen=True)
class ReferenceTable:
    """Noise-free simulations of prior draws, per phase (pilot, main), in draw order.

    Attributes:
        names: parameter names, the columns of ``thetas``.
        outputs: simulated outputs, the rows of each simulation.
        thetas: phase -> draws (n, n_parameters).
        values: phase -> noise-free outputs (n, n_outputs, n_time), SI units; NaN if failed.
        status: phase -> status of each simulation (``"ok"`` or a failure kind).
        reason: phase -> why each failed simulation failed (empty if it did not).
        elapsed: phase -> wall time of each simulation, s.
        entropy, spawn_key: the seed the draws were made with.
    """

    names: tuple[str, ...]
    outputs: tuple[str, ...]
    thetas: Mapping[int, np.ndarray]
    values: Mapping[int, np.ndarray]
    status: Mapping[int, np.ndarray]
    reason: Mapping[int, np.ndarray]
    elapsed: Mapping[int, np.ndarray]
    entropy: int
    spawn_key: tuple[int, ...]

    @property
    def n_simulations(self) -> int:
        """Simulations in the table (pilot and main)."""
        return sum(rows.shape[0] for rows in self.thetas.values())


@dataclass(frozen=True)
class _TableTask:
    """Worker side: simulate a chunk of ``(phase, index, theta)``; noise-free outputs back."""

    simulator: Simulator
    observed: ObservedData
    names: tuple[str, ...]
    entropy: int
    spawn_key: tuple[int, ...]
    time_limit: float | None

    def __call__(self, items: list[tuple[int, int, np.ndarray]]) -> list[tuple]:
        results = []
        for phase, index, theta in items:
            rng = simulation_rng(self.entropy, self.spawn_key, simulation_stream(phase), index)
            parameters = {name: float(value) for name, value in zip(self.names, theta, strict=True)}
            outcome = run_simulation(
                self.simulator, parameters, rng, self.observed, time_limit_s=self.time_limit
            )
            results.append(
                (phase, index, outcome.values, outcome.status, outcome.reason, outcome.elapsed)
            )
        return results


CHUNK_SECONDS = 2.0
"""Longest a finished simulation waits in memory before its chunk file is written (a file per
executor chunk, ~0.05 s of work, made 20,000 files for one refined estimation study)."""


class _TableCheckpoint:
    """The checkpoint folder of a table: ``settings.json`` and one ``.npz`` per chunk of
    simulations finished within :data:`CHUNK_SECONDS`."""

    def __init__(self, folder: Path, settings: dict, entropy: int | None) -> None:
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        path = self.folder / SETTINGS_FILE
        wanted = json.loads(json.dumps(settings))
        if path.exists():
            stored = json.loads(path.read_text())
            saved_entropy = int(stored.pop("entropy"))
            if stored != wanted or (entropy is not None and entropy != saved_entropy):
                differing = sorted(
                    k for k in stored.keys() | wanted.keys() if stored.get(k) != wanted.get(k)
                )
                raise CheckpointMismatchError(
                    f"reference-table checkpoint {self.folder} belongs to a build with other "
                    f"arguments (differing: {differing or ['seed']}); use the same arguments to "
                    "resume, or another folder"
                )
            self.entropy = saved_entropy
        else:
            self.entropy = (
                int(np.random.SeedSequence().entropy) if entropy is None else int(entropy)
            )
            with atomic_path(path) as partial:
                partial.write_text(json.dumps({**wanted, "entropy": self.entropy}))
        self._written = len(list(self.folder.glob("chunk-*.npz")))
        self._waiting: list[tuple] = []
        self._shape: tuple[int, int] = (0, 0)
        self._last_write = time.monotonic()

    def load(self) -> list[tuple]:
        """Every stored simulation: (phase, index, values or None, status, reason, elapsed)."""
        rows = []
        fields = ("phase", "index", "values", "status", "reason", "elapsed")
        for path in sorted(self.folder.glob("chunk-*.npz")):
            try:
                with np.load(path) as chunk:
                    columns = [chunk[name] for name in fields]
            except (OSError, ValueError, KeyError, zipfile.BadZipFile) as error:
                raise CheckpointDamagedError(
                    f"reference-table chunk {path} is damaged ({error}); delete it to simulate "
                    "its rows again"
                ) from None
            for phase, index, values, status, reason, elapsed in zip(*columns, strict=True):
                kept = values if str(status) == OK else None
                rows.append(
                    (int(phase), int(index), kept, str(status), str(reason), float(elapsed))
                )
        return rows

    def append(self, rows: list[tuple], shape: tuple[int, int]) -> None:
        """Take finished simulations (outputs of ``shape``); written with those of the last
        :data:`CHUNK_SECONDS`."""
        self._waiting.extend(rows)
        self._shape = shape
        if time.monotonic() - self._last_write >= CHUNK_SECONDS:
            self.flush()

    def flush(self) -> None:
        """Persist the simulations taken since the last write as one chunk file, atomically."""
        rows, self._waiting = self._waiting, []
        self._last_write = time.monotonic()
        if not rows:
            return
        shape = self._shape
        values = np.stack([np.full(shape, np.nan) if r[2] is None else r[2] for r in rows])
        path = self.folder / f"chunk-{self._written:06d}.npz"
        with atomic_path(path) as partial, partial.open("wb") as stream:
            np.savez(
                stream,
                phase=np.array([r[0] for r in rows]),
                index=np.array([r[1] for r in rows]),
                values=values,
                status=np.array([r[3] for r in rows]),
                reason=np.array([r[4] for r in rows]),
                elapsed=np.array([r[5] for r in rows]),
            )
        self._written += 1


def simulate_table(
    simulator: Simulator,
    prior: Prior,
    observed: OutputData,
    *,
    n_pilot: int,
    n_main: int,
    run: RunOptions | None = None,
) -> ReferenceTable:
    """Simulate the ``n_pilot`` + ``n_main`` prior draws ``abc_rejection`` would make.

    Args:
        simulator: a deterministic ``simulator(theta, rng)``, picklable for parallel executors.
        prior: distribution of the model parameters (no noise scales: the table is noise-free).
        observed: any dataset on the data's grid: selects and orders the outputs stored.
        n_pilot, n_main: draws of the pilot and main phases (as ``abc_rejection``'s).
        run: where and how the simulations run, as for ``abc_rejection``: its ``seed`` draws
            the parameters (and seeds ``abc_rejection``'s noise streams), and its
            ``checkpoint`` is a folder persisting each finished chunk (a build started again
            with the same arguments resumes there).
    """
    run = run or RunOptions()
    for name, value in (("n_pilot", n_pilot), ("n_main", n_main)):
        if isinstance(value, bool) or int(value) != value or value < 1:
            raise ValueError(f"{name} must be a positive integer, got {value!r}")
    noise_scales = [name for name in prior.names if is_noise_parameter(name)]
    if noise_scales:
        raise ValueError(
            f"a reference table is noise-free: the prior holds noise scales {noise_scales}; "
            "give the model parameters only and the sensor noise to table_rejection"
        )
    info = check_simulator(simulator)
    data = prepare_observed_for(info, observed, None)
    check_prior_support(info.support, prior.bounds)
    entropy, spawn_key = split_seed(run.seed)
    settings = {
        "n_pilot": int(n_pilot),
        "n_main": int(n_main),
        "outputs": list(data.names),
        "n_time": int(data.values.shape[1]),
        "parameters": list(prior.names),
        "prior_digest": array_digest(*(v.values for _, v in sorted(prior.to_dataset().items()))),
        "simulator": describe_callable(simulator),
        "time_limit": run.time_limit,
        "spawn_key": list(spawn_key),
    }
    store, entropy = _open_checkpoint(run.checkpoint, settings, entropy)
    sizes = {PILOT: int(n_pilot), MAIN: int(n_main)}
    thetas = {
        phase: prior.sample(size, simulation_rng(entropy, spawn_key, prior_stream(phase), 0))
        for phase, size in sizes.items()
    }
    return _simulate_rows(
        simulator,
        data,
        tuple(prior.names),
        thetas,
        store,
        (entropy, spawn_key),
        run,
    )


def simulate_draws(
    simulator: Simulator,
    names: tuple[str, ...],
    thetas: np.ndarray,
    observed: OutputData,
    *,
    run: RunOptions | None = None,
) -> ReferenceTable:
    """Noise-free simulations of given parameter sets: a table with only a main phase.

    Args:
        simulator: a deterministic ``simulator(theta, rng)``, picklable for parallel executors.
        names: the parameters, the columns of ``thetas`` (model parameters only).
        thetas: the parameter sets, (n, len(names)), in SI units.
        observed: any dataset on the data's grid: selects and orders the outputs stored.
        run: where and how the simulations run, as for :func:`simulate_table`: its ``seed``
            seeds the simulations' random streams, and its ``checkpoint`` is a folder
            persisting each finished chunk (a run started again with the same arguments
            simulates only the rest).
    """
    run = run or RunOptions()
    thetas = np.asarray(thetas, dtype=float)
    if thetas.ndim != 2 or thetas.shape[1] != len(names) or thetas.shape[0] == 0:
        raise ValueError(
            f"thetas must have shape (n >= 1, {len(names)}) for parameters {list(names)}, got "
            f"{thetas.shape}"
        )
    info = check_simulator(simulator)
    data = prepare_observed_for(info, observed, None)
    check_prior_support(
        info.support,
        {
            name: (float(column.min()), float(column.max()))
            for name, column in zip(names, thetas.T, strict=True)
        },
    )
    entropy, spawn_key = split_seed(run.seed)
    settings = {
        "outputs": list(data.names),
        "n_time": int(data.values.shape[1]),
        "parameters": list(names),
        "draws_digest": array_digest(thetas),
        "simulator": describe_callable(simulator),
        "time_limit": run.time_limit,
        "spawn_key": list(spawn_key),
    }
    store, entropy = _open_checkpoint(run.checkpoint, settings, entropy)
    return _simulate_rows(
        simulator,
        data,
        tuple(names),
        {MAIN: thetas},
        store,
        (entropy, spawn_key),
        run,
    )


def _open_checkpoint(
    checkpoint: str | Path | None, settings: dict, entropy: int | None
) -> tuple[_TableCheckpoint | None, int]:
    """The checkpoint folder (None without one) and the entropy of the draws: the stored one
    when resuming, else ``entropy`` or a fresh one."""
    if checkpoint is not None:
        store = _TableCheckpoint(Path(checkpoint), settings, entropy)
        return store, store.entropy
    return None, int(np.random.SeedSequence().entropy) if entropy is None else entropy


def _simulate_rows(
    simulator: Simulator,
    data: ObservedData,
    names: tuple[str, ...],
    thetas: dict[int, np.ndarray],
    store: _TableCheckpoint | None,
    seed: tuple[int, tuple[int, ...]],
    run: RunOptions,
) -> ReferenceTable:
    """Simulate every row of ``thetas`` (phase -> draws) not yet in ``store``, as ``run``
    says; the table."""
    entropy, spawn_key = seed
    sizes = {phase: rows.shape[0] for phase, rows in thetas.items()}
    shape = data.values.shape
    values = {phase: np.full((size, *shape), np.nan) for phase, size in sizes.items()}
    status = {phase: np.full(size, "", dtype=object) for phase, size in sizes.items()}
    reason = {phase: np.full(size, "", dtype=object) for phase, size in sizes.items()}
    elapsed = {phase: np.zeros(size) for phase, size in sizes.items()}

    def record(
        phase: int, index: int, row: np.ndarray | None, kind: str, why: str, seconds: float
    ) -> None:
        if row is not None:
            values[phase][index] = row
        status[phase][index] = kind
        reason[phase][index] = why
        elapsed[phase][index] = seconds

    for row in store.load() if store is not None else []:
        record(*row)
    task = _TableTask(simulator, data, names, entropy, spawn_key, run.time_limit)
    with (
        run.open_executor() as pool,
        PhaseProgress(progress_enabled(run.progress)) as bar,
        _flushing(store),
    ):
        for phase, size in sizes.items():
            todo = [index for index in range(size) if not status[phase][index]]
            bar.start_phase(f"{PHASE_NAMES[phase]:5s}", size, size - len(todo))
            items = ((phase, index, thetas[phase][index]) for index in todo)
            for chunk in pool.imap_chunks(task, items, batched=True, time_limit=run.time_limit):
                rows = [
                    (phase, todo[position], None, *_crash(result))
                    if isinstance(result, WorkerCrash)
                    else result
                    for position, result in chunk
                ]
                if store is not None:
                    store.append(rows, shape)
                for row in rows:
                    record(*row)
                done = int((status[phase] != "").sum())
                bar.update(done, 0, int(((status[phase] != "") & (status[phase] != OK)).sum()))
    return ReferenceTable(
        names,
        tuple(data.names),
        thetas,
        values,
        status,
        reason,
        elapsed,
        entropy,
        spawn_key,
    )


@contextmanager
def _flushing(store: _TableCheckpoint | None) -> Iterator[None]:
    """Writes the simulations ``store`` holds back when the block ends, however it ends."""
    try:
        yield
    finally:
        if store is not None:
            store.flush()


def _crash(crash: WorkerCrash) -> tuple[str, str, float]:
    outcome = crash_outcome(crash)
    return outcome.status, outcome.reason, outcome.elapsed


def table_rejection(
    table: ReferenceTable,
    observed: OutputData,
    *,
    quantile: float = 0.05,
    n_desired: int = 4000,
    sensor_noise: SensorNoise | None = None,
    distance: BatchDistance = ks_distances,
    seed: int | np.random.SeedSequence | None = None,
) -> xr.DataTree:
    """ABC rejection (Algorithm 1) of one dataset on the rows of ``table``.

    The pilot rows set ε (the ``quantile`` of their distances); the main rows are accepted in
    draw order up to ``n_desired``. ``sensor_noise`` is drawn onto each row from the stream
    ``abc_rejection`` with ``seed`` would use for that simulation.

    Returns:
        The DataTree of ``abc_rejection``; ``sample_stats.n_simulations`` counts the rows this
        dataset used, ``sample_stats.table_simulations`` the table's size (shared).
    """
    started = time.perf_counter()
    if not 0.0 < quantile < 1.0:
        raise ValueError(f"quantile must lie in (0, 1), got {quantile}")
    if isinstance(n_desired, bool) or int(n_desired) != n_desired or n_desired < 1:
        raise ValueError(f"n_desired must be a positive integer, got {n_desired!r}")
    data = prepare_observed(observed, list(table.outputs))
    if data.names != table.outputs or data.values.shape != table.values[PILOT].shape[1:]:
        raise ValueError(
            f"observed outputs {list(data.names)} on {data.values.shape[1]} times differ from the "
            f"table's {list(table.outputs)} on {table.values[PILOT].shape[2]} times"
        )
    noise = None if sensor_noise is None else sensor_noise.resolve(data)
    if sensor_noise is not None and sensor_noise.learnable:
        raise ValueError(
            "a reference table takes known noise scales (SensorNoise(learnable=False))"
        )
    entropy, spawn_key = split_seed(seed)
    if entropy is None:
        entropy = int(np.random.SeedSequence().entropy)
    records = {}
    for phase, rows in table.values.items():
        size = rows.shape[0]
        phase_records = PhaseRecords(size)
        ok = np.flatnonzero(table.status[phase] == OK)
        noisy = np.empty((ok.size, *rows.shape[1:]))
        for position, index in enumerate(ok):
            rng = simulation_rng(entropy, spawn_key, simulation_stream(phase), int(index))
            noisy[position] = rows[index] if noise is None else noise.sample(rows[index], rng)
        distances = np.full(size, np.nan)
        if ok.size:
            distances[ok] = np.asarray(distance(noisy, data.values), dtype=float)
        phase_records.distance = distances
        phase_records.status = table.status[phase].copy()
        phase_records.reason = table.reason[phase].copy()
        phase_records.elapsed = table.elapsed[phase].copy()
        phase_records.done[:] = True
        phase_records.n_done = size
        phase_records.n_failed = int(size - ok.size)
        records[phase] = phase_records
    pilot_ok = records[PILOT].status == OK
    if not pilot_ok.any():
        raise RuntimeError("every pilot simulation of the table failed; no threshold can be set")
    epsilon = float(np.quantile(records[PILOT].distance[pilot_ok], quantile))
    scan = AcceptanceScan(records[MAIN], epsilon, int(n_desired))
    scan.advance()
    n_main = records[MAIN].done.size
    settings = {
        "sampler": "table_rejection",
        "quantile": float(quantile),
        "n_desired": int(n_desired),
        "sensor_noise": repr(sensor_noise),
        "distance": describe_callable(distance),
        "table_entropy": str(table.entropy),
        "entropy": str(entropy),
        "spawn_key": list(spawn_key),
    }
    tree = result_tree(
        table.names,
        dict(table.thetas),
        records,
        n_main if scan.stop is None else scan.stop + 1,
        epsilon,
        data,
        settings,
        time.perf_counter() - started,
    )
    stats = tree["sample_stats"].to_dataset()
    tree["sample_stats"] = stats.assign(table_simulations=((), table.n_simulations))
    return tree
