"""Every way a simulation can fail becomes an outcome with a kind and a reason."""

import threading
import time

import numpy as np
import pytest
import xarray as xr

from pymc_vcc.execution.outcomes import SimulationTimeout, time_limit
from pymc_vcc.inference.series import prepare_observed
from pymc_vcc.inference.simulator import run_simulation
from pymc_vcc.physics.failures import FailureKind
from pymc_vcc.testing import AsDataset, GaussianLocation, Slow

OBSERVED = prepare_observed(np.zeros((1, 10)), output_names=("y",))
RNG = np.random.default_rng(0)


def _returning(value):
    return lambda theta, rng: value


def _raising(theta, rng):
    raise ZeroDivisionError("solver blew up")


def test_a_good_run_gives_its_outputs_in_the_observed_layout():
    outcome = run_simulation(GaussianLocation(n_time=7), {"mu": 1.0}, RNG, OBSERVED)
    assert outcome.ok and outcome.status == "ok" and outcome.reason == ""
    assert outcome.values.shape == (1, 7) and outcome.elapsed >= 0.0
    dataset_outcome = run_simulation(
        AsDataset(GaussianLocation(n_time=7)), {"mu": 1.0}, RNG, OBSERVED
    )
    assert dataset_outcome.ok and dataset_outcome.values.shape == (1, 7)


@pytest.mark.parametrize(
    ("simulator", "kind", "reason"),
    [
        (_raising, "exception", "ZeroDivisionError: solver blew up"),
        (_returning(np.array([[1.0, np.nan, 2.0]])), "non-finite", "output 'y' has 1 non-finite"),
        (_returning(np.array([[1.0, np.inf]])), "non-finite", "non-finite"),
        (_returning(np.zeros((3, 4))), "invalid-output", "expected (1, n_time)"),
        (_returning(None), "invalid-output", "shape"),
        (_returning(xr.Dataset({"PD": ("time", [1.0])})), "invalid-output", "lacks output"),
        (
            _returning(xr.Dataset(attrs={"status": "failed", "failure_reason": "Radau diverged"})),
            "reported",
            "Radau diverged",
        ),
        (_returning(xr.Dataset(attrs={"status": "timeout"})), "reported", "status 'timeout'"),
        (
            _returning(xr.Dataset(attrs={"status": "failed", "failure_kind": "solver"})),
            "solver",
            "status 'failed'",
        ),
        (
            _returning(xr.Dataset(attrs={"status": "failed", "failure_kind": "gremlins"})),
            "reported",
            "status 'failed'",
        ),
    ],
)
def test_failures_are_captured_with_kind_and_reason(simulator, kind, reason):
    outcome = run_simulation(simulator, {"mu": 0.0}, RNG, OBSERVED)
    assert not outcome.ok and outcome.values is None
    assert outcome.status == FailureKind(kind)
    assert reason in outcome.reason


def test_time_limit_stops_a_stalled_run_in_the_main_thread():
    stalled = Slow(GaussianLocation(n_time=3), seconds=5.0, busy=False)
    start = time.perf_counter()
    outcome = run_simulation(stalled, {"mu": 0.0}, RNG, OBSERVED, time_limit_s=0.1)
    assert outcome.status == "time-limit" and "0.1 s" in outcome.reason
    assert time.perf_counter() - start < 2.0


def test_time_limit_stops_a_busy_run_in_a_worker_thread():
    busy = Slow(GaussianLocation(n_time=3), seconds=5.0, busy=True)
    outcomes = []

    def work():
        outcomes.append(run_simulation(busy, {"mu": 0.0}, RNG, OBSERVED, time_limit_s=0.1))

    start = time.perf_counter()
    thread = threading.Thread(target=work)
    thread.start()
    thread.join(timeout=10.0)
    assert outcomes[0].status == "time-limit"
    assert time.perf_counter() - start < 2.0


def test_time_limit_does_not_fire_after_a_quick_run():
    with time_limit(0.05):
        pass
    time.sleep(0.1)  # a stray alarm would raise SimulationTimeout here
    quick = run_simulation(GaussianLocation(n_time=3), {"mu": 0.0}, RNG, OBSERVED, time_limit_s=5)
    assert quick.ok


def test_a_simulator_catching_exception_does_not_swallow_the_timeout():
    def stubborn(theta, rng):
        try:
            time.sleep(5.0)
        except Exception:
            return np.zeros((1, 3))
        return np.zeros((1, 3))

    outcome = run_simulation(stubborn, {}, RNG, OBSERVED, time_limit_s=0.1)
    assert outcome.status == "time-limit"
    assert issubclass(SimulationTimeout, BaseException)
    assert not issubclass(SimulationTimeout, Exception)
