"""Why a simulation failed: a kind to count and group by, and free text for people."""

from __future__ import annotations

from enum import StrEnum
from typing import NamedTuple


class FailureKind(StrEnum):
    """The kind of a failed simulation, one list for all that report one: the cycle
    (``attrs["failure_kind"]`` of a failed result), a sampler running any simulator
    (:func:`~pymc_vcc.inference.simulator.run_simulation`) and the executors. A failed
    simulation's ``status`` in a sampler's result is one of them, and the samplers count each.
    """

    INITIAL_STATE = "initial-state"  # the charge does not fit the unit at start-up
    PROPERTY_RANGE = "property-range"  # a refrigerant state left the property tables
    SOLVER = "solver"  # the stiff solver gave up or raised
    NON_FINITE = "non-finite"  # a state or output became NaN or infinite
    TIME_LIMIT = "time-limit"  # the run exceeded its wall-clock limit (or was stopped for it)
    EXCEPTION = "exception"  # the simulator raised (the reason names the exception)
    REPORTED = "reported"  # the simulator flagged a failure, of no kind listed here
    INVALID_OUTPUT = "invalid-output"  # outputs missing or misshapen
    WORKER_CRASH = "worker-crash"  # the worker process running it died (segfault, out of memory)


class Failure(NamedTuple):
    """A failed run: its kind and a one-line detail (time, solver message)."""

    kind: FailureKind
    detail: str
