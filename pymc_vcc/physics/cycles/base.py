"""What every cycle model provides, and the Numba kernels that need no topology.

A cycle model (one module per topology) owns its parameter table, inputs, outputs and
diagnostics, and one :class:`StateLayout` built from named blocks. The layout fixes every offset
once; Numba reads them from the layout's record (``c.layout.<block>``), never from a number
written in the code. A pressure zone is a ``PRESSURE`` block followed by the ``ENTHALPY``
blocks of its cells in flow order, so cell properties, total mass and the columns of the
Jacobian follow from the layout alone.

The driver (:mod:`pymc_vcc.physics.simulate`) integrates any :class:`CycleModel` through its
Numba kernels ``evaluate``, ``jacobian``, ``outputs_along`` and ``total_mass``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING, ClassVar

import numpy as np
from numba import njit
from scipy.optimize import brentq

from pymc_vcc.physics.components.density import cell_state, cell_values, fillet_memo
from pymc_vcc.physics.records import make_record
from pymc_vcc.physics.refrigerant import saturation_point, saturation_state

if TYPE_CHECKING:
    from pymc_vcc.physics.integration.solver import Solver
    from pymc_vcc.physics.unit import Unit

N_PROPERTIES = 5
"""Rows of a cell-property array: T (K), ρ (kg/m³), ∂ρ/∂p, ∂ρ/∂h, quality."""


class BlockKind(StrEnum):
    """What a block of the state holds; sets its tolerance and its role in a zone."""

    PRESSURE = "pressure"  # the pressure of a zone, Pa; the zone's cell enthalpies follow it
    ENTHALPY = "enthalpy"  # refrigerant cell enthalpies, J/kg
    TEMPERATURE = "temperature"  # wall temperatures, K
    INTEGRAL = "integral"  # controller integral, kg s


BLOCK_UNITS = {
    BlockKind.PRESSURE: "Pa",
    BlockKind.ENTHALPY: "J/kg",
    BlockKind.TEMPERATURE: "K",
    BlockKind.INTEGRAL: "kg s",
}
"""The SI unit of each kind of state block."""


@dataclass(frozen=True)
class Block:
    """A named, contiguous part of the state vector."""

    name: str
    size: int
    kind: BlockKind


class StateLayout:
    """The state vector as named blocks: offsets computed once, handed to Numba as a record."""

    def __init__(self, blocks: Sequence[Block]) -> None:
        names = [block.name for block in blocks]
        if len(set(names)) != len(names) or {"size", "zones"} & set(names):
            raise ValueError(f"state blocks need distinct names other than size, zones: {names}")
        self.blocks: tuple[Block, ...] = tuple(blocks)
        self._blocks = {block.name: block for block in self.blocks}
        self._start: dict[str, int] = {}
        zones: list[list[int]] = []
        offset = 0
        previous: BlockKind | None = None
        for block in self.blocks:
            if block.size < 1:
                raise ValueError(f"state block {block.name!r}: size must be >= 1")
            if block.kind is BlockKind.PRESSURE:
                if block.size != 1:
                    raise ValueError(f"pressure block {block.name!r} must have size 1")
                zones.append([offset, 0])
            elif block.kind is BlockKind.ENTHALPY:
                if previous not in (BlockKind.PRESSURE, BlockKind.ENTHALPY):
                    raise ValueError(
                        f"enthalpy block {block.name!r} must follow its zone's pressure block"
                    )
                zones[-1][1] += block.size
            self._start[block.name] = offset
            offset += block.size
            previous = block.kind
        self.size = offset
        self.zones = np.array(zones, dtype=np.int64).reshape(-1, 2)
        """Per zone: (offset of its pressure, number of cells); cells follow the pressure."""
        self.zones.flags.writeable = False  # cycle modules share one layout per size
        self.n_cells = int(self.zones[:, 1].sum())
        self.dtype = np.dtype(
            [(name, np.int64) for name in names]
            + [("size", np.int64), ("zones", np.int64, self.zones.shape)]
        )
        """Record type of :attr:`record` (depends on the block names, not their sizes)."""

    def __getitem__(self, name: str) -> slice:
        """Where block ``name`` lives in the state vector."""
        start = self.start(name)
        return slice(start, start + self._blocks[name].size)

    def start(self, name: str) -> int:
        """Offset of block ``name``."""
        if name not in self._start:
            raise KeyError(f"unknown state block {name!r}; blocks are {list(self._start)}")
        return self._start[name]

    @property
    def record(self) -> np.void:
        """The offsets as a Numba record: one field per block, ``size`` and ``zones``."""
        return make_record(self.dtype, {**self._start, "size": self.size, "zones": self.zones})

    @property
    def labels(self) -> tuple[str, ...]:
        """One name per state variable: the block's, with the cell index for blocks of more
        than one (``h_cond[0]``)."""
        return tuple(
            block.name if block.size == 1 else f"{block.name}[{i}]"
            for block in self.blocks
            for i in range(block.size)
        )

    @property
    def units(self) -> tuple[str, ...]:
        """The SI unit of each state variable (:data:`BLOCK_UNITS`)."""
        return tuple(BLOCK_UNITS[block.kind] for block in self.blocks for _ in range(block.size))

    def tolerances(self, solver: Solver) -> np.ndarray:
        """Absolute tolerances of the state, by block kind, from the solver's."""
        by_kind = {
            BlockKind.PRESSURE: solver.atol_pressure,
            BlockKind.ENTHALPY: solver.atol_enthalpy,
            BlockKind.TEMPERATURE: solver.atol_temperature,
            BlockKind.INTEGRAL: solver.atol_integral,
        }
        atol = np.empty(self.size)
        for block in self.blocks:
            atol[self[block.name]] = by_kind[block.kind]
        return atol


class CycleModel(ABC):
    """One cycle topology: its parameters, outputs, state layout and Numba kernels.

    Kernels (Numba dispatchers; ``c`` is the one-element record array of :meth:`constants`,
    ``u`` the inputs ordered as :data:`~pymc_vcc.physics.inputs.CYCLE_INPUT_IDS`, absent optional
    inputs at their default):

    * ``evaluate(y, u, c, tables, dydt, out) -> bool``: dy/dt into ``dydt``, outputs then
      diagnostics into ``out``; False when a property left the tables;
    * ``jacobian(y, u, c, tables, f0) -> ndarray``: ∂f/∂y given f0 = f(y);
    * ``outputs_along(ys, us, c, tables, rates) -> ndarray``: outputs and diagnostics row by
      row; with ``rates`` False those that need the walls' and zones' balances (the heats)
      may be NaN;
    * ``total_mass(y, c, tables) -> float``: refrigerant mass, kg.
    """

    name: ClassVar[str]
    """The id a unit description names in ``[unit] cycle``."""
    description: ClassVar[str]
    parameters: ClassVar[tuple[tuple[str, str], ...]]
    """(id, unit) of the calibration parameters a unit of this cycle must give."""
    output_info: ClassVar[dict[str, tuple[str, str]]]
    """Long name and unit of each output, in order."""
    diagnostic_info: ClassVar[dict[str, tuple[str, str]]]
    """Further quantities after the outputs; must include ``M`` (kg) and ``mdot_src`` (kg/s)."""
    optional_output_ids: ClassVar[tuple[str, ...]] = ()
    """Diagnostics a simulator may also return as outputs (quantities field loggers measure)."""
    capacity: ClassVar[str]
    """The diagnostic that is the unit's useful heat, W (what its COP divides)."""
    evaluate: ClassVar[Callable[..., bool]]
    jacobian: ClassVar[Callable[..., np.ndarray]]
    outputs_along: ClassVar[Callable[..., np.ndarray]]
    total_mass: ClassVar[Callable[..., float]]

    @property
    def output_ids(self) -> tuple[str, ...]:
        """Output ids in the order of ``out``."""
        return tuple(self.output_info)

    @property
    def n_eval(self) -> int:
        """Length of ``out``: outputs then diagnostics."""
        return len(self.output_info) + len(self.diagnostic_info)

    @abstractmethod
    def layout(self, n_volumes: int) -> StateLayout:
        """The state layout for ``n_volumes`` cells per heat exchanger."""

    @abstractmethod
    def constants(
        self, unit: Unit, theta: np.ndarray, controller: bool | None = None
    ) -> np.ndarray:
        """The constants record (a one-element structured array) from a unit and a parameter
        vector ordered as :attr:`parameters`; ``controller`` overrides the unit's
        charge-controller switch."""

    @abstractmethod
    def initial_state(
        self, c: np.ndarray, n_volumes: int, inputs: np.ndarray, tables
    ) -> np.ndarray:
        """A state holding exactly the charge :meth:`charge` at the first inputs ``inputs``;
        ``ValueError`` if the unit cannot hold it."""

    def charge(self, c: np.ndarray) -> float:
        """The charge M0 the controller holds, kg."""
        return float(c[0]["controller"]["m0"])

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r})"


def place_charge(
    fill: Callable[[float], np.ndarray],
    mass: Callable[[np.ndarray], float],
    target: float,
    low: float = -1.0,
    high: float = 2.0,
) -> np.ndarray:
    """The state ``fill(s)`` holding ``target`` kg, with the fill level ``s`` in [low, high]
    found by Brent's method to 1e-13 (``mass(fill(s))`` must grow with ``s``; 12 to 16 mass
    evaluations over the Table III box where bisection took 58); ``ValueError`` if the charge
    does not fit."""
    m_low = mass(fill(low))
    m_high = mass(fill(high))
    if not m_low <= target <= m_high:
        raise ValueError(
            f"charge M0 = {target} kg cannot be placed in this unit at start-up: it holds "
            f"{m_low:.3f} to {m_high:.3f} kg"
        )
    if m_low == target or m_high == target:
        return fill(low if m_low == target else high)
    level = brentq(lambda s: mass(fill(s)) - target, low, high, xtol=1e-13)
    return fill(level)


# ---- Numba kernels that read only the layout ----------------------------------------------


@njit(cache=True, error_model="numpy")
def zone_cells(y, zones, first, last, tables, props, memo=None, rates=True):
    """Properties of cells ``first`` to ``last`` (cells numbered zone after zone; all of one
    zone, so they share its pressure's saturation point) into those columns of ``props``. A
    ``memo`` from :func:`fillet_memo` carries fillet ends over from earlier calls at the same
    pressure. With ``rates`` False only T, ρ and x (the density's slopes NaN), which is all the
    outputs and the charge need."""
    zone = 0
    k = first
    while k >= zones[zone, 1]:
        k -= zones[zone, 1]
        zone += 1
    p_index = zones[zone, 0]
    p = y[p_index]
    sat = saturation_point(tables, p)
    if memo is None:
        memo = fillet_memo()
    for i in range(first, last + 1):
        h = y[p_index + 1 + k + i - first]
        if rates:
            T, rho, drho_dp, drho_dh, x = cell_state(tables, sat, p, h, memo)
        else:
            T, rho, x = cell_values(tables, sat, p, h, memo)
            drho_dp = drho_dh = np.nan
        props[0, i] = T
        props[1, i] = rho
        props[2, i] = drho_dp
        props[3, i] = drho_dh
        props[4, i] = x


@njit(cache=True, error_model="numpy")
def cell_properties(y, zones, tables, props, rates=True):
    """Fill ``props`` (shape (N_PROPERTIES, cells)) for every cell (``rates``: see
    :func:`zone_cells`); False if a property left the tables."""
    first = 0
    for zone in range(zones.shape[0]):
        zone_cells(y, zones, first, first + zones[zone, 1] - 1, tables, props, None, rates)
        first += zones[zone, 1]
    return bool(np.isfinite(props[1]).all())


@njit(cache=True, error_model="numpy")
def stored_mass(volumes, rho):
    """Σ V ρ over the cells, kg."""
    mass = 0.0
    for i in range(volumes.size):
        mass += volumes[i] * rho[i]
    return mass


@njit(cache=True, error_model="numpy")
def column_cells(zones, j):
    """(first, last) cell whose properties state variable ``j`` changes: a zone's cells for its
    pressure, one cell for an enthalpy, none (0, -1) for anything else."""
    first = 0
    for zone in range(zones.shape[0]):
        p_index = zones[zone, 0]
        count = zones[zone, 1]
        if j == p_index:
            return first, first + count - 1
        if p_index < j <= p_index + count:
            return first + j - p_index - 1, first + j - p_index - 1
        first += count
    return 0, -1


@njit(cache=True, error_model="numpy")
def perturb(y, work, j, zones, tables, props, memo):
    """Step state variable ``j`` of ``work`` for a forward difference and update the cell
    properties it touches (``memo``: see :func:`zone_cells`); returns the step."""
    step = 1e-7 * max(abs(y[j]), 1.0)
    work[j] = y[j] + step
    first, last = column_cells(zones, j)
    if first <= last:
        zone_cells(work, zones, first, last, tables, props, memo)
    return step


@njit(cache=True, error_model="numpy")
def restore(y, work, j, zones, props, saved):
    """Undo :func:`perturb`: state variable ``j`` and the cell properties it touched."""
    first, last = column_cells(zones, j)
    for i in range(first, last + 1):
        for k in range(N_PROPERTIES):
            props[k, i] = saved[k, i]
    work[j] = y[j]


@njit(cache=True, error_model="numpy")
def quality_enthalpy(tables, p, x):
    """Enthalpy at pressure ``p`` (Pa) and quality ``x`` (J/kg), extended linearly beyond the
    saturation lines for x < 0 or x > 1: the initial states' fill profiles use it."""
    sat = saturation_state(tables, p)
    return sat[1] + x * (sat[2] - sat[1])
