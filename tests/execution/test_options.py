"""RunOptions: refused settings, and the executor it opens (or leaves open)."""

import numpy as np
import pytest

from pymc_vcc.execution.executors import SerialExecutor
from pymc_vcc.execution.options import RunOptions


@pytest.mark.parametrize(
    "options",
    [
        {"executor": "threads"},
        {"n_workers": 0},
        {"n_workers": 1.5},
        {"time_limit": 0.0},
        {"time_limit": -1.0},
        {"max_failure_rate": 0.0},
        {"max_failure_rate": 1.5},
    ],
)
def test_bad_options_are_refused(options):
    with pytest.raises(ValueError, match=next(iter(options))):
        RunOptions(**options)


def test_an_executor_given_is_used_and_left_open(monkeypatch):
    given = SerialExecutor()
    closed = []
    monkeypatch.setattr(given, "close", lambda: closed.append(True))
    with RunOptions(executor=given).open_executor() as opened:
        assert opened is given
    assert not closed


def test_an_executor_kind_is_opened_for_the_run_and_closed_after(monkeypatch):
    closed = []
    monkeypatch.setattr(SerialExecutor, "close", lambda self: closed.append(self))
    with RunOptions(executor="serial").open_executor() as opened:
        assert isinstance(opened, SerialExecutor)
        assert opened.map(abs, [-1, 2]) == [1, 2]
    assert closed == [opened]


def test_a_kind_opens_its_worker_count():
    with RunOptions(executor="processes", n_workers=1).open_executor() as opened:
        assert opened.n_workers == 1
        assert opened.map(abs, [-3]) == [3]


def test_a_checkpoint_is_refused_where_the_run_keeps_none(tmp_path):
    RunOptions().refuse_checkpoint("simulate_predictive")
    with pytest.raises(ValueError, match="simulate_predictive keeps no checkpoint"):
        RunOptions(checkpoint=tmp_path / "c.sqlite").refuse_checkpoint("simulate_predictive")


def test_the_seed_as_a_seed_sequence():
    given = np.random.SeedSequence(3, spawn_key=(1,))
    assert RunOptions(seed=given).seed_sequence() is given
    assert RunOptions(seed=5).seed_sequence().entropy == 5
    assert RunOptions().seed_sequence().entropy != RunOptions().seed_sequence().entropy  # fresh
