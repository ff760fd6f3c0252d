"""The 26 calibration parameters of the paper's Table III: ids, long names, units, bounds.

The physics reads parameters by their stable short id (``M0``, ``CF_VOL``, ...). A unit
description (``models/*.toml``) gives each id its long name, unit, bounds and nominal value; this
module holds the canonical list of ids and the units the physics expects, and turns user
supplied parameter mappings into validated vectors.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass

import numpy as np

TABLE_III: tuple[tuple[str, str], ...] = (
    ("M0", "kg"),
    ("CF_VOL", "1"),
    ("CF_POW", "1"),
    ("CF_PREF", "1"),
    ("CF_SHELL", "1"),
    ("CF_LEV", "1"),
    ("CF_DPC", "1"),
    ("CF_DPE", "1"),
    ("HTC_CV", "W/(m2 K)"),
    ("HTC_CTP", "W/(m2 K)"),
    ("HTC_CL", "W/(m2 K)"),
    ("HTC_EV", "W/(m2 K)"),
    ("HTC_ETP", "W/(m2 K)"),
    ("HTC_EL", "W/(m2 K)"),
    ("FO_FLOW", "m3/s"),
    ("FO_POW", "W"),
    ("FO_SPEED", "Hz"),
    ("FI_FLOW", "m3/s"),
    ("FI_POW", "W"),
    ("FI_SPEED", "Hz"),
    ("HTC_CA", "W/(m2 K)"),
    ("HTC_EA", "W/(m2 K)"),
    ("L_COND", "m"),
    ("L_EVAP", "m"),
    ("L_VAP", "m"),
    ("L_LIQ", "m"),
)
"""(id, unit) of the 26 calibration parameters in the order of the paper's Table III."""

PARAMETER_IDS: tuple[str, ...] = tuple(pid for pid, _ in TABLE_III)
"""Parameter ids in Table III order; the index of an id is its position in parameter vectors."""

EXPECTED_UNITS: dict[str, str] = dict(TABLE_III)


@dataclass(frozen=True)
class ParameterSpec:
    """One calibration parameter: id, long name, unit, bounds [low, high] and nominal value."""

    id: str
    name: str
    unit: str
    low: float
    high: float
    nominal: float

    def __post_init__(self) -> None:
        if self.id not in EXPECTED_UNITS:
            raise ValueError(
                f"unknown parameter id {self.id!r}; allowed ids are {list(PARAMETER_IDS)}"
            )
        if self.unit != EXPECTED_UNITS[self.id]:
            raise ValueError(
                f"parameter {self.id}: unit {self.unit!r} is not the expected "
                f"{EXPECTED_UNITS[self.id]!r}"
            )
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


@dataclass(frozen=True)
class ParameterTable:
    """The ordered set of all 26 parameter specs of a unit."""

    specs: tuple[ParameterSpec, ...]

    def __post_init__(self) -> None:
        ids = tuple(spec.id for spec in self.specs)
        if ids != PARAMETER_IDS:
            missing = [pid for pid in PARAMETER_IDS if pid not in ids]
            raise ValueError(
                f"parameters must be exactly {list(PARAMETER_IDS)} in this order "
                f"(missing: {missing}); use parameter_table() to sort them"
            )

    def __getitem__(self, pid: str) -> ParameterSpec:
        for spec in self.specs:
            if spec.id == pid:
                return spec
        raise KeyError(f"unknown parameter id {pid!r}; allowed ids are {list(PARAMETER_IDS)}")

    def __iter__(self) -> Iterator[ParameterSpec]:
        return iter(self.specs)

    def __len__(self) -> int:
        return len(self.specs)

    @property
    def ids(self) -> tuple[str, ...]:
        """Parameter ids in Table III order."""
        return PARAMETER_IDS

    @property
    def lows(self) -> np.ndarray:
        """Lower bounds in Table III order."""
        return np.array([spec.low for spec in self.specs])

    @property
    def highs(self) -> np.ndarray:
        """Upper bounds in Table III order."""
        return np.array([spec.high for spec in self.specs])

    @property
    def nominal(self) -> np.ndarray:
        """Nominal values in Table III order."""
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
        for pid, value in theta.items():
            if pid not in EXPECTED_UNITS:
                raise ValueError(
                    f"unknown parameter id {pid!r}; allowed ids are {list(PARAMETER_IDS)}"
                )
            value = float(value)
            if not np.isfinite(value):
                raise ValueError(f"parameter {pid}: value must be finite, got {value!r}")
            spec = self[pid]
            if check_bounds and not spec.low <= value <= spec.high:
                raise ValueError(
                    f"parameter {pid}: value {value} lies outside its bounds "
                    f"[{spec.low}, {spec.high}]"
                )
            values[PARAMETER_IDS.index(pid)] = value
        return values

    def sample_uniform(self, n: int, rng: np.random.Generator) -> list[dict[str, float]]:
        """``n`` parameter sets drawn uniformly from the bounds box."""
        draws = rng.uniform(self.lows, self.highs, size=(n, len(self.specs)))
        return [dict(zip(PARAMETER_IDS, map(float, row), strict=True)) for row in draws]


def parameter_table(entries: Iterable[ParameterSpec]) -> ParameterTable:
    """Build a :class:`ParameterTable`, sorted into Table III order."""
    specs = {spec.id: spec for spec in entries}
    missing = [pid for pid in PARAMETER_IDS if pid not in specs]
    if missing:
        raise ValueError(f"parameters missing from the unit description: {missing}")
    return ParameterTable(tuple(specs[pid] for pid in PARAMETER_IDS))
