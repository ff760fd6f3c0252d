"""A worker process that dies (segfault, os._exit) fails only the item that killed it."""

from __future__ import annotations

import logging
import os
import signal
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import cloudpickle
import dask
import numpy as np
import pymc as pm
import pytest
import xarray as xr

from pymc_vcc.execution.executors import WorkerCrash, make_executor
from pymc_vcc.execution.options import RunOptions
from pymc_vcc.inference.predictive import simulate_predictive
from pymc_vcc.inference.priors import UniformPrior
from pymc_vcc.inference.pymc.model import add_simulator
from pymc_vcc.inference.pymc.smc import sample_smc_abc
from pymc_vcc.inference.rejection import abc_rejection
from pymc_vcc.inference.sensitivity import sobol_indices
from pymc_vcc.physics.failures import FailureKind
from pymc_vcc.testing import GaussianLocation

SEGFAULTS = {37, 211}
EXITS = {330}


def _segfault() -> None:
    os.kill(os.getpid(), signal.SIGSEGV)


def _exit() -> None:
    os._exit(1)


def _double_or_die(value: int) -> int:
    if value in SEGFAULTS:
        _segfault()
    if value in EXITS:
        _exit()
    return 2 * value


def _log_or_die(item: tuple[str, float, Path]) -> str:
    """Sleep, then die ("die") or log the run to a file ("log")."""
    action, seconds, log = item
    time.sleep(seconds)
    if action == "die":
        os._exit(1)
    with open(log, "a") as file:
        file.write("run\n")
    return action


HANG_SECONDS = 60.0


def _hang() -> None:
    """Sleep with the alarm signal blocked: like compiled code that never returns to Python."""
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGALRM})
    try:
        time.sleep(HANG_SECONDS)
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGALRM})


def _sleep_or_hang(seconds: float) -> float:
    if seconds == HANG_SECONDS:
        _hang()
    else:
        time.sleep(seconds)
    return seconds


KILLS = {"segfault": _segfault, "exit": _exit, "hang": _hang}


@dataclass(frozen=True)
class Crashing:
    """GaussianLocation whose runs with mu in one of ``regions`` (low, high, "segfault" or
    "exit") kill their process, or with ``raise_instead`` raise (the serial reference)."""

    base: GaussianLocation
    regions: tuple[tuple[float, float, str], ...]
    raise_instead: bool = False

    parameter_names = ("mu",)
    output_names = ("y",)

    def __call__(self, theta, rng):
        for low, high, how in self.regions:
            if low <= theta["mu"] < high:
                if self.raise_instead:
                    raise RuntimeError("would have killed the process")
                KILLS[how]()
        return self.base(theta, rng)

    def raising(self) -> Crashing:
        return Crashing(self.base, self.regions, raise_instead=True)

    def doomed(self, mu: np.ndarray) -> np.ndarray:
        """Which parameter values make a run fail."""
        return np.any([(low <= mu) & (mu < high) for low, high, _ in self.regions], axis=0)


# Each crash costs a new worker process (imports included), so few draws are doomed.
BASE = GaussianLocation(n_time=20)
CRASHING = Crashing(BASE, ((2.03, 2.05, "segfault"), (-2.43, -2.41, "exit")))
OBSERVED = BASE({"mu": 0.3}, np.random.default_rng(0))


@pytest.fixture(scope="module", autouse=True)
def ship_this_module_by_value():
    """Send this module's functions by value: a new worker then needs not import it (and pymc)."""
    module = sys.modules[__name__]
    cloudpickle.register_pickle_by_value(module)
    yield
    cloudpickle.unregister_pickle_by_value(module)


@pytest.fixture(scope="module")
def pool():
    with make_executor("processes", n_workers=2) as executor:
        yield executor


def test_only_the_items_that_kill_their_worker_become_crashes(pool):
    chunks = list(pool.imap_chunks(_double_or_die, range(400), chunksize=50))
    results = dict(item for chunk in chunks for item in chunk)
    assert sorted(results) == list(range(400))  # every item exactly once
    crashed = {index for index, result in results.items() if isinstance(result, WorkerCrash)}
    assert crashed == SEGFAULTS | EXITS
    for index in SEGFAULTS:
        assert "exit code -11 / signal SIGSEGV" in results[index].reason
    assert results[330].reason == "worker process died (exit code 1)"
    assert all(results[i] == 2 * i for i in set(results) - crashed)
    # the chunks that held a culprit, and only those, were rerun one item at a time
    alone = {chunk[0][0] for chunk in chunks if len(chunk) == 1}
    assert alone == set(range(0, 50)) | set(range(200, 250)) | set(range(300, 350))
    # the pool is whole again: a map gives crashes in place and keeps going
    again = pool.map(_double_or_die, [1, 37, 2])
    assert again[::2] == [2, 4] and again[1].reason == results[37].reason
    with pytest.raises(ZeroDivisionError) as error:
        pool.map(lambda x: 1 / x, [1, 0])
    assert "ZeroDivisionError" in str(error.value.__cause__)  # the worker's traceback


def test_a_crash_leaves_the_other_chunks_alone(pool, tmp_path):
    log = tmp_path / "runs.txt"
    results = pool.map(_log_or_die, [("log", 0.5, log), ("die", 0.05, log)], chunksize=1)
    assert results[0] == "log" and isinstance(results[1], WorkerCrash)
    assert log.read_text() == "run\n"  # the slow item ran once, beside the crash
    # one worker: the chunk it held ahead, behind the one that killed it, runs once, elsewhere
    queued = tmp_path / "queued.txt"
    with make_executor("processes", n_workers=1) as single:
        items = [("die", 0.05, queued), ("log", 0.0, queued)]
        results = single.map(_log_or_die, items, chunksize=1)
    assert isinstance(results[0], WorkerCrash) and results[1] == "log"
    assert queued.read_text() == "run\n"


def test_abc_counts_crashes_as_failures_and_matches_the_serial_run(pool, tmp_path):
    settings = dict(n_pilot=120, quantile=0.2, n_main=300, n_desired=300, distance=BASE.distance)
    prior = UniformPrior(BASE.bounds)
    checkpoint = tmp_path / "run.sqlite"
    crashed = abc_rejection(
        CRASHING,
        prior,
        OBSERVED,
        run=RunOptions(executor=pool, checkpoint=checkpoint, seed=4),
        **settings,
    )
    serial = abc_rejection(
        CRASHING.raising(), prior, OBSERVED, run=RunOptions(executor="serial", seed=4), **settings
    )

    stats = crashed.sample_stats
    status = stats["sim_status"].values
    doomed = CRASHING.doomed(crashed.prior["mu"].values.ravel())
    assert doomed.sum() == 3
    np.testing.assert_array_equal(status == FailureKind.WORKER_CRASH, doomed)
    assert list(stats["failure_kind"].values) == list(FailureKind)
    failures = dict(zip(stats["failure_kind"].values, stats["failures"].values, strict=True))
    assert failures[FailureKind.WORKER_CRASH] == doomed.sum() == int(stats["n_failed"])
    reasons = set(stats["sim_failure_reason"].values[doomed])
    assert reasons == {
        "worker process died (exit code -11 / signal SIGSEGV)",
        "worker process died (exit code 1)",
    }
    # the same run as one whose doomed draws fail in an ordinary way
    np.testing.assert_array_equal(crashed.posterior["mu"], serial.posterior["mu"])
    np.testing.assert_array_equal(stats["sim_distance"], serial.sample_stats["sim_distance"])
    np.testing.assert_array_equal(
        np.where(doomed, "exception", status), serial.sample_stats["sim_status"]
    )
    # crashes are checkpointed: a resumed run simulates nothing again (serially, the doomed
    # draws would now raise rather than crash)
    resumed = abc_rejection(
        CRASHING.raising(),
        prior,
        OBSERVED,
        run=RunOptions(executor="serial", checkpoint=checkpoint, seed=4),
        **settings,
    )
    np.testing.assert_array_equal(resumed.sample_stats["sim_status"], status)


def test_an_item_over_its_time_limit_is_stopped_and_its_worker_replaced(pool):
    items = [0.01, HANG_SECONDS, 0.01, 0.02]
    results = pool.map(_sleep_or_hang, items, time_limit=1.0)
    assert [results[k] for k in (0, 2, 3)] == [0.01, 0.01, 0.02]
    assert isinstance(results[1], WorkerCrash) and results[1].kind == "time-limit"
    assert "over its time limit of 2 s" in results[1].reason  # 1 s per item and 1 s of grace
    assert pool.map(abs, [-1, -2]) == [1, 2]  # a new worker took the stopped one's place


def test_abc_counts_runs_stopped_for_their_time_limit(pool):
    hanging = Crashing(BASE, ((2.0, 2.1, "hang"),))
    settings = dict(n_pilot=60, quantile=0.2, n_main=60, n_desired=60)
    tree = abc_rejection(
        hanging,
        UniformPrior(BASE.bounds),
        OBSERVED,
        run=RunOptions(executor=pool, seed=4, time_limit=0.5),
        distance=BASE.distance,
        **settings,
    )
    stats = tree.sample_stats
    doomed = hanging.doomed(tree.prior["mu"].values.ravel())
    assert doomed.sum() >= 1
    np.testing.assert_array_equal(stats["sim_status"].values == "time-limit", doomed)


def test_predictive_and_sensitivity_count_crashed_runs(pool):
    mu = np.linspace(-1.0, 1.0, 40).reshape(2, 20)
    mu[0, 3], mu[1, 7], mu[1, 8] = 2.04, -2.42, -2.42
    posterior = xr.DataTree.from_dict({"posterior": xr.Dataset({"mu": (("chain", "draw"), mu)})})
    tree = simulate_predictive(posterior, CRASHING, run=RunOptions(executor=pool, seed=1))
    predictive = tree["posterior_predictive"]
    assert predictive.attrs["n_failed"] == 3
    assert predictive.attrs["failure_kinds"] == "worker-crash: 3"
    failed = np.isnan(tree["posterior_predictive"]["y"]).all("time")
    np.testing.assert_array_equal(failed, CRASHING.doomed(mu))

    settings = dict(n_base=16, window=None, n_resamples=10)
    bounds = {"mu": (-3.0, 3.0)}
    crashing = Crashing(BASE, ((1.1, 1.15, "segfault"), (-2.05, -2.0, "exit")))
    crashed = sobol_indices(
        crashing, bounds, ["y"], run=RunOptions(executor=pool, seed=2), **settings
    )
    serial = sobol_indices(
        crashing.raising(), bounds, ["y"], run=RunOptions(executor="serial", seed=2), **settings
    )
    assert crashed.attrs["n_failed"] == serial.attrs["n_failed"] == 2
    assert "worker-crash: worker process died" in crashed.attrs["failure_reasons"]
    xr.testing.assert_equal(crashed.drop_attrs(), serial.drop_attrs())


def test_smc_gives_crashed_particles_zero_likelihood(pool, caplog):
    caplog.set_level(logging.WARNING, logger="pymc")
    crashing = Crashing(BASE, ((2.9, 3.0, "segfault"),))  # one draw of the first population
    runs = {}
    for name, simulator, executor in (
        ("crash", crashing, pool),
        ("raise", crashing.raising(), "serial"),
    ):
        with pm.Model(), warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="Numba will use object mode")
            add_simulator(
                "y", simulator, OBSERVED, prior=BASE.bounds, epsilon=0.5, distance=BASE.distance
            )
            runs[name] = sample_smc_abc(
                draws=60, executor=executor, random_seed=6, progressbar=False
            )
    stats = runs["crash"].sample_stats
    failed = int(stats["n_failed"])
    assert failed == int(runs["raise"].sample_stats["n_failed"]) > 0
    assert stats.attrs["failure_kinds"] == f"worker-crash: {failed}"
    np.testing.assert_array_equal(runs["crash"].posterior["mu"], runs["raise"].posterior["mu"])


def test_dask_gives_up_on_the_item_that_kills_every_worker_and_on_it_alone():
    # one worker: each death also counts against the innocent chunk queued beside the culprit
    pytest.importorskip("distributed")  # its config defaults, which dask.config.set must keep
    with (
        dask.config.set({"distributed.scheduler.allowed-failures": 1}),
        make_executor("dask", n_workers=1) as executor,
    ):
        results = executor.map(_double_or_die, [5, 330, 7, 8], chunksize=2)
        assert results[0] == 10 and results[2:] == [14, 16]
        assert isinstance(results[1], WorkerCrash)
        assert "Dask worker process died" in results[1].reason
        assert executor.map(_double_or_die, [1, 2]) == [2, 4]  # the function is sent again
