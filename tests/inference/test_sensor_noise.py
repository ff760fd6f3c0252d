"""Sensor noise in engineering units, and the exact likelihood under it."""

import numpy as np
import pymc as pm
import pytest
from scipy import stats

from pymc_vcc.execution.options import RunOptions
from pymc_vcc.inference.likelihood import log_likelihood
from pymc_vcc.inference.noise import OutputNoise, SensorNoise, sensor_parameter
from pymc_vcc.inference.priors import UniformPrior
from pymc_vcc.inference.pymc.model import add_simulator
from pymc_vcc.inference.pymc.smc import sample_smc_abc
from pymc_vcc.inference.rejection import abc_rejection
from pymc_vcc.inference.sequential import sequential_calibration
from pymc_vcc.inference.series import prepare_observed
from pymc_vcc.testing import SensorProblem

PROBLEM = SensorProblem()


def observed_at(charge: float = 1.5):
    return prepare_observed(PROBLEM.dataset(charge))


def test_kinds_follow_units_with_per_output_overrides():
    noise = SensorNoise(temperature=0.3, pressure=0.005, outputs={"MDOT": 0.02}).resolve(
        observed_at()
    )
    assert noise.names == ("TD", "PD", "MDOT")
    assert noise.scales == (0.3, 0.005, 0.02)
    assert noise.relative == (False, True, True)
    values = np.array([[300.0, 310.0], [2e6, 3e6], [0.02, 0.01]])
    np.testing.assert_allclose(noise.std(values), [[0.3, 0.3], [1e4, 1.5e4], [4e-4, 2e-4]])


def test_unknown_units_and_bad_scales_are_refused_by_name():
    observed = prepare_observed(np.ones((2, 5)))
    with pytest.raises(ValueError, match=r"output 'y0' has units None.*kinds"):
        SensorNoise().resolve(observed)
    noise = SensorNoise(kinds={"y0": "temperature", "y1": "power"}).resolve(observed)
    assert noise.relative == (False, True)
    with pytest.raises(ValueError, match="temperature must be a positive"):
        SensorNoise(temperature=-0.3)
    with pytest.raises(ValueError, match=r"correlation must lie in \[0, 1\)"):
        SensorNoise(correlation=1.0)
    with pytest.raises(ValueError, match="not observed"):
        SensorNoise(outputs={"TX": 0.1}).resolve(observed_at())


@pytest.mark.parametrize("correlation", [0.0, 0.6])
def test_sampled_errors_have_the_stated_scale_and_correlation(correlation):
    noise = OutputNoise(("T", "P"), (0.3, 0.005), (False, True), correlation=correlation)
    values = np.vstack([np.full(200_000, 300.0), np.full(200_000, 2e6)])
    errors = noise.sample(values, np.random.default_rng(1)) - values
    assert errors[0].std() == pytest.approx(0.3, rel=0.02)
    assert errors[1].std() == pytest.approx(0.005 * 2e6, rel=0.02)
    lag1 = np.corrcoef(errors[0, 1:], errors[0, :-1])[0, 1]
    assert lag1 == pytest.approx(correlation, abs=0.01)


def test_gaussian_ar1_likelihood_equals_the_multivariate_normal_density():
    rng = np.random.default_rng(2)
    n, phi = 12, 0.7
    noise = OutputNoise(("T", "P"), (0.3, 0.01), (False, True), correlation=phi)
    simulated = np.vstack([300 + rng.normal(size=n), 2e6 + 1e4 * rng.normal(size=n)])
    observed = noise.sample(simulated, rng)
    lags = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    expected = 0.0
    for row, sd in enumerate(noise.std(simulated)):
        covariance = np.outer(sd, sd) * phi**lags
        expected += stats.multivariate_normal(simulated[row], covariance).logpdf(observed[row])
    assert log_likelihood(observed, simulated, noise) == pytest.approx(expected, rel=1e-10)


def test_student_t_likelihood_and_failed_simulations():
    noise = OutputNoise(("T",), (0.5,), (False,), dof=4.0)
    simulated = np.array([[300.0, 301.0, 302.0]])
    observed = simulated + np.array([[0.1, -2.0, 0.4]])
    expected = stats.t.logpdf(observed - simulated, 4.0, scale=0.5).sum()
    assert log_likelihood(observed, simulated, noise) == pytest.approx(expected)
    assert log_likelihood(observed, np.full_like(simulated, np.nan), noise) == -np.inf


def test_rejection_with_sensor_noise_learns_scales_by_name():
    truth = 1.7
    data = PROBLEM.dataset(truth)
    noise = SensorNoise(learnable=True, prior_factor=2.0)
    clean = prepare_observed(data)
    noisy = noise.resolve(clean).sample(clean.values, np.random.default_rng(3))
    for name, row in zip(clean.names, noisy, strict=True):
        data[name].values = row
    tree = abc_rejection(
        PROBLEM,
        UniformPrior(PROBLEM.bounds),
        data,
        n_pilot=200,
        quantile=0.1,
        n_main=600,
        n_desired=60,
        sensor_noise=noise,
        run=RunOptions(executor="serial", seed=4, progress=False),
    )
    posterior = tree["posterior"]
    assert set(posterior.data_vars) == {"M0", *(sensor_parameter(o) for o in clean.names)}
    low, high = posterior[sensor_parameter("TD")].values.min(), posterior["sigma_TD"].max()
    assert low >= 0.15 and high <= 0.6  # Uniform(0.3 / 2, 0.3 · 2)
    assert abs(float(posterior["M0"].mean()) - truth) < 0.1


def test_smc_warns_when_noise_free_simulations_cannot_reach_noisy_data(quiet_pymc):
    data = SensorNoise().measure(PROBLEM.dataset(1.5), np.random.default_rng(5))
    with pm.Model():
        add_simulator("y", PROBLEM, data, epsilon=0.002)
        with pytest.warns(RuntimeWarning, match="distances sit about"):
            tree = sample_smc_abc(40, executor="serial", random_seed=1, progressbar=False)
    stats = tree["sample_stats"]
    assert stats["epsilon"].values.tolist() == [0.002]
    assert int(stats["n_simulations"]) == int(stats["simulations"].sum())
    assert int(stats["n_stages"].sum()) == int(np.isfinite(stats["simulations"]).sum())


def test_smc_warns_on_tiny_populations(quiet_pymc):
    data = SensorNoise().measure(PROBLEM.dataset(1.5), np.random.default_rng(6))
    with pm.Model():
        add_simulator("y", PROBLEM, data, epsilon=0.1, sensor_noise=SensorNoise(learnable=True))
        with (
            pytest.warns(RuntimeWarning, match="draws=3 particles for 4 parameters"),
            pytest.warns(RuntimeWarning, match="effective sample size fell"),
        ):
            sample_smc_abc(3, executor="serial", random_seed=1, progressbar=False)


def test_sequential_calibration_carries_learnable_sensor_scales_into_the_gmm():
    noise = SensorNoise(learnable=True)
    rng = np.random.default_rng(8)
    datasets = [noise.measure(PROBLEM.dataset(1.6), rng) for _ in range(2)]
    result = sequential_calibration(
        PROBLEM,
        UniformPrior(PROBLEM.bounds),
        datasets,
        sensor_noise=noise,
        n_pilot=100,
        quantile=0.2,
        n_main=200,
        n_desired=30,
        run=RunOptions(executor="serial", seed=9, progress=False),
    )
    names = {"M0", "sigma_TD", "sigma_PD", "sigma_MDOT"}
    assert set(result.priors[1].names) == names
    assert set(result.trees[1]["posterior"].data_vars) == names
