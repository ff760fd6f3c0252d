"""Regression-adjusted ABC: learnt summaries, rejection and the local-linear adjustment."""

import numpy as np
import pytest
import xarray as xr

from pymc_vcc.execution.options import RunOptions
from pymc_vcc.inference.noise import SensorNoise, with_noise
from pymc_vcc.inference.priors import GMMPrior, UniformPrior
from pymc_vcc.inference.regression import (
    MIN_HELD_OUT_R2,
    posterior_box,
    regression_abc,
    regression_adjustment,
    summary_features,
)
from pymc_vcc.testing import Flaky, Recording, SensorProblem

PROBLEM = SensorProblem(n_time=120)
SCALES = {"TD": 0.3, "PD": 2.0e4, "MDOT": 1.0e-3}  # the mass flow tells next to nothing
ABSOLUTE = SensorNoise(  # absolute noise on every output: the exact posterior is Gaussian
    outputs=SCALES, kinds=dict.fromkeys(SCALES, "temperature")
)


def _posterior(values: dict[str, np.ndarray]) -> xr.Dataset:
    return xr.Dataset({name: (("chain", "draw"), v[np.newaxis]) for name, v in values.items()})


def _observed(charge: float, seed: int) -> xr.Dataset:
    return ABSOLUTE.measure(PROBLEM.dataset(charge), np.random.default_rng(seed))


def test_the_adjustment_gives_the_exact_posterior_of_a_linear_gaussian_model():
    """Features linear in (a, b) with Gaussian noise, c inert: the adjusted draws have the exact
    posterior of a and b (rejection alone is several times wider) and the prior's spread of c."""
    rng = np.random.default_rng(3)
    lower, upper = np.zeros(3), np.ones(3)
    loadings = np.array([[1.0, 0.5, 0.0, 2.0, 1.0, 0.3], [0.0, 1.0, 1.0, -1.0, 0.5, 0.2]])
    loadings = np.vstack([loadings, np.zeros(6)])  # c changes no feature
    noise = 0.02
    thetas = rng.uniform(0.3, 0.7, size=(20_000, 3))
    features = thetas @ loadings + noise * rng.standard_normal((20_000, 6))
    truth = np.array([0.45, 0.55, 0.5])
    observed = truth @ loadings + noise * rng.standard_normal(6)
    found = regression_adjustment(thetas, features, observed, lower, upper, accept=0.05)
    design = loadings[:2].T
    covariance = noise**2 * np.linalg.inv(design.T @ design)
    exact_mean = np.linalg.lstsq(design, observed, rcond=None)[0]
    exact_sd = np.sqrt(np.diag(covariance))
    mean = found.weights @ found.adjusted
    sd = np.sqrt(found.weights @ (found.adjusted - mean) ** 2)
    raw_sd = np.sqrt(found.weights @ (found.thetas - found.weights @ found.thetas) ** 2)
    assert mean[:2] == pytest.approx(exact_mean, abs=0.2 * exact_sd.min())
    assert sd[:2] == pytest.approx(exact_sd, rel=0.15)
    assert (raw_sd[:2] > 2 * exact_sd).all()
    assert sd[2] == pytest.approx(0.4 / np.sqrt(12), rel=0.1)
    assert found.held_out_r2[:2].min() > 0.95 and abs(found.held_out_r2[2]) < 0.05
    assert 0.5 * len(found.weights) < found.effective_size < len(found.weights)


def test_inert_parameters_keep_the_prior_where_the_data_sit_off_the_simulations():
    """Ten inert parameters and data whose 30 noise features sit 2 sd off every simulation's:
    fitted on their noise summaries, the inert ones were shifted by up to 0.6 of their prior
    sd; unadjusted, they keep the prior, and the two informed ones their exact mean."""
    rng = np.random.default_rng(0)
    thetas = rng.uniform(0.0, 1.0, size=(6000, 12))
    loadings = rng.normal(size=(2, 10))
    features = np.column_stack(
        [thetas[:, :2] @ loadings + 0.05 * rng.normal(size=(6000, 10)), rng.normal(size=(6000, 30))]
    )
    features[-5:] *= 100  # wild simulations among the held-out draws: R² stays meaningful
    observed = np.concatenate([np.array([0.5, 0.5]) @ loadings, np.full(30, 2.0)])
    found = regression_adjustment(thetas, features, observed, 0.0, 1.0, accept=0.05)
    mean = found.weights @ found.adjusted
    sd = np.sqrt(found.weights @ (found.adjusted - mean) ** 2)
    exact_sd = 0.05 * np.sqrt(np.diag(np.linalg.inv(loadings @ loadings.T)))
    assert mean[:2] == pytest.approx([0.5, 0.5], abs=0.2 * exact_sd.min())
    assert (sd[:2] < 1.5 * exact_sd).all()  # the noise features blur the summaries a little
    assert (found.held_out_r2[:2] > 0.9).all() and (found.held_out_r2[2:] < MIN_HELD_OUT_R2).all()
    assert np.abs(mean[2:] - 0.5).max() < 0.05  # Monte Carlo error ~0.02
    np.testing.assert_allclose(sd[2:] * np.sqrt(12), 1.0, atol=0.1)


def test_few_accepted_draws_a_coefficient_keep_the_exact_spread():
    """60 accepted draws for 13 coefficients: raw residuals would be ~17 % too narrow (the fit
    bends towards its points); over sqrt(1 - leverage) they have the exact posterior's sd."""
    rng = np.random.default_rng(3)
    d, noise = 12, 0.02
    loadings = rng.normal(size=(d, 20))
    thetas = rng.uniform(0.3, 0.7, size=(20_000, d))
    features = thetas @ loadings + noise * rng.standard_normal((20_000, 20))
    observed = np.full(d, 0.5) @ loadings + noise * rng.standard_normal(20)
    exact_sd = noise * np.sqrt(np.diag(np.linalg.inv(loadings @ loadings.T)))
    found = regression_adjustment(thetas, features, observed, 0.0, 1.0, accept=0.003)
    mean = found.weights @ found.adjusted
    sd = np.sqrt(found.weights @ (found.adjusted - mean) ** 2)
    assert len(found.weights) == 60
    assert np.median(sd / exact_sd) == pytest.approx(1.0, abs=0.08)


def test_regression_abc_gives_the_exact_posterior_of_noisy_sensor_data():
    """From a posterior ~100 exact sds wide (a KS-SMC's), the second round's box is ~10 wide."""
    observed = _observed(1.37, 4)
    exact_mean, exact_sd = PROBLEM.exact_posterior(observed, SCALES)
    rough = _posterior({"M0": np.random.default_rng(1).uniform(1.1, 1.6, 64)})
    tree = regression_abc(
        PROBLEM,
        UniformPrior(PROBLEM.bounds),
        rough,
        observed,
        n=3000,
        sensor_noise=ABSOLUTE,
        run=RunOptions(executor="serial", seed=2),
    )
    draws = tree["posterior"]["M0"].values.ravel()
    assert draws.mean() == pytest.approx(exact_mean, abs=0.2 * exact_sd)
    assert draws.std() == pytest.approx(exact_sd, rel=0.15)
    stats = tree["sample_stats"]
    assert int(stats["n_simulations"]) == 6000 and int(stats["n_accepted"]) == 300
    assert int(stats["n_failed"]) == 0
    assert float(stats["held_out_r2"].sel(parameter="M0")) > 0.7  # in the narrow second box
    first, second = (stats["box_high"] - stats["box_low"]).sel(parameter="M0").values
    assert second < 0.2 * first


def test_learnable_noise_scales_are_drawn_simulated_and_adjusted_like_parameters():
    """The paper's ν: each draw's simulation gets the noise of its ν, and the posterior holds
    every prior parameter, inside the prior's bounds."""
    prior = with_noise(UniformPrior(PROBLEM.bounds), {"TD": (0.0, 0.01)}, PROBLEM.output_names)
    rough = _posterior({"M0": np.linspace(1.3, 1.45, 50), "nu_TD": np.linspace(0.0, 0.004, 50)})
    tree = regression_abc(
        PROBLEM,
        prior,
        rough,
        PROBLEM.dataset(1.37),
        n=800,
        run=RunOptions(executor="serial", seed=0),
    )
    posterior = tree["posterior"]
    assert set(posterior.data_vars) == {"M0", "nu_TD"}
    assert (posterior["nu_TD"] >= 0).all() and (posterior["nu_TD"] <= 0.01).all()
    assert abs(float(posterior["M0"].mean()) - 1.37) < 3 * float(posterior["M0"].std())
    box_sd = 0.18 / np.sqrt(12)  # the draws' range, widened by a tenth of it on each side
    assert float(posterior["M0"].std()) < 0.5 * box_sd
    # the data are noise-free: the roughness summaries draw the second round's ν near 0
    assert float(tree["sample_stats"]["box_high"].sel(parameter="nu_TD", round=1)) < 0.002


def test_failures_are_counted_and_a_checkpoint_resumes_without_simulating(tmp_path):
    log = tmp_path / "calls.txt"
    simulator = Recording(Flaky(PROBLEM, rate=0.1, modes=("raise", "nan")), str(log))
    observed = _observed(1.37, 4)
    rough = _posterior({"M0": np.linspace(1.32, 1.42, 32)})
    run = dict(
        n=600,
        sensor_noise=ABSOLUTE,
        run=RunOptions(executor="serial", seed=5, checkpoint=tmp_path / "regression"),
    )
    first = regression_abc(simulator, UniformPrior(PROBLEM.bounds), rough, observed, **run)
    calls = len(log.read_text().splitlines())
    again = regression_abc(simulator, UniformPrior(PROBLEM.bounds), rough, observed, **run)
    assert len(log.read_text().splitlines()) == calls  # every simulation came from the file
    failed = int(first["sample_stats"]["n_failed"])
    assert 60 <= failed <= 180  # 10 % of 2 rounds of 600
    xr.testing.assert_equal(first["posterior"].to_dataset(), again["posterior"].to_dataset())


def test_the_box_widens_the_posterior_range_inside_the_prior_and_draws_stay_in_it():
    prior = UniformPrior({"x": (0.0, 10.0), "y": (0.0, 1.0)})
    posterior = _posterior({"x": np.array([4.0, 6.0]), "y": np.array([0.1, 0.9])})
    box = posterior_box(posterior, prior, widen=0.5)
    assert box == {"x": (3.0, 7.0), "y": (0.0, 1.0)}
    draws = prior.sample_in_box(box, 500, np.random.default_rng(0))
    assert draws.shape == (500, 2)
    assert (draws[:, 0] >= 3.0).all() and (draws[:, 0] <= 7.0).all()
    with pytest.raises(ValueError, match=r"lacks the prior's parameter\(s\) \['y'\]"):
        posterior_box(_posterior({"x": np.array([4.0])}), prior)


def test_a_mixture_prior_is_drawn_inside_the_box_or_whole_when_the_box_holds_too_little():
    """Dataset 2's prior is a Gaussian mixture: its draws inside the box follow it there, exactly
    for diagonal components however far out the box lies; a full covariance is drawn by
    rejection, and where the box holds next to none of its mass the round warns and draws
    from the whole prior."""
    bounds = {"M0": PROBLEM.bounds["M0"]}
    narrow = GMMPrior(bounds, np.array([1.0]), np.array([[-0.6]]), np.array([[[0.01]]]))
    draws = narrow.sample_in_box({"M0": (1.30, 1.45)}, 2000, np.random.default_rng(0))
    assert ((draws >= 1.30) & (draws <= 1.45)).all()
    centre = narrow.sample(20_000, np.random.default_rng(1))
    assert np.median(draws) == pytest.approx(np.median(centre), abs=0.005)  # inside the box
    far = narrow.sample_in_box({"M0": (2.0, 2.1)}, 10, np.random.default_rng(0))  # 23 sd out
    assert ((far >= 2.0) & (far <= 2.1)).all()
    noisy = with_noise(UniformPrior(bounds), {"TD": (0.0, 0.01)}, PROBLEM.output_names)
    correlated = GMMPrior(
        noisy.bounds,
        np.array([1.0]),
        np.array([[-0.6, 0.0]]),
        np.array([[[0.01, 0.005], [0.005, 0.01]]]),
    )
    off = _posterior({"M0": np.linspace(2.0, 2.1, 20), "nu_TD": np.linspace(0.004, 0.006, 20)})
    with pytest.warns(RuntimeWarning, match="this round draws from the whole prior"):
        tree = regression_abc(
            PROBLEM,
            correlated,
            off,
            PROBLEM.dataset(1.37),
            n=200,
            rounds=1,
            run=RunOptions(executor="serial"),
        )
    assert float(tree["sample_stats"]["box_low"].sel(parameter="M0").item()) == bounds["M0"][0]


def test_bad_settings_are_refused_before_any_simulation():
    rough = _posterior({"M0": np.linspace(1.3, 1.4, 8)})
    prior = UniformPrior(PROBLEM.bounds)
    for options, message in [
        ({"n": 0}, "n must be a positive integer, got 0"),
        ({"n": 100, "rounds": 1.5}, "rounds must be a positive integer, got 1.5"),
        ({"n": 100, "accept": 1.5}, r"accept must lie in \(0.0, 1.0\), got 1.5"),
        ({"n": 100, "widen": -1.0}, "widen must be >= 0, got -1.0"),
    ]:
        with pytest.raises(ValueError, match=message):
            regression_abc(Flaky(PROBLEM, rate=1.0), prior, rough, PROBLEM.dataset(1.3), **options)
    with pytest.raises(ValueError, match="keeps 2; the adjustment of 1 parameters needs at least"):
        regression_adjustment(np.ones((20, 1)), np.ones((20, 3)), np.ones(3), 0.0, 2.0, accept=0.1)


def test_summary_features_are_window_means_over_the_observed_spread_and_roughness():
    observed = np.array([[0.0, 2.0, 0.0, 2.0], [5.0, 5.0, 7.0, 7.0]])
    features = summary_features(observed[np.newaxis], observed, window=2)
    assert features.shape == (1, 6)
    # means over the spread (1 for both); rms deviation within windows over the rms value
    np.testing.assert_allclose(features[0], [1.0, 1.0, 5.0, 7.0, 1.0 / np.sqrt(2.0), 0.0])
