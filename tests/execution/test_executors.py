"""Serial, process and Dask executors: same results, input order, lazy streaming, real cluster."""

import contextlib
import itertools
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import cloudpickle
import numpy as np
import pytest

from pymc_vcc.execution.executors import EXECUTOR_KINDS, DaskExecutor, make_executor
from pymc_vcc.execution.options import RunOptions
from pymc_vcc.inference.priors import UniformPrior
from pymc_vcc.inference.rejection import abc_rejection
from pymc_vcc.testing import Flaky, GaussianLocation

LOCAL_KINDS = ["serial", "processes"]


def _seeded_draw(index):
    return float(np.random.default_rng(np.random.SeedSequence(2024, spawn_key=(index,))).random())


def _sleep_then_return(item):
    time.sleep(item)
    return item


def _chunk_sizes(chunk):
    return [len(chunk)] * len(chunk)


@pytest.fixture(scope="module")
def process_pool():
    with make_executor("processes", n_workers=2) as executor:
        yield executor


def _executor(kind, process_pool):
    return process_pool if kind == "processes" else make_executor(kind)


@pytest.mark.parametrize("kind", LOCAL_KINDS)
def test_map_returns_results_in_input_order(kind, process_pool):
    executor = _executor(kind, process_pool)
    delays = [0.04, 0.0, 0.03, 0.0, 0.02, 0.01]
    assert executor.map(_sleep_then_return, delays) == delays
    assert executor.map(_seeded_draw, range(500)) == [_seeded_draw(i) for i in range(500)]


def test_lambdas_and_closures_run_in_worker_processes(process_pool):
    offset = 10
    assert process_pool.map(lambda x: x + offset, range(5), chunksize=2) == list(range(10, 15))


@pytest.mark.parametrize("kind", LOCAL_KINDS)
def test_errors_in_the_function_reach_the_caller(kind, process_pool):
    with pytest.raises(ZeroDivisionError):
        _executor(kind, process_pool).map(lambda x: 1 / x, [1, 0, 2])


@pytest.mark.parametrize("kind", LOCAL_KINDS)
def test_fast_items_travel_in_large_chunks_and_slow_ones_alone(kind, process_pool):
    executor = _executor(kind, process_pool)
    fast = dict(executor.imap_unordered(_chunk_sizes, range(20_000), batched=True))
    assert sorted(fast) == list(range(20_000))
    assert max(fast.values()) >= 100  # chunks grow once run times are known
    fixed = dict(executor.imap_unordered(_chunk_sizes, range(10), chunksize=3, batched=True))
    assert sorted(fixed.values()) == [1, 3, 3, 3, 3, 3, 3, 3, 3, 3]
    default = executor.target_chunk_seconds
    executor.target_chunk_seconds = 0.01
    try:
        slow = executor.map(lambda x: (time.sleep(0.02), x)[1], range(6))
    finally:
        executor.target_chunk_seconds = default
    assert slow == list(range(6))


@pytest.mark.parametrize("kind", LOCAL_KINDS)
def test_closing_the_stream_early_stops_reading_items(kind, process_pool):
    executor = _executor(kind, process_pool)
    consumed = itertools.count()

    def items():
        for i in itertools.count():
            next(consumed)
            yield 0.001 * (i % 3)

    stream = executor.imap_unordered(_sleep_then_return, items(), chunksize=2)
    with contextlib.closing(stream):
        first = [next(stream) for _ in range(5)]
    assert len(first) == 5
    # 3 chunks of 2 give 5 results; at most 2 chunks per worker more are read ahead
    assert next(consumed) <= 2 * (3 + 2 * executor.n_workers)


def test_unknown_kind_and_bad_sizes_are_clear_errors():
    with pytest.raises(ValueError, match="unknown executor kind 'threads'"):
        make_executor("threads")
    for kind in EXECUTOR_KINDS:  # refused before any worker starts, whatever the backend
        with pytest.raises(ValueError, match="n_workers must be a positive integer, got 0"):
            make_executor(kind, n_workers=0)
    with pytest.raises(ValueError, match="chunksize must be a positive integer"):
        make_executor("serial").map(abs, [1], chunksize=0)


def test_dask_executor_starts_and_closes_its_own_local_cluster():
    with make_executor("dask", n_workers=1) as executor:
        assert executor.n_workers == 1
        assert executor.map(_seeded_draw, range(20)) == [_seeded_draw(i) for i in range(20)]
    assert executor.client.status == "closed"


@contextlib.contextmanager
def dask_cli_cluster(directory: Path, n_workers: int = 2):
    """A real ``dask scheduler`` and ``n_workers`` ``dask worker`` processes on 127.0.0.1."""
    bin_dir = Path(sys.executable).parent
    scheduler_file = directory / "scheduler.json"
    log = open(directory / "dask.log", "w")  # noqa: SIM115 (closed below)
    processes = []

    def start(arguments):
        processes.append(
            subprocess.Popen(
                [str(bin_dir / "dask"), *arguments],
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
                cwd=directory,
            )
        )

    try:
        start(
            [
                *("scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard"),
                *("--scheduler-file", str(scheduler_file)),
            ]
        )
        deadline = time.monotonic() + 60
        while not scheduler_file.exists() or not scheduler_file.read_text().strip():
            if time.monotonic() > deadline or processes[0].poll() is not None:
                raise RuntimeError(f"dask scheduler did not start: {directory / 'dask.log'}")
            time.sleep(0.1)
        address = json.loads(scheduler_file.read_text())["address"]
        for _ in range(n_workers):
            start(
                [
                    *("worker", address, "--nthreads", "1", "--host", "127.0.0.1"),
                    *("--no-nanny", "--no-dashboard", "--local-directory", str(directory)),
                ]
            )
        yield address
    finally:
        # workers first (they would wait for a vanished scheduler), then the scheduler
        for group in (processes[1:], processes[:1]):
            for process in group:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(process.pid, signal.SIGTERM)
            for process in group:
                try:
                    process.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    os.killpg(process.pid, signal.SIGKILL)
                    process.wait()
        log.close()


@pytest.fixture
def ship_this_module_by_value():
    """Dask workers cannot import test modules: send their functions by value."""
    module = sys.modules[__name__]
    cloudpickle.register_pickle_by_value(module)
    yield
    cloudpickle.unregister_pickle_by_value(module)


@pytest.mark.usefixtures("ship_this_module_by_value")
def test_dask_cluster_started_from_the_command_line_gives_the_serial_results(tmp_path):
    with dask_cli_cluster(tmp_path) as address, DaskExecutor(address, n_workers=2) as executor:
        assert executor.n_workers == 2
        assert executor.map(_seeded_draw, range(300)) == [_seeded_draw(i) for i in range(300)]
        workers = executor.map(lambda _: os.getpid(), range(40), chunksize=1)
        assert os.getpid() not in workers
        # a calibration through the cluster equals the serial one, failures and all
        model = Flaky(GaussianLocation(n_time=30), rate=0.1)
        observed = GaussianLocation(n_time=30)({"mu": 0.2}, np.random.default_rng(1))
        settings = dict(n_pilot=300, quantile=0.1, n_main=2000, n_desired=80)
        prior = UniformPrior(model.base.bounds)
        on_dask = abc_rejection(
            model, prior, observed, run=RunOptions(executor=executor, seed=3), **settings
        )
    serial = abc_rejection(
        model, prior, observed, run=RunOptions(executor="serial", seed=3), **settings
    )
    assert on_dask.posterior.sizes["draw"] == 80
    for group, variable in [("posterior", "mu"), ("sample_stats", "sim_distance")]:
        np.testing.assert_array_equal(on_dask[group][variable], serial[group][variable])
    np.testing.assert_array_equal(
        on_dask.sample_stats["sim_status"], serial.sample_stats["sim_status"]
    )
