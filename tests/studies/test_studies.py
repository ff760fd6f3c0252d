"""The studies run end to end at the smoke budget, write their files, and resume after a kill."""

import io
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import xarray as xr
from scipy.ndimage import gaussian_filter1d

from pymc_vcc.cli import main
from pymc_vcc.execution.executors import make_executor
from pymc_vcc.execution.options import RunOptions
from pymc_vcc.inference.distances import BATCH_DISTANCES, windowed_distances
from pymc_vcc.inference.identifiability import Direction
from pymc_vcc.inference.likelihood import log_likelihood
from pymc_vcc.inference.noise import SensorNoise
from pymc_vcc.inference.priors import UniformPrior
from pymc_vcc.inference.sequential import SequentialResult
from pymc_vcc.inference.series import prepare_observed
from pymc_vcc.studies import StudySettings, estimation_study, leak_study
from pymc_vcc.studies.common import write_netcdf
from pymc_vcc.studies.estimate import (
    EstimationResult,
    _collapse_warnings,
    smc_sequential_calibration,
)
from pymc_vcc.studies.leak import leak_alarm
from pymc_vcc.testing import SensorProblem


def test_leak_command_writes_table_ii_and_reloadable_trees(tmp_path, capsys):
    out = tmp_path / "leak"
    main(
        [
            "leak",
            "--budget",
            "smoke",
            "--references",
            "2.0",
            "1.2",
            "--out",
            str(out),
            "--json",
            "--executor",
            "serial",
        ]
    )
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert set(summary) >= {"rows", "n_simulations", "wall_seconds", "sampler"}
    assert summary["sampler"] == "rejection"
    assert [row["reference_kg"] for row in summary["rows"]] == [2.0, 1.2]
    for row in summary["rows"]:
        assert set(row) >= {"reference_kg", "mean_kg", "sd_kg"}
        assert 0.9 <= row["mean_kg"] <= 2.2
    # two charges 0.8 kg apart are told apart even at the smoke budget
    assert summary["rows"][0]["mean_kg"] > summary["rows"][1]["mean_kg"]
    folder = out
    assert summary["files"] == sorted(str(path) for path in out.rglob("*") if path.is_file())
    for name in (
        "table_ii.csv",
        "table_ii.txt",
        "summary.json",
        "charge_posteriors.png",
        "charge_posteriors.svg",
    ):
        assert (folder / name).stat().st_size > 0
    tree = xr.open_datatree(folder / "posterior_0.nc", engine="h5netcdf")
    assert {"posterior", "prior", "observed_data", "sample_stats"} <= set(tree.children)
    assert "M0" in tree["posterior"].data_vars


def test_leak_alarm_counts_draws_below_threshold():
    posterior = xr.Dataset({"M0": (("chain", "draw"), np.array([[1.0, 1.5, 1.9, 2.0]]))})
    tree = xr.DataTree.from_dict({"posterior": posterior})
    assert leak_alarm(tree, 1.8) == pytest.approx(0.5)


def test_bad_study_settings_are_clear_errors():
    with pytest.raises(ValueError, match="unknown budget"):
        StudySettings(budget="huge")
    with pytest.raises(ValueError, match="executor"):
        StudySettings(executor="gpu")
    with pytest.raises(ValueError, match="n_workers"):
        StudySettings(n_workers=0)
    with pytest.raises(ValueError, match="time_limit"):
        StudySettings(time_limit=-1.0)
    with pytest.raises(ValueError, match="references_kg"):
        leak_study(StudySettings(budget="smoke", executor="serial"), references_kg=[3.0])
    with pytest.raises(ValueError, match="sampler"):
        leak_study(StudySettings(budget="smoke", executor="serial"), sampler="mcmc")


def test_a_studys_runs_take_its_time_limit_and_progress_and_the_seed_given(tmp_path):
    settings = StudySettings(executor="serial", time_limit=30.0, progress=False, seed=3)
    with settings.open_executor() as executor:
        run = settings.run_options(executor, seed=7, checkpoint=tmp_path / "c.sqlite")
    assert run == RunOptions(
        executor=executor,
        seed=7,
        checkpoint=tmp_path / "c.sqlite",
        time_limit=30.0,
        progress=False,
    )


def test_killed_leak_run_resumes_and_completes(tmp_path):
    out = tmp_path / "resume"
    command = [
        sys.executable,
        "-m",
        "pymc_vcc.cli",
        "leak",
        "--budget",
        "smoke",
        "--references",
        "1.6",
        "--executor",
        "serial",
        "--out",
        str(out),
        "--json",
    ]
    checkpoint = out / "checkpoints" / "leak_0.sqlite"
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None:
        if checkpoint.exists() and checkpoint.stat().st_size > 0:
            time.sleep(2.0)  # let a few simulations land
            break
        time.sleep(0.2)
    if process.poll() is None:
        os.kill(process.pid, signal.SIGKILL)
    process.wait()
    assert checkpoint.exists()
    finished = subprocess.run([*command, "--resume"], capture_output=True, text=True, timeout=300)
    assert finished.returncode == 0, finished.stderr
    summary = json.loads(finished.stdout.strip().splitlines()[-1])
    assert summary["rows"][0]["reference_kg"] == 1.6
    assert (out / "table_ii.csv").exists()


def test_estimate_command_writes_figures_and_reloadable_results(tmp_path, capsys):
    out = tmp_path / "estimate"
    main(["estimate", "--budget", "smoke", "--out", str(out)])
    table = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary) >= {"truths", "posterior_means", "sd_ratio", "n_simulations"}
    assert len(summary["truths"]) == 2 and len(summary["truths"][0]) == 26
    inside = summary["n_truths_in_95"]
    assert inside == [sum(flags.values()) for flags in summary["truth_in_95"]]
    assert f"truths inside their 95 % intervals: {inside[0]}/26 and {inside[1]}/26" in table
    assert table.count(" yes") + table.count(" NO") == 2 * 26
    # the fans' speeds change no output; the losses reach the outputs through one product
    dominant = [
        max(d["loadings"], key=lambda k: abs(d["loadings"][k])) for d in summary["unidentified"]
    ]
    assert summary["n_identify_simulations"] == 53
    assert {"FO_SPEED", "FI_SPEED", "CF_PREF"} <= set(dominant)
    assert len(summary["collapsed"]) == 2
    assert "to find what the data cannot identify" in table
    folder = out
    for stem in (
        "fig4_inputs",
        "fig5_kde_dataset1",
        "fig6_predictive_dataset1",
        "fig7_kde_dataset2",
        "fig8_predictive_dataset2",
    ):
        assert (folder / f"{stem}.png").stat().st_size > 10_000
        assert (folder / f"{stem}.svg").exists()
    predictive = xr.open_datatree(folder / "predictive_2.nc", engine="h5netcdf")
    assert {"posterior", "posterior_predictive", "observed_data"} <= set(predictive.children)
    assert float(predictive["posterior_predictive"]["time"].max()) == 2120.0
    assert predictive["posterior_predictive"].attrs["noise"] == 0  # smooth bands


def test_estimate_with_smc_mh_cvode_and_the_windowed_distance(tmp_path, capsys, monkeypatch):
    calls = []

    def windowed_spy(sims, obs):
        calls.append(sims.shape[0])
        return windowed_distances(sims, obs)

    monkeypatch.setitem(BATCH_DISTANCES, "windowed", windowed_spy)
    out = tmp_path / "estimate"
    command = ["estimate", "--budget", "smoke", "--out", str(out), "--json", "--solver", "cvode"]
    command += ["--executor", "serial", "--distance", "windowed", "--kernel", "mh"]
    main([*command, "--method", "smc", "--particles", "4", "--epsilon", "0.05"])
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert 2 * 4 <= summary["n_simulations"] < 2 * 4 * 100
    assert sum(calls) >= summary["n_simulations"]  # every simulation measured by the spy
    assert sum(summary["simulations_per_dataset"]) == summary["n_simulations"]
    assert len(summary["sd_ratio"]) == 2 and len(summary["sd_ratio"][1]) == 26
    assert all(0 <= ratio < 1.5 for ratio in summary["sd_ratio"][0].values())
    tree = xr.open_datatree(out / "predictive_1.nc", engine="h5netcdf")
    assert {"prior", "posterior", "posterior_predictive"} <= set(tree.children)
    assert tree["prior"]["M0"].size == 4
    assert tree["sample_stats"].attrs["kernel"] == "mh"
    assert (out / "fig5_kde_dataset1.png").exists()


def _exact_sequential_posteriors(observed, grid, drift=0.0):
    """(mean, sd) of the sensor problem's M0 after each dataset of ``observed`` (typical sensor
    noise), on a grid of the flat prior (the exact posteriors), M0 taking a normal step of sd
    ``drift`` × its range between datasets."""
    problem, noise = SensorProblem(), SensorNoise.typical()
    (low, high), spacing = problem.bounds["M0"], grid[1] - grid[0]
    log_p = np.zeros_like(grid)
    moments = []
    for k, data in enumerate(observed):
        if k and drift:
            spread = gaussian_filter1d(np.exp(log_p - log_p.max()), drift * (high - low) / spacing)
            log_p = np.log(np.maximum(spread, 1e-300))
        prepared = prepare_observed(data, None, problem.output_names)
        resolved = noise.resolve(prepared)
        log_p += [log_likelihood(prepared.values, problem.outputs(m), resolved) for m in grid]
        weights = np.exp(log_p - log_p.max())
        mean = np.average(grid, weights=weights)
        moments.append((mean, np.sqrt(np.average((grid - mean) ** 2, weights=weights))))
    return moments


def _two_sensor_datasets(data_seed, seed, charges=(1.3, 1.3), **options):
    """The sensor problem's sequential calibration of two noisy datasets at M0 = ``charges``
    (kg), and the datasets."""
    problem = SensorProblem()
    noise = SensorNoise.typical()
    rng = np.random.default_rng(data_seed)
    observed = [noise.measure(problem.dataset(charge), rng) for charge in charges]
    with make_executor("serial") as executor:
        result = smc_sequential_calibration(
            problem,
            UniformPrior(problem.bounds),
            observed,
            executor=executor,
            settings=StudySettings(executor="serial"),
            seed=np.random.SeedSequence(seed),
            sensor_noise=noise,
            **options,
        )
    return result, observed


def test_the_sequential_likelihood_path_matches_the_exact_posterior_of_each_stage(quiet_pymc):
    """Dataset 2, calibrated from dataset 1's GMM posterior, has the posterior of both (each
    tempered from its fit's Laplace approximation)."""
    result, observed = _two_sensor_datasets(
        5, 0, draws=600, epsilon=0.01, likelihood=True, fit_starts=1
    )
    exact = _exact_sequential_posteriors(observed, np.linspace(1.2, 1.4, 4001))
    for tree, (mean, sd) in zip(result.trees, exact, strict=True):
        draws = tree["posterior"]["M0"].values.ravel()
        assert draws.mean() == pytest.approx(mean, abs=0.1 * sd)
        assert draws.std() == pytest.approx(sd, rel=0.1)
    assert result.trees[1]["prior"]["M0"].size == 600


def test_a_drifting_charge_gets_the_posterior_of_a_parameter_that_moved(quiet_pymc):
    """With ``drift``, dataset 2's prior is dataset 1's posterior widened by the step M0 may
    have taken (here 50 g of charge lost between the datasets): its posterior is the exact one
    of that random walk, not the narrower one of an unchanged charge."""
    result, observed = _two_sensor_datasets(
        5, 0, (1.3, 1.25), draws=600, epsilon=0.01, likelihood=True, fit_starts=1, drift=0.02
    )
    grid = np.linspace(1.1, 1.5, 8001)
    (mean, sd), (unchanged_mean, unchanged_sd) = (
        _exact_sequential_posteriors(observed, grid, drift)[1] for drift in (0.02, 0.0)
    )
    assert abs(mean - unchanged_mean) > 2 * sd and sd > 1.3 * unchanged_sd  # they differ
    draws = result.trees[1]["posterior"]["M0"].values.ravel()
    assert draws.mean() == pytest.approx(mean, abs=0.1 * sd)
    assert draws.std() == pytest.approx(sd, rel=0.1)


def test_sequential_smc_with_refine_gives_each_stage_the_exact_posterior(quiet_pymc, tmp_path):
    """SMC-ABC on the KS distance only locates each posterior; the regression stage on fresh
    draws around it gives the exact one, and dataset 2 (from dataset 1's GMM) is tighter."""
    result, observed = _two_sensor_datasets(7, 1, draws=200, epsilon=0.05, refine=6000)
    exact = _exact_sequential_posteriors(observed, np.linspace(1.1, 1.5, 8001))
    spreads = []
    for tree, (mean, sd) in zip(result.trees, exact, strict=True):
        draws = tree["posterior"]["M0"].values.ravel()
        assert draws.mean() == pytest.approx(mean, abs=0.4 * sd)  # measured: |z| <= 0.32
        assert draws.std() == pytest.approx(sd, rel=0.15)
        assert "smc_posterior" in tree and int(tree["regression_stats"]["n_simulations"]) == 6000
        assert tree["sample_stats"].attrs["n_regression_simulations"] == 6000
        spreads.append(draws.std())
    assert spreads[1] < spreads[0]
    write_netcdf(result.to_datatree(), tmp_path / "calibration.nc")
    for tree in SequentialResult.from_netcdf(tmp_path / "calibration.nc").trees:
        assert {"smc_posterior", "regression_stats"} <= set(tree.children)


def test_estimate_refines_smc_only(tmp_path, capsys):
    with pytest.raises(ValueError, match="refine applies to method='smc' only"):
        estimation_study(StudySettings(budget="smoke", out=tmp_path / "e"), refine=100)
    with pytest.raises(ValueError, match="refine must be a non-negative integer, got -1"):
        estimation_study(StudySettings(budget="smoke", out=tmp_path / "e"), method="smc", refine=-1)
    with pytest.raises(
        ValueError, match=r"keeps 15; the adjustment of 35 parameters .* 2880 draws"
    ):
        estimation_study(
            StudySettings(budget="smoke", out=tmp_path / "e"), method="smc", refine=600
        )
    assert not (tmp_path / "e" / "checkpoints").exists()
    assert (
        main(["estimate", "--budget", "smoke", "--out", str(tmp_path / "e"), "--refine", "10"]) == 2
    )
    assert "refine applies to method='smc' only" in capsys.readouterr().err


def test_estimate_refuses_a_drift_outside_zero_to_one_before_any_work(tmp_path, capsys):
    for drift in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="drift must be a fraction of each range in"):
            estimation_study(StudySettings(budget="smoke", out=tmp_path / "e"), drift=drift)
    assert (
        main(["estimate", "--budget", "smoke", "--out", str(tmp_path / "e"), "--drift", "2"]) == 2
    )
    assert "drift must be a fraction of each range in [0, 1], got 2.0" in capsys.readouterr().err
    assert not (tmp_path / "e" / "checkpoints").exists()


def test_estimate_refuses_an_unknown_distance_before_any_work(tmp_path):
    with pytest.raises(ValueError, match=r"distance must be one of .*, got 'l2'"):
        estimation_study(StudySettings(budget="smoke", out=tmp_path / "e"), distance="l2")
    with pytest.raises(ValueError, match="fit_starts applies to method='likelihood' only"):
        estimation_study(StudySettings(budget="smoke", out=tmp_path / "e"), fit_starts=2)
    assert not (tmp_path / "e" / "checkpoints").exists()


def test_a_narrowed_unidentified_direction_flags_collapsed_particles():
    """No data narrow an unidentified direction beyond what they allow there: a posterior
    narrower than 0.7 of that marks the dataset's particles as collapsed."""
    fan = Direction(1.0, {"FO_SPEED": 1.0})
    losses = Direction(0.8, {"CF_PREF": 0.94, "CF_POW": -0.33})
    result = EstimationResult(
        truths=[],
        calibration=None,
        predictive=[],
        uncalibrated=None,
        contraction=[],
        covered=[],
        simulations=[],
        wall_seconds=0.0,
        unidentified=[fan, losses],
        sd_along=[[0.95, 0.5], [0.9, 0.6]],
    )
    assert result.collapsed == [{"0.8: +0.94 CF_PREF -0.33 CF_POW": 0.5}, {}]
    (line,) = _collapse_warnings(result.collapsed)
    assert line.startswith("dataset 1:") and "0.50 along 0.8: +0.94 CF_PREF -0.33 CF_POW" in line


def test_estimate_refuses_an_unknown_kernel_before_any_work(tmp_path):
    with pytest.raises(ValueError, match=r"kernel must be one of \['imh', 'mh'\], got 'hmc'"):
        estimation_study(StudySettings(budget="smoke", out=tmp_path / "e"), kernel="hmc")
    assert not (tmp_path / "e" / "checkpoints").exists()


def test_estimate_refuses_a_kernel_step_cap_below_one_before_any_work(tmp_path, capsys):
    out = tmp_path / "e"
    assert main(["estimate", "--method", "smc", "--kernel-steps", "0", "--out", str(out)]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "kernel_steps must be a positive integer" in error
    assert not (out / "checkpoints").exists()


def test_estimate_on_the_likelihood_needs_sensor_noise(tmp_path, capsys):
    assert main(["estimate", "--method", "likelihood", "--out", str(tmp_path / "e")]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "needs a sensor_noise" in error


def test_a_rejection_budget_scales_to_a_simulation_count():
    budget = StudySettings(budget="paper").work.with_rejection_simulations(8500)
    assert (budget.n_pilot, budget.n_main, budget.n_desired) == (500, 8000, 400)
    assert budget.n_pilot + budget.n_main == 8500
    with pytest.raises(ValueError, match="simulations must be an integer >= 20, got 5"):
        budget.with_rejection_simulations(5)


def test_sobol_command_writes_heatmaps(tmp_path, capsys):
    out = tmp_path / "sobol"
    main(["sobol", "--budget", "smoke", "--out", str(out), "--json"])
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["n_simulations"] == 2 * 28
    indices = xr.open_dataset(out / "sobol_indices.nc", engine="h5netcdf")
    assert indices["S1"].shape == (26, 9)
    for stem in ("sobol_first_order", "sobol_total_order"):
        assert (out / f"{stem}.png").exists()


def test_the_smc_leak_study_shows_progress_on_a_terminal(monkeypatch):
    import pymc_vcc.studies.leak as leak

    class Called(Exception):
        pass

    def fake_sample_smc_abc(*args, progressbar, **kwargs):
        raise Called(progressbar)

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    monkeypatch.setattr(leak, "sample_smc_abc", fake_sample_smc_abc)
    monkeypatch.setattr(sys, "stderr", Terminal())
    with pytest.raises(Called) as called:
        leak_study(StudySettings(budget="smoke", executor="serial"), sampler="smc")
    assert called.value.args == (True,)


def test_validate_command_writes_where_told_and_counts_its_files(tmp_path, capsys):
    out = tmp_path / "mine"
    command = ["validate", "--budget", "smoke", "--datasets", "1", "--methods", "ks"]
    assert main([*command, "--executor", "serial", "--out", str(out)]) == 0
    written = sorted(path for path in out.rglob("*") if path.is_file())
    assert {"comparison.txt", "summary.json", "runs.jsonl"} <= {path.name for path in written}
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last == f"results written to {out} ({len(written)} files)"


def test_a_shared_reference_table_serves_every_leak_dataset():
    settings = StudySettings(budget="smoke", executor="serial")
    options = {
        "references_kg": (2.0, 1.2),
        "t_calibration": 100.0,
        "sensor_noise": SensorNoise.typical(),
    }
    shared = leak_study(settings, reference_table=True, **options)
    alone = leak_study(settings, **options)
    assert shared.shared_table and shared.n_simulations == 16 + 32  # the table, once
    # the table is drawn with the first dataset's seed: that dataset's result is unchanged
    assert shared.table[0] == alone.table[0]
    assert shared.table[1]["n_simulations"] <= 48


def test_validate_command_compares_methods_on_a_shared_table(tmp_path, capsys):
    out = tmp_path / "validate"
    arguments = ["validate", "--budget", "smoke", "--solver", "cvode", "--datasets", "2"]
    main([*arguments, "--methods", "ks", "ks-noise", "--reference-table", "--out", str(out)])
    text = capsys.readouterr().out
    assert "one shared table of 48 simulations" in text
    summary = json.loads((out / "summary.json").read_text())
    assert summary["table_simulations"] == 48
    assert [row["method"] for row in summary["rows"]] == ["ks", "ks-noise"]
    assert all(row["datasets"] == 2 for row in summary["rows"])


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_the_likelihood_leak_study_takes_its_particle_count():
    result = leak_study(
        StudySettings(budget="smoke", executor="serial"),
        references_kg=(1.5,),
        sampler="likelihood",
        sensor_noise=SensorNoise.typical(),
        t_calibration=20.0,
        smc_draws=12,
    )
    assert result.trees[0]["posterior"]["M0"].size == 12  # the smoke budget's is 8


def test_the_validation_study_simulates_with_the_settings_solver(monkeypatch):
    from pymc_vcc.studies import validation

    class Stop(Exception):
        pass

    def capture(unit, *args, solver=None, **kwargs):
        raise Stop(str(solver))

    monkeypatch.setattr(validation, "VCCSimulator", capture)
    with pytest.raises(Stop, match="cvode"):
        validation.validation_study(StudySettings(solver="cvode"), methods=["ks"])


def test_the_identify_study_differences_at_a_tenth_of_the_settings_solvers_tolerances(
    monkeypatch,
):
    from pymc_vcc.physics.integration.solver import CVODE, DIFFERENCING_TOLERANCE_SCALE
    from pymc_vcc.studies import identify

    class Stop(Exception):
        pass

    def capture(unit, *args, solver=None, **kwargs):
        raise Stop(solver)

    monkeypatch.setattr(identify, "VCCSimulator", capture)
    with pytest.raises(Stop) as stopped:
        identify.identify_study(StudySettings(solver="cvode"))
    assert stopped.value.args[0] == CVODE.scaled(DIFFERENCING_TOLERANCE_SCALE)
