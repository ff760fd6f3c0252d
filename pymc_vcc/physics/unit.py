"""Unit descriptions: cycle model, fixed geometry, refrigerant, discretisation, parameters.

A unit description is a TOML file (the built-in one ships as ``pymc_vcc/data/split_3p5kw_r410a
.toml``; the format is documented in ``models/README.md``). ``[unit] cycle`` names its cycle
model (default ``split-cooling``) and the parameters are checked against that model's own table.
Loading validates it completely before any simulation runs: unknown keys, missing values,
non-positive sizes, bounds with low >= high, nominals outside their bounds, unknown cycles and
unknown refrigerants are errors that name the field and what is allowed. All values are SI.
The solver is not the unit's: a simulation takes it (``simulate(..., solver=...)``).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import MISSING, dataclass, fields
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pymc_vcc.physics.integration.solver import DEFAULT_SOLVERS, METHODS
from pymc_vcc.physics.parameters import ParameterIds, ParameterSpec, ParameterTable, parameter_table

if TYPE_CHECKING:
    from pymc_vcc.physics.cycles.base import CycleModel

BUILTIN_UNIT = "split_3p5kw_r410a.toml"
"""File name of the built-in unit description inside ``pymc_vcc/data``."""

HEAT_PUMP_UNIT = "heat_pump_3p5kw_r410a.toml"
"""The same split unit as a heat pump in heating mode, inside ``pymc_vcc/data``."""

SHIPPED_UNITS = (BUILTIN_UNIT, HEAT_PUMP_UNIT)
"""File names of the units shipped inside ``pymc_vcc/data``, which :func:`load_unit` accepts."""


@dataclass(frozen=True)
class Discretisation:
    """Finite volumes per heat exchanger."""

    n_volumes: int


@dataclass(frozen=True)
class ControllerSettings:
    """Virtual PI charge controller: proportional gain (1/s); Ki = Kp^2/4 (critical damping)."""

    kp: float
    enabled: bool


@dataclass(frozen=True)
class CompressorGeometry:
    """Fixed compressor data (its correction factors are calibration parameters)."""

    displacement: float  # m3 per revolution
    clearance: float  # clearance ratio of the volumetric-efficiency model, -
    polytropic_exponent: float  # re-expansion exponent, -
    isentropic_efficiency: float  # -
    loss_share_to_refrigerant: float  # share of the losses (power above W_s) heating the gas, -
    shell_ua: float  # shell heat-loss conductance to ambient, W/K
    max_discharge_temperature: float  # thermal limit of the discharge gas, K
    protection_pressure_start: float  # discharge pressure where the speed droop starts, Pa
    protection_pressure_stop: float  # discharge pressure of 5 % speed, Pa


@dataclass(frozen=True)
class ValveGeometry:
    """Electronic expansion valve: flow area at full opening (m2), ṁ = A a sqrt(2 ρ Δp)."""

    flow_area: float


@dataclass(frozen=True)
class HeatExchangerGeometry:
    """Fixed heat-exchanger data; coil length per path is a calibration parameter."""

    tube_inner_diameter: float  # m
    n_paths: int  # parallel refrigerant circuits
    air_side_area_per_length: float  # air-side (fin and tube) area per m of tube, m2/m
    wall_heat_capacity_per_length: float  # tube and fin heat capacity per m of tube, J/(K m)
    nominal_mass_flow: float  # refrigerant flow at which the nominal HTCs hold, kg/s


@dataclass(frozen=True)
class PipeGeometry:
    """Connecting line; its length is a calibration parameter."""

    inner_diameter: float  # m


@dataclass(frozen=True)
class TankGeometry:
    """Suction accumulator with a bleed (oil-return) hole in its J-tube."""

    volume: float  # m3
    bleed_fraction_full: float  # liquid mass fraction of the outflow with a full tank, -


@dataclass(frozen=True)
class FanSettings:
    """Fan running speed as a fraction of its rated ("nominal") speed; the fan laws scale the
    rated flow and power (Table III) to it."""

    speed_fraction: float


@dataclass(frozen=True)
class AirProperties:
    """Constant moist-air properties on both coils."""

    density: float  # kg/m3
    specific_heat: float  # J/(kg K)


@dataclass(frozen=True)
class RatingPoint:
    """Rated operating conditions of the unit (constant inputs, SI)."""

    valve_opening: float  # -
    compressor_speed: float  # Hz
    T_ambient: float  # K
    T_indoor: float  # K


@dataclass(frozen=True)
class PressureDrop:
    """Lumped pressure drops: Darcy friction factor of straight tube, and the ratio of a coil's
    drop to straight-tube homogeneous friction (return bends, headers, two-phase slip)."""

    darcy_friction_factor: float
    coil_multiplier: float


_SECTIONS: dict[str, type] = {
    "discretisation": Discretisation,
    "controller": ControllerSettings,
    "compressor": CompressorGeometry,
    "expansion_valve": ValveGeometry,
    "condenser": HeatExchangerGeometry,
    "evaporator": HeatExchangerGeometry,
    "liquid_line": PipeGeometry,
    "vapor_line": PipeGeometry,
    "suction_tank": TankGeometry,
    "outdoor_fan": FanSettings,
    "indoor_fan": FanSettings,
    "air": AirProperties,
    "pressure_drop": PressureDrop,
    "rating": RatingPoint,
}

DEFAULT_CYCLE = "split-cooling"
"""The cycle of a unit description that names none."""

_HEAD_KEYS = ["name", "description", "refrigerant", "cycle"]

_FRACTIONS = {
    ("compressor", "clearance"),
    ("compressor", "isentropic_efficiency"),
    ("compressor", "loss_share_to_refrigerant"),
    ("suction_tank", "bleed_fraction_full"),
}


@dataclass(frozen=True)
class Unit:
    """A complete, validated unit description: one field per section of the unit file
    (``models/README.md``), SI units.

    Attributes
    ----------
    name, description
        ``[unit] name`` and ``description``.
    refrigerant
        ``R410A``, ``R32`` or ``R134a``.
    cycle
        Name of the cycle model (``split-cooling`` or ``heat-pump-heating``).
    discretisation, controller
        Finite volumes per coil; the virtual PI charge controller.
    compressor, expansion_valve, condenser, evaporator, liquid_line, vapor_line, suction_tank
        The components' fixed data (m, m², m³, W/K, ...).
    outdoor_fan, indoor_fan, air, pressure_drop
        Fan speed fractions; air density (kg/m³) and heat capacity (J/(kg K)); friction.
    rating
        The rating point's inputs (fraction, Hz, K), the point ``operating_point`` uses.
    parameters
        The calibration parameters with their units, bounds and nominal values.
    """

    name: str
    description: str
    refrigerant: str
    cycle: str
    discretisation: Discretisation
    controller: ControllerSettings
    compressor: CompressorGeometry
    expansion_valve: ValveGeometry
    condenser: HeatExchangerGeometry
    evaporator: HeatExchangerGeometry
    liquid_line: PipeGeometry
    vapor_line: PipeGeometry
    suction_tank: TankGeometry
    outdoor_fan: FanSettings
    indoor_fan: FanSettings
    air: AirProperties
    pressure_drop: PressureDrop
    rating: RatingPoint
    parameters: ParameterTable

    @property
    def cycle_model(self) -> CycleModel:
        """The cycle model this unit runs (``[unit] cycle``)."""
        from pymc_vcc.physics.cycles import cycle_model

        return cycle_model(self.cycle)

    def with_changes(self, **sections: dict[str, Any]) -> Unit:
        """A copy with some fields of some sections replaced, validated like a loaded file.

        Example: ``unit.with_changes(discretisation={"n_volumes": 20})``.
        """
        data = unit_to_dict(self)
        for section, values in sections.items():
            if section not in data or not isinstance(data[section], dict):
                raise ValueError(f"unknown section {section!r}; allowed: {sorted(_SECTIONS)}")
            data[section].update(values)
        return unit_from_dict(data, source=f"{self.name} (modified)")


def _check_keys(
    where: str, given: dict[str, Any], allowed: list[str], optional: frozenset[str] = frozenset()
) -> None:
    unknown = sorted(set(given) - set(allowed))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; allowed keys are {allowed}")
    missing = [key for key in allowed if key not in given and key not in optional]
    if missing:
        raise ValueError(f"{where}: missing value(s) for {missing}")


def _section(source: str, section: str, cls: type, raw: Any) -> Any:
    where = f"{source} [{section}]"
    if not isinstance(raw, dict):
        raise ValueError(f"{where}: expected a table of values, got {type(raw).__name__}")
    names = [f.name for f in fields(cls)]
    _check_keys(where, raw, names, frozenset(f.name for f in fields(cls) if f.default != MISSING))
    values: dict[str, Any] = {}
    for f in fields(cls):
        value = raw.get(f.name, f.default)
        key = f"{where} {f.name}"
        if f.type == "bool":
            if not isinstance(value, bool):
                raise ValueError(f"{key}: expected true or false, got {value!r}")
        elif f.type == "int":
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{key}: expected a positive integer, got {value!r}")
        else:
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"{key}: expected a number, got {value!r}")
            value = float(value)
            if not math.isfinite(value) or value <= 0.0:
                raise ValueError(f"{key}: expected a finite positive number, got {value!r}")
            if (section, f.name) in _FRACTIONS and value >= 1.0:
                raise ValueError(f"{key}: expected a fraction in (0, 1), got {value!r}")
        values[f.name] = value
    return cls(**values)


_PARAMETER_KEYS = ["name", "unit", "bounds", "nominal", "tolerance"]


def _parameters(source: str, raw: Any, expected: ParameterIds) -> ParameterTable:
    if not isinstance(raw, dict):
        raise ValueError(f"{source} [parameters]: expected one table per parameter id")
    specs = []
    for pid, entry in raw.items():
        where = f"{source} [parameters.{pid}]"
        if not isinstance(entry, dict):
            raise ValueError(f"{where}: expected a table with name, unit, bounds, nominal")
        _check_keys(where, entry, _PARAMETER_KEYS, frozenset({"tolerance"}))
        bounds = entry["bounds"]
        if (
            not isinstance(bounds, list)
            or len(bounds) != 2
            or not all(isinstance(b, int | float) and not isinstance(b, bool) for b in bounds)
        ):
            raise ValueError(f"{where} bounds: expected [low, high] numbers, got {bounds!r}")
        nominal = entry["nominal"]
        if isinstance(nominal, bool) or not isinstance(nominal, int | float):
            raise ValueError(f"{where} nominal: expected a number, got {nominal!r}")
        tolerance = entry.get("tolerance")
        if tolerance is not None and (
            isinstance(tolerance, bool) or not isinstance(tolerance, int | float)
        ):
            raise ValueError(f"{where} tolerance: expected a number, got {tolerance!r}")
        try:
            specs.append(
                ParameterSpec(
                    id=pid,
                    name=str(entry["name"]),
                    unit=str(entry["unit"]),
                    low=float(bounds[0]),
                    high=float(bounds[1]),
                    nominal=float(nominal),
                    tolerance=None if tolerance is None else float(tolerance),
                )
            )
        except ValueError as error:
            raise ValueError(f"{source}: {error}") from None
    try:
        return parameter_table(specs, expected)
    except ValueError as error:
        raise ValueError(f"{source}: {error}") from None


def _check_refrigerant(source: str, name: Any) -> str:
    if not isinstance(name, str):
        raise ValueError(f"{source} [unit] refrigerant: expected a name, got {name!r}")
    from pymc_vcc.physics.refrigerant import load_refrigerant

    try:
        load_refrigerant(name)
    except ValueError as error:
        raise ValueError(f"{source} [unit] refrigerant: {error}") from None
    return name


def unit_from_dict(data: dict[str, Any], source: str = "unit description") -> Unit:
    """Validate a parsed unit description and build a :class:`Unit`."""
    if "solver" in data:
        raise ValueError(_moved_solver(source, data["solver"]))
    _check_keys(source, data, ["unit", *_SECTIONS, "parameters"])
    head = data["unit"]
    if not isinstance(head, dict):
        raise ValueError(f"{source} [unit]: expected a table")
    _check_keys(
        f"{source} [unit]", {"cycle": DEFAULT_CYCLE} | head, _HEAD_KEYS
    )  # ``cycle`` may be left out: the built-in split cooling cycle
    model = _check_cycle(source, head.get("cycle", DEFAULT_CYCLE))
    sections = {name: _section(source, name, cls, data[name]) for name, cls in _SECTIONS.items()}
    return Unit(
        name=str(head["name"]),
        description=str(head["description"]),
        refrigerant=_check_refrigerant(source, head["refrigerant"]),
        cycle=model.name,
        parameters=_parameters(source, data["parameters"], model.parameters),
        **sections,
    )


def _moved_solver(source: str, table: Any) -> str:
    """The one-line refusal of a unit's ``[solver]`` table: where its settings go now."""
    given = table if isinstance(table, dict) else {}
    method = given.get("method", METHODS[0])
    default = DEFAULT_SOLVERS.get(method, DEFAULT_SOLVERS[METHODS[0]])
    names = [f.name for f in fields(default) if f.name != "method"]
    changes = "".join(
        f", {name}={given[name]!r}"
        for name in names
        if name in given and given[name] != getattr(default, name)
    )
    return (
        f"{source} [solver]: a unit holds no solver settings any more; delete the table and "
        f"pass the solver per run: simulate(..., solver=get_solver({default.method!r}{changes}))"
        f" (pymc_vcc.get_solver: a method of {list(METHODS)} at its default tolerances, with "
        f"changes to any of {names}), or --solver {default.method} on the command line; "
        "output_interval and max_wall_time are arguments of simulate()"
    )


def _check_cycle(source: str, name: Any) -> CycleModel:
    from pymc_vcc.physics.cycles import cycle_model

    if not isinstance(name, str):
        raise ValueError(f"{source} [unit] cycle: expected a name, got {name!r}")
    try:
        return cycle_model(name)
    except ValueError as error:
        raise ValueError(f"{source} [unit] cycle: {error}") from None


def unit_to_dict(unit: Unit) -> dict[str, Any]:
    """The TOML-shaped dictionary of a unit (inverse of :func:`unit_from_dict`)."""
    data: dict[str, Any] = {
        "unit": {
            "name": unit.name,
            "description": unit.description,
            "refrigerant": unit.refrigerant,
            "cycle": unit.cycle,
        }
    }
    for name in _SECTIONS:
        section = getattr(unit, name)
        data[name] = {f.name: getattr(section, f.name) for f in fields(section)}
    data["parameters"] = {
        spec.id: {
            "name": spec.name,
            "unit": spec.unit,
            "bounds": [spec.low, spec.high],
            "nominal": spec.nominal,
        }
        | ({} if spec.tolerance is None else {"tolerance": spec.tolerance})
        for spec in unit.parameters
    }
    return data


def load_unit(path: str | Path | None = None) -> Unit:
    """Load and validate a unit description: a TOML file, or the file name of a shipped one
    (:data:`SHIPPED_UNITS`); ``None`` loads the built-in 3.5 kW R410A split in cooling mode.

    Parameters
    ----------
    path
        A TOML file, the file name of a shipped unit, or None."""
    name = BUILTIN_UNIT if path is None else str(path)
    if name in SHIPPED_UNITS and (path is None or not Path(name).is_file()):
        text = resources.files("pymc_vcc").joinpath("data", name).read_text()
        source = name
    else:
        path = Path(name)
        if not path.is_file():
            raise FileNotFoundError(
                f"unit description {path} does not exist (shipped units: {list(SHIPPED_UNITS)})"
            )
        text = path.read_text()
        source = str(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ValueError(f"{source}: not valid TOML: {error}") from None
    return unit_from_dict(data, source)
