"""The exact-likelihood path: add_likelihood sampled by PyMC's tempered SMC (ParallelIMH)."""

import numpy as np
import pymc as pm
import pytest

from pymc_vcc.inference.noise import SensorNoise
from pymc_vcc.inference.pymc.likelihood import add_likelihood
from pymc_vcc.inference.pymc.smc import sample_smc_abc
from pymc_vcc.testing import SensorProblem

PROBLEM = SensorProblem()


def posterior_draws(observed, noise, draws, seed, problem=PROBLEM, outputs=None):
    with pm.Model():
        add_likelihood("y", problem, observed, sensor_noise=noise, outputs=outputs)
        tree = sample_smc_abc(draws, executor="serial", random_seed=seed, progressbar=False)
    return tree, tree["posterior"]["M0"].values.ravel()


@pytest.mark.parametrize("correlation", [0.0, 0.6])
def test_conjugate_gaussian_posterior_is_exact(quiet_pymc, correlation):
    noise = SensorNoise(temperature=0.3, correlation=correlation)
    observed = noise.measure(PROBLEM.dataset(1.3), np.random.default_rng(7))
    mean, sd = PROBLEM.exact_posterior(observed, {"TD": 0.3}, correlation)
    tree, draws = posterior_draws(observed, noise, draws=1000, seed=3, outputs=["TD"])
    assert draws.mean() == pytest.approx(mean, abs=0.05 * sd)
    assert draws.std() == pytest.approx(sd, rel=0.05)
    stats = tree["sample_stats"]
    assert int(stats["n_simulations"]) == int(stats["simulations"].sum())
    assert float(stats["min_stage_ess"]) >= 30


def test_intervals_cover_the_truth_95_percent_of_the_time(quiet_pymc):
    """50 datasets drawn from the prior, noise of every kind, correlated errors."""
    problem = SensorProblem(n_time=60)
    noise = SensorNoise.typical(correlation=0.5)
    rng = np.random.default_rng(11)
    low, high = problem.bounds["M0"]
    covered = []
    for dataset in range(50):
        truth = rng.uniform(low, high)
        observed = noise.measure(problem.dataset(truth), rng)
        _, draws = posterior_draws(observed, noise, draws=80, seed=dataset, problem=problem)
        lower, upper = np.quantile(draws, [0.025, 0.975])
        covered.append(lower <= truth <= upper)
    assert 0.92 <= np.mean(covered) <= 0.98


def test_learnable_scales_and_bad_noise_are_refused(quiet_pymc):
    observed = PROBLEM.dataset(1.5)
    with pm.Model(), pytest.raises(ValueError, match="known noise scales"):
        add_likelihood("y", PROBLEM, observed, sensor_noise=SensorNoise(learnable=True))
    with pm.Model(), pytest.raises(TypeError, match="must be a SensorNoise"):
        add_likelihood("y", PROBLEM, observed, sensor_noise={"temperature": 0.3})
