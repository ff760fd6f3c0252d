"""SMC-ABC with the parallel IMH and MH kernels: exactness, reproducibility, failures, chains."""

from __future__ import annotations

import multiprocessing

import numpy as np
import pymc as pm
import pytest
from pymc.smc.kernels import IMH, MH
from scipy import stats

from pymc_vcc.execution.executors import ProcessExecutor, available_cores, make_executor
from pymc_vcc.inference.priors import GMMPrior
from pymc_vcc.inference.pymc import smc
from pymc_vcc.inference.pymc.layout import standard_layout
from pymc_vcc.inference.pymc.model import add_simulator
from pymc_vcc.inference.pymc.smc import ParallelIMH, ParallelMH, sample_smc_abc
from pymc_vcc.testing import Flaky, GaussianLocation, LinearGaussian, ShiftedProfile

QUIET = {"progressbar": False}


pytestmark = pytest.mark.usefixtures("quiet_pymc")


def shifted_profile_abc_moments(sim: ShiftedProfile, x_obs: float, epsilon: float):
    """Exact mean and sd of the KS-Gaussian-kernel ABC posterior of ShiftedProfile (quadrature).

    p(mu) ∝ ∫ N(x_obs + δ; mu, σ²) exp(−½ (KS(δ)/ε)²) dδ on the prior box, with
    KS(δ) = min(n, floor(|δ|/h) + 1)/n the KS statistic of two profiles offset by δ.
    """
    step = sim.span / (sim.n_time - 1)
    delta = np.arange(-1.0, 1.0, step / 16)
    ks = np.minimum(sim.n_time, np.floor(np.abs(delta) / step) + 1) / sim.n_time
    kernel = np.exp(-0.5 * (ks / epsilon) ** 2)
    mu = np.linspace(sim.low, sim.high, 2001)
    density = stats.norm.pdf(x_obs + delta[None, :], mu[:, None], sim.sigma) @ kernel
    density /= density.sum()
    mean = float(mu @ density)
    return mean, float(np.sqrt(((mu - mean) ** 2) @ density))


@pytest.fixture(scope="module")
def deterministic_model():
    """KS node on a simulator that ignores its random stream, plus an ordinary likelihood."""
    sim = ShiftedProfile(sigma=0.0)
    observed = sim({"mu": 0.2}, np.random.default_rng(0))
    with pm.Model() as model:
        add_simulator("y", sim, observed, epsilon=0.05)
        pm.Normal("z", mu=model["mu"], sigma=0.5, observed=[0.1, 0.3])
    return model


@pytest.mark.parametrize(("parallel", "stock_kernel"), [(ParallelIMH, IMH), (ParallelMH, MH)])
def test_same_seed_gives_the_stock_kernels_posterior(deterministic_model, parallel, stock_kernel):
    settings = {"draws": 150, "chains": 1, "random_seed": 11, **QUIET}
    with deterministic_model:
        stock = pm.sample_smc(kernel=stock_kernel, **settings, compute_convergence_checks=False)
        ours = pm.sample_smc(kernel=parallel, **settings, compute_convergence_checks=False)
    np.testing.assert_array_equal(ours.posterior["mu"].values, stock.posterior["mu"].values)
    np.testing.assert_array_equal(ours.sample_stats["beta"].values, stock.sample_stats["beta"])
    simulations = ours.sample_stats["simulations"].values
    assert simulations[0] >= 2 * 150  # the initial population plus at least one mutation step
    totals = standard_layout(ours, deterministic_model)["sample_stats"]
    assert totals["n_simulations"] == simulations.sum() and totals["n_failed"] == 0
    assert (ours.sample_stats["failed_simulations"].values == 0).all()


def test_results_do_not_depend_on_the_executor():
    sim = GaussianLocation(n_time=40)
    observed = sim({"mu": 0.3}, np.random.default_rng(4))
    with pm.Model():
        add_simulator("y", sim, observed, epsilon=0.5, distance=sim.distance)
        serial = sample_smc_abc(draws=100, executor="serial", random_seed=5, **QUIET)
        runs = {}
        for kind in ("processes", "dask"):
            with make_executor(kind, n_workers=2) as executor:
                runs[kind] = sample_smc_abc(draws=100, executor=executor, random_seed=5, **QUIET)
    for kind, name in (("processes", "ProcessExecutor"), ("dask", "DaskExecutor")):
        parallel = runs[kind]
        np.testing.assert_array_equal(serial.posterior["mu"].values, parallel.posterior["mu"])
        assert name in parallel.sample_stats.attrs["executor"]


def _gaussian_location_run(
    draws: int, max_steps: int | None, kernel: str = "imh", max_simulations: int | None = None
):
    """SMC-ABC of GaussianLocation and its exact ABC posterior's mean and sd: with a Gaussian
    kernel on the whitened sufficient statistic it is N(ȳ, se²(1 + ε²)) truncated to the box."""
    sim = GaussianLocation()
    observed = sim({"mu": 0.5}, np.random.default_rng(1))
    epsilon = 0.5
    exact = sim.posterior(observed)
    with pm.Model():
        add_simulator("y", sim, observed, epsilon=epsilon, distance=sim.distance)
        idata = sample_smc_abc(
            draws=draws,
            executor="serial",
            random_seed=0,
            max_steps=max_steps,
            max_simulations=max_simulations,
            kernel=kernel,
            **QUIET,
        )
    return idata, exact.mean(), exact.std() * np.sqrt(1 + epsilon**2)


@pytest.mark.parametrize(("max_steps", "kernel"), [(None, "imh"), (2, "imh"), (None, "mh")])
def test_gaussian_location_matches_the_exact_abc_posterior(max_steps, kernel):
    idata, mean, sd = _gaussian_location_run(400, max_steps, kernel)
    draws = idata.posterior["mu"].values.ravel()
    assert abs(draws.mean() - mean) < 0.3 * sd
    assert 0.85 < draws.std() / sd < 1.15
    assert idata.sample_stats.attrs["kernel"] == kernel


def test_an_unknown_kernel_is_refused_before_any_simulation():
    with pm.Model(), pytest.raises(ValueError, match=r"kernel must be one of \['imh', 'mh'\]"):
        sample_smc_abc(draws=10, executor="serial", kernel="nuts", **QUIET)


def test_a_step_cap_bounds_each_stage():
    with pm.Model(), pytest.raises(ValueError, match="max_steps must be a positive integer"):
        sample_smc_abc(draws=10, executor="serial", max_steps=0, **QUIET)
    capped, _, _ = _gaussian_location_run(400, 2)
    free, _, _ = _gaussian_location_run(400, None)
    per_stage = capped.sample_stats["simulations"].values.ravel()
    assert per_stage[0] <= 3 * 400 and (per_stage[1:] <= 2 * 400).all()
    assert free.sample_stats["simulations"].values.max() > 2 * 400  # the cap did bind
    assert capped.sample_stats.attrs["max_steps"] == 2


def test_a_simulation_budget_cuts_steps_not_the_posterior():
    with pm.Model(), pytest.raises(ValueError, match="max_simulations must be a positive integer"):
        sample_smc_abc(draws=10, executor="serial", max_simulations=0, **QUIET)
    free, mean, sd = _gaussian_location_run(400, None)
    capped, _, _ = _gaussian_location_run(400, None, max_simulations=4000)
    assert int(free.sample_stats["n_simulations"]) > 2 * 4000  # the budget binds
    per_stage = capped.sample_stats["simulations"].values.ravel()
    assert per_stage.sum() <= 4000
    assert (per_stage[-2:] == 400).all()  # one step a stage once the budget is near
    draws = capped.posterior["mu"].values.ravel()
    assert abs(draws.mean() - mean) < 0.3 * sd
    assert 0.85 < draws.std() / sd < 1.15
    assert capped.sample_stats.attrs["max_simulations"] == 4000


@pytest.mark.parametrize("kernel", ["imh", "mh"])
def test_linear_gaussian_matches_the_exact_abc_posterior(kernel):
    sim = LinearGaussian()
    observed = sim({"a": 0.2, "b": 0.1}, np.random.default_rng(2))  # far inside the box
    epsilon = 0.5
    mean, covariance = sim.posterior_moments(observed)
    sd = np.sqrt(np.diag(covariance) * (1 + epsilon**2))
    with pm.Model():
        add_simulator("y", sim, observed, epsilon=epsilon, distance=sim.distance)
        idata = sample_smc_abc(draws=400, executor="serial", random_seed=2, kernel=kernel, **QUIET)
    draws = np.column_stack([idata.posterior[name].values.ravel() for name in ("a", "b")])
    assert (np.abs(draws.mean(axis=0) - mean) < 0.3 * sd).all()
    assert ((draws.std(axis=0) / sd > 0.85) & (draws.std(axis=0) / sd < 1.15)).all()
    correlation = covariance[0, 1] / np.sqrt(covariance[0, 0] * covariance[1, 1])
    assert abs(np.corrcoef(draws.T)[0, 1] - correlation) < 0.1


@pytest.mark.parametrize("epsilon", [0.05, 0.1])
def test_ks_kernel_matches_the_exact_abc_posterior(epsilon):
    sim = ShiftedProfile()
    observed = sim({"mu": 0.2}, np.random.default_rng(0))
    mean, sd = shifted_profile_abc_moments(sim, float(observed.mean()), epsilon)
    with pm.Model():
        add_simulator("y", sim, observed, epsilon=epsilon)
        idata = sample_smc_abc(draws=400, executor="serial", random_seed=1, **QUIET)
    draws = idata.posterior["mu"].values.ravel()
    assert abs(draws.mean() - mean) < 0.3 * sd
    assert 0.85 < draws.std() / sd < 1.15


def test_sequential_step_with_a_gmm_prior_combines_both_datasets():
    # With a flat prior and ε-inflated Gaussian likelihoods N(ȳ_k; mu, se²(1 + ε²)), the
    # posterior after two datasets is N((ȳ_1 + ȳ_2)/2, se²(1 + ε²)/2); the GMM carries the first.
    sim = GaussianLocation(n_time=30)
    datasets = [sim({"mu": 0.5}, np.random.default_rng(seed)) for seed in (10, 11)]
    epsilon = 0.5
    with pm.Model():
        add_simulator("y", sim, datasets[0], epsilon=epsilon, distance=sim.distance)
        first = sample_smc_abc(draws=300, executor="serial", random_seed=0, **QUIET)
    prior = GMMPrior.fit(first, sim.bounds, max_components=2, seed=0)
    with pm.Model() as model:
        add_simulator("y", sim, datasets[1], prior=prior, epsilon=epsilon, distance=sim.distance)
        second = sample_smc_abc(draws=300, executor="serial", random_seed=1, **QUIET)
    assert [v.name for v in model.free_RVs] == ["y_theta"]
    mean = np.mean([data.mean() for data in datasets])
    sd = sim.standard_error * np.sqrt((1 + epsilon**2) / 2)
    draws = second.posterior["mu"].values.ravel()
    assert abs(draws.mean() - mean) < 0.3 * sd
    assert 0.8 < draws.std() / sd < 1.25


def test_failed_simulations_are_zero_likelihood_and_counted():
    base = GaussianLocation(n_time=50)
    observed = base({"mu": 0.5}, np.random.default_rng(3))
    sim = Flaky(base, rate=0.2)
    epsilon = 0.5
    exact = base.posterior(observed)
    with pm.Model():
        add_simulator(
            "y", sim, observed, prior=base.bounds, epsilon=epsilon, distance=base.distance
        )
        idata = sample_smc_abc(draws=300, executor="serial", random_seed=4, **QUIET)
    stats_ = idata.sample_stats
    failed = stats_["failed_simulations"].values.sum()
    total = stats_["simulations"].values.sum()
    assert failed == stats_["n_failed"]
    assert 0.15 < failed / total < 0.25  # the wrapper's failure rate
    for kind in ("exception", "non-finite", "solver"):
        assert kind in stats_.attrs["failure_kinds"]
    draws = idata.posterior["mu"].values.ravel()
    sd = exact.std() * np.sqrt(1 + epsilon**2)
    assert abs(draws.mean() - exact.mean()) < 0.3 * sd
    assert np.isfinite(draws).all()


def test_a_simulator_that_always_fails_raises_a_clear_error():
    base = GaussianLocation(n_time=20)
    observed = base({"mu": 0.0}, np.random.default_rng(0))
    with pm.Model():
        failing = Flaky(base, rate=1.0, modes=("raise",))
        add_simulator("y", failing, observed, prior=base.bounds, epsilon=0.5)
        with pytest.raises(RuntimeError, match="all 20 simulations of the initial population"):
            sample_smc_abc(draws=20, executor="serial", random_seed=0, **QUIET)


def test_parallel_chains_fall_back_to_serial_simulation_inside_them():
    sim = GaussianLocation(n_time=30)
    observed = sim({"mu": 0.0}, np.random.default_rng(0))
    with pm.Model():
        add_simulator("y", sim, observed, epsilon=0.5, distance=sim.distance)
        with (
            make_executor("processes", n_workers=2) as executor,
            pytest.warns(RuntimeWarning, match="cannot use the executor"),
        ):
            idata = pm.sample_smc(
                draws=60,
                kernel=ParallelIMH,
                executor=executor,
                chains=2,
                cores=2,
                random_seed=3,
                compute_convergence_checks=False,
                **QUIET,
            )
    assert idata.posterior["mu"].shape == (2, 60)


def test_chains_run_one_after_another_with_the_executor():
    sim = GaussianLocation(n_time=30)
    observed = sim({"mu": 0.0}, np.random.default_rng(0))
    with pm.Model():
        add_simulator("y", sim, observed, epsilon=0.5, distance=sim.distance)
        idata = sample_smc_abc(draws=60, chains=2, executor="serial", random_seed=3, **QUIET)
    posterior = idata.posterior["mu"].values
    assert posterior.shape == (2, 60)
    assert not np.array_equal(posterior[0], posterior[1])


def test_without_an_executor_the_kernel_simulates_on_every_core_and_closes_its_pool(
    monkeypatch,
):
    opened = []  # held here: only the kernel's going can close its pool

    class Recorded(ProcessExecutor):
        def __init__(self) -> None:
            super().__init__()
            opened.append(self)

    monkeypatch.setattr(smc, "ProcessExecutor", Recorded)
    sim = GaussianLocation(n_time=10)
    with pm.Model():
        add_simulator("y", sim, sim({"mu": 0.0}, np.random.default_rng(0)), epsilon=0.5)
        idata = pm.sample_smc(
            draws=20,
            kernel=ParallelIMH,
            chains=2,
            cores=1,
            random_seed=0,
            compute_convergence_checks=False,
            **QUIET,
        )
    assert [executor.n_workers for executor in opened] == [available_cores()]  # for both chains
    assert idata.sample_stats.attrs["executor"] == repr(opened[0])
    assert not [p for p in multiprocessing.active_children() if p.name == "pymc_vcc-worker"]


def test_kernel_needs_a_simulator_node_and_a_real_executor():
    with pm.Model():
        mu = pm.Normal("mu")
        pm.Normal("y", mu, 1.0, observed=[0.0, 1.0])
        with pytest.raises(ValueError, match=r"no pm\.Simulator node"):
            pm.sample_smc(draws=10, kernel=ParallelIMH, chains=1, **QUIET)
    sim = GaussianLocation(n_time=10)
    with pm.Model():
        add_simulator("y", sim, sim({"mu": 0.0}, np.random.default_rng(0)), epsilon=0.5)
        with pytest.raises(TypeError, match="executor must be"):
            pm.sample_smc(draws=10, kernel=ParallelIMH, executor="processes", chains=1, **QUIET)
        with pytest.raises(ValueError, match="chains must be a positive integer"):
            sample_smc_abc(draws=10, chains=0)


@pytest.mark.slow
def test_charge_calibration_on_the_vcc_simulator_recovers_the_true_charge():
    from pymc_vcc.physics.simulate import VCCSimulator

    # 230 s of the Fig. 4 profile (compressor step at 120 s), 30 particles, 2 workers.
    sim = VCCSimulator(t_window=(20.0, 250.0))
    observed = sim({"M0": 1.5})
    assert observed.attrs["status"] == "ok"
    with pm.Model():
        add_simulator("vcc", sim, observed, parameters=["M0"], epsilon=0.1)
        idata = sample_smc_abc(draws=30, executor="processes", n_workers=2, random_seed=1, **QUIET)
    charge = idata.posterior["M0"].values.ravel()
    assert abs(charge.mean() - 1.5) < 0.05  # kg; the prior spans [0.9, 2.2]
    assert charge.std() < 0.1
    # a work budget: the charge-observable physics of issue 13 gives a sharper likelihood,
    # hence more tempering stages (600 measured with it)
    assert idata.sample_stats["n_simulations"] < 800


ON_A_TERMINAL = """
import numpy as np, pymc as pm
from pymc_vcc.inference.pymc.model import add_simulator
from pymc_vcc.inference.pymc.smc import sample_smc_abc
from pymc_vcc.testing import GaussianLocation

sim = GaussianLocation(n_time=40)
with pm.Model():
    add_simulator("y", sim, sim({"mu": 0.3}, np.random.default_rng(4)), epsilon=0.5)
    sample_smc_abc(draws=50, executor="serial", random_seed=1)
"""


def test_the_progress_bar_is_drawn_on_a_terminal(tmp_path):
    import os
    import pty
    import subprocess
    import sys

    script = tmp_path / "run.py"
    script.write_text(ON_A_TERMINAL)
    main, terminal = pty.openpty()
    run = subprocess.Popen(
        [sys.executable, str(script)], stdout=terminal, stderr=terminal, cwd=tmp_path
    )
    os.close(terminal)
    shown = b""
    while True:
        try:
            chunk = os.read(main, 4096)
        except OSError:  # the terminal closed: the run ended
            break
        if not chunk:
            break
        shown += chunk
    assert run.wait(timeout=300) == 0
    os.close(main)
    assert b"Stage" in shown and b"Beta" in shown and b"\xe2\x94\x81" in shown  # "━": the bar
