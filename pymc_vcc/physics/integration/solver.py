"""Which stiff solver integrates a simulation, and at which tolerances: a :class:`Solver`.

``simulate(..., solver=...)`` takes a :class:`Solver` or the name of a method, which stands for
that method's default (:data:`DEFAULT_SOLVERS`), as ``diffeqsolve`` takes a solver and a
step-size controller; the unit description holds only the unit's physics.

* ``radau``: scipy's 5th-order implicit Runge-Kutta, stepped from Python; the reference.
* ``cvode``: SUNDIALS CVODE (BDF), its step loop and the model in machine code; faster.

At equal tolerances BDF's error control lets more global error through than Radau's, so CVODE's
default runs at a tenth of Radau's rtol and a hundredth of its atols. The relative tolerance sets
how close the outputs come, the absolute ones (pressures, enthalpies) how well the total mass
holds (``docs/results/bench.md``: "The two solvers' accuracy").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

METHODS: tuple[str, ...] = ("radau", "cvode")
"""Solver methods: the names ``simulate(solver=...)`` and ``--solver`` on the command line
accept."""


@dataclass(frozen=True)
class Solver:
    """A stiff ODE solver and the tolerances it runs at, SI units.

    Start from a method's default and change what differs: ``get_solver("cvode", rtol=1e-6)``.

    Attributes
    ----------
    method
        ``"radau"`` or ``"cvode"`` (:data:`METHODS`).
    rtol
        Relative tolerance, -.
    atol_pressure, atol_enthalpy, atol_temperature, atol_integral
        Absolute tolerances of the pressure (Pa), enthalpy (J/kg), temperature (K) and
        controller-integral (kg s) states.
    max_step
        Largest step, s.
    """

    method: str
    rtol: float
    atol_pressure: float  # Pa
    atol_enthalpy: float  # J/kg
    atol_temperature: float  # K
    atol_integral: float  # kg s
    max_step: float  # s

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"solver method must be one of {list(METHODS)}, got {self.method!r}")
        for name in _NUMBERS:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"solver {name}: expected a number, got {value!r}")
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"solver {name}: expected a finite positive number, got {value!r}")

    def scaled(self, factor: float) -> Solver:
        """The same solver with its rtol and every atol ``factor`` times these (the largest
        step unchanged), e.g.
        :data:`DIFFERENCING_TOLERANCE_SCALE` for simulations whose outputs are differenced."""
        if not factor > 0:
            raise ValueError(f"tolerance scale must be positive, got {factor}")
        return replace(self, **{name: factor * getattr(self, name) for name in _TOLERANCES})

    def __str__(self) -> str:
        """The method's name at its default, else every field (``cvode (rtol=1e-06, ...)``)."""
        if self == DEFAULT_SOLVERS[self.method]:
            return self.method
        values = ", ".join(f"{name}={getattr(self, name):g}" for name in _NUMBERS)
        return f"{self.method} ({values})"


_NUMBERS = tuple(f.name for f in fields(Solver) if f.name != "method")
_ATOLS = tuple(name for name in _NUMBERS if name.startswith("atol_"))
_TOLERANCES = ("rtol", *_ATOLS)

RADAU = Solver(
    "radau", rtol=1e-4, atol_pressure=20.0, atol_enthalpy=5.0, atol_temperature=0.01,
    atol_integral=1e-4, max_step=60.0,
)  # fmt: skip
"""Radau's default. With the enthalpy atol at 5 J/kg the total mass holds within 1e-4 of M0
over 200 box draws (one draw's start-up reached 1.2e-4 at 10 J/kg, 2.5e-5 at 5 J/kg;
``models/README.md``)."""

CVODE_RTOL_SCALE = 0.1
"""CVODE's default rtol as a fraction of Radau's. Over nominal and 40 box draws (1060 s, against
CVODE at a thousandth of Radau's default tolerances) the largest error is 1.2e-3 of an output's
range at the median and 3.3e-3 at the 90th percentile, against Radau's 2.0e-3 and 6.6e-3; at
0.2 × it is Radau's (2.1e-3, 6.8e-3)."""

CVODE_ATOL_SCALE = 0.01
"""CVODE's default atols as a fraction of Radau's. Over 200 box draws (seed 2026, 1060 s) the
total mass stays within 7.8e-5 of M0 (median 1.7e-5), as with both scales at 0.03 × (7.8e-5,
median 9.3e-6), which took 14 % more right-hand sides; with the atols at 0.03 × and the rtol at
0.1 × it drifted up to 1.6e-4 over 100 of them, with both at 0.1 × up to 3.7e-4."""

CVODE = Solver(
    "cvode",
    rtol=CVODE_RTOL_SCALE * RADAU.rtol,
    **{name: CVODE_ATOL_SCALE * getattr(RADAU, name) for name in _ATOLS},
    max_step=RADAU.max_step,
)
"""CVODE's default: :data:`CVODE_RTOL_SCALE` times Radau's rtol, :data:`CVODE_ATOL_SCALE` times
its atols (at equal tolerances BDF's error control lets more global error through)."""

DEFAULT_SOLVERS: dict[str, Solver] = {solver.method: solver for solver in (RADAU, CVODE)}
"""Each method's default solver, by name."""

DIFFERENCING_TOLERANCE_SCALE = 0.1
"""Solver tolerances, as a fraction of the default's, for simulations whose outputs are
differenced (``identifiability``'s central differences of 0.1 prior sd): a looser solver's
error passes for information. Measured with CVODE at M0 = 1.4 over 200 s: the CF_PREF-CF_POW
direction's expected sd ratio came out 0.53 at the default tolerances, 0.972 at 0.1 × them
(0.974 with CVODE ten times tighter still)."""


def get_solver(solver: str | Solver | None = None, **changes: float) -> Solver:
    """The :class:`Solver` ``solver`` stands for, with ``changes``, checked to run here.

    Args:
        solver: a method name (:data:`METHODS`: that method's default, :data:`RADAU` or
            :data:`CVODE`), a :class:`Solver` (itself), or None (:data:`RADAU`).
        **changes: fields to change (``rtol``, ``atol_pressure``, ..., ``max_step``).

    Raises:
        ValueError: an unknown method name or field (the message names the allowed ones).
        ImportError: CVODE's libraries do not fit this machine (see ``integration.sundials``).
    """
    if solver is None:
        solver = RADAU
    elif isinstance(solver, str):
        if solver not in DEFAULT_SOLVERS:
            raise ValueError(f"solver must be one of {list(METHODS)}, got {solver!r}")
        solver = DEFAULT_SOLVERS[solver]
    elif not isinstance(solver, Solver):
        raise TypeError(f"solver must be a method name or a Solver, got {solver!r}")
    if unknown := sorted(set(changes) - set(_NUMBERS)):
        raise ValueError(f"unknown solver field(s) {unknown}; allowed are {list(_NUMBERS)}")
    if changes:
        values: dict[str, Any] = dict(changes)
        solver = replace(solver, **values)
    if solver.method == "cvode":
        from pymc_vcc.physics.integration import sundials

        sundials.library()
    return solver
