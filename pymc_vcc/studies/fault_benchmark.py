"""The fault benchmark: diagnosis of simulated units that are not the model, scored as the
fault-detection literature scores protocols (Yuill and Braun).

Each *unit* is a truth of a real-units variant (:mod:`pymc_vcc.studies.truths`: finer coils,
sensor errors, drifted parameters...). It is commissioned once (a record of the healthy unit
calibrated with :func:`~pymc_vcc.studies.unit_log.calibrate_record`), then recorded again in
every *case* of :data:`CASES` (no fault, or one fault at a stated severity; the same sensors,
other noise, a month's wear: :func:`~pymc_vcc.studies.truths.worn_parameters`) and
each later record diagnosed (:func:`~pymc_vcc.studies.diagnose.diagnose`). A case is scored

* no-fault cases (none, or a change below its fault's threshold): ``false alarm`` when a fault
  is named or two are not distinguishable, else ``correct``;
* faulted cases: ``correct diagnosis`` when the fault is named (for sure or as likely),
  ``misdiagnosis`` when another is, ``missed detection`` on ``no fault``, ``no response`` when
  the verdict names none (two faults not distinguishable, or only possible ones); with two
  faults at once, ``correct diagnosis`` when both are named and ``partial diagnosis`` when one
  is, alone (scored apart from the cases of one fault);

with the severity error (|posterior mean intensity − true intensity| / true intensity) and
whether the 95 % interval of the intensity covers the truth; the model's own reading (before
its form error) is kept too, from which :func:`model_form_needed` measures the form error the
cases ask for. The leak alarm of ``pymc-vcc leak LOG --prior`` (the same prior and calibration:
:func:`~pymc_vcc.studies.unit_log.leak_alarm`) is the undercharge's probability; its false
alarms on the no-fault cases and its detection per charge loss are scored too.

Every finished case is appended to ``<out>/checkpoints/validate-faults.jsonl`` (and every
commissioning posterior kept beside it), so an interrupted run resumes where it stopped.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import xarray as xr

from pymc_vcc.execution.executors import Executor
from pymc_vcc.physics.cycles import OUTPUT_IDS
from pymc_vcc.physics.inputs import builtin_inputs
from pymc_vcc.physics.simulate import operating_point
from pymc_vcc.physics.unit import Unit, load_unit
from pymc_vcc.studies.common import StudySettings, holds_output_folder, write_json, write_text
from pymc_vcc.studies.diagnose import LIKELY_PREFIX, RATED, ROUNDS, diagnose, verdict
from pymc_vcc.studies.faults import FAULTS, MODEL_FORM, beyond_probability, moved_parameters
from pymc_vcc.studies.truths import (
    RECORD_SECONDS,
    VARIANTS,
    Truth,
    generate_truth,
    record_again,
    worn_parameters,
)
from pymc_vcc.studies.unit_log import (
    ALARM_PROBABILITY,
    COMMISSIONING_ATTEMPTS,
    RECORD_BUDGETS,
    calibrate_record,
    check_method,
    check_rounds,
    record_budget_name,
)

Case = tuple[str | tuple[str, str] | None, dict[str, float]]
"""A later record: its fault (None: none; two names: two faults at once) and the changes that
make it, id -> a fraction of the healthy unit's value (calibration parameters) or the value
itself (fault parameters)."""

CASES: tuple[Case, ...] = (
    (None, {}),
    (None, {"M0": -0.05}),
    (None, {"FI_FLOW": -0.10}),
    ("undercharge", {"M0": -0.20}),
    ("undercharge", {"M0": -0.30}),
    ("overcharge", {"M0": 0.20}),
    ("condenser fouling or low outdoor airflow", {"HTC_CA": -0.60}),
    ("condenser fouling or low outdoor airflow", {"FO_FLOW": -0.30}),
    ("low indoor airflow", {"FI_FLOW": -0.40}),
    ("compressor valve leakage", {"F_LEAK": 0.25}),
    ("liquid-line restriction", {"DP_RESTR": 150e3}),
    ("non-condensable gas", {"P_NCG": 120e3}),
    ("overcharge", {"M0": 0.15}),
    ("low indoor airflow", {"FI_FLOW": -0.30}),
    ("compressor valve leakage", {"F_LEAK": 0.15}),
    ("liquid-line restriction", {"DP_RESTR": 80e3}),
    ("non-condensable gas", {"P_NCG": 80e3}),
    ("condenser fouling or low outdoor airflow", {"HTC_CA": -0.70}),
    (("undercharge", "low indoor airflow"), {"M0": -0.20, "FI_FLOW": -0.40}),
    (("overcharge", "condenser fouling or low outdoor airflow"), {"M0": 0.20, "HTC_CA": -0.70}),
    (("compressor valve leakage", "liquid-line restriction"), {"F_LEAK": 0.25, "DP_RESTR": 150e3}),
    (("undercharge", "non-condensable gas"), {"M0": -0.20, "P_NCG": 120e3}),
)
"""The later records of each unit: no fault (the unit as it was, a 5 % charge loss, 10 % less
indoor airflow: changes at half their thresholds, which Yuill and Braun count as no fault, so a
verdict naming one is a false alarm), or one fault above its detection threshold, each at two
severities: about twice or three times its threshold, then 1.4-1.6 times (the five after the
first twelve, appended so that the cases before keep their seeds). Fouling and low outdoor
airflow are the condenser's: 60 % off the air-side HTC and 30 % off the outdoor airflow take
30 % and 26 % off its air-side conductance, both near its threshold, so a third, 70 % off the
HTC, takes 42 % (appended after them); 40 % and 30 % off the indoor airflow take 37 % and 28 %
off the evaporator's. Last, two faults at once, each at its first severity, as they meet in the
field: a unit short of charge with a dirty filter, a condenser fouled on an overcharged unit,
leaking compressor valves with a clogged filter-drier, and a unit recharged short without a
good vacuum (air left in it); a pair is named correctly when the verdict names both."""

UNIT_CHARGES = (1.3, 1.8)  # kg: a unit's commissioned charge is drawn between these
"""Commissioned charges leave room for a 30 % loss and a 20 % gain inside the unit's box
(0.9-2.2 kg)."""
LATER_SECONDS = RECORD_SECONDS
"""Length of each later record, s: the commissioning record's."""
LATER_START = 0.0
"""Where in the built-in profile each later record begins, s: where the commissioning record
began, at its operating points."""
PROFILE_SECONDS = float(builtin_inputs()["time"].values[-1])
"""Length of the built-in profile, s: the longest later record."""
SIZE_EDGES = (1.0, 1.75)
"""Where the bands of fault sizes begin, in units of each fault's threshold, in which correct
diagnosis is scored apart (:func:`correct_by_size`): near the threshold (the benchmark's
second severities and the condenser's first two cases, 1.1-1.6 times it) and well beyond it
(its first severities, about twice or more)."""
COST_EDGES = (0.05, 0.10)
"""Where the bands of what a case's faults cost begin (the larger of the drops of capacity and
of COP at the rating point, :func:`true_rating_change`; fraction), in which correct diagnosis
is scored apart (:func:`correct_by_cost`); the cheaper faults form a band below the first.
Yuill and Braun judge whether a case is faulted by its fault impact ratio, the capacity or COP
with the fault over without it: 5 % is a ratio of 0.95."""
PAIR_SCORES = (
    "correct diagnosis",
    "partial diagnosis",
    "misdiagnosis",
    "missed detection",
    "no response",
)
"""The categories of a case of two faults at once (:func:`score`)."""
RUNS_CHECKPOINT = "validate-faults"
_THRESHOLDS = {fault.name: fault.threshold for fault in FAULTS}  # by name, as rows name faults


@dataclass
class FaultBenchmarkResult:
    """The benchmark's cases (one row each) and its score table."""

    runs: list[dict]
    table: dict = field(default_factory=dict)
    wall_seconds: float = 0.0

    def summary(self) -> dict:
        """The JSON summary."""
        return {"table": self.table, "wall_seconds": round(self.wall_seconds, 1)}

    def format_table(self) -> str:
        """The score, as ``pymc-vcc validate --faults`` prints it."""
        t = self.table
        lines = [
            f"cases: {t['cases']} ({t['no_fault_cases']} without a fault"
            + ("" if t["pairs"] is None else f", {t['pairs']['cases']} with two at once")
            + ")",
            f"false alarms: {t['false_alarm_rate']:.2f} of the no-fault cases",
            f"correct diagnosis: {t['correct_rate']:.2f} of the cases of one fault; misdiagnosis "
            f"{t['misdiagnosis_rate']:.2f}, missed detection {t['missed_rate']:.2f}, no response "
            f"{t['no_response_rate']:.2f}",
            _bands_line(
                "the fault's size", t["by_size"], lambda *b: f"{size_band(*b)} its threshold"
            ),
            *(
                []
                if t["by_cost"] is None
                else [
                    _bands_line("what the fault costs at the rating point", t["by_cost"], cost_band)
                ]
            ),
            f"severity error (median): {t['median_severity_error']:.2f} of the intensity; "
            f"intensity inside its 95 % interval: {t['intensity_coverage']:.2f}; the model's form "
            f"error these cases ask for (95 %): {t['model_form_needed']:.3f}",
            f"leak alarm (P(charge 10 % low) > {ALARM_PROBABILITY}): false alarms "
            f"{t['leak_false_alarm_rate']:.2f} of the no-fault cases; detection "
            + ", ".join(f"{p:.2f} at a {100 * loss:.0f} % loss" for loss, p in t["leak_detection"]),
            *([] if t["pairs"] is None else [_pairs_line(t["pairs"])]),
            *([] if t["rating"] is None else [_rating_score_line(t["rating"])]),
            f"simulations per case: {t['simulations']:.0f}; s per case: {t['seconds']:.0f}",
            "",
            "fault                                     cases  correct  severity error  covered",
        ]
        for name, row in t["by_fault"].items():
            lines.append(
                f"{name:<41} {row['cases']:>5}  {row['correct']:>7.2f}  "
                f"{row['severity_error']:>14.2f}  {row['covered']:>7.2f}"
            )
        return "\n".join(lines)


def _bands_line(
    measure: str, bands: Sequence[tuple[float, float, int, float]], words: Callable[..., str]
) -> str:
    """Correct diagnosis by band of ``measure`` (:func:`correct_by_size`,
    :func:`correct_by_cost`; ``words`` names a band by its edges), as ``pymc-vcc validate
    --faults`` prints it."""
    return f"correct diagnosis by {measure}: " + "; ".join(
        f"{share:.2f} of {cases} at {words(low, high)}"
        for low, high, cases, share in bands
        if cases
    )


def _pairs_line(pairs: dict) -> str:
    """The score of two faults at once, as ``pymc-vcc validate --faults`` prints it."""
    labels = ("both named", "one of them alone", *PAIR_SCORES[2:])
    shares = ", ".join(
        f"{label} {pairs[category]:.2f}"
        for label, category in zip(labels, PAIR_SCORES, strict=True)
    )
    return (
        f"two faults at once ({pairs['cases']} case{'s' * (pairs['cases'] != 1)}): {shares}; "
        "severity error (median) "
        f"{pairs['median_severity_error']:.2f}; intensities inside their 95 % intervals "
        f"{pairs['intensity_coverage']:.2f}"
    )


def _rating_score_line(rating: dict[str, dict[str, float]]) -> str:
    """What the faults cost at the rating point, read against the true cost, as ``pymc-vcc
    validate --faults`` prints it."""
    return "what the faults cost at the rating point: " + "; ".join(
        f"{name} error (median) {100 * read['median_error']:.1f} points of the rating, inside "
        f"its 95 % interval {read['coverage']:.2f}"
        for name, read in rating.items()
    )


def size_band(low: float, high: float) -> str:
    """A band of fault sizes (:func:`correct_by_size`) in words: ``1-1.75 times``, ``1.75
    times or more``."""
    return f"{low:g} times or more" if high == float("inf") else f"{low:g}-{high:g} times"


def cost_band(low: float, high: float) -> str:
    """A band of what faults cost (:func:`correct_by_cost`) in words: ``under 5 %``, ``5-10
    %``, ``10 % or more``."""
    if low == -float("inf"):
        return f"under {100 * high:g} %"
    return f"{100 * low:g} % or more" if high == float("inf") else f"{100 * low:g}-{100 * high:g} %"


def _named(verdict: str) -> list[str]:
    """The faults a verdict names, for sure or as likely."""
    if verdict.startswith("several: "):
        return verdict.removeprefix("several: ").split(", ")
    fault = verdict.removeprefix(LIKELY_PREFIX)
    return [fault] if fault in {f.name for f in FAULTS} else []


def score(fault: str | Sequence[str] | None, verdict: str) -> str:
    """The Yuill-Braun category of a verdict on a case; of two faults at once, ``correct
    diagnosis`` only when both are named, ``partial diagnosis`` when one is and nothing else.

    Args:
        fault: the case's true fault (None: no fault; a sequence: faults at once).
        verdict: the diagnosis's verdict.
    """
    named = _named(verdict)
    if fault is None:
        alarmed = named or "not distinguishable" in verdict
        return "false alarm" if alarmed else "correct"
    if verdict == "no fault":
        return "missed detection"
    faults = {fault} if isinstance(fault, str) else set(fault)
    if set(named) == faults:
        return "correct diagnosis"
    if not set(named) <= faults:
        return "misdiagnosis"
    return "partial diagnosis" if named else "no response"


def rescored(
    rows: Sequence[dict],
    named: float,
    model_form: float | None = None,
    likely: float | None = None,
) -> list[dict]:
    """The cases' rows with the verdict and score each would have had at another naming
    probability (:func:`~pymc_vcc.studies.diagnose.verdict`) and, given ``model_form``, at
    another form error (the probabilities computed again from the rows' ``model_reads``,
    :func:`~pymc_vcc.studies.faults.beyond_probability`): a benchmark's trade-offs, read without
    diagnosing again.

    Args:
        rows: the cases' rows as :func:`fault_benchmark` keeps them.
        named: the naming probability.
        model_form: the form error's relative sd (None: the rows' own probabilities).
        likely: the probability that names a fault no other rivals as likely (None: off).
    """
    again = []
    for row in rows:
        probabilities = row["probabilities"]
        if model_form is not None:
            if "model_reads" not in row:
                raise ValueError("these rows keep no model_reads: score them at their form error")
            probabilities = {
                name: beyond_probability(np.array(reads), _THRESHOLDS[name], model_form)
                for name, reads in row["model_reads"].items()
            }
        text, _ = verdict(probabilities, named, likely)
        again.append(
            row
            | {"probabilities": probabilities, "verdict": text, "score": score(row["fault"], text)}
        )
    return again


def _reading(truth: float, draws: np.ndarray, read: np.ndarray) -> dict:
    """A fault's reading against its true intensity: the diagnosis's ``draws`` (the form error
    spread over them) and the model's own ``read``."""
    low, high = np.quantile(draws, [0.025, 0.975])
    return {
        "true_intensity": truth,
        "intensity_mean": float(draws.mean()),
        "intensity_low": float(low),
        "intensity_high": float(high),
        "severity_error": abs(float(draws.mean()) - truth) / truth,
        "covered": bool(low <= truth <= high),
        "model_mean": float(read.mean()),
        "model_sd": float(read.std()),
    }


def _case_row(
    fault: str | tuple[str, str] | None,
    truths: dict[str, float],
    diagnosis,
    rating: dict[str, float] | None = None,
) -> dict:
    """A case's row: its verdict and score, every fault's probability and reading; the true
    fault's reading (of two faults, each one's under ``faults_read``); given what the faults
    truly cost at the rating point (:func:`true_rating_change`), the diagnosis's reading of
    it."""
    row = {
        "fault": list(fault) if isinstance(fault, tuple) else fault,
        "true_intensity": truths[fault] if isinstance(fault, str) else 0.0,
        "verdict": diagnosis.verdict,
        "score": score(fault, diagnosis.verdict),
        "probabilities": diagnosis.probabilities,
        "simulations": int(diagnosis.tree["sample_stats"]["n_simulations"]),
        "model_reads": {  # every fault's reading, to score again at another form error
            name: [float(f"{value:.4g}") for value in draws]
            for name, draws in diagnosis.model_intensities.items()
        },
    }
    readings = {
        name: _reading(truth, diagnosis.intensities[name], diagnosis.model_intensities[name])
        for name, truth in truths.items()
    }
    if isinstance(fault, str):
        row |= readings[fault] | {"model_form": diagnosis.model_form}
    elif fault is not None:
        row |= {"faults_read": readings, "model_form": diagnosis.model_form}
    if rating is not None:
        row["rating"] = {
            name: _rating_reading(truth, diagnosis.rating[name], diagnosis.model_rating[name])
            for name, truth in rating.items()
        }
    return row


def _rating_reading(truth: float, changes: np.ndarray, read: np.ndarray) -> dict:
    """The diagnosis's reading of what the faults cost at the rating point (fractions; its
    ``changes``, the model's error included, and the model's own ``read``) against the true
    cost."""
    if not changes.size:
        return {"true": truth, "mean": None, "low": None, "high": None, "covered": False}
    low, high = np.quantile(changes, [0.025, 0.975])
    return {
        "true": truth,
        "mean": float(changes.mean()),
        "low": float(low),
        "high": float(high),
        "covered": bool(low <= truth <= high),
        "model_mean": float(read.mean()),
        "model_sd": float(read.std()),
    }


def true_rating_change(
    unit: Unit, healthy: Truth, parameters: dict[str, float], solver: str = "cvode"
) -> dict[str, float]:
    """What a true unit's faults cost at its rating point, as
    :func:`~pymc_vcc.studies.diagnose.rating_change` reads it: the relative change of
    capacity and COP (:data:`~pymc_vcc.studies.diagnose.RATED`) at the rating inputs between
    the unit with ``parameters`` (worn, and the case's faults; its coils' volumes) and the
    same unit with every fault undone (the fault parameters at 0, what the faults move back at
    the ``healthy`` unit's values). NaN where a run failed."""
    true_unit = unit.with_changes(discretisation={"n_volumes": healthy.n_volumes})
    undone = {name: value for name, value in parameters.items() if name not in unit.faults.ids}
    undone |= {name: healthy.parameters[name] for name in moved_parameters(unit)}
    now = operating_point(true_unit, parameters, solver=solver)
    fixed = operating_point(true_unit, undone, solver=solver)
    if now["status"] != "ok" or fixed["status"] != "ok":
        return dict.fromkeys(RATED, float("nan"))
    return {name: float(now[name]) / float(fixed[name]) - 1.0 for name in RATED}


def unbiased_naming(rows: Sequence[dict], named: float, model_form: float = MODEL_FORM) -> float:
    """The share of the faulted cases whose fault would be named at ``named`` if the model read
    each fault without bias: each case's reading draws (its row's ``model_reads``) moved to
    centre on the true intensity, their spread kept, the form error spread over them
    (:func:`~pymc_vcc.studies.faults.beyond_probability`). The ceiling the readings' widths
    (what the record tells of the fault) set on correct diagnosis: above it lies only what
    narrower readings name, not less biased ones.

    Args:
        rows: the cases' rows as :func:`fault_benchmark` keeps them.
        named: the naming probability.
        model_form: the form error's relative sd.
    """
    faulted = [row for row in rows if isinstance(row["fault"], str)]
    if any("model_reads" not in row for row in faulted):
        raise ValueError("these rows keep no model_reads: their readings' widths are unknown")
    if not faulted:
        return float("nan")
    hits = 0
    for row in faulted:
        reads = np.array(row["model_reads"][row["fault"]])
        centred = reads - reads.mean() + row["true_intensity"]
        hits += beyond_probability(centred, _THRESHOLDS[row["fault"]], model_form) >= named
    return hits / len(faulted)


def correct_by_size(
    rows: Sequence[dict], edges: Sequence[float] = SIZE_EDGES
) -> list[tuple[float, float, int, float]]:
    """Correct diagnosis by the fault's size: for each band of true intensities, in units of
    the fault's threshold, from one edge to the next (the last open), its lower and upper edge,
    its faulted cases and the share of them named correctly (nan without cases).

    Args:
        rows: the cases' rows as :func:`fault_benchmark` keeps them.
        edges: the bands' lower edges, increasing (:data:`SIZE_EDGES`).
    """
    sizes = [
        (row["true_intensity"] / _THRESHOLDS[row["fault"]], row["score"] == "correct diagnosis")
        for row in rows
        if isinstance(row["fault"], str)
    ]
    return _named_in_bands(sizes, edges)


def rating_drop(rating: dict[str, dict[str, float]]) -> float:
    """What a case's faults truly cost at the rating point: the larger of the drops of the
    rated quantities (a row's ``rating``; fraction of the rating, negative when both rose)."""
    return max(-rating[name]["true"] for name in RATED)


def correct_by_cost(
    rows: Sequence[dict], edges: Sequence[float] = COST_EDGES
) -> list[tuple[float, float, int, float]]:
    """Correct diagnosis by what the fault costs at the rating point (:func:`rating_drop`): for
    each band, below the first edge and from each edge to the next (the last open), its lower
    and upper edge, its faulted cases and the share of them named correctly (nan without
    cases). Only rows that keep the true cost count (:func:`with_true_rating_change` adds it to
    older rows).

    Args:
        rows: the cases' rows as :func:`fault_benchmark` keeps them.
        edges: the bands' lower edges after the first, increasing (:data:`COST_EDGES`).
    """
    costs = [
        (rating_drop(row["rating"]), row["score"] == "correct diagnosis")
        for row in rows
        if isinstance(row["fault"], str)
        and "rating" in row
        and all(np.isfinite(row["rating"][name]["true"]) for name in RATED)
    ]
    return _named_in_bands(costs, [-float("inf"), *edges])


def _named_in_bands(
    cases: Sequence[tuple[float, bool]], edges: Sequence[float]
) -> list[tuple[float, float, int, float]]:
    """Of ``cases`` (a measure and whether the fault was named), per band from each of
    ``edges`` to the next (the last open): its edges, its cases and the share named."""
    if any(high <= low for low, high in itertools.pairwise(edges)):
        raise ValueError(f"band edges must increase, got {list(edges)}")
    bands = []
    for low, high in zip(edges, [*edges[1:], float("inf")], strict=True):
        named = [right for measure, right in cases if low <= measure < high]
        share = statistics.fmean(named) if named else float("nan")
        bands.append((float(low), float(high), len(named), share))
    return bands


def model_form_needed(rows: Sequence[dict], coverage: float = 0.95) -> float:
    """The model's form error (relative sd, :data:`~pymc_vcc.studies.faults.MODEL_FORM`) at
    which the faulted cases' intensity intervals cover their truths at ``coverage``: the split
    conformal quantile of the spread each case needs, sqrt(((m − t)/z)² − s²)/abs(m) (0 when its
    model's reading covers alone), of the model's mean m and sd s and the truth t, z the
    normal quantile of ``coverage`` (a case needing more than any is ``inf``).

    Args:
        rows: the cases' rows as :func:`fault_benchmark` keeps them (rows of runs before the
            form error was drawn give the model's reading as ``intensity_mean`` and their 95 %
            interval).
        coverage: the intervals' aim, in (0, 1).
    """
    from scipy.stats import norm

    if not 0.0 < coverage < 1.0:
        raise ValueError(f"coverage must lie in (0, 1), got {coverage}")
    z = float(norm.ppf(0.5 + coverage / 2))
    needed = []
    for row in rows:
        if not isinstance(row["fault"], str):
            continue
        if "model_mean" in row:
            mean, sd = row["model_mean"], row["model_sd"]
        else:
            mean = row["intensity_mean"]
            sd = (row["intensity_high"] - row["intensity_low"]) / (2 * 1.96)
        miss = (mean - row["true_intensity"]) / z
        needed.append(np.sqrt(max(0.0, miss**2 - sd**2)) / abs(mean))
    if not needed:
        return float("nan")
    rank = int(np.ceil((len(needed) + 1) * coverage))
    return float(np.sort(needed)[rank - 1]) if rank <= len(needed) else float("inf")


def case_faults(case: Case) -> tuple[str, ...]:
    """The faults of a case: none, one, or two at once."""
    fault = case[0]
    return () if fault is None else (fault,) if isinstance(fault, str) else tuple(fault)


def _faulted(
    unit, healthy: dict[str, float], worn: dict[str, float], case: Case
) -> tuple[dict[str, float], dict[str, float]]:
    """The unit's parameters in ``case``, its changes made to the ``worn`` parameters (the
    ``healthy`` ones a month later; the charge among them, kg), and each of its faults' true
    intensity (against the healthy unit, as the diagnosis reads it against commissioning)."""
    moved = dict(worn)
    for pid, change in case[1].items():
        moved[pid] = change if pid in unit.faults.ids else worn[pid] * (1 + change)
    before = {pid: np.array([healthy.get(pid, 0.0)]) for pid in moved}
    after = {pid: np.array([value]) for pid, value in moved.items()}
    faults = {f.name: f for f in FAULTS}
    return moved, {
        name: float(faults[name].intensity(after, before, unit)[0]) for name in case_faults(case)
    }


def _case_parameters(
    unit: Unit, healthy: Truth, seed: int, n: int, case: Case
) -> tuple[dict[str, float], dict[str, float]]:
    """Unit ``seed``'s parameters in ``case``, its ``n``-th (a month's wear drawn by the seed
    and ``n``), and each of the case's faults' true intensity (:func:`_faulted`)."""
    worn = worn_parameters(unit, healthy.parameters, np.random.default_rng([seed, n]))
    return _faulted(unit, healthy.parameters, worn, case)


def with_true_rating_change(rows: Sequence[dict], solver: str = "cvode") -> list[dict]:
    """The rows, each that lacks it with what its case truly cost at the rating point
    (:func:`true_rating_change`, under ``rating`` as ``{quantity: {"true": change}}``),
    computed again from its unit's seed and its case (one of :data:`CASES`): rows written
    before rows kept it. Two runs of the model at the rating inputs a row; the wear is drawn as
    the benchmark draws it now."""
    unit = load_unit()
    labels = {case_label(case): n for n, case in enumerate(CASES)}
    unknown = sorted({r["case"] for r in rows if "rating" not in r and r["case"] not in labels})
    if unknown:
        raise ValueError(f"rows of unknown case(s) {unknown}; the benchmark's cases are CASES")
    units: dict[tuple[str, int], Truth] = {}
    again = []
    for row in rows:
        if "rating" not in row:
            key = (row.get("variant", "all"), row["unit_seed"])
            if key not in units:
                units[key] = benchmark_unit(*key)
            n = labels[row["case"]]
            parameters, _ = _case_parameters(unit, units[key], key[1], n, CASES[n])
            cost = true_rating_change(unit, units[key], parameters, solver)
            row = row | {"rating": {name: {"true": change} for name, change in cost.items()}}
        again.append(row)
    return again


def case_label(case: Case) -> str:
    """A case's key in the benchmark's rows: ``fault: {"ID": change, ...}`` (two faults at
    once: ``fault + fault: ...``)."""
    fault, changes = case
    name = " + ".join(fault) if isinstance(fault, tuple) else fault
    return f"{name}: {json.dumps(changes, sort_keys=True)}"


def summarise_cases(rows: Sequence[dict]) -> dict:
    """The score table (see the module docstring).

    Args:
        rows: the cases' rows as :func:`fault_benchmark` keeps them.
    """
    healthy = [r for r in rows if r["fault"] is None]
    faulted = [r for r in rows if isinstance(r["fault"], str)]
    pairs = [r for r in rows if isinstance(r["fault"], list)]

    def rate(subset, category):
        return statistics.fmean(r["score"] == category for r in subset) if subset else float("nan")

    by_fault = {}
    for f in FAULTS:
        mine = [r for r in faulted if r["fault"] == f.name]
        if mine:
            by_fault[f.name] = {
                "cases": len(mine),
                "correct": rate(mine, "correct diagnosis"),
                "severity_error": statistics.median(r["severity_error"] for r in mine),
                "covered": statistics.fmean(r["covered"] for r in mine),
            }

    def alarmed(row):
        return row["probabilities"]["undercharge"] > ALARM_PROBABILITY

    def loss(row):  # the case's charge loss, fraction (rounded: truths differ in the last digit)
        return round(row["true_intensity"], 3)

    leaks = [r for r in faulted if r["fault"] == "undercharge"]
    return {
        "cases": len(rows),
        "no_fault_cases": len(healthy),
        "false_alarm_rate": rate(healthy, "false alarm"),
        "correct_rate": rate(faulted, "correct diagnosis"),
        "misdiagnosis_rate": rate(faulted, "misdiagnosis"),
        "missed_rate": rate(faulted, "missed detection"),
        "no_response_rate": rate(faulted, "no response"),
        "median_severity_error": (
            statistics.median(r["severity_error"] for r in faulted) if faulted else float("nan")
        ),
        "intensity_coverage": (
            statistics.fmean(r["covered"] for r in faulted) if faulted else float("nan")
        ),
        "leak_false_alarm_rate": (
            statistics.fmean(alarmed(r) for r in healthy) if healthy else float("nan")
        ),
        "leak_detection": [
            (size, statistics.fmean(alarmed(r) for r in leaks if loss(r) == size))
            for size in sorted({loss(r) for r in leaks})
        ],
        "model_form_needed": model_form_needed(rows),
        "rating": _summarise_rating(rows),
        "simulations": statistics.fmean(r["simulations"] for r in rows),
        "seconds": statistics.median(r["seconds"] for r in rows),
        "by_fault": by_fault,
        "by_size": correct_by_size(rows),
        "by_cost": correct_by_cost(rows) if any("rating" in r for r in faulted) else None,
        "pairs": _summarise_pairs(pairs) if pairs else None,
    }


def _summarise_rating(rows: Sequence[dict]) -> dict[str, dict[str, float]] | None:
    """Per rated quantity, of the rows that read it (:func:`true_rating_change`), the median
    error of the reading's mean (fraction of the rating) and the share of true changes inside
    the 95 % intervals (a reading every run of which failed counts as not covering; rows with
    only the true cost, :func:`with_true_rating_change`, do not count)."""
    rated = [r["rating"] for r in rows if "rating" in r and "mean" in r["rating"][RATED[0]]]
    if not rated:
        return None
    summary = {}
    for name in RATED:
        readings = [read[name] for read in rated if np.isfinite(read[name]["true"])]
        errors = [abs(r["mean"] - r["true"]) for r in readings if r["mean"] is not None]
        summary[name] = {
            "cases": len(readings),
            "median_error": statistics.median(errors) if errors else float("nan"),
            "coverage": statistics.fmean(r["covered"] for r in readings) if readings else 0.0,
        }
    return summary


def _summarise_pairs(rows: Sequence[dict]) -> dict:
    """The score of the cases with two faults at once: each category's share, and of their
    faults' readings the median severity error and the share inside their 95 % intervals."""
    readings = [read for row in rows for read in row["faults_read"].values()]
    return {
        "cases": len(rows),
        **{
            category: statistics.fmean(r["score"] == category for r in rows)
            for category in PAIR_SCORES
        },
        "median_severity_error": statistics.median(r["severity_error"] for r in readings),
        "intensity_coverage": statistics.fmean(r["covered"] for r in readings),
    }


@holds_output_folder("validate")
def fault_benchmark(
    settings: StudySettings,
    variant: str = "all",
    n_units: int = 12,
    cases: Sequence[Case] = CASES,
    *,
    rounds: int = ROUNDS,
    method: str = "likelihood",
    later_seconds: float = LATER_SECONDS,
    later_start: float = LATER_START,
    outputs: Sequence[str] = OUTPUT_IDS,
    commission_seconds: float = RECORD_SECONDS,
    commission_rounds: int = 1,
) -> FaultBenchmarkResult:
    """Run the benchmark (see the module docstring).

    Args:
        settings: where and how it runs; its budget is each calibration's.
        variant: the truth variant of every unit (:data:`~pymc_vcc.studies.truths.VARIANTS`).
        n_units: units, each commissioned once and recorded in every case.
        cases: the later records of each unit (:data:`CASES`).
        rounds, method: each diagnosis's (:func:`~pymc_vcc.studies.diagnose.diagnose`); a
            resumed benchmark reuses only the rows of its rounds and method (a row written before
            rows kept them counts as any).
        later_seconds: length of each later record, s; a resumed benchmark reuses only the
            rows of that length (older rows are 1060 s).
        later_start: where in the built-in profile each later record begins, s (0: at the
            commissioning record's operating points; 1060: at others, as on another day's
            weather); the record must end inside the profile. A resumed benchmark reuses only
            the rows of that start (older rows start at 0).
        outputs: the outputs every record logs, commissioning and later (default: the nine;
            a field unit without a mass-flow meter logs all but ``MDOT``); a resumed benchmark
            reuses only the rows and commissionings of those outputs (older rows log the nine).
        commission_seconds: length of the commissioning record, s, from the profile's start
            (longer: the same unit, sensors and logger logged longer, new noise); a resumed
            benchmark reuses only the rows and commissionings of that length (older rows are
            1060 s).
        commission_rounds: calibrations in turn at commissioning (the ``rounds`` of
            :func:`~pymc_vcc.studies.unit_log.calibrate_once`); a resumed benchmark reuses
            only the rows and commissionings of that many (older rows made one).
    """
    if variant not in VARIANTS:
        raise ValueError(f"unknown truth variant {variant!r}; allowed are {list(VARIANTS)}")
    if n_units < 1:
        raise ValueError(f"n_units must be at least 1, got {n_units}")
    check_rounds(rounds)
    check_rounds(commission_rounds)
    check_method(method)
    for name, seconds in (
        ("later_seconds", later_seconds),
        ("commission_seconds", commission_seconds),
    ):
        if not 0.0 < seconds <= PROFILE_SECONDS:
            raise ValueError(
                f"{name} = {seconds} s: a record lies in the built-in profile, "
                f"(0, {PROFILE_SECONDS:.0f}] s"
            )
    if not 0.0 <= later_start <= PROFILE_SECONDS - later_seconds:
        raise ValueError(
            f"later_start = {later_start} s: a later record of {later_seconds:.0f} s ends inside "
            f"the built-in profile, so it starts in [0, {PROFILE_SECONDS - later_seconds:.0f}] s"
        )
    logged = check_outputs(outputs)
    known = {f.name for f in FAULTS}
    unknown = [name for case in cases for name in case_faults(case) if name not in known]
    if unknown:
        raise ValueError(f"unknown fault(s) {unknown}; allowed are {sorted(known)}")
    budget = record_budget_name(settings)
    coils = "model" if variant == "model" else "finer"
    started = time.perf_counter()
    log = settings.checkpoint(RUNS_CHECKPOINT, ".jsonl")
    done = {}
    if log is not None and log.is_file():
        for line in log.read_text().splitlines():
            row = json.loads(line)
            same = row.get("rounds", rounds) == rounds and row.get("method", method) == method
            same &= row.get("outputs", list(OUTPUT_IDS)) == logged
            same &= row.get("commission_seconds", RECORD_SECONDS) == commission_seconds
            same &= row.get("commission_rounds", 1) == commission_rounds
            # a row written before rows kept their window was the commissioning record's
            window = row.get("later_seconds", RECORD_SECONDS), row.get("later_start", LATER_START)
            if same and window == (later_seconds, later_start):
                done[(row["unit_seed"], row["case"], row["budget"])] = row
    unit = load_unit()
    runs = []
    with settings.open_executor() as executor:
        for k in range(n_units):
            seed = settings.seed + 100 * k
            keys = [(seed, case_label(case), budget) for case in cases]
            runs += [done[key] for key in keys if key in done]
            if all(key in done for key in keys):
                continue
            healthy = _logging(benchmark_unit(variant, seed), logged)
            record = _commissioning_record(healthy, seed, commission_seconds)
            commissioning = _commissioned(
                record, seed, executor, settings, budget, coils, log, commission_rounds
            )
            for n, (case, key) in enumerate(zip(cases, keys, strict=True)):
                if key in done:
                    continue
                case_started = time.perf_counter()
                parameters, truths = _case_parameters(unit, healthy, seed, n, case)
                later = _logging(
                    record_again(healthy, seed + n + 1, parameters, later_seconds, later_start),
                    logged,
                )
                diagnosis = diagnose(
                    later.observed,
                    later.inputs,
                    commissioning,
                    executor,
                    budget=budget,
                    seed=settings.seed,
                    solver=settings.solver or "cvode",
                    coils=coils,
                    rounds=rounds,
                    method=method,
                )
                rating = true_rating_change(unit, healthy, parameters, settings.solver or "cvode")
                row = _case_row(case[0], truths, diagnosis, rating) | {
                    "case": key[1],
                    "unit_seed": seed,
                    "variant": variant,
                    "truth_kg": healthy.charge,
                    "budget": budget,
                    "rounds": rounds,
                    "method": method,
                    "later_seconds": later_seconds,
                    "later_start": later_start,
                    "outputs": logged,
                    "commission_seconds": commission_seconds,
                    "commission_rounds": commission_rounds,
                    "seconds": time.perf_counter() - case_started,
                }
                if log is not None:
                    with log.open("a") as stream:
                        stream.write(json.dumps(row) + "\n")
                runs.append(row)
    result = FaultBenchmarkResult(runs, summarise_cases(runs))
    result.wall_seconds = time.perf_counter() - started
    if settings.out is not None:
        write_json(settings.out / "summary.json", result.summary())
        write_text(settings.out / "table.txt", result.format_table() + "\n")
    return result


def check_outputs(outputs: Sequence[str]) -> list[str]:
    """The outputs a benchmark's records log, in the cycle's order; unknown or no outputs are
    refused in one line."""
    unknown = [name for name in outputs if name not in OUTPUT_IDS]
    if unknown or not outputs:
        raise ValueError(
            f"outputs {list(outputs)}: a record logs one or more of {list(OUTPUT_IDS)}"
        )
    return [name for name in OUTPUT_IDS if name in outputs]


def _logging(truth: Truth, outputs: list[str]) -> Truth:
    """``truth`` with only ``outputs`` logged."""
    return dataclasses.replace(truth, observed=truth.observed[outputs])


def _commissioning_record(healthy: Truth, seed: int, seconds: float) -> Truth:
    """The record a unit is commissioned on: ``healthy`` itself, or, ``seconds`` long, the
    same unit logged longer from the profile's start, its noise drawn from ``seed`` and the
    length."""
    if seconds == healthy.seconds:
        return healthy
    noise = np.random.SeedSequence([seed, round(seconds)])
    longer = record_again(healthy, noise, healthy.parameters, seconds)
    return _logging(longer, list(healthy.observed.data_vars))


def benchmark_unit(variant: str, seed: int) -> Truth:
    """Unit ``seed`` of the benchmark: a truth of ``variant`` whose charge is drawn uniformly
    in :data:`UNIT_CHARGES` by ``seed``."""
    charge = float(np.random.default_rng(seed).uniform(*UNIT_CHARGES))
    return generate_truth(variant, seed, charge=charge)


def commission(
    healthy: Truth,
    executor: Executor,
    budget: str = "small",
    seed: int = 0,
    solver: str = "cvode",
    coils: str = "finer",
    rounds: int = 1,
) -> xr.DataTree:
    """The commissioning posterior of a unit's healthy record, calibrated as the benchmark does
    (:func:`~pymc_vcc.studies.unit_log.calibrate_record` at ``budget``'s particles and
    model-error draws, :data:`~pymc_vcc.studies.unit_log.RECORD_BUDGETS`, in ``rounds``
    calibrations in turn, calibrated again while its predictive check fails,
    :data:`~pymc_vcc.studies.unit_log.COMMISSIONING_ATTEMPTS` times at most; ``seed`` seeds
    it)."""
    draws, error_draws = RECORD_BUDGETS[budget]
    return calibrate_record(
        healthy.observed,
        healthy.inputs,
        executor,
        draws=draws,
        error_draws=error_draws,
        seed=seed,
        solver=solver,
        coils=coils,
        attempts=COMMISSIONING_ATTEMPTS,
        rounds=rounds,
    )


def _commissioned(healthy, seed, executor, settings, budget, coils, log, rounds) -> xr.DataTree:
    """:func:`commission` of a unit, kept beside the checkpoint."""
    from pymc_vcc.studies.common import write_netcdf

    unit = f"unit-{seed}-{healthy.variant}-{healthy.charge:.4f}kg-{budget}"
    unlogged = [name for name in OUTPUT_IDS if name not in healthy.observed.data_vars]
    unit += "-without-" + "-".join(unlogged) if unlogged else ""
    unit += f"-{healthy.seconds:.0f}s" if healthy.seconds != RECORD_SECONDS else ""
    unit += f"-{rounds}rounds" if rounds != 1 else ""
    kept = None if log is None else log.with_name(f"{log.stem}-{unit}.nc")
    if kept is not None and kept.is_file():
        return xr.open_datatree(kept, engine="h5netcdf")
    solver = settings.solver or "cvode"
    tree = commission(healthy, executor, budget, settings.seed, solver, coils, rounds)
    if kept is not None:
        write_netcdf(tree, kept)
    return tree


__all__ = [
    "CASES",
    "COST_EDGES",
    "PAIR_SCORES",
    "SIZE_EDGES",
    "FaultBenchmarkResult",
    "benchmark_unit",
    "case_faults",
    "case_label",
    "check_outputs",
    "commission",
    "correct_by_cost",
    "correct_by_size",
    "cost_band",
    "fault_benchmark",
    "model_form_needed",
    "rating_drop",
    "rescored",
    "score",
    "size_band",
    "summarise_cases",
    "unbiased_naming",
    "with_true_rating_change",
]
