"""The real-units benchmark: charge identification on data the inference model did not make.

For each truth variant (:mod:`pymc_vcc.studies.truths`) and each of ``n_datasets`` seeds, a
unit is drawn, its record generated, and the charge calibrated with
:func:`~pymc_vcc.studies.unit_log.calibrate_record` (the charge among the nuisance parameters,
under the error budget, uniform prior on the unit's box; the ``model`` variant's records as
the model's own data, the others as a physical unit's: ``coils``). Reported per variant: the
mean absolute error of the posterior mean, the median width of the 95 % interval, the
fraction of intervals covering the true charge, simulations and wall time per dataset, and
the outputs the predictive check flagged.

With ``alarm`` each unit is also recorded twice more, unchanged and with 20 % of its charge
lost (same unit and sensors, other noise, a month's wear:
:func:`~pymc_vcc.studies.truths.worn_parameters`), and each later record is calibrated as ``pymc-vcc
leak LOG --prior`` does (prior :func:`~pymc_vcc.studies.unit_log.later_prior`, alarm
:func:`~pymc_vcc.studies.unit_log.leak_alarm`): the leak alarm's false-alarm rate on unchanged
units and its detection rate at a 20 % loss (each row keeps the later records' charge readings
too, ``later_unchanged`` and ``later_leaked``).

Each finished dataset is appended to ``<out>/checkpoints/validate-real-units.jsonl`` as it
completes; ``resume`` skips the datasets already there.
"""

from __future__ import annotations

import json
import statistics
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from pymc_vcc.physics.unit import load_unit
from pymc_vcc.studies.common import StudySettings, holds_output_folder, write_json, write_text
from pymc_vcc.studies.truths import VARIANTS, generate_truth, record_again, worn_parameters
from pymc_vcc.studies.unit_log import (
    ALARM_FRACTION,
    ALARM_PROBABILITY,
    RECORD_BUDGETS,
    calibrate_record,
    charge_summary,
    check_method,
    leak_alarm,
    predictive_checks,
    record_budget_name,
)

LOSS = 0.2  # the leak the alarm must detect, a fraction of the commissioned charge
RUNS_CHECKPOINT = "validate-real-units"  # <out>/checkpoints/validate-real-units.jsonl


@dataclass
class RealUnitsResult:
    """The benchmark's rows (one per dataset) and its table (one per variant)."""

    runs: list[dict]
    table: list[dict] = field(default_factory=list)
    wall_seconds: float = 0.0

    def summary(self) -> dict:
        """The JSON summary."""
        return {"table": self.table, "wall_seconds": round(self.wall_seconds, 1)}

    def format_table(self) -> str:
        """The table as printed by ``pymc-vcc validate --truth``."""
        lines = [
            "variant  datasets  MAE (kg)  median 95% width (kg)  coverage  sims/dataset  "
            "s/dataset  false alarms  detection"
        ]
        for row in self.table:
            alarms = (
                f"{row['false_alarm_rate']:.2f}  {row['detection_rate']:.2f}"
                if "false_alarm_rate" in row
                else "-  -"
            )
            lines.append(
                f"{row['variant']:<8} {row['datasets']:>8}  {row['mae_kg']:8.3f}  "
                f"{row['median_width_kg']:21.3f}  {row['coverage']:8.2f}  "
                f"{row['simulations']:12.0f}  {row['seconds']:9.0f}  {alarms}"
            )
        return "\n".join(lines)


def _calibrated(truth, executor, settings: StudySettings, budget, commissioning=None):
    draws, error_draws, rounds, method = budget
    started = time.perf_counter()
    tree = calibrate_record(
        truth.observed,
        truth.inputs,
        executor,
        commissioning=commissioning,
        draws=draws,
        error_draws=error_draws,
        rounds=rounds,
        seed=settings.seed,
        solver=settings.solver or "cvode",
        coils="model" if truth.variant == "model" else "finer",
        method=method,
    )
    return tree, {
        **charge_summary(tree),
        "simulations": int(tree["sample_stats"]["n_simulations"]),
        "seconds": time.perf_counter() - started,
        "misfit": [name for name, check in predictive_checks(tree).items() if check["misfit"]],
    }


def _dataset(variant, seed, executor, settings, budget, alarm, unit) -> dict:
    truth = generate_truth(variant, seed)
    tree, row = _calibrated(truth, executor, settings, budget)
    row |= {"variant": variant, "seed": seed, "truth_kg": truth.charge}
    row["covers"] = row["low_kg"] <= truth.charge <= row["high_kg"]
    if not alarm:
        return row
    worn = worn_parameters(unit, truth.parameters, np.random.default_rng([seed, 10_000_000]))
    for name, charge in (("unchanged", truth.charge), ("leaked", (1 - LOSS) * truth.charge)):
        later = record_again(truth, seed + 10_000_000, worn | {"M0": charge})
        later_tree, later_row = _calibrated(later, executor, settings, budget, tree)
        row[f"alarm_{name}"] = leak_alarm(later_tree, tree, unit, ALARM_FRACTION, seed)
        row[f"later_{name}"] = later_row | {"truth_kg": charge}
    return row


def _summarise(variant: str, rows: list[dict]) -> dict:
    errors = [abs(r["mean_kg"] - r["truth_kg"]) for r in rows]
    summary = {
        "variant": variant,
        "datasets": len(rows),
        "mae_kg": statistics.fmean(errors),
        "median_width_kg": statistics.median(r["high_kg"] - r["low_kg"] for r in rows),
        "coverage": statistics.fmean(float(r["covers"]) for r in rows),
        "simulations": statistics.fmean(r["simulations"] for r in rows),
        "seconds": statistics.median(r["seconds"] for r in rows),
        "misfit_datasets": sum(bool(r["misfit"]) for r in rows),
    }
    if all("alarm_unchanged" in r for r in rows):
        summary["false_alarm_rate"] = statistics.fmean(
            float(r["alarm_unchanged"] > ALARM_PROBABILITY) for r in rows
        )
        summary["detection_rate"] = statistics.fmean(
            float(r["alarm_leaked"] > ALARM_PROBABILITY) for r in rows
        )
    return summary


@holds_output_folder("validate")
def real_units_benchmark(
    settings: StudySettings,
    variants: Sequence[str] = VARIANTS,
    n_datasets: int = 20,
    *,
    alarm: bool = False,
    rounds: int = 1,
    method: str = "likelihood",
) -> RealUnitsResult:
    """Run the benchmark (see the module docstring); ``settings.budget`` picks the particles
    and model-error draws of each calibration (:data:`RECORD_BUDGETS`), ``rounds`` and
    ``method`` as for :func:`~pymc_vcc.studies.unit_log.calibrate_record`."""
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        raise ValueError(f"unknown truth variant(s) {unknown}; allowed are {list(VARIANTS)}")
    if n_datasets < 1:
        raise ValueError(f"n_datasets must be at least 1, got {n_datasets}")
    budget = record_budget_name(settings)
    check_method(method)
    work = (*RECORD_BUDGETS[budget], rounds, method)
    started = time.perf_counter()
    log = settings.checkpoint(RUNS_CHECKPOINT, ".jsonl")  # removed first unless resuming
    done: dict[tuple, dict] = {}  # rows of another budget, rounds or alarm are not reused
    if log is not None and log.is_file():
        for line in log.read_text().splitlines():
            row = json.loads(line)
            key = (row["variant"], row["seed"], tuple(row.get("work", ())), "alarm_leaked" in row)
            done[key] = row
    unit = load_unit()
    runs = []
    with settings.open_executor() as executor:
        for k in range(n_datasets):  # dataset-major: an interrupted run covers every variant
            for variant in variants:
                seed = settings.seed + 1000 * VARIANTS.index(variant) + k
                row = done.get((variant, seed, work, alarm))
                if row is None:
                    row = _dataset(variant, seed, executor, settings, work, alarm, unit)
                    row["work"] = list(work)
                    if log is not None:
                        with log.open("a") as stream:
                            stream.write(json.dumps(row) + "\n")
                runs.append(row)
    result = RealUnitsResult(runs)
    result.table = [_summarise(v, [r for r in runs if r["variant"] == v]) for v in variants]
    result.wall_seconds = time.perf_counter() - started
    if settings.out is not None:
        write_json(settings.out / "summary.json", result.summary())
        write_text(settings.out / "table.txt", result.format_table() + "\n")
    return result
