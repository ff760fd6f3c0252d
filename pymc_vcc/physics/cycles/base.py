"""What every cycle model provides, and the Numba kernels that need no topology.

A cycle model (one module per topology) owns its whole description: the sections of its unit
file (:attr:`CycleModel.hardware`), its parameter table, its inputs (:class:`InputLayout`), its
outputs and diagnostics (:class:`OutputLayout`), its operating-point summary, and one
:class:`StateLayout` built from named blocks. The layouts fix every offset once; Numba reads
them by name, never as a number written in the code: the state's from the layout's record
(``c.layout.<block>``), the inputs' and outputs' from a layout's ``offsets`` (a named tuple
of constants, folded at compile time). A pressure zone is a ``PRESSURE`` block followed by the
``ENTHALPY`` blocks of its cells in flow order, so cell properties, total mass and the columns
of the Jacobian follow from the layout alone.

The driver (:mod:`pymc_vcc.physics.simulate`) integrates any :class:`CycleModel` through its
Numba kernels ``evaluate``, ``jacobian``, ``outputs_along`` and ``total_mass``. This package
knows nothing of unit files: the unit loader (:mod:`pymc_vcc.physics.unit`) reads a file
against the cycle model it names.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections import namedtuple
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import Field, dataclass
from enum import StrEnum
from typing import Any, ClassVar, Protocol

import numpy as np
from numba import njit
from scipy.optimize import brentq

from pymc_vcc.physics.components.density import FILLET_MEMO_SHAPE, cell_state, cell_values
from pymc_vcc.physics.parameters import ParameterIds, ParameterTable, declared_table
from pymc_vcc.physics.records import make_record
from pymc_vcc.physics.refrigerant import saturation_point
from pymc_vcc.physics.scratch import all_finite, stack_full, uncounted

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


FRACTION = {"fraction": True}
"""Metadata of a hardware section's field (``field(metadata=FRACTION)``) that must lie in (0, 1)."""


def is_fraction(section_field: Field) -> bool:
    """Whether a hardware section's field was declared with :data:`FRACTION`."""
    return bool(section_field.metadata.get("fraction"))


@dataclass(frozen=True)
class Discretisation:
    """Finite volumes per heat exchanger."""

    n_volumes: int


@dataclass(frozen=True)
class ControllerSettings:
    """Virtual PI charge controller: proportional gain (1/s); Ki = Kp^2/4 (critical damping)."""

    kp: float
    enabled: bool


class Tolerances(Protocol):
    """Absolute tolerances of the state by block kind (a solver's,
    :class:`pymc_vcc.physics.integration.solver.Solver`)."""

    @property
    def atol_pressure(self) -> float: ...  # Pa

    @property
    def atol_enthalpy(self) -> float: ...  # J/kg

    @property
    def atol_temperature(self) -> float: ...  # K

    @property
    def atol_integral(self) -> float: ...  # kg s


class UnitDescription(Protocol):
    """What a cycle model reads of a unit description (a :class:`pymc_vcc.physics.unit.Unit`):
    the sections every cycle has and its own ones (an instance of :attr:`CycleModel.hardware`)."""

    @property
    def refrigerant(self) -> str: ...

    @property
    def discretisation(self) -> Discretisation: ...

    @property
    def controller(self) -> ControllerSettings: ...

    @property
    def hardware(self) -> Any: ...

    @property
    def parameters(self) -> ParameterTable: ...


def offsets(names: Sequence[str]) -> Any:
    """A named tuple of 0, 1, 2, ... by ``names``: a Numba kernel reads a module-level one as
    constants (folded at compile time, as fast as a number written in the code)."""
    return namedtuple("Offsets", names)(*range(len(names)))


@dataclass(frozen=True)
class InputSpec:
    """One input: id, long name, SI unit, the physically allowed range [low, high], the value a
    cycle uses when a profile does not carry it (None: the input is required), and whether a
    controller sets it in steps (``stepped``: a measured log's reader never averages across a
    step of it)."""

    id: str
    name: str
    unit: str
    low: float
    high: float
    default: float | None = None
    stepped: bool = False


class InputLayout:
    """The inputs a cycle reads, in the order of its input vector ``u``: the required ones, then
    the optional ones; a kernel reads ``u[offsets.<id>]``."""

    def __init__(self, specs: Sequence[InputSpec]) -> None:
        self.specs: tuple[InputSpec, ...] = tuple(specs)
        ids = [spec.id for spec in self.specs]
        if len(set(ids)) != len(ids):
            raise ValueError(f"inputs need distinct ids: {ids}")
        optional = [spec.default is not None for spec in self.specs]
        if optional != sorted(optional):
            raise ValueError(f"required inputs come before the optional ones: {ids}")
        self.ids: tuple[str, ...] = tuple(ids)
        self.required_ids: tuple[str, ...] = tuple(
            spec.id for spec in self.specs if spec.default is None
        )
        self.defaults: dict[str, float] = {
            spec.id: spec.default for spec in self.specs if spec.default is not None
        }
        self.offsets = offsets(ids)

    def __getitem__(self, input_id: str) -> InputSpec:
        for spec in self.specs:
            if spec.id == input_id:
                return spec
        raise KeyError(f"unknown input {input_id!r}; inputs are {list(self.ids)}")

    def __iter__(self) -> Iterator[InputSpec]:
        return iter(self.specs)

    def __len__(self) -> int:
        return len(self.specs)


class OutputLayout:
    """What a cycle's kernels write into ``out``: its outputs, then its diagnostics, each by id
    at a fixed offset (a kernel writes ``out[offsets.<id>]``), with a long name and SI unit.

    ``optional`` names diagnostics a simulator may also return as outputs (quantities field
    loggers measure)."""

    def __init__(
        self,
        outputs: Mapping[str, tuple[str, str]],
        diagnostics: Mapping[str, tuple[str, str]],
        optional: Sequence[str] = (),
    ) -> None:
        if set(outputs) & set(diagnostics):
            raise ValueError(f"ids both outputs and diagnostics: {set(outputs) & set(diagnostics)}")
        if not set(optional) <= set(diagnostics):
            raise ValueError(f"optional outputs must be diagnostics: {list(optional)}")
        self.output_info: dict[str, tuple[str, str]] = dict(outputs)
        """Long name and SI unit of each output, in order."""
        self.diagnostic_info: dict[str, tuple[str, str]] = dict(diagnostics)
        """Long name and SI unit of each further quantity after the outputs, in order."""
        self.info: dict[str, tuple[str, str]] = {**outputs, **diagnostics}
        self.output_ids: tuple[str, ...] = tuple(outputs)
        self.optional_ids: tuple[str, ...] = tuple(optional)
        self.ids: tuple[str, ...] = tuple(self.info)
        self.size = len(self.ids)
        self.offsets = offsets(self.ids)

    @property
    def measurable_info(self) -> dict[str, tuple[str, str]]:
        """Outputs a simulator may return and a logger may measure: the outputs, then the
        optional ones."""
        return {name: self.info[name] for name in self.output_ids + self.optional_ids}


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

    def tolerances(self, solver: Tolerances) -> np.ndarray:
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
    """One cycle topology: its description (unit-file sections, parameters, inputs, outputs,
    operating-point summary), state layout and Numba kernels.

    Kernels (Numba dispatchers; ``c`` is the one-element record array of :meth:`constants`,
    ``u`` the inputs ordered as :attr:`inputs`, absent optional inputs at their default):

    * ``evaluate(y, u, c, tables, dydt, out) -> bool``: dy/dt into ``dydt``, outputs then
      diagnostics into ``out`` (:attr:`outputs`); False when a property left the tables;
    * ``jacobian(y, u, c, tables, f0) -> ndarray``: ∂f/∂y given f0 = f(y);
    * ``outputs_along(ys, us, c, tables, rates) -> ndarray``: outputs and diagnostics row by
      row; with ``rates`` False those that need the walls' and zones' balances (the heats)
      may be NaN;
    * ``total_mass(y, c, tables) -> float``: refrigerant mass, kg.
    """

    name: ClassVar[str]
    """The id a unit description names in ``[unit] cycle``."""
    description: ClassVar[str]
    hardware: ClassVar[type]
    """A frozen dataclass with one field per section of the unit file that this cycle adds to
    the common ones (``[discretisation]``, ``[controller]``, ``[rating]``), each a
    frozen dataclass of numbers (SI; a field declared with :data:`FRACTION` must lie in
    (0, 1)). The unit loader reads and checks them; :meth:`constants` reads them."""
    parameters: ClassVar[ParameterIds]
    """(id, unit) of the calibration parameters a unit of this cycle must give."""
    faults: ClassVar[ParameterTable] = declared_table(())
    """Its fault parameters, declared in full (id, meaning, unit, bounds, nominal 0 = no fault):
    physics a faulty unit adds, apart from the calibration parameters and their box; a run
    takes them by id like those (none by default)."""
    inputs: ClassVar[InputLayout]
    """The inputs it reads (a unit's ``[rating]`` gives the required ones)."""
    outputs: ClassVar[OutputLayout]
    """Its outputs then diagnostics; the diagnostics must include ``M`` (kg) and ``mdot_src``
    (kg/s)."""
    evaluate: ClassVar[Callable[..., bool]]
    jacobian: ClassVar[Callable[..., np.ndarray]]
    outputs_along: ClassVar[Callable[..., np.ndarray]]
    total_mass: ClassVar[Callable[..., float]]

    @property
    def output_ids(self) -> tuple[str, ...]:
        """Output ids in the order of ``out``."""
        return self.outputs.output_ids

    @property
    def n_eval(self) -> int:
        """Length of ``out``: outputs then diagnostics."""
        return self.outputs.size

    @abstractmethod
    def layout(self, n_volumes: int) -> StateLayout:
        """The state layout for ``n_volumes`` cells per heat exchanger."""

    @abstractmethod
    def constants(
        self,
        unit: UnitDescription,
        theta: np.ndarray,
        controller: bool | None = None,
        faults: np.ndarray | None = None,
    ) -> np.ndarray:
        """The constants record (a one-element structured array) from a unit and a parameter
        vector ordered as :attr:`parameters`; ``controller`` overrides the unit's
        charge-controller switch; ``faults`` is a vector ordered as :attr:`faults` (None: no
        fault, their nominal values)."""

    @abstractmethod
    def initial_state(
        self, c: np.ndarray, n_volumes: int, inputs: np.ndarray, tables
    ) -> np.ndarray:
        """A state holding exactly the charge :meth:`charge` at the first inputs ``inputs``;
        ``ValueError`` if the unit cannot hold it."""

    @abstractmethod
    def summary(self, final: Mapping[str, float], tables) -> dict[str, float]:
        """What an operating point adds to the outputs and diagnostics ``final`` at its end
        (:func:`~pymc_vcc.physics.simulate.operating_point`): at least ``capacity`` (W, the
        useful heat) and ``COP``."""

    @abstractmethod
    def box_ranges(self, unit: UnitDescription) -> dict[str, tuple[float, float]]:
        """Ranges (low, high) that diagnostics must stay inside anywhere in the unit's parameter
        box, SI; the physics probes check them."""

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


@uncounted
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
        memo = stack_full(FILLET_MEMO_SHAPE, np.nan)
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


@uncounted
def cell_properties(y, zones, tables, props, rates=True):
    """Fill ``props`` (shape (N_PROPERTIES, cells)) for every cell (``rates``: see
    :func:`zone_cells`); False if a property left the tables."""
    first = 0
    for zone in range(zones.shape[0]):
        zone_cells(y, zones, first, first + zones[zone, 1] - 1, tables, props, None, rates)
        first += zones[zone, 1]
    return all_finite(props[1])


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
    return quality_enthalpy_at(saturation_point(tables, p), x)


@njit(cache=True, error_model="numpy", inline="always")
def quality_enthalpy_at(sat, x):
    """:func:`quality_enthalpy` given ``sat``, the saturation point of the pressure."""
    return sat.h_l + x * (sat.h_v - sat.h_l)
