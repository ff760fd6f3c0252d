"""Why a simulation failed: a kind to count and group by, and free text for people."""

from __future__ import annotations

from enum import StrEnum
from typing import NamedTuple


class FailureKind(StrEnum):
    """The kind of a failed simulation (``attrs["failure_kind"]`` of a result)."""

    INITIAL_STATE = "initial-state"  # the charge does not fit the unit at start-up
    PROPERTY_RANGE = "property-range"  # a refrigerant state left the property tables
    SOLVER = "solver"  # the stiff solver gave up or raised
    NON_FINITE = "non-finite"  # a state or output became NaN or infinite
    WALL_CLOCK = "wall-clock"  # the run exceeded its wall-clock limit


class Failure(NamedTuple):
    """A failed run: its kind and a one-line detail (time, solver message)."""

    kind: FailureKind
    detail: str
