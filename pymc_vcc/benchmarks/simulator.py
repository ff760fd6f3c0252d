"""Speed and robustness of the dynamic cycle simulator.

* ``sim_seconds_median``: one 1060 s simulation of the built-in profile at nominal parameters,
  one process, median after a warm-up run;
* ``sims_per_second`` and ``failure_rate``: 1060 s simulations of uniform draws from the Table
  III box on all cores (a process pool), with the failure kinds counted.
"""

from __future__ import annotations

import multiprocessing
import os
import time
from collections import Counter
from statistics import median

import numpy as np

from pymc_vcc.physics.simulate import VCCSimulator
from pymc_vcc.physics.unit import load_unit

T_WINDOW = (0.0, 1060.0)

_simulator: VCCSimulator | None = None


def _init_worker() -> None:
    global _simulator
    _simulator = VCCSimulator(t_window=T_WINDOW)


def _run_draw(theta: dict[str, float]) -> str:
    """The draw's failure kind (:class:`~pymc_vcc.physics.failures.FailureKind`), "" if ok."""
    assert _simulator is not None
    return _simulator(theta, None).attrs["failure_kind"]


def run(quick: bool) -> dict[str, float | int | str]:
    """Timings of nominal runs and a box sweep; ``quick`` uses 5 repeats and 20 draws."""
    simulator = VCCSimulator(t_window=T_WINDOW)
    simulator({}, None)  # warm-up: compile or load the cached kernels
    times, result = [], None
    for _ in range(5 if quick else 7):
        start = time.perf_counter()
        result = simulator({}, None)
        times.append(time.perf_counter() - start)
    assert result is not None
    attrs = result.attrs

    n_draws = 20 if quick else 200
    draws = load_unit().parameters.sample_uniform(n_draws, np.random.default_rng(12345))
    workers = os.cpu_count() or 1
    context = multiprocessing.get_context("fork")
    start = time.perf_counter()
    with context.Pool(workers, initializer=_init_worker) as pool:
        outcomes = pool.map(_run_draw, draws, chunksize=1)
    elapsed = time.perf_counter() - start
    reasons = Counter(kind for kind in outcomes if kind)
    failures = sum(reasons.values())
    return {
        "sim_seconds_median": median(times),
        "sim_seconds_min": min(times),
        "n_states": int(attrs["n_states"]),
        "rhs_evals": int(attrs["n_rhs"]),
        "jac_evals": int(attrs["n_jac"]),
        "solver_steps": int(attrs["n_steps"]),
        "mass_error_nominal": float(attrs["mass_error"]),
        "source_integral_kg": float(attrs["source_integral"]),
        "box_draws": n_draws,
        "workers": workers,
        "sims_per_second": n_draws / elapsed,
        "failure_rate": failures / n_draws,
        "failure_reasons": "; ".join(f"{count} x {kind}" for kind, count in reasons.items()),
    }
