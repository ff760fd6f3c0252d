"""Posterior predictive on a (longer) profile: groups, bands, noise, failures, reproducibility."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pymc as pm
import pytest
import xarray as xr

from pymc_vcc.execution.options import RunOptions
from pymc_vcc.inference.predictive import predictive_bands, simulate_predictive
from pymc_vcc.inference.pymc.model import add_simulator
from pymc_vcc.inference.pymc.smc import sample_smc_abc
from pymc_vcc.testing import AsDataset, Flaky, GaussianLocation, LinearGaussian


def posterior_tree(draws: dict[str, np.ndarray]) -> xr.DataTree:
    """A DataTree with a posterior group of (chain, draw) variables."""
    posterior = xr.Dataset({name: (("chain", "draw"), values) for name, values in draws.items()})
    return xr.DataTree.from_dict({"posterior": posterior})


@pytest.fixture(scope="module")
def line_posterior() -> xr.DataTree:
    rng = np.random.default_rng(0)
    return posterior_tree(
        {
            "a": rng.normal(2.0, 0.05, (2, 60)),
            "b": rng.normal(-0.5, 0.1, (2, 60)),
            "nu_y": rng.uniform(0.2, 0.3, (2, 60)),
        }
    )


def test_predictive_groups_and_bands(line_posterior):
    sim = AsDataset(LinearGaussian(n_time=40, sigma=0.01))
    truth = sim({"a": 2.0, "b": -0.5}, np.random.default_rng(1))
    tree = simulate_predictive(
        line_posterior, sim, reference=truth, noise=False, run=RunOptions(executor="serial", seed=3)
    )
    predictive = tree["posterior_predictive"].to_dataset()
    assert predictive["y"].dims == ("chain", "draw", "time")
    assert predictive["y"].shape == (2, 60, 40)
    bands = predictive_bands(tree)
    assert list(bands["band"].values) == ["lower", "median", "upper"]
    np.testing.assert_allclose(bands["probability"].values, [0.05, 0.5, 0.95])
    lower, median, upper = bands["y"].values
    assert (lower < median).all() and (median < upper).all()
    t = np.linspace(0.0, 1.0, 40)
    np.testing.assert_allclose(median, 2.0 - 0.5 * t, atol=0.04)  # the posterior mean line
    sd = np.sqrt(0.05**2 + (0.1 * t) ** 2 + 0.01**2)  # spread of a + b·t + σe over draws
    np.testing.assert_allclose(upper - lower, 2 * 1.645 * sd, rtol=0.35)
    assert bands.attrs["n_draws"] == 120 and bands.attrs["n_failed"] == 0
    xr.testing.assert_equal(tree["observed_data"].to_dataset(), truth[["y"]])
    assert set(tree.children) == {"posterior", "posterior_predictive", "observed_data"}


def test_noise_scales_widen_the_bands(line_posterior):
    sim = AsDataset(LinearGaussian(n_time=40, sigma=0.01))
    settings = {"run": RunOptions(executor="serial", seed=4), "outputs": ["y"]}
    clean = simulate_predictive(line_posterior, sim, noise=False, **settings)
    noisy = simulate_predictive(line_posterior, sim, noise=True, **settings)
    width_clean = np.diff(predictive_bands(clean)["y"].values[[0, 2]], axis=0)
    width_noisy = np.diff(predictive_bands(noisy)["y"].values[[0, 2]], axis=0)
    assert width_noisy.mean() > 1.5 * width_clean.mean()


def test_sensor_noise_in_engineering_units_widens_the_bands(line_posterior):
    from pymc_vcc.inference.noise import SensorNoise

    line_posterior = posterior_tree(  # without the paper's ν
        {name: line_posterior["posterior"][name].values for name in ("a", "b")}
    )
    sim = AsDataset(LinearGaussian(n_time=40, sigma=0.0))
    settings = {"parameters": ["a", "b"]}
    serial = RunOptions(executor="serial", seed=7)
    clean = simulate_predictive(line_posterior, sim, noise=False, run=serial, **settings)
    sensor = SensorNoise(kinds={"y": "temperature"}, temperature=0.5)  # 0.5 (K) absolute
    noisy = simulate_predictive(line_posterior, sim, sensor_noise=sensor, run=serial, **settings)
    residual = noisy["posterior_predictive"]["y"] - clean["posterior_predictive"]["y"]
    assert float(residual.std()) == pytest.approx(0.5, rel=0.05)
    parallel = simulate_predictive(
        line_posterior,
        sim,
        sensor_noise=sensor,
        run=replace(serial, executor="processes"),
        **settings,
    )
    xr.testing.assert_equal(
        noisy["posterior_predictive"].to_dataset(), parallel["posterior_predictive"].to_dataset()
    )
    unchanged = simulate_predictive(
        line_posterior,
        sim,
        sensor_noise=sensor,
        noise=False,
        run=serial,
        **settings,
    )
    xr.testing.assert_equal(
        unchanged["posterior_predictive"].to_dataset(), clean["posterior_predictive"].to_dataset()
    )


def test_learned_sensor_noise_scales_are_used_draw_by_draw(line_posterior):
    from pymc_vcc.inference.noise import SensorNoise

    posterior = line_posterior["posterior"].to_dataset().drop_vars("nu_y")
    scales = np.where(np.arange(60) < 30, 0.1, 2.0) * np.ones((2, 1))
    learned = xr.DataTree.from_dict(
        {"posterior": posterior.assign(sigma_y=(("chain", "draw"), scales))}
    )
    sim = AsDataset(LinearGaussian(n_time=200, sigma=0.0))
    settings = {"parameters": ["a", "b"], "run": RunOptions(executor="serial", seed=8)}
    clean = simulate_predictive(learned, sim, noise=False, **settings)
    sensor = SensorNoise(kinds={"y": "temperature"}, temperature=0.5)
    noisy = simulate_predictive(learned, sim, sensor_noise=sensor, **settings)
    residual = noisy["posterior_predictive"]["y"] - clean["posterior_predictive"]["y"]
    spread = residual.std("time").values
    np.testing.assert_allclose(spread[:, :30], 0.1, rtol=0.25)
    np.testing.assert_allclose(spread[:, 30:], 2.0, rtol=0.25)


def test_sensor_noise_needs_to_know_the_kind_of_each_output(line_posterior):
    from pymc_vcc.inference.noise import SensorNoise

    sim = AsDataset(LinearGaussian(n_time=20))
    with pytest.raises(ValueError, match="output 'y' has units None; SensorNoise knows"):
        simulate_predictive(
            line_posterior,
            sim,
            sensor_noise=SensorNoise(),
            run=RunOptions(executor="serial", seed=1),
        )


def test_failed_draws_are_nan_counted_and_left_out_of_the_bands(line_posterior):
    sim = Flaky(AsDataset(LinearGaussian(n_time=20)), rate=0.3)
    tree = simulate_predictive(
        line_posterior, sim, parameters=["a", "b"], run=RunOptions(executor="serial", seed=5)
    )
    values = tree["posterior_predictive"]["y"].values
    failed = np.isnan(values).all(axis=2)
    bands = predictive_bands(tree)
    assert failed.sum() == bands.attrs["n_failed"] == tree["posterior_predictive"].attrs["n_failed"]
    assert 0.15 < failed.mean() < 0.45
    assert not np.isnan(values[~failed]).any()
    assert np.isfinite(bands["y"].values).all()
    assert "exception" in tree["posterior_predictive"].attrs["failure_kinds"]


def test_results_do_not_depend_on_the_executor_and_draws_can_be_thinned(line_posterior):
    sim = AsDataset(LinearGaussian(n_time=20))
    settings = {"max_draws": 30}
    serial = simulate_predictive(
        line_posterior, sim, run=RunOptions(executor="serial", seed=6), **settings
    )
    parallel = simulate_predictive(
        line_posterior, sim, run=RunOptions(executor="processes", seed=6), **settings
    )
    xr.testing.assert_equal(
        serial["posterior_predictive"].to_dataset(), parallel["posterior_predictive"].to_dataset()
    )
    assert serial["posterior_predictive"]["y"].shape == (2, 15, 20)
    from_sequence = simulate_predictive(
        line_posterior,
        sim,
        run=RunOptions(executor="serial", seed=np.random.SeedSequence(6)),
        max_draws=30,
    )
    xr.testing.assert_equal(
        serial["posterior_predictive"].to_dataset(),
        from_sequence["posterior_predictive"].to_dataset(),
    )


def test_bad_arguments_are_named(line_posterior):
    sim = AsDataset(LinearGaussian(n_time=20))
    with pytest.raises(ValueError, match="interval must lie in"):
        predictive_bands(
            simulate_predictive(line_posterior, sim, run=RunOptions(executor="serial")), 1.0
        )
    with pytest.raises(ValueError, match="no posterior_predictive group; run simulate_predictive"):
        predictive_bands(line_posterior)
    with pytest.raises(ValueError, match=r"posterior lacks parameter\(s\) \['c'\]"):
        simulate_predictive(
            line_posterior, sim, parameters=["c"], run=RunOptions(executor="serial")
        )
    with pytest.raises(ValueError, match="unknown outputs"):
        simulate_predictive(line_posterior, sim, outputs=["TD"], run=RunOptions(executor="serial"))
    with pytest.raises(ValueError, match="max_draws must be"):
        simulate_predictive(line_posterior, sim, max_draws=0, run=RunOptions(executor="serial"))


def test_smc_posterior_predicts_a_longer_profile():
    short, long = GaussianLocation(n_time=50), GaussianLocation(n_time=200)
    observed = short({"mu": 0.4}, np.random.default_rng(7))
    with pm.Model(), warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Numba will use object mode")
        add_simulator("y", short, observed, noise=(0.0, 0.05), epsilon=0.5, distance=short.distance)
        idata = sample_smc_abc(draws=100, executor="serial", random_seed=8, progressbar=False)
    tree = simulate_predictive(idata, long, run=RunOptions(executor="serial", seed=9))
    assert tree["posterior_predictive"]["y"].shape == (1, 100, 200)
    median = predictive_bands(tree)["y"].sel(band="median").values
    assert abs(median.mean() - idata.posterior["mu"].mean().item()) < 0.05


def test_vcc_predictive_keeps_time_and_units_of_the_simulator():
    from pymc_vcc.physics.simulate import VCCSimulator

    sim = VCCSimulator(t_window=(20.0, 300.0), outputs=["PD", "TS", "MDOT"])
    truth = sim({"M0": 1.5})
    rng = np.random.default_rng(0)
    tree = simulate_predictive(
        posterior_tree({"M0": rng.normal(1.5, 0.02, (1, 6))}),
        sim,
        reference=truth,
        run=RunOptions(executor="processes", n_workers=2, seed=1),
    )
    predictive = tree["posterior_predictive"].to_dataset()
    np.testing.assert_array_equal(predictive["time"].values, truth["time"].values)
    for name in ("PD", "TS", "MDOT"):
        assert predictive[name].attrs["units"] == truth[name].attrs["units"]
        assert predictive[name].attrs["long_name"] == truth[name].attrs["long_name"]
    median = predictive_bands(tree)["PD"].sel(band="median").values
    np.testing.assert_allclose(median, truth["PD"].values, rtol=0.02)
