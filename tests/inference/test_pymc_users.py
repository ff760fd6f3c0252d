"""A PyMC user's habits: their own priors, PyMC's distance vocabulary, checks at build time."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pymc as pm
import pytest
import xarray as xr

from pymc_vcc.inference.priors import GMMPrior
from pymc_vcc.inference.pymc.layout import stage_statistics
from pymc_vcc.inference.pymc.model import add_simulator, gmm_prior_variable
from pymc_vcc.inference.pymc.smc import sample_smc_abc
from pymc_vcc.testing import Flaky, GaussianLocation, LinearGaussian

pytestmark = pytest.mark.usefixtures("quiet_pymc")

QUIET = {"progressbar": False}
SIM = GaussianLocation(n_time=40)
OBSERVED = SIM({"mu": 0.3}, np.random.default_rng(4))


def test_a_prior_declared_under_the_parameters_name_is_used():
    with pm.Model() as model:
        mu = pm.TruncatedNormal("mu", mu=0.0, sigma=1.0, lower=-3.0, upper=3.0)
        node = add_simulator("y", SIM, OBSERVED, epsilon=0.5, distance=SIM.distance)
    assert node.variables["mu"] is mu
    assert node.prior is None
    assert [v.name for v in model.free_RVs] == ["mu"]


def test_pymc_variables_mixed_with_bounds():
    sim = LinearGaussian()
    observed = sim({"a": 0.5, "b": 1.0}, np.random.default_rng(0))
    with pm.Model() as model:
        a = pm.Beta("slope", alpha=2.0, beta=2.0)
        node = add_simulator("y", sim, observed, prior={"a": a, "b": (0.0, 1.5)}, epsilon=0.5)
    assert node.variables["a"] is a
    assert node.prior.bounds == {"b": (0.0, 1.5)}
    assert node.parameter_names == ("a", "b")
    assert {v.name for v in model.free_RVs} == {"slope", "b"}


def test_the_entries_of_a_gmm_prior_variable():
    rng = np.random.default_rng(0)
    samples = np.column_stack([rng.uniform(0.1, 0.9, 300), rng.uniform(0.5, 1.4, 300)])
    gmm = GMMPrior.fit(samples, {"a": (0.0, 1.0), "b": (0.0, 1.5)}, max_components=2, seed=0)
    sim = LinearGaussian()
    observed = sim({"a": 0.5, "b": 1.0}, np.random.default_rng(0))
    with pm.Model():
        theta = gmm_prior_variable("theta", gmm)
        node = add_simulator("y", sim, observed, prior={"a": theta[0], "b": theta[1]})
        tree = sample_smc_abc(draws=20, executor="serial", random_seed=1, **QUIET)
    assert node.prior is None and node.parameter_names == ("a", "b")
    assert {"a", "b", "theta"} <= set(tree["posterior"].data_vars)


def test_a_prior_with_mass_outside_the_bounds_is_refused():
    with pm.Model():
        mu = pm.Normal("theta_mu", mu=2.5, sigma=1.0)
        with pytest.raises(ValueError, match=r"prior of 'mu' puts .* outside the bounds \[-3, 3\]"):
            add_simulator("y", SIM, OBSERVED, prior={"mu": mu})
        vector = pm.Uniform("v", 0.0, 1.0, shape=2)
        with pytest.raises(ValueError, match=r"must be a scalar PyMC variable.*theta\[0\]"):
            add_simulator("y", SIM, OBSERVED, prior={"mu": vector})


@pytest.mark.parametrize(("distance", "sum_stat"), [("gaussian", "mean"), ("laplace", "median")])
def test_pymcs_distance_names_and_summary_statistics(distance, sum_stat):
    with pm.Model():
        add_simulator("y", SIM, OBSERVED, epsilon=0.2, distance=distance, sum_stat=sum_stat)
        tree = sample_smc_abc(draws=100, executor="serial", random_seed=1, **QUIET)
    mean = float(tree.posterior["mu"].mean())
    assert abs(mean - float(OBSERVED.mean())) < 0.15


def test_stock_sample_smc_with_a_pymc_distance_takes_failed_runs_as_zero_likelihood():
    flaky = Flaky(SIM, rate=0.3, modes=("nan", "raise"))
    with pm.Model():
        options = {"epsilon": 0.2, "distance": "gaussian", "sum_stat": "mean"}
        add_simulator("y", flaky, OBSERVED, prior=SIM.bounds, **options)
        tree = pm.sample_smc(draws=100, chains=1, random_seed=2, **QUIET)
    assert np.isfinite(tree.posterior["mu"].values).all()
    assert abs(float(tree.posterior["mu"].mean()) - float(OBSERVED.mean())) < 0.3


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"distance": "kullback_leibler"}, r"'kullback_leibler' is not available \(PyMC does not"),
        ({"distance": "euclid"}, r"distance 'euclid' is not available; use one of \['ks'"),
        ({"sum_stat": "mode"}, r"sum_stat 'mode' is not available"),
        ({"sum_stat": "mean"}, r"sum_stat 'mean' does not suit distance 'ks'"),
        ({"distance": lambda sims, obs: sims.mean()}, "one finite number per simulation"),
        ({"distance": lambda sims, obs: sims.mean(axis=2)}, "one finite number per simulation"),
        ({"outputs": ["z"]}, r"observed output\(s\) \['z'\] are not produced by the simulator"),
        ({"prior": {"sigma": (0.0, 1.0)}}, r"unknown parameter\(s\) \['sigma'\]"),
    ],
)
def test_mistakes_are_refused_when_the_model_is_built(options, match):
    observed = xr.Dataset({"y": ("time", OBSERVED[0]), "z": ("time", OBSERVED[0])})
    with pm.Model(), pytest.raises(ValueError, match=match):
        add_simulator("y", SIM, observed, **{"outputs": ["y"], **options})


UNGUARDED_SCRIPT = """
import numpy as np
import pymc as pm
from pymc_vcc import add_simulator, sample_smc_abc
from pymc_vcc.testing import GaussianLocation

sim = GaussianLocation()
with pm.Model():
    add_simulator("y", sim, sim({"mu": 0.3}, np.random.default_rng(0)), epsilon=0.5)
    sample_smc_abc(draws=8, executor="processes", n_workers=1, progressbar=False)
"""


@pytest.mark.slow
def test_a_script_without_a_main_guard_is_told_what_to_do(tmp_path):
    script = tmp_path / "calibrate.py"
    script.write_text(UNGUARDED_SCRIPT)
    run = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=600, cwd=tmp_path
    )
    assert run.returncode != 0
    last = run.stderr.strip().splitlines()[-1]
    assert "MainGuardError" in last and "calibrate.py has no 'if __name__ ==" in last
    assert "worker-crash" not in run.stderr


def test_one_result_layout_stages_totals_units_and_netcdf(tmp_path):
    observed = xr.Dataset(
        {"y": ("time", OBSERVED[0], {"units": "K", "long_name": "a temperature"})},
        coords={"time": ("time", np.arange(40.0), {"units": "s"})},
    )
    with pm.Model():
        add_simulator("node", SIM, observed, epsilon=0.3, distance=SIM.distance)
        tree = sample_smc_abc(draws=30, chains=2, executor="serial", random_seed=3, **QUIET)
    stats = tree["sample_stats"].to_dataset()
    assert stats["beta"].dims == ("chain", "stage") and stats.sizes["chain"] == 2
    assert (stats["beta"].max("stage") == 1.0).all()
    assert stats["n_simulations"] == int(stats["simulations"].sum()) > 2 * 3 * 30
    observed_data = tree["observed_data"].to_dataset()
    assert list(observed_data.data_vars) == ["y"]
    assert observed_data["y"].attrs == {"units": "K", "long_name": "a temperature"}
    np.testing.assert_array_equal(observed_data["time"], np.arange(40.0))
    path = tmp_path / "smc.nc"
    tree.to_netcdf(path)
    back = xr.open_datatree(path)
    np.testing.assert_array_equal(back["sample_stats"]["beta"], stats["beta"])
    np.testing.assert_array_equal(back["posterior"]["mu"], tree["posterior"]["mu"])


def test_chains_with_different_numbers_of_stages_are_padded():
    ragged = np.empty(2, dtype=object)
    ragged[0], ragged[1] = [120, 90, 90], [120, 90]
    nested = np.empty((2, 1), dtype=object)
    nested[0, 0], nested[1, 0] = [0.1, 0.4, 1], [0.2, 1]  # ints and floats mixed, as PyMC's
    stats = stage_statistics(
        xr.Dataset({"simulations": ("chain", ragged), "beta": (("chain", "beta_dim_0"), nested)})
    )
    np.testing.assert_array_equal(stats["beta"], [[0.1, 0.4, 1.0], [0.2, 1.0, np.nan]])
    assert stats["simulations"].dims == ("chain", "stage")
    assert stats["n_simulations"] == 510


def test_both_samplers_return_the_same_layout():
    from pymc_vcc.execution.options import RunOptions
    from pymc_vcc.inference.priors import UniformPrior
    from pymc_vcc.inference.rejection import abc_rejection

    observed = xr.Dataset(
        {"y": ("time", OBSERVED[0], {"units": "K", "long_name": "a temperature"})},
        coords={"time": ("time", np.arange(40.0), {"units": "s"})},
    )
    rejection = abc_rejection(
        SIM,
        UniformPrior(SIM.bounds),
        observed,
        n_pilot=40,
        n_main=100,
        n_desired=10,
        quantile=0.2,
        run=RunOptions(executor="serial", seed=1, progress=False),
    )
    with pm.Model():
        add_simulator("y", SIM, observed, epsilon=0.3, distance=SIM.distance)
        smc = sample_smc_abc(draws=20, executor="serial", random_seed=1, **QUIET)
    data = [tree["observed_data"].to_dataset() for tree in (rejection, smc)]
    for dataset in data:
        dataset.attrs = {}  # the samplers' own metadata
    xr.testing.assert_identical(*data)  # variables, units, long names, time
    assert list(rejection["posterior"].data_vars) == list(smc["posterior"].data_vars) == ["mu"]
    assert rejection["posterior"]["mu"].dims == smc["posterior"]["mu"].dims == ("chain", "draw")


def test_pymcs_sample_posterior_predictive_is_not_shadowed():
    import pymc_vcc

    assert "simulate_predictive" in pymc_vcc.__all__
    assert "sample_posterior_predictive" not in pymc_vcc.__all__
    assert not hasattr(pymc_vcc, "sample_posterior_predictive")
