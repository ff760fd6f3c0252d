"""One simulation run with its failures captured: nothing a simulator does is fatal to a sampler.

:func:`run_simulation` calls a simulator, enforces an optional time limit, and turns every way a
run can go wrong into a :class:`SimulationOutcome` with a failure kind and a reason:

``exception``       the simulator raised (the reason names the exception)
``time-limit``      the run took longer than its time limit (or a local worker process was
                    stopped for it: see :mod:`pymc_vcc.execution.executors`)
``reported``        the simulator returned a Dataset with ``attrs["status"] != "ok"``
``invalid-output``  outputs missing or misshapen
``non-finite``      NaN or infinite outputs
``worker-crash``    the worker process running it died (segfault, ``os._exit``, out of memory):
                    reported by the executor as a
                    :class:`~pymc_vcc.execution.executors.WorkerCrash`,
                    which :func:`crash_outcome` turns into an outcome
"""

from __future__ import annotations

import ctypes
import signal
import threading
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import xarray as xr

from pymc_vcc.execution.worker_pool import TIME_LIMIT, WORKER_CRASH, WorkerCrash
from pymc_vcc.inference.series import InvalidOutputError, ObservedData, extract_outputs
from pymc_vcc.inference.simulator import Simulator

OK = "ok"
FAILURE_KINDS: tuple[str, ...] = (
    "exception",
    TIME_LIMIT,
    "reported",
    "invalid-output",
    "non-finite",
    WORKER_CRASH,
)
"""Every failure kind of a simulation, in a fixed order: those :func:`run_simulation` reports,
then ``worker-crash`` (:func:`crash_outcome`)."""

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
        status: ``"ok"`` or one of :data:`FAILURE_KINDS`.
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


def _shorten(text: str) -> str:
    return text if len(text) <= _MAX_REASON_LENGTH else text[: _MAX_REASON_LENGTH - 3] + "..."


def run_simulation(
    simulator: Simulator,
    theta: Mapping[str, float],
    rng: np.random.Generator,
    observed: ObservedData,
    *,
    time_limit_s: float | None = None,
) -> SimulationOutcome:
    """Run ``simulator(theta, rng)`` and return its outputs in ``observed``'s layout, or why not.

    Args:
        simulator: the model, ``simulator(theta, rng) -> Dataset | array``.
        theta: parameter values by name.
        rng: the run's own random generator.
        observed: validated observed data; selects and orders the outputs.
        time_limit_s: wall-time limit of the run, s (None: no limit).
    """
    start = time.perf_counter()
    try:
        with time_limit(time_limit_s):
            result = simulator(theta, rng)
    except SimulationTimeout:
        return SimulationOutcome(
            None,
            TIME_LIMIT,
            f"exceeded the time limit of {time_limit_s} s",
            time.perf_counter() - start,
        )
    except Exception as exc:
        return SimulationOutcome(
            None, "exception", _shorten(f"{type(exc).__name__}: {exc}"), time.perf_counter() - start
        )
    elapsed = time.perf_counter() - start
    if time_limit_s is not None and elapsed > time_limit_s:
        return SimulationOutcome(
            None, TIME_LIMIT, f"took {elapsed:.3g} s, over the limit of {time_limit_s} s", elapsed
        )
    if isinstance(result, xr.Dataset):
        status = result.attrs.get("status", OK)
        if status != OK:
            reason = result.attrs.get("failure_reason") or f"status {status!r}"
            return SimulationOutcome(None, "reported", _shorten(str(reason)), elapsed)
    try:
        values = extract_outputs(result, observed)
    except (InvalidOutputError, TypeError, ValueError) as exc:
        return SimulationOutcome(None, "invalid-output", _shorten(str(exc)), elapsed)
    finite = np.isfinite(values)
    if not finite.all():
        row = int(np.flatnonzero(~finite.all(axis=1))[0])
        count = int((~finite[row]).sum())
        reason = f"output {observed.names[row]!r} has {count} non-finite value(s)"
        return SimulationOutcome(None, "non-finite", reason, elapsed)
    return SimulationOutcome(values, OK, "", elapsed)


def crash_outcome(crash: WorkerCrash) -> SimulationOutcome:
    """The outcome of a simulation whose worker process died running it, or was stopped for
    overrunning its time limit."""
    return SimulationOutcome(None, crash.kind, _shorten(crash.reason), crash.elapsed)
