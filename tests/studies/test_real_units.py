"""The real-units benchmark: its command, its rows, resume, and its summary's arithmetic."""

import json

import numpy as np
import pytest
import xarray as xr

from pymc_vcc.cli import main
from pymc_vcc.physics.inputs import builtin_inputs, input_segments, window
from pymc_vcc.physics.unit import load_unit
from pymc_vcc.studies.real_units import _summarise
from pymc_vcc.studies.record_budget import fixed_spread, held_inputs


@pytest.mark.slow
def test_validate_truth_runs_the_benchmark_and_resumes(tmp_path, capsys):
    out = tmp_path / "bench"
    arguments = ["validate", "--truth", "lag", "--datasets", "1", "--budget", "smoke"]
    assert main([*arguments, "--out", str(out)]) == 0
    assert "coverage" in capsys.readouterr().out
    (row,) = [
        json.loads(line)
        for line in (out / "checkpoints" / "validate-real-units.jsonl").read_text().splitlines()
    ]
    assert row["variant"] == "lag" and 1.0 <= row["truth_kg"] <= 2.1
    # particles, model-error draws, rounds, method: resume keys on it
    assert row["work"] == [24, 12, 1, "likelihood"]
    assert row["low_kg"] <= row["mean_kg"] <= row["high_kg"]
    assert row["covers"] == (row["low_kg"] <= row["truth_kg"] <= row["high_kg"])
    assert main([*arguments, "--out", str(out), "--resume", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["table"][0]["datasets"] == 1
    assert (
        len((out / "checkpoints" / "validate-real-units.jsonl").read_text().splitlines()) == 1
    )  # nothing run again
    assert summary["table"][0]["mae_kg"] == pytest.approx(abs(row["mean_kg"] - row["truth_kg"]))


def test_summary_counts_errors_widths_coverage_and_alarms():
    rows = [
        {"mean_kg": 1.0, "truth_kg": 1.1, "low_kg": 0.9, "high_kg": 1.2, "covers": True,
         "simulations": 100, "seconds": 10.0, "misfit": [], "alarm_unchanged": 0.1,
         "alarm_leaked": 0.9},
        {"mean_kg": 2.0, "truth_kg": 1.7, "low_kg": 1.9, "high_kg": 2.2, "covers": False,
         "simulations": 300, "seconds": 30.0, "misfit": ["TD"], "alarm_unchanged": 0.7,
         "alarm_leaked": 0.4},
    ]  # fmt: skip
    summary = _summarise("all", rows)
    assert summary["mae_kg"] == pytest.approx(0.2)
    assert summary["median_width_kg"] == pytest.approx(0.3)
    assert summary["coverage"] == 0.5 and summary["misfit_datasets"] == 1
    assert summary["false_alarm_rate"] == 0.5 and summary["detection_rate"] == 0.5
    without_alarms = [{k: v for k, v in r.items() if not k.startswith("alarm")} for r in rows]
    assert "false_alarm_rate" not in _summarise("all", without_alarms)


def test_held_parameters_spread_by_their_stated_tolerance():
    unit = load_unit()
    spread = fixed_spread(unit, ("M0", "CF_LEV"), 0.2)
    assert "M0" not in spread and "CF_LEV" not in spread
    low, high = spread["L_COND"]  # from the drawings: ±1 %
    assert (low, high) == pytest.approx((0.99 * 19.0, 1.01 * 19.0))
    assert spread["HTC_CV"] == pytest.approx((0.8 * 800.0, 1.2 * 800.0))  # no tolerance stated
    assert spread["L_LIQ"] == pytest.approx((19.0, 21.0))


def test_logged_inputs_are_held_at_their_mean_over_each_step():
    """A logger's noise at every row would restart the solver at every row."""
    profile = window(builtin_inputs(), 1060.0)
    for got, held_as_given in zip(
        input_segments(held_inputs(profile)), input_segments(profile), strict=True
    ):
        assert np.array_equal(got, held_as_given)  # a stepped profile is unchanged
    times = np.arange(0.0, 1061.0)
    logged = profile.reindex(time=times, method="ffill")
    noise = np.random.default_rng(0).normal(0.0, 0.05, times.size)
    logged["T_ambient"] = logged["T_ambient"] + noise  # K, every row
    assert len(input_segments(logged)[0]) == times.size  # a restart at every row
    held = held_inputs(logged)
    edges, _ = input_segments(held)
    assert np.array_equal(edges, input_segments(profile)[0])  # the steps, and only them
    first_step = logged["T_ambient"].sel(time=slice(0.0, 119.0)).mean()
    assert float(held["T_ambient"][0]) == pytest.approx(float(first_step))
    assert held["T_ambient"].attrs["units"] == "K"


@pytest.mark.slow
def test_finer_coils_read_as_the_model_at_a_higher_charge():
    """Most of the model's discretisation error is an equivalent charge: the model at the
    measured offset reproduces the 20-volume unit far better than at the same charge."""
    from pymc_vcc.execution.executors import make_executor
    from pymc_vcc.inference.error_model import SensorAccuracy, summarise
    from pymc_vcc.physics.simulate import VCCSimulator
    from pymc_vcc.studies.record_budget import (
        FINE_VOLUMES,
        CoilOffset,
        SensorBudget,
        coil_offset,
    )
    from pymc_vcc.studies.truths import generate_truth
    from pymc_vcc.studies.unit_log import SETTLE

    truth = generate_truth("model", seed=2, charge=1.5, t_end=600.0)
    unit = load_unit()
    fine_unit = unit.with_changes(discretisation={"n_volumes": FINE_VOLUMES})
    model, fine = (
        VCCSimulator(u, held_inputs(truth.inputs), t_window=(0.0, 600.0), settle=SETTLE)
        for u in (unit, fine_unit)
    )
    sensors = SensorBudget.of(model, truth.observed, SensorAccuracy())
    with make_executor("processes", 2) as executor:
        offset, n_runs = coil_offset(
            model, fine_unit, sensors.scale, sensors.windows, executor, (0.9, 2.2)
        )
    assert n_runs > 100 and offset.charges.size >= 4
    assert np.all((offset.offsets > 0.01) & (offset.offsets < 0.08))  # kg: tens of grams

    def misfit(charge: float, model_charge: float) -> float:
        runs = [sim({"M0": c}) for sim, c in ((fine, charge), (model, model_charge))]
        unit_s, model_s = (
            summarise(np.stack([r[n].values for n in r.data_vars]), sensors.windows) for r in runs
        )
        return float((((unit_s - model_s) / sensors.scale) ** 2).sum())

    for charge in (1.2, 1.7):
        shifted = misfit(charge, charge + float(offset(charge)))
        assert shifted < misfit(charge, charge) / 4

    constant = CoilOffset(np.array([1.0, 2.0]), np.array([0.04, 0.04]))
    unit_charges = constant.unit_charge(np.full(4000, 1.5), np.random.default_rng(0))
    assert unit_charges.min() >= 1.5 - 2 * 0.04 and unit_charges.max() <= 1.5
    assert unit_charges.mean() == pytest.approx(1.46, abs=0.003)  # continuum: twice the offset


class _CrashingExecutor:
    """Runs every item in turn, but every fourth (from the second) killed its worker."""

    def map(self, fn, items):
        from pymc_vcc.execution.executors import WorkerCrash

        return [
            WorkerCrash("worker process died (signal SIGKILL)") if k % 4 == 1 else fn(item)
            for k, item in enumerate(items)
        ]


def test_runs_that_kill_their_worker_are_failures_not_fatal_to_the_error_budget(monkeypatch):
    """The coil offset and the model's errors count a run whose worker died as a failed run: a
    unit whose PD reads as the model's 0.05 kg heavier is measured so through the crashes."""
    from pymc_vcc.inference.error_model import model_errors
    from pymc_vcc.studies import record_budget

    def run(task):
        coils, charge = task
        value = charge + (0.05 if coils == "fine" else 0.0)
        return xr.Dataset({"PD": ("time", np.full(10, value))}, attrs={"status": "ok"})

    monkeypatch.setattr(record_budget, "_unit_runs", lambda model, unit: unit)
    monkeypatch.setattr(record_budget, "_run_at_charge", run)
    model = type("Model", (), {"unit": "nominal"})()
    windows = [np.arange(10)]
    offset, n_runs = record_budget.coil_offset(
        model, "fine", np.array([1.0]), windows, _CrashingExecutor(), (1.0, 2.0)
    )
    assert n_runs > 100 and offset.charges.size >= 4
    assert np.allclose(offset.offsets, 0.05, atol=1e-6)

    def pair(k):
        series = np.full((1, 10), float(k))
        return series + 1.0, series

    errors = model_errors(pair, list(range(8)), windows, _CrashingExecutor())
    assert [e is None for e in errors] == [k % 4 == 1 for k in range(8)]
    assert all(np.allclose(e, 1.0) for e in errors if e is not None)
