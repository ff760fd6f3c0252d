"""The Laplace start of tempered SMC on the exact likelihood (pymc_vcc.inference.pymc.laplace)."""

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pymc as pm
import pytest
from scipy.special import expit

from pymc_vcc.execution.options import RunOptions
from pymc_vcc.inference.error_model import ErrorBudget, summarise
from pymc_vcc.inference.noise import SensorNoise
from pymc_vcc.inference.pymc.laplace import fit_reference, laplace_draws
from pymc_vcc.inference.pymc.likelihood import add_likelihood
from pymc_vcc.inference.pymc.model import add_simulator
from pymc_vcc.inference.pymc.reference import GaussianReference
from pymc_vcc.inference.pymc.smc import sample_smc_abc
from pymc_vcc.testing import as_dataset

NOISE = SensorNoise(temperature=0.3)


@dataclass(frozen=True)
class Quadratic:
    """A deterministic temperature TD = a + b·x + c·x² (K) on x = linspace(-1, 1, n_time):
    under Gaussian noise of sd 0.3 K and a flat prior far wider than the posterior, the
    posterior is N(β̂, 0.09 (XᵀX)⁻¹) exactly."""

    n_time: int = 200
    parameter_names: ClassVar[tuple[str, ...]] = ("a", "b", "c")
    output_names: ClassVar[tuple[str, ...]] = ("TD",)
    bounds: ClassVar[dict[str, tuple[float, float]]] = {
        "a": (280.0, 320.0),
        "b": (-20.0, 20.0),
        "c": (-20.0, 20.0),
    }

    @property
    def design(self) -> np.ndarray:
        x = np.linspace(-1.0, 1.0, self.n_time)
        return np.column_stack([np.ones_like(x), x, x**2])

    def __call__(self, theta, rng) -> np.ndarray:
        return (self.design @ np.array([theta[n] for n in self.parameter_names]))[np.newaxis]

    def observed(self, truth: np.ndarray, seed: int):
        data = as_dataset((self.design @ truth)[np.newaxis], self.output_names)
        data["TD"].attrs["units"] = "K"
        return NOISE.measure(data, np.random.default_rng(seed))

    def exact_posterior(self, observed) -> tuple[np.ndarray, np.ndarray]:
        design = self.design
        precision = design.T @ design / NOISE.temperature**2
        mean = np.linalg.solve(design.T @ design, design.T @ observed["TD"].values)
        return mean, np.linalg.inv(precision)


PROBLEM = Quadratic()
TRUTH = np.array([300.0, 3.0, -2.0])


def test_gaussian_reference_matches_scipy():
    from scipy import stats

    rng = np.random.default_rng(0)
    mean, factor = rng.normal(size=3), rng.normal(size=(3, 3))
    covariance = factor @ factor.T + np.eye(3)
    reference = GaussianReference(mean, covariance)
    points = rng.normal(size=(5, 3))
    expected = stats.multivariate_normal(mean, covariance).logpdf(points)
    np.testing.assert_allclose(reference.logpdf(points), expected, rtol=1e-12)
    draws = reference.sample(20000, rng)
    np.testing.assert_allclose(np.cov(draws.T), covariance, atol=0.1 * covariance.max())
    mixture = GaussianReference([mean, mean + 10], [covariance, np.eye(3)])
    both = [stats.multivariate_normal(mean, covariance), stats.multivariate_normal(mean + 10)]
    expected = np.log(0.5 * both[0].pdf(points) + 0.5 * both[1].pdf(points))
    np.testing.assert_allclose(mixture.logpdf(points), expected, rtol=1e-10)
    near_second = np.linalg.norm(mixture.sample(4000, rng) - (mean + 10), axis=1) < 5
    assert 0.47 < near_second.mean() < 0.53
    with pytest.raises(ValueError, match="3 x 3"):
        GaussianReference(mean, np.eye(2))
    with pytest.raises(np.linalg.LinAlgError):
        GaussianReference(mean, -np.eye(3))


def test_a_weighted_mixture_reference_is_the_mixture_prior_in_the_value_space():
    """``of_mixture``: the reference's density is PyMC's value-space density of the prior
    variable (so tempering from it is tempering from the prior), and its draws follow the
    weights."""
    from scipy.special import logit

    from pymc_vcc.inference.priors import GMMPrior
    from pymc_vcc.inference.pymc.model import prior_variables

    bounds = {"a": (0.0, 2.0), "b": (-1.0, 1.0)}
    prior = GMMPrior(
        bounds,
        np.array([0.8, 0.2]),
        np.array([[0.0, 0.5], [2.0, -1.0]]),
        np.array([np.eye(2) * 0.3, [[0.5, 0.1], [0.1, 0.2]]]),
    )
    reference = GaussianReference.of_mixture(prior)
    with pm.Model() as model:
        prior_variables(prior)
    value_logp = model.compile_logp(jacobian=True)
    (value_var,) = model.value_vars
    rng = np.random.default_rng(1)
    points = prior.means[rng.integers(2, size=6)] + rng.normal(size=(6, 2))
    expected = [value_logp({value_var.name: point}) for point in points]
    np.testing.assert_allclose(reference.logpdf(points), expected, rtol=1e-10)
    draws = reference.sample(5000, rng)
    assert 0.77 < np.mean(np.linalg.norm(draws - prior.means[0], axis=1) < 2.0) < 0.83
    inside = prior.sample(4000, rng)  # the same mixture, drawn in the parameters' units
    places = logit((inside - prior.lower) / (prior.upper - prior.lower))
    assert abs(np.mean(places[:, 0] > 1.0) - np.mean(draws[:, 0] > 1.0)) < 0.04
    with pytest.raises(ValueError, match="summing to 1"):
        GaussianReference(prior.means, prior.covariances, weights=np.array([0.5, 0.6]))


def test_smc_from_the_fit_gives_the_exact_posterior_with_fewer_simulations(quiet_pymc, tmp_path):
    observed = PROBLEM.observed(TRUTH, seed=4)
    mean, covariance = PROBLEM.exact_posterior(observed)
    runs = {}
    for start in ("prior", "fit"):
        with pm.Model():
            add_likelihood("y", PROBLEM, observed, sensor_noise=NOISE)
            reference = None
            if start == "fit":
                reference = fit_reference(
                    run=RunOptions(executor="serial", seed=0, checkpoint=tmp_path / "fit.json")
                )
            tree = sample_smc_abc(
                600, executor="serial", random_seed=1, reference=reference, progressbar=False
            )
        draws = np.column_stack(
            [tree["posterior"][n].values.ravel() for n in PROBLEM.parameter_names]
        )
        fitted = 0 if reference is None else reference.simulations
        runs[start] = (draws, int(tree["sample_stats"]["n_simulations"]) + fitted, reference)
    sd = np.sqrt(np.diag(covariance))
    for start, (draws, _, _) in runs.items():
        offsets = (draws.mean(axis=0) - mean) / sd
        ratios = draws.std(axis=0) / sd
        assert np.all(np.abs(offsets) < 0.15), (start, offsets)
        assert np.all(np.abs(ratios - 1) < 0.12), (start, ratios)
    reference = runs["fit"][2]
    assert reference.failed_simulations == 0
    # the reference is the Laplace approximation in logit coordinates: close to the posterior
    assert reference.costs[0] == pytest.approx(
        0.5 * np.sum(((observed["TD"].values - PROBLEM.design @ mean) / 0.3) ** 2), rel=1e-3
    )
    assert runs["fit"][1] < 0.5 * runs["prior"][1], {k: v[1] for k, v in runs.items()}


def test_an_error_budgets_summaries_are_fitted_and_sampled_exactly(quiet_pymc):
    """Under an error budget the fit reads the whitened residuals of the summaries: the budget
    of four window means with a known covariance makes a linear-Gaussian posterior, which the
    SMC from the fit reproduces."""
    observed = PROBLEM.observed(TRUTH, seed=6)
    windows = np.array_split(np.arange(PROBLEM.n_time), 4)
    means = np.array([PROBLEM.design[w].mean(axis=0) for w in windows])  # summaries = means @ β
    variance = np.array([NOISE.temperature**2 / w.size for w in windows])
    summaries = summarise(observed["TD"].values[np.newaxis], windows)
    budget = ErrorBudget(("TD",), windows, summaries, np.zeros(4), {"noise": np.diag(variance)})
    precision = means.T @ (means / variance[:, np.newaxis])
    covariance = np.linalg.inv(precision)
    mean = covariance @ means.T @ (summaries / variance)
    with pm.Model():
        add_likelihood("y", PROBLEM, observed, error_budget=budget)
        reference = fit_reference(run=RunOptions(executor="serial", seed=0))
        tree = sample_smc_abc(
            600, executor="serial", random_seed=1, reference=reference, progressbar=False
        )
    draws = np.column_stack([tree["posterior"][n].values.ravel() for n in PROBLEM.parameter_names])
    sd = np.sqrt(np.diag(covariance))
    assert np.all(np.abs((draws.mean(axis=0) - mean) / sd) < 0.15)
    assert np.all(np.abs(draws.std(axis=0) / sd - 1) < 0.12)
    residual = summaries - means @ mean
    assert reference.costs[0] == pytest.approx(0.5 * np.sum(residual**2 / variance), rel=1e-2)


def test_laplace_draws_are_the_exact_posterior_of_a_linear_model(quiet_pymc):
    """Without secant corrections or inflation, the fit's Laplace approximation of a linear
    Gaussian problem is its posterior: the draws, mapped back to the parameters, match it."""
    observed = PROBLEM.observed(TRUTH, seed=7)
    mean, covariance = PROBLEM.exact_posterior(observed)
    with pm.Model():
        add_likelihood("y", PROBLEM, observed, sensor_noise=NOISE)
        reference = fit_reference(
            run=RunOptions(executor="serial", seed=0), step=1e-4, inflation=1.0, axis_rounds=0
        )
        draws = laplace_draws(reference, 20_000, np.random.default_rng(1))
    values = np.column_stack([draws[n] for n in PROBLEM.parameter_names])
    sd = np.sqrt(np.diag(covariance))
    assert np.all(np.abs((values.mean(axis=0) - mean) / sd) < 0.05)
    assert np.all(np.abs(values.std(axis=0) / sd - 1) < 0.05)


def test_a_saved_fit_is_reused_only_for_the_same_data(quiet_pymc, tmp_path):
    path = tmp_path / "fit.json"
    fits = []
    for seed in (4, 4, 5):
        with pm.Model():
            add_likelihood("y", PROBLEM, PROBLEM.observed(TRUTH, seed), sensor_noise=NOISE)
            fits.append(fit_reference(run=RunOptions(executor="serial", seed=0, checkpoint=path)))
    assert fits[1].digest() == fits[0].digest() and fits[1].simulations == fits[0].simulations
    assert fits[2].digest() != fits[0].digest()


def test_abc_nodes_and_bad_settings_are_refused(quiet_pymc):
    observed = PROBLEM.observed(TRUTH, seed=4)
    with pm.Model():
        add_simulator("y", PROBLEM, observed, epsilon=0.1)
        with pytest.raises(ValueError, match="exact-likelihood nodes only"):
            fit_reference(run=RunOptions(executor="serial"))
    with pm.Model():
        add_likelihood("y", PROBLEM, observed, sensor_noise=NOISE)
        with pytest.raises(ValueError, match="inflation must be >= 1"):
            fit_reference(run=RunOptions(executor="serial"), inflation=0.5)
        with pytest.raises(ValueError, match="max_simulations must allow"):
            fit_reference(run=RunOptions(executor="serial"), max_simulations=5)


@dataclass(frozen=True)
class SignBlind(Quadratic):
    """TD = 300 + a²·(1 + x) + b·x: the data tell a only up to its sign, so the posterior has
    two equal modes at ±a."""

    parameter_names: ClassVar[tuple[str, ...]] = ("a", "b")
    bounds: ClassVar[dict[str, tuple[float, float]]] = {"a": (-3.0, 3.0), "b": (-5.0, 5.0)}

    def __call__(self, theta, rng) -> np.ndarray:
        x = np.linspace(-1.0, 1.0, self.n_time)
        return (300.0 + theta["a"] ** 2 * (1 + x) + theta["b"] * x)[np.newaxis]

    def observed(self, truth: np.ndarray, seed: int):
        data = as_dataset(self(dict(zip("ab", truth, strict=True)), None), self.output_names)
        data["TD"].attrs["units"] = "K"
        return NOISE.measure(data, np.random.default_rng(seed))


def test_several_starts_find_both_modes_and_smc_weighs_them(quiet_pymc):
    problem = SignBlind()
    observed = problem.observed(np.array([1.5, 1.0]), seed=2)
    with pm.Model():
        add_likelihood("y", problem, observed, sensor_noise=NOISE)
        single = fit_reference(run=RunOptions(executor="serial", seed=0))
        reference = fit_reference(run=RunOptions(executor="serial", seed=1), starts=4)
        tree = sample_smc_abc(
            400, executor="serial", random_seed=2, reference=reference, progressbar=False
        )
    assert len(single.means) == 1 and len(reference.means) == 2
    with pm.Model():  # starts at given values find the mode each lies near
        add_likelihood("y", problem, observed, sensor_noise=NOISE)
        near = [{"a": a, "b": 1.0} for a in (-1.3, 1.3)]
        from_points = fit_reference(run=RunOptions(executor="serial", seed=0), points=near)
    assert len(from_points.means) == 2
    found = sorted(from_points.means[:, 0])  # a's value space: its place in (-3, 3), in logit
    assert 6 * expit(np.array(found)) - 3 == pytest.approx([-1.5, 1.5], abs=0.05)
    a = tree["posterior"]["a"].values.ravel()
    assert 0.35 < np.mean(a > 0) < 0.65
    assert np.abs(a).mean() == pytest.approx(1.5, abs=0.02)
