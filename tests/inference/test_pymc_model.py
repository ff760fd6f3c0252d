"""The simulator node of a PyMC model: priors, GMM distribution, KS kernel, noise, failures."""

from __future__ import annotations

import warnings

import numpy as np
import pymc as pm
import pytest
from scipy import stats
from scipy.special import expit

from pymc_vcc.inference.distances import ks_distance
from pymc_vcc.inference.priors import GMMPrior, UniformPrior
from pymc_vcc.inference.pymc.model import (
    DistanceKernel,
    SimulatorFunction,
    add_simulator,
    gmm_prior_variable,
    prior_variables,
    simulator_bounds,
)
from pymc_vcc.inference.series import prepare_observed
from pymc_vcc.physics.simulate import VCCSimulator
from pymc_vcc.testing import Flaky, GaussianLocation, ShiftedProfile


@pytest.fixture(autouse=True)
def _quiet():
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Numba will use object mode")
        yield


@pytest.fixture(scope="module")
def gmm_prior() -> GMMPrior:
    """A skewed, bimodal three-parameter mixture fitted on bounded samples."""
    rng = np.random.default_rng(0)
    samples = np.column_stack(
        [
            2.0 * rng.beta(2, 5, 600),
            10.0 + 10.0 * rng.beta(5, 2, 600),
            rng.uniform(-1.0, 1.0, 600),
        ]
    )
    samples[:200, 0] = 1.7 + 0.2 * rng.random(200)
    bounds = {"a": (0.0, 2.0), "b": (10.0, 20.0), "c": (-1.0, 1.0)}
    return GMMPrior.fit(samples, bounds, max_components=3, seed=0)


def test_gmm_log_density_in_pymc_equals_gmmprior_logpdf(gmm_prior):
    assert gmm_prior.n_components > 1
    with pm.Model():
        x = gmm_prior_variable("x", gmm_prior)
    points = np.vstack(
        [
            gmm_prior.sample(40, np.random.default_rng(1)),
            [[0.5, 15.0, 0.99999], [1e-6, 19.9, -0.5]],  # near the bounds
            [[2.5, 15.0, 0.0], [1.0, 9.0, 0.0], [0.0, 15.0, 0.0]],  # outside or on them
        ]
    )
    expected = gmm_prior.logpdf(points)
    actual = pm.logp(x, points).eval()
    assert np.isneginf(expected[-3:]).all()
    np.testing.assert_array_equal(np.isneginf(actual), np.isneginf(expected))
    finite = np.isfinite(expected)
    np.testing.assert_allclose(actual[finite], expected[finite], rtol=1e-10, atol=1e-9)


def test_gmm_variable_lives_in_logit_space_with_the_right_jacobian(gmm_prior):
    with pm.Model() as model:
        gmm_prior_variable("x", gmm_prior)
    (value_name,) = model.initial_point()
    logp = model.compile_logp()
    unbounded = np.array([0.3, -1.2, 2.0])
    x = gmm_prior.lower + (gmm_prior.upper - gmm_prior.lower) * expit(unbounded)
    jacobian = np.sum(
        np.log((gmm_prior.upper - gmm_prior.lower) * expit(unbounded) * expit(-unbounded))
    )
    expected = gmm_prior.logpdf(x)[0] + jacobian
    np.testing.assert_allclose(logp({value_name: unbounded}), expected, rtol=1e-10)


def test_gmm_variable_draws_follow_the_prior(gmm_prior):
    with pm.Model():
        x = gmm_prior_variable("x", gmm_prior)
    draws = pm.draw(x, draws=3000, random_seed=2)
    reference = gmm_prior.sample(3000, np.random.default_rng(3))
    assert draws.shape == (3000, 3)
    for column in range(3):
        result = stats.ks_2samp(draws[:, column], reference[:, column])
        assert result.statistic < 0.05


def test_prior_variables_give_one_posterior_variable_per_name(gmm_prior):
    with pm.Model() as model:
        uniform = prior_variables(UniformPrior({"p": (1.0, 3.0), "q": (0.0, 0.1)}))
    assert list(uniform) == ["p", "q"]
    assert {v.name for v in model.free_RVs} == {"p", "q"}
    with pm.Model() as model:
        joint = prior_variables(gmm_prior, joint_name="theta")
    assert list(joint) == ["a", "b", "c"]
    assert [v.name for v in model.free_RVs] == ["theta"]
    assert {v.name for v in model.deterministics} == {"a", "b", "c"}
    with pytest.raises(TypeError, match="UniformPrior or a GMMPrior"):
        prior_variables({"p": (0, 1)})


def test_add_simulator_makes_priors_noise_scales_and_coords():
    sim = GaussianLocation(n_time=30)
    observed = sim({"mu": 0.0}, np.random.default_rng(0))
    with pm.Model() as model:
        node = add_simulator("y", sim, observed, noise=(0.0, 0.2), epsilon=0.1)
    assert node.parameter_names == ("mu",)
    assert node.noise_outputs == ("y",)
    assert node.prior.bounds == {"mu": (sim.low, sim.high), "nu_y": (0.0, 0.2)}
    assert {v.name for v in model.free_RVs} == {"mu", "nu_y"}
    assert list(model.coords["y_output"]) == ["y"]
    assert len(model.coords["y_time"]) == 30
    assert node.variable.eval().shape == (1, 30)  # the node simulates with noise from its prior


def test_add_simulator_takes_uniform_priors_from_the_unit_description():
    sim = VCCSimulator()
    observed = np.ones((len(sim.output_names), 5))  # not simulated here
    assert simulator_bounds(sim)["M0"] == (0.9, 2.2)
    assert len(simulator_bounds(sim)) == 26
    with pm.Model() as model:
        node = add_simulator("vcc", sim, observed, parameters=["M0", "CF_LEV"])
    assert node.parameter_names == ("M0", "CF_LEV")
    assert node.prior.bounds == {"M0": (0.9, 2.2), "CF_LEV": (0.3, 1.5)}
    assert {v.name for v in model.free_RVs} == {"M0", "CF_LEV"}
    assert list(model.coords["vcc_output"]) == list(sim.output_names)


def test_add_simulator_with_a_gmm_prior_over_parameters_and_noise():
    sim = GaussianLocation(n_time=20)
    observed = sim({"mu": 0.5}, np.random.default_rng(0))
    rng = np.random.default_rng(1)
    samples = {"mu": rng.normal(0.5, 0.1, 300), "nu_y": rng.uniform(0.01, 0.05, 300)}
    prior = GMMPrior.fit(samples, {"mu": (-3.0, 3.0), "nu_y": (0.0, 0.1)}, seed=0)
    with pm.Model() as model:
        node = add_simulator("y", sim, observed, prior=prior, epsilon=0.5)
    assert node.noise_outputs == ("y",)
    assert [v.name for v in model.free_RVs] == ["y_theta"]
    assert {v.name for v in model.deterministics} == {"mu", "nu_y"}
    with pm.Model(), pytest.raises(ValueError, match="differ from the noise bounds"):
        add_simulator("y", sim, observed, prior=prior, noise={"y": (0.0, 0.3)})


def test_add_simulator_rejects_bad_input_before_simulating():
    sim = GaussianLocation(n_time=20)
    observed = sim({"mu": 0.0}, np.random.default_rng(0))
    with pm.Model(), pytest.raises(ValueError, match=r"unknown parameter\(s\) \['sigma'\]"):
        add_simulator("y", sim, observed, parameters=["sigma"])
    with pm.Model(), pytest.raises(ValueError, match="epsilon must be a positive number"):
        add_simulator("y", sim, observed, epsilon=0.0)
    with pm.Model(), pytest.raises(ValueError, match="noise names unknown outputs"):
        add_simulator("y", sim, observed, noise={"TD": (0.0, 0.1)})
    with pm.Model(), pytest.raises(ValueError, match="neither `bounds` nor a unit"):
        add_simulator("y", Flaky(sim, rate=0.5), observed)
    with pm.Model(), pytest.raises(ValueError, match="unknown outputs"):
        add_simulator("y", sim, observed, outputs=["PD"])
    with pm.Model(), pytest.raises(ValueError, match="non-finite"):
        add_simulator("y", sim, np.full((1, 20), np.nan))


def test_distance_kernel_is_the_gaussian_kernel_of_the_ks_distance():
    rng = np.random.default_rng(5)
    observed = rng.normal(size=(3, 80))
    simulated = rng.normal(0.3, 1.2, size=(3, 60))
    epsilon = 0.2
    d = ks_distance(simulated, observed)
    scipy_d = np.mean([stats.ks_2samp(simulated[j], observed[j]).statistic for j in range(3)])
    assert d == pytest.approx(scipy_d, abs=1e-12)
    kernel = DistanceKernel()
    assert kernel.log_kernel(epsilon, observed, simulated) == pytest.approx(
        -0.5 * (d / epsilon) ** 2, abs=1e-12
    )
    simulated[1, 7] = np.nan
    assert kernel.log_kernel(epsilon, observed, simulated) == -np.inf


def test_model_log_likelihood_is_the_kernel_of_the_simulation():
    sim = ShiftedProfile(sigma=0.0)  # deterministic: the likelihood is a plain function
    observed = sim({"mu": 0.1}, np.random.default_rng(0))
    epsilon = 0.05
    with pm.Model() as model:
        node = add_simulator("y", sim, observed, epsilon=epsilon)
    (value_name,) = model.initial_point()
    loglik = model.compile_fn(model.datalogp, inputs=model.value_vars)
    for mu in (0.1051, 0.131, -0.397):  # offsets between KS grid steps (h = 0.002)
        unbounded = np.log((mu - sim.low) / (sim.high - mu))
        d = ks_distance(sim({"mu": mu}, np.random.default_rng(0)), observed)
        assert loglik({value_name: unbounded}) == pytest.approx(-0.5 * (d / epsilon) ** 2)
    assert node.function.parameter_names == ("mu",)


def test_simulator_function_reports_failures_and_returns_nan_to_pytensor():
    base = GaussianLocation(n_time=10)
    observed = prepare_observed(base({"mu": 0.0}, np.random.default_rng(0)))
    function = SimulatorFunction(Flaky(base, rate=1.0, modes=("status",)), ("mu",), observed)
    outcome = function.outcome(np.random.default_rng(1), np.array([0.2]))
    assert outcome.status == "solver"
    assert "synthetic solver failure" in outcome.reason
    values = function(np.random.default_rng(1), np.array([[[0.2]]]), (1, 10))
    assert values.shape == (1, 10)
    assert np.isnan(values).all()


def test_noise_scales_add_relative_gaussian_noise():
    base = ShiftedProfile(sigma=0.0, n_time=4001)
    observed = prepare_observed(base({"mu": 0.0}, np.random.default_rng(0)), None, ("y",))
    function = SimulatorFunction(base, ("mu",), observed, noise_outputs=("y",))
    clean = base({"mu": 0.7}, np.random.default_rng(0))
    noisy = function(np.random.default_rng(2), np.array([0.7]), np.array([0.1]), None)
    relative = (noisy - clean) / np.abs(clean)
    assert relative.std() == pytest.approx(0.1, rel=0.05)
    assert abs(relative.mean()) < 0.01
    again = function(np.random.default_rng(2), np.array([0.7]), np.array([0.1]), None)
    np.testing.assert_array_equal(noisy, again)
    with pytest.raises(ValueError, match=r"noise_outputs \['TD'\] are not among"):
        SimulatorFunction(base, ("mu",), observed, noise_outputs=("TD",))
