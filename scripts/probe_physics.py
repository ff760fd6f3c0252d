"""Probe the built-in unit over its Table III box and print what an engineer checks.

    python scripts/probe_physics.py box --draws 200 --workers 2
    python scripts/probe_physics.py charge          # 0.1 kg steps, rating point and profile
    python scripts/probe_physics.py effects         # every parameter to either bound

See :mod:`pymc_vcc.physics.probes` for what each check means.
"""

from __future__ import annotations

import argparse
import multiprocessing
from collections import Counter
from functools import partial

import numpy as np

from pymc_vcc.physics.inputs import builtin_inputs
from pymc_vcc.physics.probes import (
    OSCILLATION_LIMIT,
    charge_observability,
    check_draw,
    parameter_effects,
)
from pymc_vcc.physics.unit import load_unit


def box(draws: int, seed: int, workers: int) -> None:
    unit = load_unit()
    thetas = unit.parameters.sample_uniform(draws, np.random.default_rng(seed))
    with multiprocessing.get_context("fork").Pool(workers) as pool:
        reports = pool.map(partial(check_draw, unit), thetas, chunksize=1)
    ok = [r for r in reports if r.status == "ok"]
    print(f"draws {draws}, succeeded {len(ok)} ({100 * len(ok) / draws:.1f} %)")
    for reason, count in Counter(r.failure_reason for r in reports if r.status != "ok").items():
        print(f"  failed x{count}: {reason}")
    print(f"first law held in {sum(r.first_law for r in ok)}/{len(ok)}")
    print(f"second law held in {sum(r.second_law for r in ok)}/{len(ok)}")
    print(f"air flows and fan powers in range in {sum(r.air_in_range for r in ok)}/{len(ok)}")
    for name, (low, high) in unit.cycle_model.box_ranges(unit).items():
        print(f"  {name}: [{low:g}, {high:g}]")
    still = [r.oscillation for r in ok]
    print(
        f"PC peak-to-peak over the last 300 s: max {max(still):.1e}, "
        f"{sum(s >= OSCILLATION_LIMIT for s in still)} at or above {OSCILLATION_LIMIT:g}"
    )
    print(f"mass error: max {max(r.mass_error for r in ok):.1e}")
    print(f"all checks held in {sum(r.holds for r in reports)}/{draws}")
    for r in reports:
        if r.status == "ok" and not r.holds:
            print("  not held:", r)


def charge() -> None:
    charges = [round(0.9 + 0.1 * k, 1) for k in range(14)]
    for label, inputs in (("rating point (steady)", None), ("built-in profile", builtin_inputs())):
        print(f"charge steps, {label}: output moved most, time-averaged |change| / noise sd")
        for low, high, output, moved in charge_observability(charges, inputs=inputs):
            print(f"  {low:.1f} -> {high:.1f} kg  {output:5s} {moved:6.1f}")


def effects() -> None:
    print("parameter to lower / upper bound: output moved most, |change| / noise sd (rating)")
    for pid, ((out_low, low), (out_high, high)) in parameter_effects().items():
        print(f"  {pid:9s} {out_low:5s} {low:7.1f}   {out_high:5s} {high:7.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("probe", choices=["box", "charge", "effects"])
    parser.add_argument("--draws", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args()
    if args.probe == "box":
        box(args.draws, args.seed, args.workers)
    elif args.probe == "charge":
        charge()
    else:
        effects()


if __name__ == "__main__":
    main()
