"""Commission fault-benchmark units again under other sampler seeds, and print where each run
puts the condenser's conductance and the charge against the unit's truth: a posterior whose
mean moves between seeds by more than its own sd is the sampler's, not the record's.

    .venv/bin/python scripts/commissioning_seeds.py UNIT_SEED [UNIT_SEED ...] --seeds 0 1 2

Each unit is the benchmark's (``pymc-vcc validate --faults all``: the ``all`` variant of that
seed, its charge drawn as the benchmark draws it), calibrated by ``calibrate_record`` at the
``small`` budget on 2 worker processes with the CVODE solver.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from pymc_vcc.execution.executors import make_executor
from pymc_vcc.physics.unit import load_unit
from pymc_vcc.studies.fault_benchmark import UNIT_CHARGES
from pymc_vcc.studies.faults import coil_conductance
from pymc_vcc.studies.truths import generate_truth
from pymc_vcc.studies.unit_log import RECORD_BUDGETS, calibrate_record


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("units", nargs="+", type=int, help="the benchmark units' seeds")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    args = parser.parse_args()
    unit = load_unit()
    draws, error_draws = RECORD_BUDGETS["small"]
    with make_executor("processes", 2) as executor:
        for unit_seed in args.units:
            charge = float(np.random.default_rng(unit_seed).uniform(*UNIT_CHARGES))
            healthy = generate_truth("all", unit_seed, charge=charge)
            truth = {name: np.array([value]) for name, value in healthy.parameters.items()}
            true_conductance = coil_conductance("condenser", unit, truth)[0]
            for seed in args.seeds:
                started = time.perf_counter()
                tree = calibrate_record(
                    healthy.observed,
                    healthy.inputs,
                    executor,
                    draws=draws,
                    error_draws=error_draws,
                    seed=seed,
                    solver="cvode",
                )
                posterior = tree["posterior"]
                draws_of = {
                    name: posterior[name].values.ravel()
                    for name in posterior.data_vars
                    if name in unit.parameters.ids
                }
                conductance = coil_conductance("condenser", unit, draws_of)
                m0 = draws_of["M0"]
                z = (conductance.mean() - true_conductance) / conductance.std()
                print(
                    f"unit {unit_seed} seed {seed}: condenser UA true {true_conductance:.0f} W/K,"
                    f" read {conductance.mean():.0f} ± {conductance.std():.0f} (z {z:+.1f});"
                    f" M0 true {charge:.3f} kg, read {m0.mean():.3f} ± {m0.std():.3f};"
                    f" {time.perf_counter() - started:.0f} s",
                    flush=True,
                )


if __name__ == "__main__":
    main()
