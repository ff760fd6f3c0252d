"""Checkpoints: a run killed with SIGKILL resumes, recomputes nothing persisted, same result."""

import os
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time
from collections import Counter
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np
import pytest
import xarray as xr

from pymc_vcc.execution.executors import make_executor
from pymc_vcc.execution.options import RunOptions
from pymc_vcc.execution.store import CheckpointDamagedError, CheckpointMismatchError
from pymc_vcc.inference.priors import UniformPrior
from pymc_vcc.inference.rejection import abc_rejection
from pymc_vcc.testing import GaussianLocation, Recording

MODEL = GaussianLocation(n_time=20, low=-1.0, high=1.0)
OBSERVED = MODEL({"mu": 0.2}, np.random.default_rng(0))
SETTINGS = dict(n_pilot=150, quantile=0.1, n_main=1500, n_desired=60)
SERIAL = RunOptions(executor="serial", seed=21)

RUN_SCRIPT = textwrap.dedent(
    """
    import sys

    import numpy as np

    from pymc_vcc.execution.options import RunOptions
    from pymc_vcc.inference.rejection import abc_rejection
    from pymc_vcc.inference.priors import UniformPrior
    from pymc_vcc.testing import GaussianLocation, Recording, Slow


    def main(checkpoint, log, out):
        model = GaussianLocation(n_time=20, low=-1.0, high=1.0)
        observed = model({"mu": 0.2}, np.random.default_rng(0))
        tree = abc_rejection(
            Recording(Slow(model, 0.004, busy=False), log),
            UniformPrior(model.bounds),
            observed,
            n_pilot=150, quantile=0.1, n_main=1500, n_desired=60,
            distance=model.distance,
            run=RunOptions(executor="serial", seed=21, checkpoint=checkpoint),
        )
        tree.to_netcdf(out, engine="h5netcdf")


    if __name__ == "__main__":
        main(*sys.argv[1:])
    """
)


def _reference():
    return abc_rejection(
        MODEL,
        UniformPrior(MODEL.bounds),
        OBSERVED,
        distance=MODEL.distance,
        run=SERIAL,
        **SETTINGS,
    )


def _assert_same_result(tree, reference):
    for group, variable in [
        ("posterior", "mu"),
        ("prior", "mu"),
        ("sample_stats", "sim_distance"),
        ("sample_stats", "sim_status"),
        ("sample_stats", "epsilon"),
    ]:
        np.testing.assert_array_equal(
            tree[group][variable].values, reference[group][variable].values
        )


def _persisted(path):
    if not path.exists():
        return []
    connection = sqlite3.connect(path, timeout=10)
    try:
        return connection.execute("SELECT phase, idx FROM simulations").fetchall()
    except sqlite3.OperationalError:  # not created yet
        return []
    finally:
        connection.close()


def _logged(path):
    return path.read_text().splitlines() if path.exists() else []


def test_a_run_killed_with_sigkill_resumes_and_equals_an_uninterrupted_run(tmp_path):
    script = tmp_path / "run.py"
    script.write_text(RUN_SCRIPT)
    checkpoint, log, out = tmp_path / "run.sqlite", tmp_path / "calls.log", tmp_path / "run.nc"
    command = [sys.executable, str(script), str(checkpoint), str(log), str(out)]
    process = subprocess.Popen(command, start_new_session=True)
    deadline = time.monotonic() + 120
    while len(_persisted(checkpoint)) < 300:  # the pilot's 150 and some of the main phase
        assert process.poll() is None, "the run ended before it could be killed"
        assert time.monotonic() < deadline, "the run made no progress"
        time.sleep(0.01)
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    assert process.returncode == -signal.SIGKILL and not out.exists()
    persisted = set(_persisted(checkpoint))
    first_calls = _logged(log)

    subprocess.run(command, check=True, timeout=120)
    second_calls = _logged(log)[len(first_calls) :]
    tree = xr.open_datatree(out, engine="h5netcdf")
    _assert_same_result(tree, _reference())

    # which θ each persisted simulation had, from the draws in the result
    draws = tree.prior["mu"].values.ravel()
    n_pilot = SETTINGS["n_pilot"]
    assert max(index for phase, index in persisted if phase == 1) < draws.size - n_pilot
    persisted_theta = {repr(float(draws[index + n_pilot * phase])) for phase, index in persisted}
    rerun = Counter(second_calls)
    assert not persisted_theta & set(rerun), "a persisted simulation was recomputed"
    # only simulations of the chunk running at the kill (0.05 s of work, ~11 runs) ran twice
    twice = set(first_calls) & set(rerun)
    assert len(twice) <= 20
    assert len(set(first_calls) | set(rerun)) >= int(tree.sample_stats["n_simulations"])


@dataclass(frozen=True)
class InterruptAfter:
    """Raises KeyboardInterrupt (Ctrl-C) after ``limit`` runs in this process; None: never."""

    base: GaussianLocation
    limit: int | None
    calls: ClassVar[list[int]] = []

    parameter_names: ClassVar[tuple[str, ...]] = ("mu",)
    output_names: ClassVar[tuple[str, ...]] = ("y",)

    def __call__(self, theta, rng):
        if self.limit is not None:
            self.calls.append(1)
            if len(self.calls) > self.limit:
                raise KeyboardInterrupt
        return self.base(theta, rng)


def test_an_interrupted_run_resumes_on_another_executor_with_the_same_result(tmp_path):
    checkpoint = tmp_path / "run.sqlite"
    common = dict(distance=MODEL.distance, **SETTINGS)
    with pytest.raises(KeyboardInterrupt):
        abc_rejection(
            InterruptAfter(MODEL, 400),
            UniformPrior(MODEL.bounds),
            OBSERVED,
            run=replace(SERIAL, checkpoint=checkpoint),
            **common,
        )
    assert 150 < len(_persisted(checkpoint)) <= 400
    with make_executor("processes", n_workers=2) as pool:
        resumed = abc_rejection(
            InterruptAfter(MODEL, None),
            UniformPrior(MODEL.bounds),
            OBSERVED,
            run=replace(SERIAL, executor=pool, checkpoint=checkpoint),
            **common,
        )
    _assert_same_result(resumed, _reference())


def test_a_finished_checkpoint_reruns_nothing_and_a_seedless_one_keeps_its_seed(tmp_path):
    log = tmp_path / "calls.log"
    simulator = Recording(MODEL, str(log))
    arguments = dict(
        distance=MODEL.distance,
        run=replace(SERIAL, seed=None, checkpoint=tmp_path / "run.sqlite"),
        **SETTINGS,
    )
    first = abc_rejection(simulator, UniformPrior(MODEL.bounds), OBSERVED, **arguments)
    calls = len(_logged(log))
    again = abc_rejection(simulator, UniformPrior(MODEL.bounds), OBSERVED, **arguments)
    assert len(_logged(log)) == calls  # nothing ran again
    assert calls >= int(first.sample_stats["n_simulations"])  # (the last chunk ran past the stop)
    _assert_same_result(again, first)


def test_a_checkpoint_refuses_a_run_with_other_arguments(tmp_path):
    run = replace(SERIAL, checkpoint=tmp_path / "c.sqlite")
    arguments = dict(distance=MODEL.distance, run=run)
    abc_rejection(MODEL, UniformPrior(MODEL.bounds), OBSERVED, **arguments, **SETTINGS)
    with pytest.raises(CheckpointMismatchError, match=r"differing: \['quantile'\]"):
        abc_rejection(
            MODEL,
            UniformPrior(MODEL.bounds),
            OBSERVED,
            **arguments,
            **(SETTINGS | {"quantile": 0.2}),
        )
    with pytest.raises(CheckpointMismatchError, match=r"differing: \['seed'\]"):
        abc_rejection(
            MODEL,
            UniformPrior(MODEL.bounds),
            OBSERVED,
            distance=MODEL.distance,
            run=replace(run, seed=5),
            **SETTINGS,
        )
    with pytest.raises(CheckpointMismatchError, match="observed_digest"):
        abc_rejection(MODEL, UniformPrior(MODEL.bounds), OBSERVED + 1.0, **arguments, **SETTINGS)


@dataclass(frozen=True)
class SolvedLocation(GaussianLocation):
    """A location model that names its solver, as VCCSimulator does."""

    solver: str = "radau"

    @property
    def checkpoint_identity(self) -> str:
        return f"solver {self.solver}"


def test_a_checkpoint_refuses_to_resume_with_another_solver(tmp_path):
    arguments = dict(distance=MODEL.distance, run=replace(SERIAL, checkpoint=tmp_path / "c.sqlite"))
    radau, cvode = SolvedLocation(), SolvedLocation(solver="cvode")
    abc_rejection(radau, UniformPrior(MODEL.bounds), OBSERVED, **arguments, **SETTINGS)
    with pytest.raises(CheckpointMismatchError, match=r"differing: \['simulator'\]"):
        abc_rejection(cvode, UniformPrior(MODEL.bounds), OBSERVED, **arguments, **SETTINGS)


def test_a_damaged_checkpoint_is_refused_naming_the_file(tmp_path):
    checkpoint = tmp_path / "run.sqlite"
    checkpoint.write_bytes(b"this is not a database, it was overwritten" * 100)
    arguments = dict(distance=MODEL.distance, run=replace(SERIAL, checkpoint=checkpoint))
    with pytest.raises(CheckpointDamagedError, match=rf"checkpoint {checkpoint} is damaged"):
        abc_rejection(MODEL, UniformPrior(MODEL.bounds), OBSERVED, **arguments, **SETTINGS)


def test_an_altered_row_is_refused_rather_than_change_the_posterior(tmp_path):
    checkpoint = tmp_path / "run.sqlite"
    arguments = dict(distance=MODEL.distance, run=replace(SERIAL, checkpoint=checkpoint))
    abc_rejection(MODEL, UniformPrior(MODEL.bounds), OBSERVED, **arguments, **SETTINGS)
    connection = sqlite3.connect(checkpoint)
    with connection:
        connection.execute("UPDATE simulations SET distance = 0.0 WHERE phase = 1 AND idx = 7")
    connection.close()
    with pytest.raises(CheckpointDamagedError, match="simulation 1/7 fails its checksum"):
        abc_rejection(MODEL, UniformPrior(MODEL.bounds), OBSERVED, **arguments, **SETTINGS)
