"""Unit descriptions: cycle model, fixed hardware, refrigerant, discretisation, rating
point, parameters.

A unit description is a TOML file (the built-in one ships as ``pymc_vcc/data/split_3p5kw_r410a
.toml``; the format is documented in ``models/README.md``). ``[unit] cycle`` names its cycle
model (default ``split-cooling``), which declares the rest: the sections of its hardware
(:attr:`~pymc_vcc.physics.cycles.base.CycleModel.hardware`), its inputs (the keys of
``[rating]``) and its parameter table. Every unit has ``[discretisation]`` and
``[controller]``. Loading validates it completely before any simulation runs: unknown keys,
missing values, non-positive sizes, bounds with low >= high, nominals outside their bounds,
unknown cycles and unknown refrigerants are errors that name the field and what is allowed. All
values are SI. The solver is not the unit's: a simulation takes it
(``simulate(..., solver=...)``).
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import MISSING, dataclass, field, fields
from importlib import resources
from pathlib import Path
from typing import Any, get_type_hints

import numpy as np

from pymc_vcc.physics.cycles import cycle_model
from pymc_vcc.physics.cycles.base import (
    ControllerSettings,
    CycleModel,
    Discretisation,
    InputLayout,
    is_fraction,
)
from pymc_vcc.physics.integration.solver import DEFAULT_SOLVERS, METHODS
from pymc_vcc.physics.parameters import (
    ParameterIds,
    ParameterSpec,
    ParameterTable,
    parameter_table,
    table_vectors,
)

BUILTIN_UNIT = "split_3p5kw_r410a.toml"
"""File name of the built-in unit description inside ``pymc_vcc/data``."""

HEAT_PUMP_UNIT = "heat_pump_3p5kw_r410a.toml"
"""The same split unit as a heat pump in heating mode, inside ``pymc_vcc/data``."""

SHIPPED_UNITS = (BUILTIN_UNIT, HEAT_PUMP_UNIT)
"""File names of the units shipped inside ``pymc_vcc/data``, which :func:`load_unit` accepts."""


_SECTIONS: dict[str, type] = {
    "discretisation": Discretisation,
    "controller": ControllerSettings,
}
"""The sections every unit has; its cycle model adds its hardware's, then ``[rating]``."""

DEFAULT_CYCLE = "split-cooling"
"""The cycle of a unit description that names none."""

_HEAD_KEYS = ["name", "description", "refrigerant", "cycle"]


@dataclass(frozen=True)
class Unit:
    """A complete, validated unit description: one field per common section of the unit file
    (``models/README.md``), the cycle's own sections in ``hardware``, SI units.

    Attributes
    ----------
    name, description
        ``[unit] name`` and ``description``.
    refrigerant
        ``R410A``, ``R32`` or ``R134a``.
    cycle
        Name of the cycle model (one of :data:`~pymc_vcc.physics.cycles.CYCLE_MODELS`).
    discretisation, controller
        Finite volumes per coil; the virtual PI charge controller.
    hardware
        The cycle's sections (an instance of its model's ``hardware``; for the split unit
        ``compressor``, ``condenser``, ``outdoor_fan``, ... with their fixed data, m, m², W/K).
    rating
        The rating point: a value per input of the cycle (SI), the point ``operating_point``
        uses.
    parameters
        The calibration parameters with their units, bounds and nominal values (the box of
        estimation); its cycle's fault parameters are apart, in :attr:`faults`.
    """

    name: str
    description: str
    refrigerant: str
    cycle: str
    discretisation: Discretisation
    controller: ControllerSettings
    hardware: Any
    rating: dict[str, float] = field(hash=False)  # compared, but a unit stays hashable
    parameters: ParameterTable

    @property
    def cycle_model(self) -> CycleModel:
        """The cycle model this unit runs (``[unit] cycle``)."""
        return cycle_model(self.cycle)

    @property
    def faults(self) -> ParameterTable:
        """Its cycle's fault parameters (nominal 0: no fault), declared by the cycle model and
        apart from :attr:`parameters`; a run takes them by id like those."""
        return self.cycle_model.faults

    def parameter_vectors(
        self, values: Mapping[str, float] | None = None, *, check_bounds: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """(calibration vector, fault vector) from one mapping id -> value over both tables,
        nominal where not given; an unknown id is one error line naming both tables' ids."""
        calibration, faults = table_vectors(
            {"calibration": self.parameters, "fault": self.faults},
            values,
            check_bounds=check_bounds,
        )
        return calibration, faults

    def parameter_spec(self, pid: str) -> ParameterSpec:
        """The spec of calibration or fault parameter ``pid``; ``KeyError`` naming both
        tables' ids otherwise."""
        for table in (self.parameters, self.faults):
            if pid in table.ids:
                return table[pid]
        raise KeyError(
            f"unknown parameter id {pid!r}; allowed are calibration ids "
            f"{list(self.parameters.ids)} and fault ids {list(self.faults.ids)}"
        )

    def with_changes(self, **sections: dict[str, Any]) -> Unit:
        """A copy with some fields of some sections replaced, validated like a loaded file.

        Example: ``unit.with_changes(discretisation={"n_volumes": 20})``.
        """
        data = unit_to_dict(self)
        allowed = sorted(set(data) - {"unit", "parameters"})
        for section, values in sections.items():
            if section not in allowed:
                raise ValueError(f"unknown section {section!r}; allowed: {allowed}")
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
            if is_fraction(f) and value >= 1.0:
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


def _hardware_sections(model: CycleModel) -> dict[str, type]:
    """Section name -> its dataclass, of the cycle's hardware, in order."""
    types = get_type_hints(model.hardware)
    return {f.name: types[f.name] for f in fields(model.hardware)}


def _rating(source: str, raw: Any, inputs: InputLayout) -> dict[str, float]:
    where = f"{source} [rating]"
    if not isinstance(raw, dict):
        raise ValueError(f"{where}: expected a table of values, got {type(raw).__name__}")
    _check_keys(where, raw, list(inputs.ids), frozenset(inputs.defaults))
    rating = {}
    for spec in inputs:
        if spec.id not in raw:
            continue
        value = raw[spec.id]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{where} {spec.id}: expected a number, got {value!r}")
        if not spec.low <= value <= spec.high:
            raise ValueError(
                f"{where} {spec.id}: {value!r} {spec.unit} is outside the allowed range "
                f"[{spec.low}, {spec.high}]"
            )
        rating[spec.id] = float(value)
    return rating


def unit_from_dict(data: dict[str, Any], source: str = "unit description") -> Unit:
    """Validate a parsed unit description and build a :class:`Unit`."""
    if "solver" in data:
        raise ValueError(_moved_solver(source, data["solver"]))
    head = data.get("unit")
    if not isinstance(head, dict):
        raise ValueError(f"{source} [unit]: expected a table")
    _check_keys(
        f"{source} [unit]", {"cycle": DEFAULT_CYCLE} | head, _HEAD_KEYS
    )  # ``cycle`` may be left out: the built-in split cooling cycle
    model = _check_cycle(source, head.get("cycle", DEFAULT_CYCLE))
    hardware = _hardware_sections(model)
    _check_keys(source, data, ["unit", *_SECTIONS, *hardware, "rating", "parameters"])
    sections = {name: _section(source, name, cls, data[name]) for name, cls in _SECTIONS.items()}
    return Unit(
        name=str(head["name"]),
        description=str(head["description"]),
        refrigerant=_check_refrigerant(source, head["refrigerant"]),
        cycle=model.name,
        hardware=model.hardware(
            **{name: _section(source, name, cls, data[name]) for name, cls in hardware.items()}
        ),
        rating=_rating(source, data["rating"], model.inputs),
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
    sections = {name: getattr(unit, name) for name in _SECTIONS}
    sections |= {f.name: getattr(unit.hardware, f.name) for f in fields(unit.hardware)}
    for name, section in sections.items():
        data[name] = {f.name: getattr(section, f.name) for f in fields(section)}
    data["rating"] = dict(unit.rating)
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
