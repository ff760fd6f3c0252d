"""Markdown tables of a fault benchmark's rows, for the docs' results page.

``pymc-vcc validate --faults all --out DIR`` appends one JSON row per case to
``DIR/checkpoints/validate-faults.jsonl``; the measured rows behind the docs are kept in
``docs/results/runs/``. Run ``.venv/bin/python scripts/fault_tables.py ROWS.jsonl [MORE.jsonl ...]``
(several runs' rows are pooled; ``--likely P`` scores them again first with a fault no other
rivals named as likely at P): the score
(:func:`~pymc_vcc.studies.fault_benchmark.summarise_cases`), correct diagnosis by the fault's size
(:func:`~pymc_vcc.studies.fault_benchmark.correct_by_size`) and by what it costs at the rating point
(:func:`~pymc_vcc.studies.fault_benchmark.correct_by_cost`; for rows written before rows kept the
true cost, computed again: :func:`~pymc_vcc.studies.fault_benchmark.with_true_rating_change`, about
20 ms a row), the scores of each case (of the cases of two faults at once apart), the cases not
diagnosed correctly or whose interval misses, what the units truly lost at their rating point beside
the diagnosis's reading of it (rows that keep it), and what the verdicts would have scored at other
naming probabilities, or with a fault no other rivals named as likely
(:func:`~pymc_vcc.studies.fault_benchmark.rescored`), beside what a reading
without bias would have named (:func:`~pymc_vcc.studies.fault_benchmark.unbiased_naming`, for rows
that keep the readings).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from collections.abc import Callable
from pathlib import Path

from pymc_vcc.studies.diagnose import LIKELY, NAMED, RATED
from pymc_vcc.studies.fault_benchmark import (
    CASES,
    PAIR_SCORES,
    case_label,
    correct_by_cost,
    correct_by_size,
    cost_band,
    rescored,
    size_band,
    summarise_cases,
    unbiased_naming,
    with_true_rating_change,
)
from pymc_vcc.studies.faults import FAULTS

CATEGORIES = ("false alarm", "misdiagnosis", "missed detection", "no response")
SHOWN_PROBABILITY = 0.1  # the probabilities a failed case lists
NAMING_PROBABILITIES = (0.5, 0.6, 0.7, 0.8, 0.9, 0.95)  # the trade-off table's rows
LIKELY_PROBABILITIES = (0.5, 0.6, 0.7)  # its rows naming a fault no other rivals, at 0.9
TRADE_OFF_RATES = (  # the trade-off table's columns, keys of the score table
    "false_alarm_rate",
    "correct_rate",
    "misdiagnosis_rate",
    "missed_rate",
    "no_response_rate",
)


def _case_name(label: str) -> str:
    """``fault: {"ID": change}`` -> ``fault (ID ±x %)`` (``no fault`` for None)."""
    fault, changes = label.split(": ", 1)
    moves = ", ".join(
        f"{pid} {value / 1e3:.0f} kPa" if abs(value) > 1 else f"{pid} {100 * value:+.0f} %"
        for pid, value in json.loads(changes).items()
    )
    name = "no fault" if fault == "None" else fault
    return f"{name} ({moves})" if moves else name


def _summary(rows: list[dict]) -> str:
    t = summarise_cases(rows)
    faulted = [r for r in rows if isinstance(r["fault"], str)]
    lines = [
        "| | |",
        "|---|---:|",
        f"| false alarms (of the no-fault cases) | {100 * t['false_alarm_rate']:.0f} % |",
        f"| correct diagnosis (of the cases of one fault) | {100 * t['correct_rate']:.0f} % "
        f"({sum(r['score'] == 'correct diagnosis' for r in faulted)} of {len(faulted)}) |",
        f"| misdiagnosis | {100 * t['misdiagnosis_rate']:.0f} % |",
        f"| missed detection | {100 * t['missed_rate']:.0f} % |",
        f"| no response | {100 * t['no_response_rate']:.0f} % |",
        f"| median severity error (of the intensity) | {t['median_severity_error']:.2f} |",
        f"| true intensity inside its 95 % interval | {100 * t['intensity_coverage']:.0f} % "
        f"({sum(r['covered'] for r in faulted)} of {len(faulted)}) |",
        f"| the model's form error these cases ask for (95 %) | {t['model_form_needed']:.3f} |",
        f"| leak alarm: false alarms (of the no-fault cases) | "
        f"{100 * t['leak_false_alarm_rate']:.0f} % |",
    ]
    lines += [
        f"| leak alarm: detection at a {100 * loss:.0f} % loss | {100 * p:.0f} % |"
        for loss, p in t["leak_detection"]
    ]
    lines += [
        f"| simulations a case (mean) | {t['simulations']:.0f} |",
        f"| wall time a case (median) | {t['seconds']:.0f} s |",
    ]
    return "\n".join(lines)


def _bands(
    heading: str, bands: list[tuple[float, float, int, float]], words: Callable[[float, float], str]
) -> str:
    """A table of correct diagnosis per band (``words`` names a band by its edges)."""
    lines = [f"| {heading} | faulted cases | correct diagnosis |", "|---|---:|---:|"]
    for low, high, cases, share in bands:
        named = f"{round(share * cases)} ({100 * share:.0f} %)" if cases else "—"
        lines.append(f"| {words(low, high)} | {cases} | {named} |")
    return "\n".join(lines)


def _by_size(rows: list[dict]) -> str:
    return _bands("the fault's size, in thresholds", correct_by_size(rows), size_band)


def _by_cost(rows: list[dict]) -> str:
    bands = correct_by_cost(with_true_rating_change(rows))
    return _bands("what the fault costs at the rating point", bands, cost_band)


def _by_case(rows: list[dict]) -> str:
    lines = [
        "| case | cases | correct | " + " | ".join(CATEGORIES) + " | median severity error | "
        "covered |",
        "|---|" + "---:|" * (len(CATEGORIES) + 4),
    ]
    for case in CASES:
        mine = [r for r in rows if r["case"] == case_label(case)]
        if not mine or isinstance(case[0], tuple):
            continue
        right = "correct" if case[0] is None else "correct diagnosis"
        cells = [_case_name(case_label(case)), str(len(mine))]
        cells += [str(sum(r["score"] == s for r in mine)) for s in (right, *CATEGORIES)]
        if case[0] is None:
            cells += ["—", "—"]
        else:
            cells.append(f"{statistics.median(r['severity_error'] for r in mine):.2f}")
            cells.append(f"{sum(r['covered'] for r in mine)}/{len(mine)}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _failures(rows: list[dict]) -> str:
    lines = [
        "| unit | case | verdict | probabilities ≥ 0.1 | intensity: true, read (95 %) |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        right = r["score"] in ("correct", "correct diagnosis")
        if right and r.get("covered", True):
            continue
        shown = ", ".join(
            f"{name} {p:.2f}" for name, p in r["probabilities"].items() if p >= SHOWN_PROBABILITY
        )
        if isinstance(r["fault"], str):
            intensity = _reading(r["fault"], r)
        else:  # of two faults at once, each one's
            reads = r.get("faults_read", {})
            intensity = "; ".join(f"{name}: {_reading(name, read)}" for name, read in reads.items())
        lines.append(
            f"| {r['unit_seed']} | {_case_name(r['case'])} | {r['verdict']} | {shown} | "
            f"{intensity} |"
        )
    return "\n".join(lines)


def _reading(fault: str, read: dict) -> str:
    """A fault's true intensity and its reading (95 %), in the fault's display unit."""
    unit, factor = {f.name: f.display for f in FAULTS}[fault]
    true, mean, low, high = (
        factor * read[key]
        for key in ("true_intensity", "intensity_mean", "intensity_low", "intensity_high")
    )
    return f"{true:.0f}, {mean:.0f} ({low:.0f}–{high:.0f}) {unit}"


def _pairs(rows: list[dict]) -> str:
    """The cases of two faults at once: how often both, one or a wrong fault was named."""
    lines = [
        "| case | cases | both named | one of them alone | misdiagnosis | missed detection | "
        "no response | median severity error | covered |",
        "|---|" + "---:|" * 8,
    ]
    pairs = [case for case in CASES if isinstance(case[0], tuple)]
    groups = [
        (_case_name(case_label(case)), [r for r in rows if r["case"] == case_label(case)])
        for case in pairs
    ]
    groups.append(("**all**", [r for r in rows if isinstance(r["fault"], list)]))
    for name, mine in groups:
        if not mine:
            continue
        reads = [read for r in mine for read in r["faults_read"].values()]
        cells = [name, str(len(mine))]
        cells += [str(sum(r["score"] == s for r in mine)) for s in PAIR_SCORES]
        cells.append(f"{statistics.median(read['severity_error'] for read in reads):.2f}")
        cells.append(f"{sum(read['covered'] for read in reads)}/{len(reads)}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _rating(rows: list[dict]) -> str:
    """Per case, what the unit truly lost at its rating point and how the diagnosis read it:
    the median true change of each rated quantity, the median error of its reading and how
    many true changes its 95 % intervals hold (rows that read it only)."""
    header = " | ".join(
        f"{name}: true change (median) | error (median) | covered" for name in RATED
    )
    lines = [f"| case | cases | {header} |", "|---|" + "---:|" * (1 + 3 * len(RATED))]
    for case in CASES:
        mine = [r["rating"] for r in rows if r["case"] == case_label(case) and "rating" in r]
        if not mine:
            continue
        cells = [_case_name(case_label(case)), str(len(mine))]
        for name in RATED:
            reads = [m[name] for m in mine]
            read = [r for r in reads if r["mean"] is not None]
            cells.append(f"{100 * statistics.median(r['true'] for r in reads):+.1f} %")
            error = statistics.median(abs(r["mean"] - r["true"]) for r in read) if read else None
            cells.append("—" if error is None else f"{100 * error:.1f}")
            cells.append(f"{sum(r['covered'] for r in reads)}/{len(reads)}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _trade_off(rows: list[dict]) -> str:
    widths = all("model_reads" in r for r in rows if isinstance(r["fault"], str))
    lines = [
        "| naming probability | false alarms | correct diagnosis | misdiagnosis | missed "
        "detection | no response |" + (" named if read without bias |" if widths else ""),
        "|---:|---:|---:|---:|---:|---:|" + ("---:|" if widths else ""),
    ]
    rules: list[tuple[float, float | None]] = [(named, None) for named in NAMING_PROBABILITIES]
    rules += [(NAMED, likely) for likely in LIKELY_PROBABILITIES]
    for named, likely in rules:
        t = summarise_cases(rescored(rows, named, likely=likely))
        cells = [f"{100 * t[key]:.0f} %" for key in TRADE_OFF_RATES]
        if widths:
            unbiased = unbiased_naming(rows, named) if likely is None else None
            cells.append("—" if unbiased is None else f"{100 * unbiased:.0f} %")
        rule = f"{named}" if likely is None else f"{named}, likely at {likely}"
        mark = f"**{rule}** (default)" if (named, likely) == (NAMED, LIKELY) else rule
        lines.append(f"| {mark} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(description="Markdown tables of fault benchmark rows.")
    parser.add_argument("rows", nargs="+", metavar="ROWS.jsonl", help="rows of one or more runs")
    parser.add_argument(
        "--likely",
        type=float,
        metavar="P",
        help="score every row again first, a fault no other rivals named as likely at P",
    )
    args = parser.parse_args(argv)
    rows = [json.loads(line) for path in args.rows for line in Path(path).read_text().splitlines()]
    if args.likely is not None:
        rows = rescored(rows, NAMED, likely=args.likely)
    single = [r for r in rows if not isinstance(r["fault"], list)]
    tables = [_summary(rows), _by_size(rows), _by_cost(rows), _by_case(rows)] if single else []
    if len(single) < len(rows):
        tables.append(_pairs(rows))
    tables.append(_failures(rows))
    if any("rating" in r for r in rows):
        tables.append(_rating(rows))
    if single:
        tables.append(_trade_off(rows))
    print(*tables, sep="\n\n")


if __name__ == "__main__":
    main(sys.argv[1:])
