"""Uniform and bounded-GMM priors: bounds respected, densities normalised, disk round trip."""

import numpy as np
import pytest
import xarray as xr
from scipy import stats
from scipy.integrate import trapezoid
from scipy.special import expit, logit

from pymc_vcc.execution.options import RunOptions
from pymc_vcc.inference.priors import (
    GMMPrior,
    UniformPrior,
    check_prior_support,
    load_prior,
    validate_bounds,
)

BOUNDS = {"M0": (0.9, 2.2), "CF_VOL": (0.5, 1.5)}


@pytest.mark.parametrize(
    ("bounds", "message"),
    [
        ({"M0": (2.2, 0.9)}, "bounds of 'M0' need low < high, got low=2.2 >= high=0.9"),
        ({"M0": (1.0, 1.0)}, "low < high"),
        ({"M0": (0.0, np.inf)}, "bounds of 'M0' must be finite"),
        ({"M0": (0.0, np.nan)}, "must be finite"),
        ({"M0": (1.0,)}, "must be a pair"),
        ({}, "non-empty mapping"),
        ({"": (0, 1)}, "non-empty strings"),
    ],
)
def test_bad_bounds_are_clear_errors(bounds, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        validate_bounds(bounds)
    with pytest.raises(ValueError):
        UniformPrior(bounds)


def test_uniform_prior_draws_inside_its_box_with_the_right_density():
    prior = UniformPrior(BOUNDS)
    draws = prior.sample(10_000, np.random.default_rng(0))
    assert draws.shape == (10_000, 2) and prior.names == ("M0", "CF_VOL")
    assert (draws >= prior.lower).all() and (draws <= prior.upper).all()
    np.testing.assert_allclose(draws.mean(axis=0), [1.55, 1.0], atol=0.02)
    assert prior.logpdf([1.0, 1.0])[0] == pytest.approx(-np.log(1.3 * 1.0))
    assert prior.logpdf([[3.0, 1.0]])[0] == -np.inf
    extended = prior.extended({"nu_TD": (0.0, 0.05)})
    assert extended.names == ("M0", "CF_VOL", "nu_TD")
    with pytest.raises(ValueError, match=r"\['M0'\] are already in the prior"):
        prior.extended({"M0": (1.0, 2.0)})


def _bimodal_near_a_bound(n, rng):
    """A posterior-like sample with one mode hugging the lower bound of M0."""
    first = np.column_stack([rng.normal(0.95, 0.02, n), rng.normal(0.7, 0.05, n)])
    second = np.column_stack([rng.normal(1.8, 0.1, n), rng.normal(1.2, 0.1, n)])
    sample = np.vstack([first, second])
    return np.clip(sample, [0.9 + 1e-6, 0.5 + 1e-6], [2.2 - 1e-6, 1.5 - 1e-6])


def test_gmm_chooses_components_by_bic():
    rng = np.random.default_rng(1)
    assert GMMPrior.fit(_bimodal_near_a_bound(1500, rng), BOUNDS, seed=0).n_components >= 2
    unimodal = np.column_stack([rng.normal(1.5, 0.05, 3000), rng.normal(1.0, 0.05, 3000)])
    assert GMMPrior.fit(unimodal, BOUNDS, seed=0).n_components == 1
    assert GMMPrior.fit(unimodal, BOUNDS, max_components=1, seed=0).n_components == 1


def test_gmm_draws_always_respect_the_bounds_and_reproduce_the_sample():
    rng = np.random.default_rng(2)
    sample = _bimodal_near_a_bound(2000, rng)
    prior = GMMPrior.fit(sample, BOUNDS, seed=0)
    draws = prior.sample(50_000, np.random.default_rng(3))
    assert (draws > prior.lower).all() and (draws < prior.upper).all()
    np.testing.assert_allclose(draws.mean(axis=0), sample.mean(axis=0), atol=0.01)
    np.testing.assert_allclose(draws.std(axis=0), sample.std(axis=0), rtol=0.03)
    assert abs((draws[:, 0] < 1.2).mean() - 0.5) < 0.02  # mode weights kept


def test_gmm_logpdf_is_the_physical_density_with_the_logit_jacobian():
    rng = np.random.default_rng(4)
    prior = GMMPrior.fit(_bimodal_near_a_bound(1000, rng), BOUNDS, seed=0)
    # normalised in the physical space: quadrature nodes dense near the bounds (logit-spaced)
    nodes = [low + (high - low) * expit(np.linspace(-18, 18, 901)) for low, high in BOUNDS.values()]
    grid = np.stack(np.meshgrid(*nodes, indexing="ij"), axis=-1).reshape(-1, 2)
    density = np.exp(prior.logpdf(grid)).reshape(901, 901)
    total = trapezoid(trapezoid(density, nodes[1], axis=1), nodes[0])
    assert total == pytest.approx(1.0, abs=1e-3)
    # equal to the mixture density in logit space plus the log-Jacobian, computed independently
    points = prior.sample(50, np.random.default_rng(5))
    fraction = (points - prior.lower) / (prior.upper - prior.lower)
    mixture = sum(
        w * stats.multivariate_normal(m, c).pdf(logit(fraction))
        for w, m, c in zip(prior.weights, prior.means, prior.covariances, strict=True)
    )
    jacobian = np.prod(1 / ((prior.upper - prior.lower) * fraction * (1 - fraction)), axis=1)
    np.testing.assert_allclose(prior.logpdf(points), np.log(mixture * jacobian), rtol=1e-10)
    assert prior.logpdf([0.9, 1.0])[0] == -np.inf and prior.logpdf([1.0, 1.6])[0] == -np.inf


@pytest.mark.parametrize("make", ["uniform", "gmm"])
def test_priors_round_trip_through_netcdf(make, tmp_path):
    rng = np.random.default_rng(6)
    prior = (
        UniformPrior(BOUNDS)
        if make == "uniform"
        else GMMPrior.fit(_bimodal_near_a_bound(500, rng), BOUNDS, seed=0)
    )
    prior.save(tmp_path / "prior.nc")
    loaded = load_prior(tmp_path / "prior.nc")
    assert type(loaded) is type(prior) and loaded.bounds == prior.bounds
    points = prior.sample(20, np.random.default_rng(7))
    np.testing.assert_array_equal(loaded.sample(20, np.random.default_rng(7)), points)
    np.testing.assert_array_equal(loaded.logpdf(points), prior.logpdf(points))


def test_gmm_fits_posterior_datasets_and_mappings_alike():
    rng = np.random.default_rng(8)
    sample = _bimodal_near_a_bound(300, rng)
    posterior = xr.Dataset(
        {name: (("chain", "draw"), sample[:, j][None, :]) for j, name in enumerate(BOUNDS)}
    )
    from_dataset = GMMPrior.fit(posterior, BOUNDS, seed=0)
    from_mapping = GMMPrior.fit({"CF_VOL": sample[:, 1], "M0": sample[:, 0]}, BOUNDS, seed=0)
    np.testing.assert_allclose(from_dataset.means, from_mapping.means)
    from_tree = GMMPrior.fit(xr.DataTree.from_dict({"posterior": posterior}), BOUNDS, seed=0)
    np.testing.assert_allclose(from_tree.means, from_mapping.means)


def test_gmm_fit_rejects_bad_samples():
    with pytest.raises(ValueError, match=r"sample\(s\) of 'M0' lie outside its bounds"):
        GMMPrior.fit(np.array([[0.5, 1.0], [1.0, 1.0]]), BOUNDS)
    with pytest.raises(ValueError, match=r"lack parameter\(s\) \['CF_VOL'\]"):
        GMMPrior.fit({"M0": np.ones(5)}, BOUNDS)
    with pytest.raises(ValueError, match=r"shape \(n, 2\)"):
        GMMPrior.fit(np.ones((5, 3)), BOUNDS)
    with pytest.raises(ValueError, match="max_components must be a positive integer"):
        GMMPrior.fit(np.ones((5, 2)), BOUNDS, max_components=0)
    with pytest.raises(ValueError, match="NaN"):
        GMMPrior.fit(np.array([[1.0, np.nan], [1.0, 1.0]]), BOUNDS)


def test_prior_bounds_outside_the_units_are_refused_by_every_sampler():
    import pymc as pm

    from pymc_vcc.inference.pymc.model import add_simulator
    from pymc_vcc.inference.rejection import abc_rejection
    from pymc_vcc.inference.sensitivity import sobol_indices
    from pymc_vcc.inference.simulator import check_simulator
    from pymc_vcc.physics.simulate import VCCSimulator

    simulator = VCCSimulator(parameters=["M0"], outputs=["PD"])
    observed = np.ones((1, 5))  # never simulated: refused first
    wide = {"M0": (0.1, 5.0)}
    message = r"prior bounds of 'M0' \(0.1, 5\) .* parameter bounds \[0.9, 2.2\]"
    with pytest.raises(ValueError, match=message):
        abc_rejection(simulator, UniformPrior(wide), observed, run=RunOptions(executor="serial"))
    with pytest.raises(ValueError, match=message), pm.Model():
        add_simulator("vcc", simulator, observed, prior=wide)
    with pytest.raises(ValueError, match=message):
        sobol_indices(simulator, wide, ["PD"], run=RunOptions(executor="serial"))
    extrapolating = VCCSimulator(parameters=["M0"], outputs=["PD"], allow_outside_unit_bounds=True)
    check_prior_support(check_simulator(extrapolating).support, wide)  # asked for: allowed
    check_prior_support(check_simulator(simulator).support, {"M0": (1.0, 2.0)})


def test_gmm_with_few_samples_falls_back_to_a_mixture_as_wide_as_the_samples():
    rng = np.random.default_rng(5)
    three = rng.uniform([0.2, 0.2], [0.8, 0.8], size=(3, 2))
    prior = GMMPrior.fit(three, {"a": (0.0, 1.0), "b": (0.0, 1.0)}, seed=0)
    assert prior.n_components == 1
    draws = prior.sample(50_000, rng)
    np.testing.assert_allclose(draws.std(axis=0), three.std(axis=0, ddof=1), rtol=0.1)
    np.testing.assert_allclose(draws.mean(axis=0), three.mean(axis=0), atol=0.02)
    bounds = {f"p{j}": (0.0, 1.0) for j in range(35)}
    forty = rng.beta(4.0, 4.0, size=(40, 35))
    wide = GMMPrior.fit(forty, bounds, seed=0)
    assert wide.n_components == 1
    assert np.linalg.matrix_rank(wide.covariances[0]) == 35
    np.testing.assert_allclose(wide.sample(20_000, rng).std(axis=0), forty.std(axis=0), rtol=0.1)


def test_gmm_transfer_keeps_marginal_means_and_sds_within_five_hundredths_of_an_sd():
    """A skewed posterior against a bound, where one logit Gaussian shifts the moments."""
    rng = np.random.default_rng(6)
    samples = np.column_stack(
        [np.clip(0.9 + 0.02 * rng.standard_normal(1000) ** 3, 0.6, 0.999), rng.beta(20, 2, 1000)]
    )
    prior = GMMPrior.fit(samples, {"a": (0.0, 1.0), "b": (0.0, 1.0)}, seed=1)
    draws = prior.sample(200_000, np.random.default_rng(7))
    sd = samples.std(axis=0, ddof=1)
    assert np.all(np.abs(draws.mean(axis=0) - samples.mean(axis=0)) <= 0.05 * sd)
    assert np.all(np.abs(draws.std(axis=0) - sd) <= 0.05 * sd)


def test_a_diagonal_mixture_is_drawn_exactly_inside_a_box_however_little_it_holds():
    """Two components: the draws inside a box follow the mixture there (as rejection's do),
    and in 35 dimensions a box holding ~1e-590 of the mass (8.5 sd out in each) is drawn
    without a miss."""
    prior = GMMPrior(
        {"a": (0.0, 1.0), "b": (0.0, 10.0)},
        np.array([0.3, 0.7]),
        np.array([[0.0, 0.0], [2.0, -1.0]]),
        np.array([np.diag([1.0, 0.25]), np.diag([0.5, 2.0])]),
    )
    assert prior.is_diagonal
    box = {"a": (0.4, 0.9), "b": (1.0, 5.0)}
    rng = np.random.default_rng(0)
    exact = prior.sample_in_box(box, 20_000, rng)
    tried = prior.sample(400_000, rng)
    inside = tried[((tried >= [0.4, 1.0]) & (tried <= [0.9, 5.0])).all(axis=1)]
    for j in range(2):
        assert stats.ks_2samp(exact[:, j], inside[:, j]).pvalue > 0.01
    d = 35
    narrow = GMMPrior(
        {f"p{j}": (0.0, 1.0) for j in range(d)},
        np.ones(1),
        np.zeros((1, d)),
        0.01 * np.eye(d)[None],
    )
    far = narrow.sample_in_box({f"p{j}": (0.7, 0.75) for j in range(d)}, 4000, rng)
    assert ((far >= 0.7) & (far <= 0.75)).all()
    # each logit is its normal truncated to [logit 0.7, logit 0.75]: ~8.5 sd out, mean near the edge
    edges = logit(np.array([0.7, 0.75])) / 0.1
    expected = expit(0.1 * stats.truncnorm(*edges).mean())
    assert np.median(far) == pytest.approx(expected, abs=0.002)
    assert (
        narrow.sample_in_box({"p0": (1.0, 1.0)} | {f"p{j}": (0, 1) for j in range(1, d)}, 5, rng)
        is None
    )


def test_a_full_covariance_mixture_is_drawn_in_a_box_by_rejection():
    correlated = GMMPrior(
        BOUNDS, np.ones(1), np.zeros((1, 2)), np.array([[[1.0, 0.9], [0.9, 1.0]]])
    )
    assert not correlated.is_diagonal
    rng = np.random.default_rng(1)
    box = {"M0": (1.4, 1.8), "CF_VOL": (0.8, 1.2)}
    draws = correlated.sample_in_box(box, 1000, rng)
    assert draws.shape == (1000, 2)
    assert ((draws >= [1.4, 0.8]) & (draws <= [1.8, 1.2])).all()
    assert correlated.sample_in_box({"M0": (2.19, 2.2), "CF_VOL": (0.5, 0.51)}, 10, rng) is None


def test_a_drift_widens_the_fitted_prior_by_the_step_the_parameters_may_take():
    """Samples at one point, moved by a 5 %-of-range step before the fit: the prior's sd is
    the step's (the sample's own spread is 100 times smaller); an undrifted parameter keeps
    the samples' spread."""
    rng = np.random.default_rng(2)
    samples = np.column_stack(
        [1.5 + 1e-4 * rng.standard_normal(400), 1.0 + 1e-3 * rng.standard_normal(400)]
    )
    prior = GMMPrior.fit(samples, BOUNDS, seed=3, drift={"M0": 0.05})
    draws = prior.sample(100_000, rng)
    assert draws[:, 0].std() == pytest.approx(0.05 * 1.3, rel=0.1)
    assert draws[:, 0].mean() == pytest.approx(1.5, abs=0.01)
    assert draws[:, 1].std() == pytest.approx(1e-3, rel=0.15)
    same = GMMPrior.fit(samples, BOUNDS, seed=3, drift=0.0)
    assert same.sample(100_000, rng)[:, 0].std() == pytest.approx(1e-4, rel=0.15)
    with pytest.raises(ValueError, match=r"drift names parameter\(s\) \['L_COND'\]"):
        GMMPrior.fit(samples, BOUNDS, drift={"L_COND": 0.1})
    with pytest.raises(ValueError, match=r"drift of 'M0' must be a finite fraction >= 0"):
        GMMPrior.fit(samples, BOUNDS, drift=-0.1)


def test_slabs_spread_each_group_with_its_probability_at_most_two_at_once():
    """A narrow spike with a slab for each of three one-parameter groups, at most two at once:
    each group is spread in its probability's share of draws (renormalised over the sets kept),
    never all three, and a spread group is near-uniform over its range."""
    bounds = {"A": (0.0, 1.0), "B": (0.0, 1.0), "C": (0.0, 1.0)}
    rng = np.random.default_rng(4)
    spike = GMMPrior.fit(0.5 + 0.01 * rng.standard_normal((300, 3)), bounds, seed=1)
    prior = spike.with_slabs([("A",), ("B",), ("C",)], 0.2)
    p = 0.2
    kept = (1 - p) ** 3 + 3 * p * (1 - p) ** 2 + 3 * p**2 * (1 - p)
    share = (p * (1 - p) ** 2 + 2 * p**2 * (1 - p)) / kept
    assert prior.n_components == 7 * spike.n_components
    draws = prior.sample(200_000, rng)
    away = np.abs(draws - 0.5) > 0.1
    outside_spike = np.mean(np.abs(rng.uniform(size=200_000) - 0.5) > 0.1)
    assert away.mean(axis=0) == pytest.approx([share * outside_spike] * 3, rel=0.03)
    assert not (away.sum(axis=1) == 3).any()  # never three at once
    edges = [0.02, 0.14, 0.26, 0.38, 0.62, 0.74, 0.86, 0.98]
    histogram = np.delete(np.histogram(draws[away[:, 0], 0], bins=edges)[0], 3)
    assert histogram.max() / histogram.min() < 1.35  # near-uniform where spread
    with pytest.raises(ValueError, match=r"slab group\(s\) name \['D'\]"):
        spike.with_slabs([("D",)], 0.1)
    with pytest.raises(ValueError, match=r"probability must lie in \(0, 1\), got 1.5"):
        spike.with_slabs([("A",)], 1.5)


def test_a_downward_slab_spreads_below_the_spike_only():
    """A two-parameter group that a fault only lowers: where spread, each parameter lies below
    the spike's value in 97.7 % of draws (2 sds of its logit normal), a 70 % drop within its
    lowest 5 %; the other group still spreads both ways."""
    bounds = {"A": (0.0, 10.0), "B": (0.0, 1.0), "C": (0.0, 1.0)}
    rng = np.random.default_rng(6)
    centre = np.array([6.0, 0.7, 0.5])
    spike = GMMPrior.fit(centre * (1 + 0.01 * rng.standard_normal((300, 3))), bounds, seed=1)
    prior = spike.with_slabs([("A", "B"), ("C",)], 0.5, downward=[("A", "B")])
    draws = prior.sample(100_000, rng)
    spread = np.abs(draws[:, 0] / 6.0 - 1) > 0.05  # A away from the spike
    assert 0.3 < spread.mean() < 0.7
    for j, value in ((0, 6.0), (1, 0.7)):
        below = draws[spread, j] < value
        assert below.mean() == pytest.approx(0.977, abs=0.01)
        assert np.quantile(draws[spread, j], 0.05) < 0.3 * value  # a 70 % drop inside its 5 %
    moved_c = np.abs(draws[:, 2] - 0.5) > 0.1
    assert 0.3 < np.mean(draws[moved_c, 2] > 0.5) < 0.7  # both ways
    with pytest.raises(ValueError, match=r"downward group\(s\) \[\('C', 'B'\)\] are not slabs"):
        spike.with_slabs([("A", "B"), ("C",)], 0.5, downward=[("C", "B")])


def test_a_full_covariance_can_be_asked_for_when_the_samples_are_few():
    """40 samples on a ridge in 3-D: by sample count the fit is diagonal and loses the ridge;
    asked for a full covariance, its draws keep the samples' correlation."""
    bounds = {"A": (0.0, 1.0), "B": (0.0, 1.0), "C": (0.0, 1.0)}
    rng = np.random.default_rng(5)
    a = 0.5 + 0.1 * rng.standard_normal(40)
    samples = np.column_stack([a, 1.0 - a + 0.005 * rng.standard_normal(40), np.full(40, 0.5)])
    samples[:, 2] += 0.05 * rng.standard_normal(40)
    for covariance, correlation in [(None, 0.0), ("full", -0.95)]:
        prior = GMMPrior.fit(samples, bounds, max_components=1, seed=1, covariance=covariance)
        draws = prior.sample(20_000, rng)
        assert np.corrcoef(draws[:, 0], draws[:, 1])[0, 1] == pytest.approx(correlation, abs=0.05)
    with pytest.raises(ValueError, match="covariance must be 'full', 'diag' or None, got 'tied'"):
        GMMPrior.fit(samples, bounds, covariance="tied")
