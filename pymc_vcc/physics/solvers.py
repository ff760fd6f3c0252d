"""Stepping an autonomous stiff ODE over one input segment: scipy's Radau or SUNDIALS CVODE.

Both solvers implement one small interface, :class:`SegmentSolver`: integrate ``dy/dt = f(y)``
from ``t0`` to ``t1``, fill the states at the output times inside the segment by the solver's
own interpolation, stop at a wall-clock deadline, count the work, and never raise: a failure is
returned as a :class:`~pymc_vcc.physics.failures.Failure` (kind and one-line detail). The caller
(:mod:`pymc_vcc.physics.simulate`) knows the model; this module knows only
``rhs(y, dydt) -> finite`` and ``jac(y, f) -> ∂f/∂y``.

* ``radau``: scipy's 5th-order implicit Runge-Kutta, stepped from Python; the reference.
* ``cvode``: SUNDIALS CVODE (BDF of orders 1 to :data:`CVODE_MAX_ORDER`, dense direct linear
  solver, Jacobian reused across steps) through ``scikit-sundae``; its whole step loop and the
  output interpolation run in C, so the model's kernels dominate the cost.

At equal tolerances BDF's error control lets more global error through than Radau's, so CVODE
runs at :data:`CVODE_TOLERANCE_SCALE` times the unit's tolerances. Against an rtol 1e-8
reference (1060 s of the Fig. 4 profile, largest error as a fraction of each output's range)
that makes it as accurate as Radau or more: 1.2e-3 against Radau's 6.9e-3 at nominal, closer
than Radau on 28 of 31 box draws; at 0.1 times (order 5) it was up to 4 times further than
Radau on a draw (2.0e-2 against 5.0e-3).
"""

from __future__ import annotations

import contextlib
import io
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from scipy.integrate import Radau
from scipy.linalg import get_lapack_funcs

from pymc_vcc.physics.failures import Failure, FailureKind

METHODS: tuple[str, ...] = ("radau", "cvode")
"""Solver names accepted by ``[solver] method`` in a unit file, ``simulate(solver=...)`` and
``--solver`` on the command line."""

CVODE_TOLERANCE_SCALE = 0.03
"""CVODE's rtol and atol as a fraction of the unit's (see the module docstring)."""

CVODE_MAX_ORDER = 3
"""Highest BDF order. With orders 4 and 5 (CVODE's default) the onset of a fast transient that
starts by itself (box draw 33 of ``tests/test_solvers.py``: MDOT falls 25 % within 2 s) came
1 s late, with order 3 within 0.01 s; and order 3 took 7 % fewer right-hand sides (median;
-14 % to +3 %). Measured on 31 Table III box draws (1060 s) against an rtol 1e-8 reference:
largest error 59 % (order 5) against 0.9 % (order 3) of an output's range; Radau at the unit's
tolerances 11 %."""

Rhs = Callable[[np.ndarray, np.ndarray], bool]
"""``rhs(y, dydt)``: write f(y) into ``dydt``; return False when it is not finite."""

Jac = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``jac(y, f)``: the Jacobian ∂f/∂y at ``y``, given ``f = f(y)``."""


def _wall_clock_failure(limit: float, t: float) -> Failure:
    """The failure of a run stopped by its wall-clock ``limit`` (s) at model time ``t`` (s)."""
    return Failure(
        FailureKind.WALL_CLOCK, f"wall-clock limit of {limit:.1f} s reached at t = {t:.1f} s"
    )


@dataclass
class Counters:
    """Work done so far, summed over segments.

    ``n_steps`` is -1 for CVODE: scikit-sundae does not report its internal step count.
    """

    n_rhs: int = 0
    n_jac: int = 0
    n_steps: int = 0
    bad_rhs: int = 0  # right-hand sides that were not finite (a property out of range)


class SegmentSolver(Protocol):
    """What both solvers offer the simulation driver."""

    counters: Counters

    def integrate(
        self,
        rhs: Rhs,
        jac: Jac,
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


def make_solver(
    method: str, rtol: float, atol: np.ndarray, max_step: float, wall_limit: float
) -> SegmentSolver:
    """A fresh solver called ``method`` (one of :data:`METHODS`) with these tolerances, the
    largest step (s) and the wall-clock limit (s, only named in failure reasons)."""
    if method == "radau":
        return RadauSolver(rtol, atol, max_step, wall_limit)
    if method == "cvode":
        return CvodeSolver(rtol, atol, max_step, wall_limit)
    raise ValueError(f"solver method must be one of {list(METHODS)}, got {method!r}")


_HUGE = 1e30
"""Stands in for a non-finite derivative in CVODE, so that the step fails and is retried."""


class _WallClockLimit(Exception):
    """Raised from inside a right-hand side when the run passes its deadline."""


def _clean(matrix: np.ndarray) -> np.ndarray:
    """Columns that left the property tables are zeroed: the step-size control backs off."""
    return np.nan_to_num(matrix, nan=0.0, posinf=0.0, neginf=0.0)


class RadauSolver:
    """scipy's Radau IIA (order 5), one step at a time, with direct LAPACK LU calls."""

    def __init__(self, rtol: float, atol: np.ndarray, max_step: float, wall_limit: float):
        self.rtol, self.atol, self.max_step, self.wall_limit = rtol, atol, max_step, wall_limit
        self.counters = Counters()

    def integrate(self, rhs, jac, y0, t0, t1, t_out, states_out, deadline):
        counters, limit = self.counters, self.wall_limit
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
            return _clean(jac(y, dydt.copy()))

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
                return solver.y, _failure(solver.t, message or "Radau failed", counters)
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


def _failure(t: float, message: str, counters: Counters) -> Failure:
    if counters.bad_rhs:
        message += f" (property out of range in {counters.bad_rhs} evaluations)"
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
    """SUNDIALS CVODE (BDF, orders 1 to :data:`CVODE_MAX_ORDER`, dense LU) through scikit-sundae.

    One CVODE instance serves every segment (re-initialised at each segment's start); the
    outputs come from CVODE's own interpolation in normal mode, so it never stops at them.
    """

    MAX_STEPS = 20_000
    """Internal steps allowed between two output times (a run that needs more is stuck)."""

    MIN_STEP = 1e-8
    """Smallest step, s: a step that must be shorter fails the run (as scipy's Radau does near
    10 ε t) instead of creeping towards a state where a property leaves its table."""

    def __init__(self, rtol: float, atol: np.ndarray, max_step: float, wall_limit: float):
        from sksundae.cvode import CVODE

        self.counters = Counters(n_steps=-1)
        self.wall_limit = wall_limit
        self._rhs: Rhs | None = None
        self._jac: Jac | None = None
        self._deadline = 0.0
        self._t = 0.0  # time of the latest right-hand side, s
        # CVODE hands read-only views of its vectors; the model gets writable copies, so the
        # Numba kernels are compiled (and cached) for one array type only
        self._y = np.empty(atol.size)
        self._f = np.empty(atol.size)
        self._cvode = CVODE(
            self._rhs_callback,
            jacfn=self._jac_callback,
            rtol=rtol * CVODE_TOLERANCE_SCALE,
            atol=atol * CVODE_TOLERANCE_SCALE,
            max_step=max_step,
            min_step=self.MIN_STEP,
            max_num_steps=self.MAX_STEPS,
            max_order=CVODE_MAX_ORDER,
        )

    def _rhs_callback(self, t: float, y: np.ndarray, dydt: np.ndarray) -> None:
        self.counters.n_rhs += 1
        self._t = t
        self._y[:] = y
        assert self._rhs is not None, "integrate() sets the model before CVODE calls back"
        if not self._rhs(self._y, dydt):
            # scikit-sundae cannot pass CVODE a recoverable error, and CVODE's tests let NaN
            # through: a huge finite derivative fails the step, which is retried shorter
            self.counters.bad_rhs += 1
            np.nan_to_num(dydt, copy=False, nan=_HUGE, posinf=_HUGE, neginf=-_HUGE)
        if time.perf_counter() > self._deadline:
            raise _WallClockLimit

    def _jac_callback(self, t: float, y: np.ndarray, f: np.ndarray, matrix: np.ndarray) -> None:
        self.counters.n_jac += 1
        self._y[:] = y
        self._f[:] = f
        assert self._jac is not None, "integrate() sets the model before CVODE calls back"
        matrix[:, :] = _clean(self._jac(self._y, self._f))

    def integrate(self, rhs, jac, y0, t0, t1, t_out, states_out, deadline):
        self._rhs, self._jac, self._deadline = rhs, jac, deadline
        ends_on_output = t_out.size > 0 and t_out[-1] == t1
        tspan = np.concatenate(([t0], t_out, [] if ends_on_output else [t1]))
        try:
            # scikit-sundae prints SUNDIALS' failures; the run's failure reason carries them
            with contextlib.redirect_stdout(io.StringIO()):
                result = self._cvode.solve(tspan, y0)
        except _WallClockLimit:
            return y0, _wall_clock_failure(self.wall_limit, self._t)
        except Exception as error:
            return y0, Failure(
                FailureKind.SOLVER,
                f"solver failure after t = {t0:.2f} s: {type(error).__name__}: {error}",
            )
        if tspan.size == 2:  # scikit-sundae then returns every internal step: keep t1 only
            rows = result.y[-1:] if result.success else result.y[:0]
        else:  # the output times reached, then t1 (on failure: where it stopped, dropped)
            rows = result.y[1 : len(result.t) - (not result.success)]
        reached = min(len(rows), t_out.size)
        states_out[:reached] = rows[:reached]
        y_end = result.y[-1]
        finite = np.isfinite(result.y).all(axis=1)
        if not finite.all():
            return y_end, Failure(
                FailureKind.NON_FINITE,
                f"non-finite state at t = {result.t[np.argmin(finite)]:.2f} s",
            )
        if not result.success:
            return y_end, _failure(float(result.t[-1]), result.message, self.counters)
        return y_end, None
