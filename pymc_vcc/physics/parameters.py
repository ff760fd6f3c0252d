"""Calibration and fault parameters: ids, long names, units, bounds.

The physics reads parameters by their stable short id (``M0``, ``CF_VOL``, ...). Each cycle
model declares the ids and units it expects (the split unit's are the 26 of the paper's Table
III, :data:`pymc_vcc.physics.cycles.split_unit.PARAMETERS`); a unit
description (``models/*.toml``) gives each id its long name, unit, bounds and nominal value, and
this module checks them against the model and turns user parameter mappings into vectors.

A cycle model also declares its fault parameters in full (:func:`declared_table`; the split
unit's :data:`pymc_vcc.physics.cycles.split_unit.FAULTS`), nominal 0 = no fault: they are not
the unit's to describe and not part of its calibration box. One mapping of values reaches both
tables (:func:`table_vectors`).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass

import numpy as np

ParameterIds = tuple[tuple[str, str], ...]
"""(id, unit) of the parameters a cycle model expects, in vector order."""


@dataclass(frozen=True)
class ParameterSpec:
    """One calibration parameter: id, long name, unit, bounds [low, high] and nominal value.

    Attributes
    ----------
    id
        Short id (``M0``, ``CF_VOL``, ...).
    name
        Long name.
    unit
        Unit of the values (``kg``, ``1``, ``W/(m2 K)``, ``m3/s``, ``W``, ``Hz``, ``m``).
    low, high
        Physical bounds, in ``unit``.
    nominal
        Nominal value, in ``unit``, inside the bounds.
    tolerance
        How well the nominal value is known when the parameter is not calibrated, a fraction
        of it (a coil length from the drawings: 0.01); None when only the bounds are known.
    """

    id: str
    name: str
    unit: str
    low: float
    high: float
    nominal: float
    tolerance: float | None = None

    def __post_init__(self) -> None:
        for field in ("low", "high", "nominal"):
            value = getattr(self, field)
            if not np.isfinite(value):
                raise ValueError(f"parameter {self.id}: {field} must be finite, got {value!r}")
        if not self.low < self.high:
            raise ValueError(
                f"parameter {self.id}: bounds need low < high, got [{self.low}, {self.high}]"
            )
        if not self.low <= self.nominal <= self.high:
            raise ValueError(
                f"parameter {self.id}: nominal {self.nominal} lies outside its bounds "
                f"[{self.low}, {self.high}]"
            )
        if self.tolerance is not None and not 0.0 < self.tolerance < 1.0:
            raise ValueError(
                f"parameter {self.id}: tolerance must be a fraction in (0, 1), "
                f"got {self.tolerance!r}"
            )

    def known_range(self, spread: float | None = None) -> tuple[float, float]:
        """Where the value lies when it is not calibrated: ± its tolerance (else ± ``spread``)
        × nominal inside the bounds; the bounds when neither is given."""
        known_to = self.tolerance if self.tolerance is not None else spread
        if known_to is None:
            return self.low, self.high
        return (
            max(self.low, self.nominal * (1.0 - known_to)),
            min(self.high, self.nominal * (1.0 + known_to)),
        )


@dataclass(frozen=True)
class ParameterTable:
    """The ordered parameter specs of a unit: exactly the ids and units of ``expected`` (its
    cycle model's parameters), in that order.

    Attributes
    ----------
    specs
        One :class:`ParameterSpec` per parameter.
    expected
        (id, unit) pairs the cycle model expects, in vector order.
    """

    specs: tuple[ParameterSpec, ...]
    expected: ParameterIds

    def __post_init__(self) -> None:
        ids = tuple(spec.id for spec in self.specs)
        if ids != self.ids:
            missing = [pid for pid in self.ids if pid not in ids]
            raise ValueError(
                f"parameters must be exactly {list(self.ids)} in this order "
                f"(missing: {missing}); use parameter_table() to sort them"
            )
        for spec, (pid, unit) in zip(self.specs, self.expected, strict=True):
            if spec.unit != unit:
                raise ValueError(
                    f"parameter {pid}: unit {spec.unit!r} is not the expected {unit!r}"
                )

    def __getitem__(self, pid: str) -> ParameterSpec:
        for spec in self.specs:
            if spec.id == pid:
                return spec
        raise KeyError(f"unknown parameter id {pid!r}; allowed ids are {list(self.ids)}")

    def __iter__(self) -> Iterator[ParameterSpec]:
        return iter(self.specs)

    def __len__(self) -> int:
        return len(self.specs)

    @property
    def ids(self) -> tuple[str, ...]:
        """Parameter ids in vector order."""
        return tuple(pid for pid, _ in self.expected)

    @property
    def lows(self) -> np.ndarray:
        """Lower bounds in vector order."""
        return np.array([spec.low for spec in self.specs])

    @property
    def highs(self) -> np.ndarray:
        """Upper bounds in vector order."""
        return np.array([spec.high for spec in self.specs])

    @property
    def nominal(self) -> np.ndarray:
        """Nominal values in vector order."""
        return np.array([spec.nominal for spec in self.specs])

    def vector(
        self, theta: Mapping[str, float] | None = None, *, check_bounds: bool = False
    ) -> np.ndarray:
        """Full parameter vector: nominal values overridden by ``theta`` (id -> value).

        Unknown ids and non-finite values raise ``ValueError``; with ``check_bounds`` values
        outside their bounds do too.
        """
        values = self.nominal
        if not theta:
            return values
        ids = self.ids
        for pid, value in theta.items():
            if pid not in ids:
                raise ValueError(f"unknown parameter id {pid!r}; allowed ids are {list(ids)}")
            value = float(value)
            if not np.isfinite(value):
                raise ValueError(f"parameter {pid}: value must be finite, got {value!r}")
            spec = self[pid]
            if check_bounds and not spec.low <= value <= spec.high:
                raise ValueError(
                    f"parameter {pid}: value {value} lies outside its bounds "
                    f"[{spec.low}, {spec.high}]"
                )
            values[ids.index(pid)] = value
        return values

    def sample_uniform(self, n: int, rng: np.random.Generator) -> list[dict[str, float]]:
        """``n`` parameter sets drawn uniformly from the bounds box."""
        draws = rng.uniform(self.lows, self.highs, size=(n, len(self.specs)))
        return [dict(zip(self.ids, map(float, row), strict=True)) for row in draws]


def declared_table(specs: Iterable[ParameterSpec]) -> ParameterTable:
    """A :class:`ParameterTable` whose specs are declared in code (a cycle model's fault
    parameters): the ids and units it expects are the specs' own."""
    specs = tuple(specs)
    return ParameterTable(specs, tuple((spec.id, spec.unit) for spec in specs))


def table_vectors(
    tables: Mapping[str, ParameterTable],
    values: Mapping[str, float] | None = None,
    *,
    check_bounds: bool = False,
) -> tuple[np.ndarray, ...]:
    """One vector per table (its nominal values overridden by ``values``, id -> value, as
    :meth:`ParameterTable.vector`), the tables given by kind (``{"calibration": ..., "fault":
    ...}``); an id of none of them is one error line naming it and each kind's ids."""
    given = dict(values or {})
    unknown = [pid for pid in given if not any(pid in table.ids for table in tables.values())]
    if unknown:
        allowed = " and ".join(
            f"{kind} ids {list(table.ids)}" for kind, table in tables.items() if len(table)
        )
        raise ValueError(f"unknown parameter id(s) {unknown}; allowed are {allowed}")
    return tuple(
        table.vector(
            {pid: value for pid, value in given.items() if pid in table.ids},
            check_bounds=check_bounds,
        )
        for table in tables.values()
    )


def parameter_table(entries: Iterable[ParameterSpec], expected: ParameterIds) -> ParameterTable:
    """Build a :class:`ParameterTable` of the ``expected`` ids (a cycle model's parameters),
    sorted into their order; unknown and missing ids are errors naming them."""
    specs = {spec.id: spec for spec in entries}
    ids = [pid for pid, _ in expected]
    unknown = [pid for pid in specs if pid not in ids]
    if unknown:
        raise ValueError(f"unknown parameter id(s) {unknown}; allowed ids are {ids}")
    missing = [pid for pid in ids if pid not in specs]
    if missing:
        raise ValueError(f"parameters missing from the unit description: {missing}")
    return ParameterTable(tuple(specs[pid] for pid in ids), expected)
