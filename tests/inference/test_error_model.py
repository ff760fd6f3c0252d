"""The error budget of plateau summaries: windows, noise, bias, model error, likelihood, check."""

import numpy as np
import pytest
from scipy import stats

from pymc_vcc.execution.executors import make_executor
from pymc_vcc.inference.error_model import (
    ErrorBudget,
    SensorAccuracy,
    approximation_error,
    bias_covariance,
    lagged,
    noise_variance,
    plateau_windows,
    predictive_check,
    summarise,
)

TIMES = np.arange(0.0, 361.0)
EDGES = np.array([0.0, 120.0, 240.0, 360.0])


def test_plateaus_are_the_late_part_of_each_step():
    windows = plateau_windows(EDGES, TIMES, skip=60.0)
    assert [(TIMES[w[0]], TIMES[w[-1]]) for w in windows] == [(60, 119), (180, 239), (300, 360)]
    with pytest.raises(ValueError, match="no input step"):
        plateau_windows(np.array([0.0, 50.0]), TIMES[:51], skip=60.0)


def test_summaries_are_output_major_plateau_means():
    values = np.vstack([TIMES, 2 * TIMES])
    windows = plateau_windows(EDGES, TIMES, skip=60.0)
    assert summarise(values, windows) == pytest.approx([89.5, 209.5, 330, 179, 419, 660])


def test_noise_variance_of_a_plateau_mean_matches_ar1_theory():
    """AR(1) noise φ = 0.6, σ = 0.3 on top of a slow trend: the estimate is within 30 % of
    σ²(1 + φ)/((1 − φ) n) (the record's own noise, learnt from its differences)."""
    rng = np.random.default_rng(1)
    phi, sigma, n = 0.6, 0.3, 20000
    e = np.empty(n)
    e[0] = rng.normal(0, sigma)
    for t in range(1, n):
        e[t] = phi * e[t - 1] + rng.normal(0, sigma * np.sqrt(1 - phi**2))
    times = np.arange(float(n))
    edges = np.array([0.0, n / 2, n - 1.0])
    windows = plateau_windows(edges, times, skip=60.0)
    variance = noise_variance((1e-3 * times + e)[None, :], windows)
    expected = sigma**2 * (1 + phi) / ((1 - phi) * np.array([w.size for w in windows]))
    assert variance == pytest.approx(expected, rel=0.3)


def test_bias_is_shared_by_the_plateaus_of_a_sensor():
    accuracy = SensorAccuracy()
    cov = bias_covariance(np.array([300.0, 301.0, 2e6, 3e6]), ["K", "Pa"], 2, accuracy)
    assert cov[0, 1] == pytest.approx(0.5**2 / 3)  # uniform within ±0.5 K
    assert cov[2, 3] == pytest.approx(0.01**2 / 3 * 6e12)  # ±1 % of each reading
    assert cov[0, 2] == 0.0
    with pytest.raises(ValueError, match="no sensor accuracy"):
        bias_covariance(np.ones(1), ["m"], 1, accuracy)


def test_lagged_sensor_is_a_first_order_response():
    step = np.r_[np.zeros(10), np.ones(200)]
    read = lagged(step[None, :], np.array([20.0]), dt=1.0)[0]
    assert read[10 + 20] == pytest.approx(1 - np.exp(-1), abs=0.03)  # 63 % after one τ
    assert lagged(step[None, :], np.array([0.0]), 1.0)[0] == pytest.approx(step)


def _budget(observed, mean, cov, windows):
    return ErrorBudget(
        outputs=("a", "b"), windows=windows, observed=observed, mean=mean, parts={"all": cov}
    )


def test_log_likelihood_is_the_gaussian_of_the_summaries():
    windows = plateau_windows(EDGES, TIMES, skip=60.0)
    rng = np.random.default_rng(2)
    a = rng.normal(size=(6, 6))
    cov = a @ a.T + 6 * np.eye(6)
    observed, mean = rng.normal(size=6), rng.normal(size=6)
    simulated = rng.normal(size=(2, TIMES.size))
    budget = _budget(observed, mean, cov, windows)
    expected = stats.multivariate_normal(summarise(simulated, windows) + mean, cov).logpdf(observed)
    assert budget.log_likelihood(simulated) == pytest.approx(expected)
    assert budget.log_likelihood(np.full((2, TIMES.size), np.nan)) == -np.inf


def test_the_budgets_distance_makes_abc_kernel_its_likelihood():
    """At ε = 1 the ABC Gaussian kernel of the budget's distance is the budget's likelihood
    up to a constant, for every simulation; a failed simulation is infinitely far."""
    windows = plateau_windows(EDGES, TIMES, skip=60.0)
    rng = np.random.default_rng(3)
    a = rng.normal(size=(6, 6))
    cov = a @ a.T + 6 * np.eye(6)
    record = rng.normal(size=(2, TIMES.size))
    budget = _budget(summarise(record, windows), rng.normal(size=6), cov, windows)
    sims = rng.normal(size=(5, 2, TIMES.size))
    sims[4, 1, 200] = np.nan
    d = budget.distance(sims, record)
    assert d.shape == (5,) and d[4] == np.inf and np.isfinite(d[:4]).all()
    gap = [budget.log_likelihood(sim) + 0.5 * dk**2 for sim, dk in zip(sims[:4], d, strict=False)]
    assert np.ptp(gap) < 1e-9 * abs(gap[0])
    assert budget.distance(sims[:1], record)[0] == pytest.approx(d[0])  # one at a time alike


def _pair(draw):
    """A 'unit' offset by 1 from its 'model', plus the draw's scatter; draw 3 fails."""
    if draw == 3:
        return None
    model = np.zeros((2, TIMES.size))
    return model + 1.0 + 0.1 * np.sin(draw), model


def test_approximation_error_is_the_mean_and_covariance_of_unit_minus_model():
    windows = plateau_windows(EDGES, TIMES, skip=60.0)
    with make_executor("serial") as executor:
        mean, cov, n_ok = approximation_error(_pair, list(range(40)), windows, executor)
        with pytest.raises(RuntimeError, match="at least 10"):
            approximation_error(_pair, [3] * 12, windows, executor)
    assert n_ok == 39
    offsets = 1.0 + 0.1 * np.sin([d for d in range(40) if d != 3])
    assert mean == pytest.approx(np.full(6, offsets.mean()))
    assert np.diag(cov) == pytest.approx(np.full(6, offsets.var()), rel=0.05)


FEW_CAUSES = np.random.default_rng(3).normal(size=(2, 12))  # 12 summaries from two causes


def _few_causes_pair(draw):
    """Unit − model from two causes plus 5 % independent scatter: 6 outputs × 2 plateaus."""
    rng = np.random.default_rng(draw)
    error = rng.normal(size=2) @ FEW_CAUSES + 0.05 * rng.normal(size=12)
    unit = np.repeat(error.reshape(6, 2), [120, TIMES.size - 120], axis=1)
    return unit, np.zeros_like(unit)


def test_model_error_from_few_causes_keeps_its_correlations():
    """Fresh errors are as far from the estimate as Gaussian ones should be (12 summaries:
    mean squared Mahalanobis distance 12). Ledoit-Wolf's shrinkage put them at 2.5: it
    overstated the error in the directions the causes leave alone, where the data inform."""
    windows = plateau_windows(np.array([0.0, 120.0, 360.0]), TIMES, skip=60.0)
    with make_executor("serial") as executor:
        mean, cov, _ = approximation_error(_few_causes_pair, list(range(40)), windows, executor)
    fresh = np.array([summarise(_few_causes_pair(d)[0], windows) for d in range(100, 400)])
    z = np.linalg.solve(np.linalg.cholesky(cov), (fresh - mean).T)
    assert 6.0 < np.mean(np.sum(z**2, axis=0)) < 24.0


def test_predictive_check_flags_the_output_the_model_misses():
    windows = plateau_windows(EDGES, TIMES, skip=60.0)
    budget = _budget(np.array([0.0, 0.1, -0.1, 5.0, 5.0, 5.0]), np.zeros(6), np.eye(6), windows)
    rng = np.random.default_rng(3)
    predicted = 0.05 * rng.normal(size=(30, 6))
    check = predictive_check(budget, predicted)
    assert check["a"]["misfit"] == 0.0 and check["a"]["p_value"] > 0.5
    assert check["b"]["misfit"] == 1.0 and check["b"]["z_mean"] > 4
