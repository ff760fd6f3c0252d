"""Speed and robustness of the dynamic cycle simulator, every ODE solver side by side.

For each solver of :data:`~pymc_vcc.physics.integration.solver.METHODS` (``_<solver>`` suffix):

* ``sim_seconds_median``/``_min`` (wall) and ``sim_cpu_seconds_median`` (process CPU time, steadier
  on a shared machine): one 1060 s simulation of the built-in profile at nominal parameters, in
  a fresh process, after a warm-up run; its ``rhs_evals``, ``jac_evals`` and ``solver_steps``;
* ``sims_per_second`` and ``failure_rate``: 1060 s simulations of uniform draws from the Table
  III box on all cores (a process pool), with the failure kinds counted, and
  ``sims_per_cpu_second`` (draws over the CPU time the workers spent on them: what one idle core
  would do, whatever else the machine runs).

Then ``speedup_<solver>`` (Radau's median over the solver's), ``parallel_speedup_<fastest>`` (the
box sweep on all cores over the same sweep on one; meaningful only on an otherwise idle
machine, so ``load_average`` (1 min, at the start) is reported beside it), and, unsuffixed as
before, the default solver's figures.

What the model itself costs, with no solver (:func:`_model_costs`): ``model_rhs_us``,
``model_jacobian_ms`` and ``model_outputs_ms`` (the outputs on the whole grid), and per solver
``model_share_<solver>``: those costs times the run's right-hand sides and Jacobians, plus the
outputs, over the run's CPU time. The rest is the solver and Python.
"""

from __future__ import annotations

import multiprocessing
import os
import time
from collections import Counter
from collections.abc import Callable
from statistics import median
from typing import Any

import numpy as np

from pymc_vcc.physics.inputs import CALIBRATION_SECONDS, builtin_inputs, input_segments
from pymc_vcc.physics.integration.callbacks import BoundCycle
from pymc_vcc.physics.integration.solver import METHODS, get_solver
from pymc_vcc.physics.refrigerant import load_refrigerant
from pymc_vcc.physics.simulate import VCCSimulator, simulate
from pymc_vcc.physics.unit import load_unit

T_WINDOW = (0.0, CALIBRATION_SECONDS)

_simulator: VCCSimulator | None = None
_start_line: Any = None  # a multiprocessing Barrier shared by the sweep's workers


def _init_worker(solver: str, start_line: Any) -> None:
    global _simulator, _start_line
    _simulator = VCCSimulator(t_window=T_WINDOW, solver=solver)
    # warm-up, as for the nominal runs: a worker's first simulation also starts thread pools
    # (0.32 s of CPU in 0.20 s of wall time, where later ones take 0.08 s of each)
    _simulator({}, None)
    _start_line = start_line


def _wait_at_start_line(_: int) -> None:
    """Block until every worker has started (and loaded the kernels): one such task each."""
    _start_line.wait()


def _run_draw(theta: dict[str, float]) -> tuple[str, float]:
    """The draw's failure kind (:class:`~pymc_vcc.physics.failures.FailureKind`, "" if ok) and
    the CPU time it took, s."""
    assert _simulator is not None
    start = time.process_time()
    kind = _simulator(theta, None).attrs["failure_kind"]
    return kind, time.process_time() - start


def _nominal(solver: str, repeats: int) -> dict[str, float | int]:
    simulator = VCCSimulator(t_window=T_WINDOW, solver=solver)
    simulator({}, None)  # warm-up: compile or load the cached kernels
    wall, cpu, result = [], [], None
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        result = simulator({}, None)
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    assert result is not None
    attrs = result.attrs
    return {
        "sim_seconds_median": median(wall),
        "sim_seconds_min": min(wall),
        "sim_cpu_seconds_median": median(cpu),
        "rhs_evals": int(attrs["n_rhs"]),
        "jac_evals": int(attrs["n_jac"]),
        "solver_steps": int(attrs["n_steps"]),
        "mass_error_nominal": float(attrs["mass_error"]),
        "source_integral_kg": float(attrs["source_integral"]),
        "n_states": int(attrs["n_states"]),
    }


def _fresh[R](function: Callable[..., R], *arguments: Any) -> R:
    """``function(*arguments)`` in a new process: a timing that no earlier run disturbs (after
    Radau's runs OpenBLAS's threads spun on, and a CVODE run timed next took twice its wall
    time in CPU)."""
    with multiprocessing.get_context("spawn").Pool(1) as pool:
        return pool.apply(function, arguments)


def _model_costs() -> dict[str, float]:
    """What the cycle's kernels cost without any solver, over the states of a nominal CVODE
    run: a right-hand side (µs, mean over the 1061 grid states), a Jacobian (ms, every 20th
    state) and the outputs on the whole grid (ms), each the median of 5 repeats."""
    unit = load_unit()
    run = simulate(unit, t_end=T_WINDOW[1], solver="cvode", states=True)
    model = unit.cycle_model
    tables = load_refrigerant(unit.refrigerant).tables
    c = model.constants(unit, unit.parameters.nominal)
    states = np.ascontiguousarray(run["states"].values)
    edges, held = input_segments(builtin_inputs())
    inputs = held[np.clip(np.searchsorted(edges, run["time"].values, side="right") - 1, 0, None)]
    cycle = BoundCycle(model, states[0], inputs[0], c, tables)
    dydt = np.empty(states.shape[1])
    timings: dict[str, list[float]] = {"rhs": [], "jacobian": [], "outputs": []}
    for _ in range(5):
        start = time.perf_counter()
        for y, u in zip(states, inputs, strict=True):
            cycle.u[:] = u
            cycle.rhs(y, dydt)
        timings["rhs"].append((time.perf_counter() - start) / len(states) * 1e6)
        start = time.perf_counter()
        for y, u in zip(states[::20], inputs[::20], strict=True):
            cycle.u[:] = u
            cycle.jac(y, dydt)  # f(y) only enters the differences: any vector costs the same
        timings["jacobian"].append((time.perf_counter() - start) / len(states[::20]) * 1e3)
        start = time.perf_counter()
        model.outputs_along(states, inputs, c, tables, False)
        timings["outputs"].append((time.perf_counter() - start) * 1e3)
    return {
        "model_rhs_us": median(timings["rhs"]),
        "model_jacobian_ms": median(timings["jacobian"]),
        "model_outputs_ms": median(timings["outputs"]),
    }


def _sweep(solver: str, draws: list[dict[str, float]], workers: int) -> dict[str, float | str]:
    context = multiprocessing.get_context("fork")
    start_line = context.Barrier(workers)
    with context.Pool(workers, initializer=_init_worker, initargs=(solver, start_line)) as pool:
        # the clock starts once all workers are up and warm: starting them (1.2 s) is not
        # throughput, and with 0.1 s simulations it was a tenth of a 2-worker sweep
        pool.map(_wait_at_start_line, range(workers), chunksize=1)
        start = time.perf_counter()
        outcomes = pool.map(_run_draw, draws, chunksize=1)
        elapsed = time.perf_counter() - start
    reasons = Counter(kind for kind, _ in outcomes if kind)
    return {
        "sims_per_second": len(draws) / elapsed,
        "sims_per_cpu_second": len(draws) / sum(cpu for _, cpu in outcomes),
        "failure_rate": sum(reasons.values()) / len(draws),
        "failure_reasons": "; ".join(f"{count} x {kind}" for kind, count in reasons.items()),
    }


def run(quick: bool) -> dict[str, float | int | str]:
    """Timings of nominal runs and a box sweep per solver; ``quick``: 5 repeats, 20 draws."""
    unit = load_unit()
    n_draws = 20 if quick else 200
    draws = unit.parameters.sample_uniform(n_draws, np.random.default_rng(12345))
    workers = os.cpu_count() or 1
    results: dict[str, float | int | str] = {
        "box_draws": n_draws,
        "workers": workers,
        "load_average": os.getloadavg()[0],
    }
    per_solver = {}
    for solver in METHODS:
        figures = _fresh(_nominal, solver, 5 if quick else 7) | _sweep(solver, draws, workers)
        per_solver[solver] = figures
        results |= {f"{key}_{solver}": value for key, value in figures.items()}
    reference = per_solver["radau"]["sim_seconds_median"]
    costs = _model_costs()
    results |= costs
    for solver, figures in per_solver.items():
        results[f"speedup_{solver}"] = reference / figures["sim_seconds_median"]
        model_seconds = 1e-3 * (
            costs["model_rhs_us"] * 1e-3 * float(figures["rhs_evals"])
            + costs["model_jacobian_ms"] * float(figures["jac_evals"])
            + costs["model_outputs_ms"]
        )
        results[f"model_share_{solver}"] = model_seconds / float(figures["sim_cpu_seconds_median"])
    fastest = min(per_solver, key=lambda name: per_solver[name]["sim_seconds_median"])
    one_core = _sweep(fastest, draws, 1)["sims_per_second"]
    results[f"parallel_speedup_{fastest}"] = per_solver[fastest]["sims_per_second"] / one_core
    return results | per_solver[get_solver().method]


SIDE_BY_SIDE = (
    "sim_seconds_median",
    "sim_seconds_min",
    "sim_cpu_seconds_median",
    "rhs_evals",
    "jac_evals",
    "solver_steps",
    "sims_per_second",
    "sims_per_cpu_second",
    "failure_rate",
    "speedup",
    "model_share",
)
"""Figures shown as one row per figure and one column per solver."""


def format_table(results: dict[str, float | int | str]) -> str:
    """The per-solver figures of ``results`` side by side (figures as rows, solvers as columns)."""
    lines = [f"  {'':24s}" + "".join(f"{solver:>12s}" for solver in METHODS)]
    for key in SIDE_BY_SIDE:
        cells = [results.get(f"{key}_{solver}", "") for solver in METHODS]
        lines.append(
            f"  {key:24s}"
            + "".join(
                f"{cell:12.4g}" if isinstance(cell, float) else f"{cell!s:>12s}" for cell in cells
            )
        )
    return "\n".join(lines)
