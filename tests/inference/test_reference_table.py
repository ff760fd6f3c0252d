"""A reference table of prior simulations, shared by rejection runs on many datasets."""

import numpy as np
import pytest

from pymc_vcc.execution.options import RunOptions
from pymc_vcc.execution.store import CheckpointDamagedError, CheckpointMismatchError
from pymc_vcc.inference.noise import SensorNoise
from pymc_vcc.inference.priors import UniformPrior
from pymc_vcc.inference.reference_table import simulate_table, table_rejection
from pymc_vcc.inference.rejection import abc_rejection
from pymc_vcc.testing import SensorProblem

PROBLEM = SensorProblem(n_time=60)
PRIOR = UniformPrior({"M0": PROBLEM.bounds["M0"]})
NOISE = SensorNoise(temperature=0.3)
SIZES = {"n_pilot": 40, "n_main": 160}


def measured(charge: float, seed: int):
    return NOISE.measure(PROBLEM.dataset(charge), np.random.default_rng(seed))


def table(seed: int, checkpoint=None):
    return simulate_table(
        PROBLEM,
        PRIOR,
        PROBLEM.dataset(1.5),
        run=RunOptions(executor="serial", seed=seed, checkpoint=checkpoint),
        **SIZES,
    )


def test_table_with_the_samplers_seed_gives_abc_rejections_posterior():
    observed = measured(1.3, 1)
    direct = abc_rejection(
        PROBLEM,
        PRIOR,
        observed,
        quantile=0.2,
        n_desired=15,
        sensor_noise=NOISE,
        run=RunOptions(executor="serial", seed=7),
        **SIZES,
    )
    shared = table_rejection(
        table(7), observed, quantile=0.2, n_desired=15, sensor_noise=NOISE, seed=7
    )
    np.testing.assert_array_equal(
        shared["posterior"]["M0"].values, direct["posterior"]["M0"].values
    )
    for name in ("epsilon", "n_simulations", "n_accepted", "sim_distance"):
        np.testing.assert_array_equal(
            shared["sample_stats"][name].values, direct["sample_stats"][name].values
        )
    assert int(shared["sample_stats"]["table_simulations"]) == 200


def test_datasets_share_the_draws_but_not_the_noise():
    shared = table(3)
    first, second = (
        table_rejection(
            shared, measured(1.3, 1), quantile=0.2, n_desired=15, sensor_noise=NOISE, seed=s
        )
        for s in (11, 12)
    )
    np.testing.assert_array_equal(first["prior"]["M0"].values, second["prior"]["M0"].values)
    assert not np.array_equal(
        first["sample_stats"]["sim_distance"].values, second["sample_stats"]["sim_distance"].values
    )


def test_a_checkpointed_table_resumes_without_simulating(tmp_path, monkeypatch):
    built = table(5, checkpoint=tmp_path / "table")

    def refuse(self, theta, rng):
        raise AssertionError("a finished simulation was run again")

    monkeypatch.setattr(SensorProblem, "__call__", refuse)

    again = simulate_table(
        PROBLEM,
        PRIOR,
        PROBLEM.dataset(1.5),
        run=RunOptions(executor="serial", seed=5, checkpoint=tmp_path / "table"),
        **SIZES,
    )
    for phase in built.values:
        np.testing.assert_array_equal(again.values[phase], built.values[phase])
    with pytest.raises(CheckpointMismatchError, match="differing: \\['n_main'\\]"):
        simulate_table(
            PROBLEM,
            PRIOR,
            PROBLEM.dataset(1.5),
            run=RunOptions(executor="serial", seed=5, checkpoint=tmp_path / "table"),
            n_pilot=40,
            n_main=100,
        )


def test_an_interrupted_table_keeps_every_finished_simulation_in_few_files(tmp_path, monkeypatch):
    """Simulations finished within 2 s share a chunk file, and an interrupted run writes the
    ones it holds before it stops: the run started again simulates only the rest."""
    simulate = SensorProblem.__call__
    calls = []

    def interrupted(self, theta, rng):
        if len(calls) == 70:
            raise KeyboardInterrupt
        calls.append(theta)
        return simulate(self, theta, rng)

    monkeypatch.setattr(SensorProblem, "__call__", interrupted)
    with pytest.raises(KeyboardInterrupt):
        table(5, checkpoint=tmp_path / "table")
    (chunk,) = (tmp_path / "table").glob("chunk-*.npz")  # not one file per simulation
    with np.load(chunk) as saved:
        stored = saved["index"].size
    assert stored >= SIZES["n_pilot"]  # all but the executor's unfinished batch
    calls.clear()
    monkeypatch.setattr(
        SensorProblem,
        "__call__",
        lambda self, theta, rng: (calls.append(theta), simulate(self, theta, rng))[1],
    )
    again = table(5, checkpoint=tmp_path / "table")
    assert len(calls) == SIZES["n_pilot"] + SIZES["n_main"] - stored
    for phase, values in table(5).values.items():
        np.testing.assert_array_equal(again.values[phase], values)


def test_observed_data_off_the_tables_grid_are_refused():
    with pytest.raises(ValueError, match="differ from the table's"):
        table_rejection(table(1), SensorProblem(n_time=30).dataset(1.5), quantile=0.2, n_desired=5)


def test_a_damaged_chunk_and_noise_scales_in_the_prior_are_refused(tmp_path):
    folder = tmp_path / "table"
    table(2, checkpoint=folder)
    next(folder.glob("chunk-*.npz")).write_bytes(b"not a chunk")
    with pytest.raises(CheckpointDamagedError, match=r"chunk-.*damaged"):
        table(2, checkpoint=folder)
    with pytest.raises(ValueError, match=r"noise scales \['sigma_TD'\]"):
        simulate_table(
            PROBLEM,
            PRIOR.extended({"sigma_TD": (0.1, 1.0)}),
            PROBLEM.dataset(1.5),
            run=RunOptions(executor="serial"),
            **SIZES,
        )
