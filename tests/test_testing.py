"""The shipped test problems: their exact posteriors and KS windows are right."""

import numpy as np
import pytest
import xarray as xr
from scipy import stats
from scipy.integrate import trapezoid

from pymc_vcc.inference.distances import ks_distance
from pymc_vcc.testing import (
    AsDataset,
    Flaky,
    GaussianLocation,
    LinearGaussian,
    ShiftedProfile,
)


def test_gaussian_location_posterior_matches_a_grid_posterior_with_truncation():
    model = GaussianLocation(n_time=40, sigma=1.0, low=-0.2, high=3.0)
    observed = model({"mu": 0.0}, np.random.default_rng(0))
    grid = np.linspace(model.low, model.high, 20001)
    loglik = stats.norm.logpdf(observed[0][:, None], loc=grid, scale=model.sigma).sum(axis=0)
    density = np.exp(loglik - loglik.max())
    density /= trapezoid(density, grid)
    mean = trapezoid(grid * density, grid)
    sd = np.sqrt(trapezoid((grid - mean) ** 2 * density, grid))
    posterior = model.posterior(observed)
    assert posterior.mean() == pytest.approx(mean, abs=1e-6)
    assert posterior.std() == pytest.approx(sd, rel=1e-4)


def test_linear_gaussian_moments_match_a_grid_posterior():
    model = LinearGaussian(n_time=30, sigma=0.5)
    observed = model({"a": 0.4, "b": -1.2}, np.random.default_rng(1))
    mean, covariance = model.posterior_moments(observed)
    sd = np.sqrt(np.diag(covariance))
    a, b = np.meshgrid(
        np.linspace(mean[0] - 8 * sd[0], mean[0] + 8 * sd[0], 401),
        np.linspace(mean[1] - 8 * sd[1], mean[1] + 8 * sd[1], 401),
        indexing="ij",
    )
    x = model.design[:, 1]
    residual = observed[0][None, None, :] - a[..., None] - b[..., None] * x
    loglik = -0.5 * (residual**2).sum(axis=-1) / model.sigma**2
    weights = np.exp(loglik - loglik.max())
    weights /= weights.sum()
    grid_mean = np.array([(a * weights).sum(), (b * weights).sum()])
    grid_cov = np.cov(np.stack([a.ravel(), b.ravel()]), aweights=weights.ravel(), ddof=0)
    np.testing.assert_allclose(mean, grid_mean, atol=1e-4 * sd.max())
    np.testing.assert_allclose(covariance, grid_cov, rtol=1e-3, atol=1e-6)


def test_sufficient_distances_are_zero_for_equal_statistics_and_scale_in_sds():
    location = GaussianLocation(n_time=25, sigma=2.0)
    obs = np.zeros((1, 25))
    sims = np.stack([obs, obs + location.standard_error])
    np.testing.assert_allclose(location.distance(sims, obs), [0.0, 1.0])
    line = LinearGaussian(n_time=20)
    base = line({"a": 0.1, "b": 0.2}, np.random.default_rng(2))
    _, covariance = line.posterior_moments(base)
    shift = np.sqrt(covariance[0, 0])
    shifted = base + shift  # moves the intercept fit by one posterior sd, leaves the slope
    distance = line.distance(np.stack([base, shifted]), base)
    assert distance[0] == pytest.approx(0.0, abs=1e-12)
    expected = np.sqrt(shift**2 * np.linalg.inv(covariance)[0, 0])
    assert distance[1] == pytest.approx(expected, rel=1e-10)


def test_abc_targets_reduce_to_the_posterior_and_to_a_gaussian_plus_window():
    # far from the bounds, a whitened ball of radius ε adds variance ε²/(d + 2) per axis
    location = GaussianLocation(n_time=50, sigma=1.0, low=-3.0, high=3.0)
    observed = location({"mu": 0.2}, np.random.default_rng(3))
    posterior = location.posterior(observed)
    mean, sd = location.abc_target(observed, 1e-3)
    assert mean == pytest.approx(posterior.mean(), abs=1e-6)
    assert sd == pytest.approx(posterior.std(), rel=1e-5)
    mean, sd = location.abc_target(observed, 1.5)
    assert mean == pytest.approx(posterior.mean(), abs=1e-6)
    assert sd == pytest.approx(location.standard_error * np.sqrt(1 + 1.5**2 / 3), rel=1e-4)
    line = LinearGaussian(n_time=20, sigma=1.0, low=-8.0, high=8.0)
    observed = line({"a": 0.1, "b": -0.3}, np.random.default_rng(4))
    exact_mean, exact_cov = line.posterior_moments(observed)
    mean, covariance = line.abc_target(observed, 1e-2)
    np.testing.assert_allclose(mean, exact_mean, atol=1e-4)
    np.testing.assert_allclose(covariance, exact_cov, rtol=1e-3, atol=1e-6)
    mean, covariance = line.abc_target(observed, 1.3)
    np.testing.assert_allclose(covariance, exact_cov * (1 + 1.3**2 / 4), rtol=2e-3, atol=1e-6)
    profile = ShiftedProfile()
    observed = profile({"mu": 0.1}, np.random.default_rng(5))
    window = profile.ks_window(0.05)
    _, sd = profile.abc_target(observed, 0.05)
    assert sd == pytest.approx(np.sqrt(profile.sigma**2 + window**2 / 3), rel=1e-4)


def test_gaussian_location_abc_target_matches_brute_force_abc_near_a_bound():
    location = GaussianLocation(n_time=25, sigma=1.0, low=-0.1, high=1.0)
    observed = location({"mu": 0.0}, np.random.default_rng(6))
    rng = np.random.default_rng(7)
    mu = rng.uniform(location.low, location.high, 2_000_000)
    sample_mean = mu + location.standard_error * rng.standard_normal(mu.size)
    epsilon = 0.8
    accepted = mu[np.abs(sample_mean - observed.mean()) <= epsilon * location.standard_error]
    mean, sd = location.abc_target(observed, epsilon)
    assert accepted.mean() == pytest.approx(mean, abs=4 * sd / np.sqrt(accepted.size))
    assert accepted.std() == pytest.approx(sd, rel=4 / np.sqrt(2 * accepted.size))


def test_ks_of_shifted_profiles_is_the_stated_step_function():
    model = ShiftedProfile(n_time=101, span=1.0)
    step = model.span / (model.n_time - 1)
    base = model.profile[np.newaxis, :]
    for delta in (0.0, 0.001, 0.0099, 0.0101, 0.0537, -0.0537, 0.999, 1.5):
        expected = 0.0 if delta == 0 else min(101, np.floor(abs(delta) / step) + 1) / 101
        assert ks_distance(base + delta, base) == pytest.approx(expected, abs=1e-12)
    epsilon = 6 / 101
    window = model.ks_window(epsilon)
    assert ks_distance(base + 0.999 * window, base) <= epsilon < ks_distance(base + window, base)


def test_flaky_fails_at_its_rate_in_every_mode():
    flaky = Flaky(GaussianLocation(n_time=5), rate=0.3)
    counts = {"raise": 0, "nan": 0, "inf": 0, "status": 0, "ok": 0}
    for seed in range(2000):
        try:
            result = flaky({"mu": 0.0}, np.random.default_rng(seed))
        except RuntimeError:
            counts["raise"] += 1
            continue
        if isinstance(result, xr.Dataset):
            assert result.attrs["status"] == "failed"
            counts["status"] += 1
        elif np.isnan(result).any():
            counts["nan"] += 1
        elif np.isinf(result).any():
            counts["inf"] += 1
        else:
            counts["ok"] += 1
    assert counts["ok"] / 2000 == pytest.approx(0.7, abs=0.04)
    for mode in ("raise", "nan", "inf", "status"):
        assert counts[mode] / 2000 == pytest.approx(0.075, abs=0.02)
    with pytest.raises(ValueError, match="rate must be in"):
        Flaky(GaussianLocation(), rate=1.5)


def test_as_dataset_names_the_outputs():
    result = AsDataset(GaussianLocation(n_time=4))({"mu": 1.0}, np.random.default_rng(0))
    assert list(result.data_vars) == ["y"] and result.y.sizes == {"time": 4}
    assert result.attrs["status"] == "ok"
