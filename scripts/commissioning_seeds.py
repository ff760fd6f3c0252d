"""Commission fault-benchmark units again under other sampler seeds, and print where each run
puts the condenser's conductance and the charge against the unit's truth: a posterior whose
mean moves between seeds by more than its own sd is the sampler's, not the record's.

    .venv/bin/python scripts/commissioning_seeds.py UNIT_SEED [UNIT_SEED ...] --seeds 0 1 2

Each unit is the benchmark's (``pymc-vcc validate --faults all``: ``benchmark_unit``),
commissioned as the benchmark commissions it (``commission``: the ``small`` budget, the CVODE
solver) on 2 worker processes.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from pymc_vcc.execution.executors import make_executor
from pymc_vcc.physics.unit import load_unit
from pymc_vcc.studies.fault_benchmark import benchmark_unit, commission
from pymc_vcc.studies.faults import coil_conductance


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("units", nargs="+", type=int, help="the benchmark units' seeds")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    args = parser.parse_args()
    unit = load_unit()
    with make_executor("processes", 2) as executor:
        for unit_seed in args.units:
            healthy = benchmark_unit("all", unit_seed)
            truth = {name: np.array([value]) for name, value in healthy.parameters.items()}
            true_conductance = coil_conductance("condenser", unit, truth)[0]
            for seed in args.seeds:
                started = time.perf_counter()
                tree = commission(healthy, executor, seed=seed)
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
                    f" M0 true {healthy.charge:.3f} kg, read {m0.mean():.3f} ± {m0.std():.3f};"
                    f" {time.perf_counter() - started:.0f} s",
                    flush=True,
                )


if __name__ == "__main__":
    main()
