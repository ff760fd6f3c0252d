"""SMC-ABC checkpoints: a killed run resumes, runs nothing finished again, same posterior."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time

import numpy as np
import pymc as pm
import pytest
import xarray as xr

from pymc_vcc.execution.store import CheckpointMismatchError
from pymc_vcc.inference.pymc.model import add_simulator
from pymc_vcc.inference.pymc.smc import sample_smc_abc
from pymc_vcc.studies import StudySettings, leak_study
from pymc_vcc.testing import Flaky, GaussianLocation, Recording

MODEL = GaussianLocation(n_time=20)
OBSERVED = MODEL({"mu": 0.3}, np.random.default_rng(4))
SETTINGS = {"draws": 60, "executor": "serial", "random_seed": 3, "progressbar": False}

RUN_SCRIPT = textwrap.dedent(
    """
    import sys

    import numpy as np
    import pymc as pm

    from pymc_vcc.inference.pymc.model import add_simulator
    from pymc_vcc.inference.pymc.smc import sample_smc_abc
    from pymc_vcc.testing import GaussianLocation, Recording, Slow


    def main(checkpoint, log, out):
        model = GaussianLocation(n_time=20)
        observed = model({"mu": 0.3}, np.random.default_rng(4))
        with pm.Model():
            simulator = Recording(Slow(model, 0.003, busy=False), log)
            add_simulator(
                "y", simulator, observed, prior=model.bounds, epsilon=0.5,
                distance=model.distance,
            )
            tree = sample_smc_abc(
                draws=60, executor="serial", random_seed=3, progressbar=False,
                checkpoint=checkpoint,
            )
        tree.to_netcdf(out, engine="h5netcdf")


    if __name__ == "__main__":
        main(*sys.argv[1:])
    """
)


pytestmark = pytest.mark.usefixtures("quiet_pymc")


def _run(simulator=MODEL, observed=OBSERVED, epsilon=0.5, **options):
    with pm.Model():
        add_simulator(
            "y", simulator, observed, prior=MODEL.bounds, epsilon=epsilon, distance=MODEL.distance
        )
        return sample_smc_abc(**(SETTINGS | options))


def _totals(tree) -> tuple[int, int]:
    """(simulations run, simulations resumed from the checkpoint) over all stages."""
    stats = tree.sample_stats
    return int(stats["simulations"].sum()), int(stats["resumed_simulations"].sum())


def _assert_same_posterior(tree, reference):
    np.testing.assert_array_equal(tree.posterior["mu"].values, reference.posterior["mu"].values)
    np.testing.assert_array_equal(
        tree.sample_stats["beta"].values, reference.sample_stats["beta"].values
    )


def _persisted(path) -> int:
    if not path.exists():
        return 0
    connection = sqlite3.connect(path, timeout=10)
    try:
        return connection.execute("SELECT COUNT(*) FROM likelihoods").fetchone()[0]
    except sqlite3.OperationalError:  # not created yet
        return 0
    finally:
        connection.close()


def _logged(path) -> list[str]:
    return path.read_text().splitlines() if path.exists() else []


@pytest.fixture(scope="module")
def reference():
    return _run()


def test_a_checkpointed_run_equals_a_run_without_and_a_rerun_simulates_nothing(tmp_path, reference):
    log = tmp_path / "calls.log"
    simulator = Recording(MODEL, str(log))
    first = _run(simulator, checkpoint=tmp_path / "run.sqlite")
    _assert_same_posterior(first, reference)
    ran, resumed = _totals(first)
    assert (ran, resumed) == (_totals(reference)[0], 0)
    assert len(_logged(log)) == ran == _persisted(tmp_path / "run.sqlite")

    again = _run(simulator, checkpoint=tmp_path / "run.sqlite")
    assert len(_logged(log)) == ran  # nothing simulated again
    assert _totals(again) == (0, ran)
    _assert_same_posterior(again, reference)


def test_failed_simulations_are_restored_as_failures(tmp_path):
    flaky = Flaky(MODEL, rate=0.2)
    checkpoint = tmp_path / "flaky.sqlite"
    first = _run(flaky, checkpoint=checkpoint)
    again = _run(flaky, checkpoint=checkpoint)
    _assert_same_posterior(again, first)
    assert _totals(again) == (0, _totals(first)[0])
    np.testing.assert_array_equal(
        again.sample_stats["failed_simulations"].values,
        first.sample_stats["failed_simulations"].values,
    )
    assert first.sample_stats["n_failed"] > 0
    assert again.sample_stats.attrs["failure_kinds"] == first.sample_stats.attrs["failure_kinds"]


def test_a_run_killed_with_sigkill_resumes_and_equals_an_uninterrupted_run(tmp_path, reference):
    script = tmp_path / "run.py"
    script.write_text(RUN_SCRIPT)
    checkpoint, log, out = tmp_path / "run.sqlite", tmp_path / "calls.log", tmp_path / "run.nc"
    command = [sys.executable, str(script), str(checkpoint), str(log), str(out)]
    total = _totals(reference)[0]
    process = subprocess.Popen(command, start_new_session=True)
    deadline = time.monotonic() + 120
    while _persisted(checkpoint) < total // 3:
        assert process.poll() is None, "the run ended before it could be killed"
        assert time.monotonic() < deadline, "the run made no progress"
        time.sleep(0.01)
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    assert process.returncode == -signal.SIGKILL and not out.exists()
    persisted = _persisted(checkpoint)
    first_calls = len(_logged(log))
    assert total // 3 <= persisted < total
    # at most the chunk running at the kill (0.05 s of work, ~16 runs) was lost
    assert persisted <= first_calls <= persisted + 20

    subprocess.run(command, check=True, timeout=120)
    second_calls = len(_logged(log)) - first_calls
    tree = xr.open_datatree(out, engine="h5netcdf")
    _assert_same_posterior(tree, reference)
    assert _totals(tree) == (total - persisted, persisted)
    assert second_calls == total - persisted  # exactly what had not been persisted


def test_a_checkpoint_refuses_a_run_with_other_settings(tmp_path):
    checkpoint = tmp_path / "run.sqlite"
    _run(checkpoint=checkpoint, draws=20)
    with pytest.raises(CheckpointMismatchError, match=r"differing: \['draws'\]"):
        _run(checkpoint=checkpoint, draws=30)
    with pytest.raises(CheckpointMismatchError, match=r"differing: \['seed'\]"):
        _run(checkpoint=checkpoint, draws=20, random_seed=4)
    with pytest.raises(CheckpointMismatchError, match=r"differing: \['epsilon'"):
        _run(checkpoint=checkpoint, draws=20, epsilon=0.4)
    with pytest.raises(CheckpointMismatchError, match=r"differing: \['observed_digest'\]"):
        _run(observed=OBSERVED + 0.1, checkpoint=checkpoint, draws=20)
    with pytest.raises(ValueError, match="random_seed must be a non-negative integer"):
        _run(checkpoint=checkpoint, draws=20, random_seed=np.random.default_rng(0))


def test_a_seedless_checkpointed_run_keeps_its_seed(tmp_path):
    checkpoint = tmp_path / "run.sqlite"
    first = _run(checkpoint=checkpoint, random_seed=None, draws=20)
    again = _run(checkpoint=checkpoint, random_seed=None, draws=20)
    assert _totals(again) == (0, _totals(first)[0])
    _assert_same_posterior(again, first)


def test_the_leak_study_resumes_its_smc_stages_from_their_checkpoints(tmp_path):
    def study(resume: bool):
        settings = StudySettings("smoke", executor="serial", out=tmp_path, resume=resume, seed=1)
        result = leak_study(settings, references_kg=(2.0,), sampler="smc", t_calibration=100.0)
        return result, _totals(result.trees[0])

    first, (ran, resumed) = study(resume=False)
    assert ran > 0 and resumed == 0 and first.n_simulations == ran
    assert (tmp_path / "checkpoints" / "leak_smc_0.sqlite").exists()
    again, totals = study(resume=True)
    assert totals == (0, ran) and again.n_simulations == ran
    assert again.table == first.table
    _, totals = study(resume=False)  # a fresh start discards the checkpoint
    assert totals == (ran, 0)
