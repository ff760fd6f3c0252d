"""Sampler speed: overhead per simulation, and parallel speed-up with a 50 ms simulator.

Overhead: ABC rejection on a trivial simulator (a 10-point Gaussian draw), wall time per
simulation minus the simulator's own time per call; targets < 0.5 ms. Speed-up: the same run
with a 50 ms simulator, serial against 2 local worker processes and a local Dask cluster of 2
single-threaded workers (executors started before timing); target ≥ 1.8× for processes. Two
50 ms simulators: ``cpu`` spends 50 ms of CPU (its speed-up needs 2 idle cores), ``sleep``
waits 50 ms (its speed-up measures the executors alone, whatever else loads the machine).
Overheads are medians over repetitions; the load average is reported beside the figures.
"""

from __future__ import annotations

import os
import statistics
import time

import numpy as np

from pymc_vcc.execution.executors import Executor, ExecutorKind, make_executor
from pymc_vcc.execution.options import RunOptions
from pymc_vcc.inference.priors import UniformPrior
from pymc_vcc.inference.rejection import abc_rejection
from pymc_vcc.testing import GaussianLocation, Slow

MODEL = GaussianLocation(n_time=10)
PRIOR = UniformPrior(MODEL.bounds)
OBSERVED = MODEL({"mu": 0.5}, np.random.default_rng(0))


def _seconds_per_simulation(
    simulator: object,
    executor: Executor | ExecutorKind,
    n_pilot: int,
    n_main: int,
    **options: object,
) -> float:
    start = time.perf_counter()
    tree = abc_rejection(
        simulator,
        PRIOR,
        OBSERVED,
        n_pilot=n_pilot,
        quantile=0.1,
        n_main=n_main,
        n_desired=n_main,
        run=RunOptions(executor=executor, seed=1, progress=False),
        **options,
    )
    return (time.perf_counter() - start) / int(tree.sample_stats["n_simulations"])


def _simulator_seconds(calls: int) -> float:
    rng = np.random.default_rng(0)
    start = time.perf_counter()
    for _ in range(calls):
        MODEL({"mu": 0.5}, rng)
    return (time.perf_counter() - start) / calls


def run(quick: bool) -> dict[str, float | int | str]:
    """Measure; ``quick`` uses fewer simulations and repetitions."""
    repeats = 1 if quick else 3
    n_pilot, n_main = (500, 5000) if quick else (2000, 20000)
    results: dict[str, float | int | str] = {"sampler_load_average_1min": os.getloadavg()[0]}
    alone = statistics.median(_simulator_seconds(20000) for _ in range(3))
    serial = statistics.median(
        _seconds_per_simulation(MODEL, "serial", n_pilot, n_main, distance=MODEL.distance)
        for _ in range(repeats)
    )
    serial_ks = statistics.median(
        _seconds_per_simulation(MODEL, "serial", n_pilot, n_main) for _ in range(repeats)
    )
    results["sampler_simulator_alone_ms"] = round(alone * 1e3, 4)
    results["sampler_overhead_per_sim_serial_ms"] = round((serial - alone) * 1e3, 4)
    results["sampler_overhead_per_sim_serial_ks_ms"] = round((serial_ks - alone) * 1e3, 4)

    n_slow_pilot, n_slow_main = (20, 40) if quick else (40, 160)
    n_workers = 2
    simulators = {"cpu": Slow(MODEL, 0.05, busy=True), "sleep": Slow(MODEL, 0.05, busy=False)}
    timings: dict[tuple[str, str], float] = {}
    for load, slow in simulators.items():
        timings["serial", load] = _seconds_per_simulation(slow, "serial", n_slow_pilot, n_slow_main)
    for kind in ("processes", "dask"):
        with make_executor(kind, n_workers=n_workers) as executor:
            _seconds_per_simulation(MODEL, executor, 50, 100)  # start and warm the workers
            if kind == "processes":
                results["sampler_overhead_per_sim_processes_ms"] = round(
                    _seconds_per_simulation(
                        MODEL, executor, n_pilot, n_main, distance=MODEL.distance
                    )
                    * 1e3,
                    4,
                )
            for load, slow in simulators.items():
                timings[kind, load] = _seconds_per_simulation(
                    slow, executor, n_slow_pilot, n_slow_main
                )
    for load in simulators:
        results[f"sampler_50ms_{load}_serial_s_per_sim"] = round(timings["serial", load], 4)
        for kind in ("processes", "dask"):
            results[f"sampler_50ms_{load}_{kind}_s_per_sim"] = round(timings[kind, load], 4)
            results[f"sampler_speedup_{load}_{kind}_{n_workers}_workers"] = round(
                timings["serial", load] / timings[kind, load], 3
            )
    return results
