"""A simulation's outcome: its outputs, or the kind and the reason of its failure.

Nothing a simulation does is fatal to a sampler: every way it can go wrong becomes a
:class:`SimulationOutcome` with a :class:`~pymc_vcc.physics.failures.FailureKind` and a reason.
Running a simulator into one is :func:`pymc_vcc.inference.simulator.run_simulation`
(:func:`time_limit` stops it at its time limit); a worker process that died running it (or was
stopped for its time limit: see :mod:`pymc_vcc.execution.executors`) is reported by the
executor as a :class:`~pymc_vcc.execution.executors.WorkerCrash`, which :func:`crash_outcome`
turns into an outcome.
"""

from __future__ import annotations

import ctypes
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from pymc_vcc.execution.worker_pool import WorkerCrash
from pymc_vcc.physics.failures import FailureKind

OK = "ok"


def finished(run: object) -> bool:
    """Whether an executor's result is a run that reached its end: neither a
    :class:`~pymc_vcc.execution.executors.WorkerCrash` nor a run whose ``status`` reports a
    failure."""
    return not isinstance(run, WorkerCrash) and run.attrs["status"] == OK  # type: ignore[attr-defined]


_MAX_REASON_LENGTH = 300


class SimulationTimeout(BaseException):
    """Raised inside a simulation that exceeds its time limit.

    A BaseException, so that a simulator catching ``Exception`` to report its own failures does
    not swallow it.
    """


@dataclass(frozen=True, slots=True)
class SimulationOutcome:
    """What one simulation produced.

    Attributes:
        values: the outputs (n_outputs, n_time) when the run succeeded, else None.
        status: ``"ok"`` or a :class:`~pymc_vcc.physics.failures.FailureKind`.
        reason: why it failed ("" when ok).
        elapsed: wall time of the simulator call, s.
    """

    values: np.ndarray | None
    status: str
    reason: str
    elapsed: float

    @property
    def ok(self) -> bool:
        """True when the run produced finite outputs."""
        return self.status == OK

    @classmethod
    def failed(cls, kind: FailureKind, reason: str, elapsed: float) -> SimulationOutcome:
        """A failed run's outcome, its reason cut to a readable length."""
        if len(reason) > _MAX_REASON_LENGTH:
            reason = reason[: _MAX_REASON_LENGTH - 3] + "..."
        return cls(None, kind, reason, elapsed)


def _raise_in_thread(thread_id: int, exception: type[BaseException] | None) -> None:
    """Schedule ``exception`` in another thread (None clears a pending one)."""
    ctypes.pythonapi.PyThreadState_SetAsyncExc(
        ctypes.c_ulong(thread_id), ctypes.py_object(exception) if exception else None
    )


@contextmanager
def time_limit(seconds: float | None) -> Iterator[None]:
    """Raise :class:`SimulationTimeout` in the calling thread after ``seconds`` of wall time.

    In the main thread a SIGALRM timer interrupts even a sleeping call; in other threads (Dask
    workers) the exception is delivered at the next Python bytecode, so a simulator stuck in one
    long C call is stopped when that call returns. ``None`` means no limit.
    """
    if seconds is None:
        yield
        return
    if threading.current_thread() is threading.main_thread() and hasattr(signal, "setitimer"):

        def _alarm(signum: int, frame: object) -> None:
            raise SimulationTimeout

        previous = signal.signal(signal.SIGALRM, _alarm)
        signal.setitimer(signal.ITIMER_REAL, seconds)
        try:
            yield
        finally:
            try:
                signal.setitimer(signal.ITIMER_REAL, 0)
            finally:
                signal.signal(signal.SIGALRM, previous)
        return
    thread_id = threading.get_ident()
    lock = threading.Lock()
    state = {"done": False, "fired": False}

    def _fire() -> None:
        with lock:
            if not state["done"]:
                state["fired"] = True
                _raise_in_thread(thread_id, SimulationTimeout)

    timer = threading.Timer(seconds, _fire)
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        with lock:
            state["done"] = True
            timer.cancel()
            if state["fired"]:
                _raise_in_thread(thread_id, None)


def crash_outcome(crash: WorkerCrash) -> SimulationOutcome:
    """The outcome of a simulation whose worker process died running it, or was stopped for
    overrunning its time limit."""
    return SimulationOutcome.failed(crash.kind, crash.reason, crash.elapsed)
