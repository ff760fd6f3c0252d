"""Probe the built-in unit over its Table III box and print what an engineer checks.

    python scripts/probe_physics.py box --draws 200 --workers 2
    python scripts/probe_physics.py charge          # 0.1 kg steps, rating point and profile
    python scripts/probe_physics.py effects         # every parameter to either bound
    python scripts/probe_physics.py faults          # each fault, both modes, rating point
    python scripts/probe_physics.py box --draws 12 --seed 7 --solver cvode --fault P_NCG

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
    FAULT_QUANTITIES,
    OSCILLATION_LIMIT,
    charge_observability,
    check_draw,
    fault_effects,
    parameter_effects,
)
from pymc_vcc.physics.simulate import operating_point
from pymc_vcc.physics.unit import HEAT_PUMP_UNIT, load_unit


def box(
    draws: int, seed: int, workers: int, unit_file: str | None, solver: str, faults: list[str]
) -> None:
    unit = load_unit(unit_file)
    at_bound = {pid: unit.faults[pid].high for pid in faults}
    thetas = [
        theta | at_bound
        for theta in unit.parameters.sample_uniform(draws, np.random.default_rng(seed))
    ]
    if at_bound:
        print(f"every draw with {at_bound}")
    with multiprocessing.get_context("fork").Pool(workers) as pool:
        reports = pool.map(partial(check_draw, unit, solver=solver), thetas, chunksize=1)
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
    print(f"energy balance at the end: max {max(abs(r.energy_balance) for r in ok):.1e}")
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


def faults(held_between: tuple[float, float] = (0.38, 0.37)) -> None:
    """Each fault at half and all of its upper bound, both shipped units at their rating point
    (CVODE, the valve opening held); then, cooling, the largest non-condensable pressure with
    the valve closed to hold the fault-free superheat (interpolated between two openings)."""
    for unit_file in (None, HEAT_PUMP_UNIT):
        unit = load_unit(unit_file)
        effects = fault_effects(unit)
        nominal = effects.pop("nominal")
        print(f"{unit.name} ({unit.cycle}), rating point; fault-free:")
        print("  " + ", ".join(f"{name} {nominal[name]:.5g}" for name in FAULT_QUANTITIES))
        for label, values in effects.items():
            print(f"  {label}: {_changes(values, nominal)}")
        if unit.cycle != "split-cooling":
            continue
        gas = {"P_NCG": unit.faults["P_NCG"].high}
        ends = [operating_point(unit, gas, solver="cvode", valve_opening=v) for v in held_between]
        share = (nominal["superheat"] - ends[0]["superheat"]) / (
            ends[1]["superheat"] - ends[0]["superheat"]
        )
        held = {
            name: float(ends[0][name] + share * (ends[1][name] - ends[0][name]))
            for name in FAULT_QUANTITIES
        }
        opening = held_between[0] + share * (held_between[1] - held_between[0])
        print(f"  P_NCG={gas['P_NCG']:g}, superheat held (opening {opening:.3f}):")
        print(f"    {_changes(held, nominal)}")


def _changes(values: dict[str, float], nominal: dict[str, float]) -> str:
    return ", ".join(
        f"{name} {values[name] - nominal[name]:+.4g} "
        f"({100 * (values[name] - nominal[name]) / abs(nominal[name]):+.1f} %)"
        for name in FAULT_QUANTITIES
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("probe", choices=["box", "charge", "effects", "faults"])
    parser.add_argument("--draws", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--unit", default=None, help="box: unit file (default: the built-in)")
    parser.add_argument("--solver", default="radau", help="box: radau (default) or cvode")
    parser.add_argument(
        "--fault", nargs="*", default=[], metavar="ID", help="box: faults at their upper bound"
    )
    args = parser.parse_args()
    if args.probe == "box":
        box(args.draws, args.seed, args.workers, args.unit, args.solver, args.fault)
    elif args.probe == "charge":
        charge()
    elif args.probe == "faults":
        faults()
    else:
        effects()


if __name__ == "__main__":
    main()
