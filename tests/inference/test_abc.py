"""ABC rejection (Algorithm 1): exact answers on known problems, failures, validation, results.

Tolerances. The sampler draws from the ABC target p(θ) P(d ≤ ε | θ), which the test problems
give exactly for the realised ε (pymc_vcc.testing). With N accepted draws, the sample mean is
within 4 sd/√N of the target mean and the sample sd within a relative 4/√(2N) of the target sd
(4 standard errors: a false alarm once in ~16 000 runs; the seeds are fixed, so the tests are
deterministic). The distance of the target from the exact posterior is computed, not assumed,
and bounded separately, so each test also bounds the sampler's error against the exact posterior.
"""

from dataclasses import replace

import numpy as np
import pytest
import xarray as xr
from scipy import stats

from pymc_vcc.execution.executors import make_executor
from pymc_vcc.execution.options import RunOptions
from pymc_vcc.inference.priors import GMMPrior, UniformPrior
from pymc_vcc.inference.rejection import (
    SimulationTask,
    TooManyFailuresError,
    abc_rejection,
    simulation_rng,
)
from pymc_vcc.testing import AsDataset, Flaky, GaussianLocation, LinearGaussian, ShiftedProfile


def _within_monte_carlo_error(sample, mean, sd):
    n = sample.size
    assert abs(sample.mean() - mean) <= 4 * sd / np.sqrt(n), (sample.mean(), mean, sd, n)
    assert abs(sample.std() / sd - 1) <= 4 / np.sqrt(2 * n), (sample.std(), sd, n)


def test_gaussian_location_posterior_matches_the_exact_posterior():
    model = GaussianLocation(n_time=100, sigma=1.0, low=-1.0, high=1.0)
    observed = model({"mu": 0.3}, np.random.default_rng(1))
    tree = abc_rejection(
        model,
        UniformPrior(model.bounds),
        observed,
        n_pilot=2000,
        quantile=0.03,
        n_main=30_000,
        n_desired=30_000,
        distance=model.distance,
        run=RunOptions(executor="serial", seed=1),
    )
    sample = tree.posterior["mu"].values.ravel()
    epsilon = float(tree.sample_stats["epsilon"])
    target_mean, target_sd = model.abc_target(observed, epsilon)
    exact = model.posterior(observed)
    assert sample.size > 700
    _within_monte_carlo_error(sample, target_mean, target_sd)
    # the window ε (0.28 standard errors here) moves the target < 2 % from the exact posterior
    assert abs(target_mean - exact.mean()) < 0.01 * exact.std()
    assert 1.0 <= target_sd / exact.std() < 1.02


def test_linear_gaussian_posterior_matches_the_exact_correlated_target():
    model = LinearGaussian()
    observed = model({"a": 0.3, "b": -0.4}, np.random.default_rng(2))
    tree = abc_rejection(
        model,
        UniformPrior(model.bounds),
        observed,
        n_pilot=1000,
        quantile=0.02,
        n_main=30_000,
        n_desired=30_000,
        distance=model.distance,
        run=RunOptions(executor="serial", seed=3),
    )
    sample = np.column_stack([tree.posterior[name].values.ravel() for name in ("a", "b")])
    epsilon = float(tree.sample_stats["epsilon"])
    target_mean, target_cov = model.abc_target(observed, epsilon)
    target_sd = np.sqrt(np.diag(target_cov))
    for j in range(2):
        _within_monte_carlo_error(sample[:, j], target_mean[j], target_sd[j])
    target_rho = target_cov[0, 1] / np.prod(target_sd)
    rho = np.corrcoef(sample.T)[0, 1]
    assert abs(rho - target_rho) <= 4 * (1 - target_rho**2) / np.sqrt(sample.shape[0])
    # the target is the exact posterior widened by the whitened window, sd × sqrt(1 + ε²/4)
    # (ε ≈ 1.3 here: about 20 %), less a few % where the prior bounds trim the tails
    exact_mean, exact_cov = model.posterior_moments(observed)
    exact_sd = np.sqrt(np.diag(exact_cov))
    inflation = np.sqrt(1 + epsilon**2 / 4)
    np.testing.assert_allclose(target_sd / exact_sd, inflation, rtol=0.05)
    np.testing.assert_allclose(target_mean, exact_mean, atol=0.05 * exact_sd.max())


def test_ks_distance_posterior_matches_its_exact_target_and_tightens_with_the_quantile():
    model = ShiftedProfile()
    observed = AsDataset(model)({"mu": 0.3}, np.random.default_rng(3))
    spreads = {}
    for quantile, n_main in ((0.2, 4000), (0.02, 20_000)):
        tree = abc_rejection(
            AsDataset(model),
            UniformPrior(model.bounds),
            observed,
            n_pilot=1000,
            quantile=quantile,
            n_main=n_main,
            n_desired=n_main,
            run=RunOptions(executor="serial", seed=4),
        )
        sample = tree.posterior["mu"].values.ravel()
        epsilon = float(tree.sample_stats["epsilon"])
        target_mean, target_sd = model.abc_target(observed, epsilon)
        _within_monte_carlo_error(sample, target_mean, target_sd)
        spreads[quantile] = (epsilon, sample.std())
    assert spreads[0.02][0] < spreads[0.2][0] / 5  # a smaller quantile: a smaller threshold
    assert spreads[0.02][1] < spreads[0.2][1] / 2  # and a much tighter posterior
    assert spreads[0.02][1] < 1.05 * model.posterior(observed).std()


def test_simulation_based_calibration_finds_no_bias():
    """SBC: θ* from the prior, data from θ*, rank of θ* in its posterior; ranks ~ uniform."""
    model = GaussianLocation(n_time=20, sigma=1.0, low=-1.0, high=1.0)
    prior = UniformPrior(model.bounds)
    rng = np.random.default_rng(5)
    ranks = []
    for replication in range(120):
        truth = prior.sample(1, rng)[0, 0]
        observed = model({"mu": truth}, rng)
        tree = abc_rejection(
            model,
            prior,
            observed,
            n_pilot=200,
            quantile=0.1,
            n_main=1000,
            n_desired=1000,
            distance=model.distance,
            run=RunOptions(executor="serial", seed=replication),
        )
        ranks.append((tree.posterior["mu"].values < truth).mean())
    ranks = np.array(ranks)
    assert stats.kstest(ranks, "uniform").pvalue > 0.01
    assert abs(ranks.mean() - 0.5) < 3 * np.sqrt(1 / 12 / ranks.size)


def test_failures_are_excluded_counted_and_explained():
    model = GaussianLocation(n_time=20, low=-1.0, high=1.0)
    flaky = Flaky(
        model, rate=0.25, modes=("raise", "nan", "inf", "status", "stall"), stall_seconds=5
    )
    observed = model({"mu": 0.0}, np.random.default_rng(6))
    tree = abc_rejection(
        flaky,
        UniformPrior(model.bounds),
        observed,
        n_pilot=200,
        quantile=0.2,
        n_main=600,
        n_desired=600,
        distance=model.distance,
        run=RunOptions(executor="serial", seed=7, time_limit=0.05),
    )
    stats_ = tree.sample_stats
    status = stats_["sim_status"].values
    failures = dict(zip(stats_["failure_kind"].values, stats_["failures"].values, strict=True))
    assert int(stats_["n_failed"]) == (status != "ok").sum() == sum(failures.values())
    assert 0.2 < int(stats_["n_failed"]) / int(stats_["n_simulations"]) < 0.3
    for kind in ("exception", "non-finite", "solver", "time-limit"):
        assert failures[kind] > 0, kind
    reasons = set(stats_["sim_failure_reason"].values[status != "ok"])
    assert {"RuntimeError: synthetic failure", "synthetic solver failure"} <= reasons
    assert np.isnan(stats_["sim_distance"].values[status != "ok"]).all()
    assert not stats_["sim_accepted"].values[status != "ok"].any()


def test_a_run_where_most_simulations_fail_stops_with_a_clear_message():
    model = GaussianLocation(n_time=5)
    with pytest.raises(TooManyFailuresError, match=r"most simulations failed: \d+ of \d+"):
        abc_rejection(
            Flaky(model, rate=0.9),
            UniformPrior(model.bounds),
            np.zeros((1, 5)),
            n_pilot=500,
            n_main=500,
            n_desired=10,
            run=RunOptions(executor="serial", seed=0),
        )


def test_main_phase_stops_at_n_desired_accepting_the_first_draws_in_order():
    model = GaussianLocation(n_time=20)
    tree = abc_rejection(
        model,
        UniformPrior(model.bounds),
        model({"mu": 0.5}, np.random.default_rng(8)),
        n_pilot=300,
        quantile=0.1,
        n_main=5000,
        n_desired=40,
        distance=model.distance,
        run=RunOptions(executor="serial", seed=9),
    )
    stats_ = tree.sample_stats
    main = stats_["sim_phase"].values == "main"
    distances = stats_["sim_distance"].values[main]
    acceptable = distances <= float(stats_["epsilon"])
    assert tree.posterior.sizes["draw"] == int(stats_["n_accepted"]) == 40
    assert acceptable.sum() == 40 and acceptable[-1]  # stopped at the 40th acceptance
    assert main.sum() < 5000 and int(stats_["n_simulations"]) == 300 + main.sum()
    np.testing.assert_array_equal(
        tree.posterior["mu"].values.ravel(), tree.prior["mu"].values.ravel()[300:][acceptable]
    )
    assert float(stats_["acceptance_rate"]) == pytest.approx(40 / main.sum())


def test_same_seed_same_result_on_serial_and_processes_and_different_seeds_differ():
    model = Flaky(GaussianLocation(n_time=30), rate=0.1)
    observed = GaussianLocation(n_time=30)({"mu": 0.2}, np.random.default_rng(10))
    settings = dict(n_pilot=300, quantile=0.1, n_main=1500, n_desired=100)
    prior = UniformPrior(model.base.bounds)
    run = RunOptions(executor="serial", seed=11)
    serial = abc_rejection(model, prior, observed, run=run, **settings)
    with make_executor("processes", n_workers=2) as pool:
        parallel = abc_rejection(
            model, prior, observed, run=replace(run, executor=pool), **settings
        )
    for group, variable in [
        ("posterior", "mu"),
        ("prior", "mu"),
        ("sample_stats", "sim_distance"),
        ("sample_stats", "sim_status"),
    ]:
        np.testing.assert_array_equal(serial[group][variable], parallel[group][variable])
    other = abc_rejection(model, prior, observed, run=replace(run, seed=12), **settings)
    assert not np.array_equal(other.prior["mu"].values, serial.prior["mu"].values)


def test_noise_scales_are_parameters_and_perturb_outputs_as_in_algorithm_1():
    model = GaussianLocation(n_time=10)
    observed = model({"mu": 0.0}, np.random.default_rng(12))
    tree = abc_rejection(
        model,
        UniformPrior(model.bounds),
        observed,
        noise={"y": (0.0, 0.3)},
        n_pilot=100,
        quantile=0.2,
        n_main=300,
        n_desired=300,
        run=RunOptions(executor="serial", seed=13),
    )
    assert list(tree.posterior.data_vars) == ["mu", "nu_y"]
    nu = tree.prior["nu_y"].values
    assert (nu >= 0).all() and (nu <= 0.3).all() and nu.std() > 0.05
    # one simulation by hand: Y + ν·|Y|·Z with Z drawn after the simulator from its stream
    from pymc_vcc.inference.series import prepare_observed

    data = prepare_observed(observed, output_names=model.output_names)
    task = SimulationTask(model, data, ("mu",), (0,), (1,), model.distance, 99, (), None)
    theta = np.array([0.4, 0.2])
    (record,) = task([(1, 7, theta)])
    rng = simulation_rng(99, (), 3, 7)
    values = model({"mu": 0.4}, rng)
    noisy = values + 0.2 * np.abs(values) * rng.standard_normal(values.shape)
    assert record.distance == pytest.approx(model.distance(noisy[None], data.values)[0], abs=1e-12)


def test_result_tree_has_the_arviz_groups_and_round_trips_through_netcdf(tmp_path):
    model = Flaky(GaussianLocation(n_time=15), rate=0.1)
    observed = xr.Dataset({"y": ("time", np.linspace(-1, 1, 15))}, coords={"time": np.arange(15.0)})
    tree = abc_rejection(
        model,
        UniformPrior(model.base.bounds),
        observed,
        n_pilot=100,
        n_main=400,
        n_desired=20,
        quantile=0.1,
        run=RunOptions(executor="serial", seed=14),
    )
    assert {"posterior", "prior", "observed_data", "sample_stats"} <= set(tree.children)
    assert tree.posterior.sizes == {"chain": 1, "draw": 20}
    assert tree.sample_stats["distance"].dims == ("chain", "draw")
    for name in ("epsilon", "n_simulations", "n_failed", "acceptance_rate", "wall_time"):
        assert tree.sample_stats[name].ndim == 0, name
    tree.to_netcdf(tmp_path / "result.nc", engine="h5netcdf")
    loaded = xr.open_datatree(tmp_path / "result.nc", engine="h5netcdf")
    for group in ("posterior", "prior", "observed_data", "sample_stats"):
        xr.testing.assert_identical(loaded[group].to_dataset(), tree[group].to_dataset())
    assert loaded.attrs["settings"] == tree.attrs["settings"]


def _never_called(theta, rng):
    raise AssertionError("no simulation may run before the inputs are checked")


_never_called.parameter_names = ("mu",)
_never_called.output_names = ("y",)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"observed": np.array([[0.0, np.nan, 1.0]])}, "non-finite value"),
        ({"observed": np.zeros((2, 5))}, r"2 rows but the simulator names 1 outputs"),
        ({"outputs": ["PE"]}, r"unknown outputs \['PE'\]"),
        ({"quantile": 0.0}, r"quantile must lie in \(0, 1\), got 0.0"),
        ({"quantile": 1.2}, r"quantile must lie in \(0, 1\)"),
        ({"n_desired": 2000, "n_main": 1000}, "n_desired=2000 exceeds n_main=1000"),
        ({"n_pilot": 0}, "n_pilot must be a positive integer"),
        ({"prior": UniformPrior({"sigma": (0, 1)})}, r"disagree on parameter names"),
        ({"noise": {"TD": (0, 0.1)}}, r"noise names unknown outputs \['TD'\]"),
        ({"noise": {"y": (-0.1, 0.1)}}, "0 <= low < high"),
        ({"run": RunOptions(executor="serial", seed=-3)}, "seed must be a non-negative integer"),
    ],
)
def test_bad_input_is_a_clear_error_before_any_simulation(change, message):
    arguments = {
        "simulator": _never_called,
        "prior": UniformPrior({"mu": (-1.0, 1.0)}),
        "observed": np.zeros((1, 5)),
        "n_pilot": 10,
        "n_main": 100,
        "n_desired": 10,
        "run": RunOptions(executor="serial"),
    } | change
    with pytest.raises(ValueError, match=message):
        abc_rejection(**arguments)


def test_a_prior_fitted_with_noise_scales_is_used_as_is_and_must_match_their_bounds():
    bounds = {"mu": (-1.0, 1.0), "nu_y": (0.0, 0.1)}
    rng = np.random.default_rng(15)
    sample = np.column_stack([rng.uniform(-0.5, 0.5, 200), rng.uniform(0.01, 0.09, 200)])
    fitted = GMMPrior.fit(sample, bounds, max_components=1, seed=0)
    model = GaussianLocation(n_time=5)
    common = dict(n_pilot=50, n_main=100, n_desired=5, run=RunOptions(executor="serial", seed=0))
    tree = abc_rejection(model, fitted, np.zeros((1, 5)), noise={"y": (0.0, 0.1)}, **common)
    assert set(tree.posterior.data_vars) == {"mu", "nu_y"}
    with pytest.raises(ValueError, match=r"prior bounds \(0.0, 0.1\) of 'nu_y' differ"):
        abc_rejection(model, fitted, np.zeros((1, 5)), noise={"y": (0.0, 0.2)}, **common)
    with pytest.raises(ValueError, match="cannot be extended"):
        abc_rejection(
            model,
            GMMPrior.fit(sample[:, :1], {"mu": (-1.0, 1.0)}, max_components=1, seed=0),
            np.zeros((1, 5)),
            noise={"y": (0.0, 0.1)},
            **common,
        )


def test_progress_bar_shows_done_accepted_and_failed_when_asked(capsys):
    model = GaussianLocation(n_time=10)
    arguments = dict(n_pilot=100, quantile=0.2, n_main=300, n_desired=300)
    run = RunOptions(executor="serial", seed=16)
    abc_rejection(
        Flaky(model, 0.2), UniformPrior(model.bounds), np.zeros((1, 10)), run=run, **arguments
    )
    assert capsys.readouterr().err == ""  # off by default when not on a terminal
    tree = abc_rejection(
        Flaky(model, 0.2),
        UniformPrior(model.bounds),
        np.zeros((1, 10)),
        run=replace(run, progress=True),
        **arguments,
    )
    err = capsys.readouterr().err
    assert "pilot" in err and "main" in err and "ETA" in err
    main_failed = int((tree.sample_stats["sim_status"].values[100:] != "ok").sum())
    assert f"accepted {int(tree.sample_stats['n_accepted'])}" in err
    assert f"failed {main_failed}" in err
