"""Markdown tables of a real-units benchmark's rows, for the docs' results pages.

``pymc-vcc validate --truth ... --out DIR`` appends one JSON row per dataset to
``DIR/checkpoints/validate-real-units.jsonl``; the measured rows behind the docs are kept in
``docs/results/runs/``. Run ``.venv/bin/python scripts/real_units_tables.py ROWS.jsonl``: per
variant the error, width, coverage and simulations, the datasets whose interval misses, and
with ``--alarm`` rows the leak alarm's false alarms and detections with each later reading.
"""

from __future__ import annotations

import json
import statistics
import sys
from pathlib import Path

from pymc_vcc.studies.truths import VARIANTS
from pymc_vcc.studies.unit_log import ALARM_PROBABILITY

BUDGET = 5000  # simulations a dataset may take


def _count(hits: int, total: int) -> str:
    return f"{hits}/{total} ({100 * hits / total:.0f} %)"


def _variant_row(name: str, rows: list[dict]) -> str:
    errors = [abs(r["mean_kg"] - r["truth_kg"]) for r in rows]
    width = statistics.median(r["high_kg"] - r["low_kg"] for r in rows)
    sims = [r["simulations"] for r in rows]
    cells = [
        name,
        str(len(rows)),
        f"{statistics.fmean(errors):.3f}",
        f"{width:.3f}",
        _count(sum(r["covers"] for r in rows), len(rows)),
        f"{statistics.fmean(sims):.0f} (max {max(sims)})",
        f"{statistics.median(r['seconds'] for r in rows):.0f}",
    ]
    if all("alarm_unchanged" in r for r in rows):
        for key in ("alarm_unchanged", "alarm_leaked"):
            cells.append(_count(sum(r[key] > ALARM_PROBABILITY for r in rows), len(rows)))
    return "| " + " | ".join(cells) + " |"


def tables(rows: list[dict]) -> str:
    """The tables of ``rows`` as Markdown."""
    alarm = all("alarm_unchanged" in r for r in rows)
    header = (
        "| variant | datasets | MAE (kg) | median 95 % width (kg) | coverage "
        "| simulations / dataset | s / dataset (median) |"
    )
    rule = "|---|---:|---:|---:|---:|---:|---:|"
    if alarm:
        header += " false alarms | detections |"
        rule += "---:|---:|"
    lines = [header, rule]
    variants = [v for v in VARIANTS if any(r["variant"] == v for r in rows)]
    lines += [_variant_row(v, [r for r in rows if r["variant"] == v]) for v in variants]
    if len(variants) > 1:
        lines.append(_variant_row("**every dataset**", rows))
    over = sum(r["simulations"] > BUDGET for r in rows)
    lines += ["", f"Datasets above {BUDGET} simulations: {over} of {len(rows)}.", ""]
    misses = [r for r in rows if not r["covers"]]
    if misses:
        lines += [
            "| variant (seed) | true charge (kg) | posterior mean ± sd (kg) "
            "| 95 % interval (kg) | error (kg) |",
            "|---|---:|---:|---:|---:|",
        ]
        lines += [
            f"| {r['variant']} ({r['seed']}) | {r['truth_kg']:.3f} | {r['mean_kg']:.3f} ± "
            f"{r['sd_kg']:.3f} | {r['low_kg']:.3f}–{r['high_kg']:.3f} "
            f"| {r['mean_kg'] - r['truth_kg']:+.3f} |"
            for r in misses
        ]
    if alarm and all("later_leaked" in r for r in rows):
        lines += [
            "",
            "| variant (seed) | commissioned (kg) | read at commissioning | unchanged: read, "
            "P(leak) | 20 % lost: true, read (95 %), P(leak) |",
            "|---|---:|---:|---:|---:|",
        ]
        for r in rows:
            same, lost = r["later_unchanged"], r["later_leaked"]
            lines.append(
                f"| {r['variant']} ({r['seed']}) | {r['truth_kg']:.3f} | {r['mean_kg']:.3f} "
                f"| {same['mean_kg']:.3f}, {r['alarm_unchanged']:.2f} "
                f"| {lost['truth_kg']:.3f}, {lost['mean_kg']:.3f} "
                f"({lost['low_kg']:.3f}–{lost['high_kg']:.3f}), {r['alarm_leaked']:.2f} |"
            )
    return "\n".join(lines)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: real_units_tables.py ROWS.jsonl")
    text = Path(sys.argv[1]).read_text()
    print(tables([json.loads(line) for line in text.splitlines() if line.strip()]))
