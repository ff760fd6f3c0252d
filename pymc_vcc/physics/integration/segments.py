"""Stepping an autonomous stiff ODE over one input segment: scipy's Radau or SUNDIALS CVODE.

Both solvers implement one small interface, :class:`SegmentSolver`: integrate ``dy/dt = f(y)``
from ``t0`` to ``t1``, fill the states at the output times inside the segment by the solver's
own interpolation, stop at a wall-clock deadline, count the work, and never raise: a failure is
returned as a :class:`~pymc_vcc.physics.failures.Failure` (kind and one-line detail). The caller
(:mod:`pymc_vcc.physics.simulate`) knows the model; this module knows only a
:class:`SegmentModel`: ``rhs(y, dydt) -> finite``, ``jac(y, f) -> ∂f/∂y`` and the same two as
C callbacks.

* ``radau``: scipy's 5th-order implicit Runge-Kutta, stepped from Python; the reference.
* ``cvode``: SUNDIALS CVODE (BDF of orders 1 to :data:`CVODE_MAX_ORDER`, dense direct linear
  solver, Jacobian reused across steps) from scikit-sundae's libraries, calling the model's
  Numba kernels as C callbacks (:mod:`.sundials`): its step loop, the model and the output
  interpolation all run in machine code.

The solver and its tolerances are a :class:`~pymc_vcc.physics.integration.solver.Solver`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from scipy.integrate import Radau
from scipy.linalg import get_lapack_funcs

from pymc_vcc.physics.failures import Failure, FailureKind
from pymc_vcc.physics.integration import sundials
from pymc_vcc.physics.integration.solver import Solver
from pymc_vcc.physics.integration.stops import StopPlan, segment_stops, stop_plan

CVODE_MAX_ORDER = 3
"""Highest BDF order. With orders 4 and 5 (CVODE's default) the onset of a fast transient that
starts by itself (box draw 33 of ``tests/physics/test_solvers.py``: MDOT falls 25 % within 2 s) came
1 s late, with order 3 within 0.01 s; and order 3 took 7 % fewer right-hand sides (median;
-14 % to +3 %). Measured on 31 Table III box draws (1060 s) against an rtol 1e-8 reference:
largest error 59 % (order 5) against 0.9 % (order 3) of an output's range; Radau at its default
tolerances 11 %."""


class SegmentModel(Protocol):
    """The right-hand side of one input segment, as Python callables and as C callbacks."""

    u: np.ndarray
    """The inputs the right-hand side reads: each segment's are written here."""

    def rhs(self, y: np.ndarray, dydt: np.ndarray) -> bool:
        """Write f(y) into ``dydt``; return False when it is not finite."""
        ...

    def jac(self, y: np.ndarray, f: np.ndarray) -> np.ndarray:
        """The Jacobian ∂f/∂y at ``y``, given ``f = f(y)``."""
        ...

    def c_callbacks(self) -> sundials.Callbacks:
        """The same two as C callbacks (compiled on the first call)."""
        ...

    @property
    def bad_rhs(self) -> int:
        """C right-hand sides so far that were not finite."""
        ...


def _wall_clock_failure(limit: float, t: float) -> Failure:
    """The failure of a run stopped by its wall-clock ``limit`` (s) at model time ``t`` (s)."""
    return Failure(
        FailureKind.TIME_LIMIT, f"wall-clock limit of {limit:.1f} s reached at t = {t:.1f} s"
    )


@dataclass
class Counters:
    """Work done so far, summed over segments."""

    n_rhs: int = 0
    n_jac: int = 0
    n_steps: int = 0
    bad_rhs: int = 0  # right-hand sides that were not finite (a property out of range)


class SegmentSolver(Protocol):
    """What both solvers offer the simulation driver."""

    counters: Counters
    calls_blas: bool
    """Whether its linear algebra goes through BLAS and LAPACK from Python (the driver then
    keeps BLAS on one thread for the run)."""

    def integrate(
        self,
        model: SegmentModel,
        y0: np.ndarray,
        t0: float,
        t1: float,
        t_out: np.ndarray,
        states_out: np.ndarray,
        deadline: float,
    ) -> tuple[np.ndarray, Failure | None]:
        """Integrate from ``(t0, y0)`` to ``t1``; write the state at each of ``t_out`` (sorted,
        inside ``(t0, t1]``) into the rows of ``states_out``. Return the state at ``t1`` and None
        or, on failure, the last state and the :class:`Failure`; rows not reached stay untouched.
        ``deadline`` is a ``time.perf_counter()`` value."""
        ...

    def integrate_segments(
        self,
        model: SegmentModel,
        y0: np.ndarray,
        edges: np.ndarray,
        held: np.ndarray,
        times: np.ndarray,
        states: np.ndarray,
        deadline: float,
    ) -> Failure | None:
        """Integrate from ``y0`` at ``edges[0]`` through the segments between ``edges`` (s),
        each under its row of inputs ``held`` (written into ``model.u``), restarting at each;
        write the state at each of ``times`` (sorted, in ``[edges[0], edges[-1]]``) into its row
        of ``states``. Return None or the :class:`Failure`; rows not reached stay untouched."""
        ...


def make_solver(solver: Solver, atol: np.ndarray, wall_limit: float) -> SegmentSolver:
    """A fresh segment solver running ``solver``, with the absolute tolerance of each state
    (``atol``, from the solver's by the state's kind) and the wall-clock limit (s, only named in
    failure reasons)."""
    if solver.method == "radau":
        return RadauSolver(solver.rtol, atol, solver.max_step, wall_limit)
    return CvodeSolver(solver.rtol, atol, solver.max_step, wall_limit)


class _WallClockLimit(Exception):
    """Raised from inside a right-hand side when the run passes its deadline."""


class RadauSolver:
    """scipy's Radau IIA (order 5), one step at a time, with direct LAPACK LU calls."""

    calls_blas = True

    def __init__(self, rtol: float, atol: np.ndarray, max_step: float, wall_limit: float):
        self.rtol, self.atol, self.max_step, self.wall_limit = rtol, atol, max_step, wall_limit
        self.counters = Counters()

    def integrate_segments(self, model, y0, edges, held, times, states, deadline):
        y = y0
        dydt = np.empty(y.size)
        plan = stop_plan(edges, held, times, model.u)
        for k, u in enumerate(held):
            model.u[:] = u
            if plan.start_rows[k] >= 0:
                states[plan.start_rows[k]] = y
            if not model.rhs(y, dydt):
                return _property_range_failure(float(edges[k]))
            t_out, rows = segment_stops(plan, k)
            filled = np.full((rows.size, y.size), np.nan)
            y, failure = self.integrate(
                model, y, float(edges[k]), float(edges[k + 1]), t_out, filled, deadline
            )
            states[rows] = filled
            if failure is not None:
                return failure
        return None

    def integrate(self, model, y0, t0, t1, t_out, states_out, deadline):
        counters, limit = self.counters, self.wall_limit
        rhs, jac = model.rhs, model.jac
        dydt = np.empty(y0.size)

        def fun(t, y):
            counters.n_rhs += 1
            if not rhs(y, dydt):
                counters.bad_rhs += 1
            if time.perf_counter() > deadline:  # also stops a step that never ends
                raise _WallClockLimit
            return dydt.copy()

        def jacobian(t, y):
            counters.n_jac += 1
            rhs(y, dydt)
            # columns that left the property tables are zeroed: the step-size control backs off
            return np.nan_to_num(jac(y, dydt.copy()), nan=0.0, posinf=0.0, neginf=0.0)

        try:
            solver = Radau(
                fun, t0, y0, t1, rtol=self.rtol, atol=self.atol, jac=jacobian,
                max_step=self.max_step,
            )  # fmt: skip
        except _WallClockLimit:
            return y0, _wall_clock_failure(limit, t0)
        except Exception as error:
            return y0, Failure(
                FailureKind.SOLVER,
                f"solver start at t = {t0:.1f} s: {type(error).__name__}: {error}",
            )
        _use_direct_lapack(solver)
        done = 0
        while solver.status == "running":
            try:
                message = solver.step()
            except _WallClockLimit:
                return solver.y, _wall_clock_failure(limit, solver.t)
            except Exception as error:
                reason = f"{type(error).__name__}: {error}"
                return solver.y, Failure(
                    FailureKind.SOLVER, f"solver failure at t = {solver.t:.2f} s: {reason}"
                )
            counters.n_steps += 1
            if solver.status == "failed":
                reason = message or "Radau failed"
                return solver.y, _failure(solver.t, reason, counters.bad_rhs)
            if not np.isfinite(solver.y).all():
                return solver.y, Failure(
                    FailureKind.NON_FINITE, f"non-finite state at t = {solver.t:.2f} s"
                )
            ready = done + int(np.searchsorted(t_out[done:], solver.t, side="right"))
            if ready > done:
                states_out[done:ready] = solver.dense_output()(t_out[done:ready]).T
                done = ready
            if time.perf_counter() > deadline:
                return solver.y, _wall_clock_failure(limit, solver.t)
        return solver.y, None


def _property_range_failure(t: float) -> Failure:
    """A right-hand side not finite at the start ``t`` (s) of a segment."""
    return Failure(
        FailureKind.PROPERTY_RANGE,
        f"right-hand side not finite at t = {t:.1f} s (property out of range)",
    )


def _failure(t: float, message: str, bad_rhs: int) -> Failure:
    """A solver failure at ``t`` (s), naming the right-hand sides that were not finite."""
    if bad_rhs:
        message += f" (property out of range in {bad_rhs} evaluations)"
    return Failure(FailureKind.SOLVER, f"solver failure at t = {t:.2f} s: {message}")


_LAPACK_REAL = get_lapack_funcs(("getrf", "getrs"), (np.zeros(1),))
_LAPACK_COMPLEX = get_lapack_funcs(("getrf", "getrs"), (np.zeros(1, dtype=complex),))


def _use_direct_lapack(solver: Radau) -> None:
    """Give scipy's Radau direct LAPACK getrf/getrs for its dense LU work.

    Same factorisations as ``scipy.linalg.lu_factor``/``lu_solve`` without their per-call
    argument checking, which costs more than the 46 x 46 factorisation itself.
    """

    def lu(matrix):
        solver.nlu += 1
        getrf, getrs = _LAPACK_COMPLEX if np.iscomplexobj(matrix) else _LAPACK_REAL
        factors, pivots, _ = getrf(matrix, overwrite_a=True)
        return factors, pivots, getrs

    def solve_lu(decomposition, rhs):
        factors, pivots, getrs = decomposition
        return getrs(factors, pivots, rhs)[0]

    solver.lu = lu
    solver.solve_lu = solve_lu


class CvodeSolver:
    """SUNDIALS CVODE (BDF, orders 1 to :data:`CVODE_MAX_ORDER`, dense LU) called directly, with
    the model's C callbacks (:mod:`pymc_vcc.physics.integration.sundials`).

    One CVODE instance serves every segment of a model (re-initialised at each segment's start,
    which stops it at the segment's end); the outputs come from CVODE's own interpolation in normal
    mode, so it never stops at them. One compiled loop runs every segment: it writes the
    segment's inputs, restarts CVODE, calls it for each output time and checks the state finite
    (:meth:`.sundials.Cvode.run`); Python reads the wall clock between its chunks of stops.
    """

    calls_blas = False  # SUNDIALS' own dense LU

    MAX_STEPS = 20_000
    """Internal steps allowed between two output times (a run that needs more is stuck)."""

    MIN_STEP = 1e-8
    """Smallest step, s: a step that must be shorter fails the run (as scipy's Radau does near
    10 ε t) instead of creeping towards a state where a property leaves its table."""

    def __init__(self, rtol: float, atol: np.ndarray, max_step: float, wall_limit: float):
        self.counters = Counters()
        self.wall_limit = wall_limit
        self._settings = (rtol, atol, max_step)
        self._cvode: sundials.Cvode | None = None
        self._model: SegmentModel | None = None
        self._stops: tuple[tuple, StopPlan] | None = None

    def _instance(self, model: SegmentModel) -> sundials.Cvode:
        """The CVODE instance for ``model`` (one holds the model's callbacks)."""
        if self._cvode is None or model is not self._model:
            self._model = model
            rtol, atol, max_step = self._settings
            self._cvode = sundials.Cvode(model.c_callbacks(), atol.size, rtol, atol)
            self._cvode.configure(CVODE_MAX_ORDER, self.MAX_STEPS, self.MIN_STEP, max_step)
        return self._cvode

    def _plan(self, model: SegmentModel, edges, held, times) -> StopPlan:
        """The :class:`StopPlan` of these segments and output times for ``model``: the last
        run's when they are the same (a simulator's runs share them)."""
        key = tuple((a.shape, np.ascontiguousarray(a).tobytes()) for a in (edges, held, times))
        if self._stops is None or self._stops[0] != key or self._stops[1].u is not model.u:
            self._stops = key, stop_plan(edges, held, times, model.u)
        return self._stops[1]

    def integrate_segments(self, model, y0, edges, held, times, states, deadline):
        cvode = self._instance(model)
        plan = self._plan(model, edges, held, times)
        done, flag, finite, late = cvode.run(y0, plan, states, deadline)
        n_steps, n_rhs, n_jac = cvode.statistics()
        self.counters.n_steps += n_steps
        self.counters.n_rhs += n_rhs
        self.counters.n_jac += n_jac
        self.counters.bad_rhs = model.bad_rhs
        if late:
            return _wall_clock_failure(self.wall_limit, cvode.t)
        if flag == sundials.CV_FIRST_RHSFUNC_ERR:
            return _property_range_failure(cvode.t)
        if flag < 0:
            return _failure(cvode.t, sundials.flag_name(flag), model.bad_rhs)
        if not finite:
            return Failure(
                FailureKind.NON_FINITE, f"non-finite state at t = {plan.times[done]:.2f} s"
            )
        return None

    def integrate(self, model, y0, t0, t1, t_out, states_out, deadline):
        edges = np.array([t0, t1])
        failure = self.integrate_segments(
            model, y0, edges, model.u[None], t_out, states_out, deadline
        )
        return self._instance(model).y.copy(), failure
