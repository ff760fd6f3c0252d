"""The local worker processes behind the ``"processes"`` executor, and the worker-side code.

Each worker has its own pipe, so a worker that dies (a segfault in compiled code, ``os._exit``,
the out-of-memory killer) is pinned on the chunk it was running: that chunk's future fails with
:class:`WorkerDiedError` carrying a :class:`WorkerCrash`, a new worker takes its place and the
others go on. A chunk given a time limit that its worker overruns is stopped the same way: the
worker is terminated (whatever it is doing, compiled code included) and replaced, and the
chunk fails with a crash of kind ``"time-limit"``. A chunk's clock starts when its worker has
loaded the function (so unpickling and compiling it never count). :func:`run_chunk` is what
every backend's workers run (Dask's too).

A worker started with ``forkserver`` imports the main module; a script that samples at its top
level, without an ``if __name__ == "__main__":`` guard, thus starts its sampling again in every
worker, which dies at once. The first such death raises :class:`MainGuardError`, saying so.
"""

from __future__ import annotations

import ast
import math
import signal
import sys
import time
import traceback
from collections import deque
from collections.abc import Callable
from concurrent import futures
from contextlib import suppress
from dataclasses import dataclass, field
from multiprocessing import connection as mp_connection
from multiprocessing import util as mp_util
from multiprocessing.connection import Connection
from multiprocessing.context import BaseContext
from multiprocessing.process import BaseProcess
from multiprocessing.reduction import ForkingPickler
from pathlib import Path
from typing import Any

import cloudpickle

from pymc_vcc.physics.failures import FailureKind

_FUNCTION_CACHE: dict[str, Callable[..., Any]] = {}
_FUNCTION_CACHE_SIZE = 4
_STOP_SECONDS = 5.0
_AHEAD_BYTES = 4096  # a chunk message this small may wait in a busy worker's pipe (never blocks)
_LOADED = "loaded"  # a worker's note that it has the chunk's function and starts its items


@dataclass(frozen=True, slots=True)
class WorkerCrash:
    """Stands in for the result of an item whose run killed, or overran, its worker process.

    Attributes:
        reason: what happened, e.g. ``"worker process died (exit code -11 / signal SIGSEGV)"``.
        elapsed: wall time from the start of the item's lone run to the death, s (0 if unknown).
        kind: ``"worker-crash"`` (the process died) or ``"time-limit"`` (it was stopped for
            overrunning its time limit).
    """

    reason: str
    elapsed: float = 0.0
    kind: FailureKind = FailureKind.WORKER_CRASH


class WorkerDiedError(Exception):
    """Set on the future of a chunk whose worker process died while running it."""

    def __init__(self, crash: WorkerCrash) -> None:
        super().__init__(crash.reason)
        self.crash = crash


class MainGuardError(RuntimeError):
    """Worker processes die starting up because the main script has no main guard."""


def unguarded_main_script() -> str | None:
    """The path of the running script if it lacks an ``if __name__ == "__main__":`` guard."""
    path = getattr(sys.modules.get("__main__"), "__file__", None)
    try:
        tree = ast.parse(Path(path).read_text(encoding="utf-8")) if path else None
    except (OSError, SyntaxError, ValueError):
        return None
    if tree is None:
        return None
    for node in tree.body:
        if isinstance(node, ast.If):
            test = ast.unparse(node.test)
            if "__name__" in test and "__main__" in test:
                return None
    return str(path)


def _check_main_guard(exit_code: int | None) -> None:
    """Raise :class:`MainGuardError` if a worker exited with 1 under an unguarded script."""
    script = unguarded_main_script() if exit_code == 1 else None
    if script is not None:
        raise MainGuardError(
            f"worker processes die starting up because {script} has no "
            "'if __name__ == \"__main__\":' guard (each worker imports the script and runs it "
            "again): put the code that samples under that guard, or use executor='serial'"
        )


class _RemoteTraceback(Exception):
    """The traceback of an exception raised in a worker process, shown as its cause."""

    def __init__(self, text: str) -> None:
        super().__init__(text)
        self.text = text

    def __str__(self) -> str:
        return f'\n"""\n{self.text}"""'


def _load_function(token: str, payload: bytes) -> Callable[..., Any]:
    function = _FUNCTION_CACHE.get(token)
    if function is None:
        function = cloudpickle.loads(payload)
        if len(_FUNCTION_CACHE) >= _FUNCTION_CACHE_SIZE:
            _FUNCTION_CACHE.pop(next(iter(_FUNCTION_CACHE)))
        _FUNCTION_CACHE[token] = function
    return function


def run_chunk(
    token: str,
    payload: bytes,
    values: list,
    batched: bool,
    loaded: Callable[[], None] | None = None,
) -> tuple[list, float]:
    """Worker side: apply the function to one chunk; returns (results, seconds spent).

    ``loaded`` is called once the function is ready, before the first item runs.
    """
    function = _load_function(token, payload)
    if loaded is not None:
        loaded()
    start = time.perf_counter()
    results = function(values) if batched else [function(value) for value in values]
    return list(results), time.perf_counter() - start


def _worker_main(connection: Connection) -> None:
    """A local worker process: run the chunks received on ``connection`` until told to stop.

    Sends ``"loaded"`` once a chunk's function is ready, then replies ``(True, (results,
    seconds))`` or ``(False, exception, traceback text)``. Ctrl-C is left to the parent, which
    stops the workers; a ``SystemExit`` ends the worker like a crash.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)

    def loaded() -> None:
        connection.send(_LOADED)

    while True:
        try:
            job = connection.recv()
        except EOFError:  # the parent has gone
            return
        if job is None:
            return
        try:
            reply: tuple = (True, run_chunk(*job, loaded=loaded))
        except Exception as error:
            reply = (False, error, traceback.format_exc())
        try:
            connection.send(reply)
        except Exception as error:  # results or exception that cannot be pickled
            message = f"the worker could not send its reply back: {type(error).__name__}: {error}"
            connection.send((False, RuntimeError(message), traceback.format_exc()))


def _death_reason(exit_code: int | None) -> str:
    if exit_code is not None and exit_code < 0:
        try:
            name = signal.Signals(-exit_code).name
        except ValueError:
            name = f"signal {-exit_code}"
        hint = "; e.g. the out-of-memory killer" if -exit_code == signal.SIGKILL else ""
        return f"worker process died (exit code {exit_code} / signal {name}{hint})"
    return f"worker process died (exit code {exit_code})"


@dataclass
class _Job:
    future: futures.Future
    message: tuple
    data: bytes | None = None  # the pickled message, once taken from the queue
    started: float = 0.0
    time_limit: float | None = None  # s from the worker's "loaded" note; None: no limit
    loaded: bool = False

    def overdue(self, now: float) -> float:
        """Seconds past its time limit (negative: time left; -inf: no limit or not started)."""
        if self.time_limit is None or not self.loaded:
            return -math.inf
        return now - self.started - self.time_limit


@dataclass
class _Worker:
    process: BaseProcess
    connection: Connection
    jobs: deque[_Job] = field(default_factory=deque)  # sent, in order: the first one runs


def _stop_workers(workers: list[_Worker]) -> None:
    """Stop idle workers politely and busy ones (whose results nobody awaits) at once."""
    for worker in workers:
        if worker.jobs:
            worker.process.terminate()
        else:
            with suppress(OSError):
                worker.connection.send(None)
    deadline = time.monotonic() + _STOP_SECONDS
    for worker in workers:
        worker.process.join(max(deadline - time.monotonic(), 0.0))
        if worker.process.exitcode is None:
            worker.process.kill()
            worker.process.join()
        worker.connection.close()
    workers.clear()


class WorkerPool:
    """Local worker processes, each with its own pipe, driven from the calling thread.

    Each worker runs the chunks sent to it in order, and may hold one small chunk ahead (so
    that it never waits for the caller between chunks); knowing which chunk each worker runs
    pins a worker's death on that chunk alone, the chunk queued behind it goes back to the
    queue, and a new worker takes the dead one's place. No background thread: queued chunks go
    to workers whenever the caller submits or waits.
    """

    def __init__(self, context: BaseContext, n_workers: int) -> None:
        self._context = context
        self._workers: list[_Worker] = []
        self._queue: deque[_Job] = deque()
        self._finalizer = mp_util.Finalize(
            self, _stop_workers, args=(self._workers,), exitpriority=10
        )
        for _ in range(n_workers):
            self._workers.append(self._start_worker())

    def _start_worker(self) -> _Worker:
        parent_end, child_end = self._context.Pipe(duplex=True)
        process = self._context.Process(
            target=_worker_main, args=(child_end,), name="pymc_vcc-worker"
        )
        process.start()
        child_end.close()
        return _Worker(process, parent_end)

    def _replace(self, worker: _Worker, stopped: WorkerCrash | None = None) -> None:
        """Start a new process in place of ``worker``'s dead one; fail the chunk it was running.

        ``stopped`` is the crash to report when this pool ended the worker itself.
        """
        while worker.jobs and worker.connection.poll():  # replies sent before it died count
            if not self._receive_reply(worker):
                break
        worker.process.join(_STOP_SECONDS)
        if worker.process.exitcode is None:  # its pipe broke, yet it runs: end it
            worker.process.kill()
            worker.process.join()
        reason = _death_reason(worker.process.exitcode)
        worker.connection.close()
        _check_main_guard(worker.process.exitcode)
        jobs = worker.jobs
        new = self._start_worker()
        worker.process, worker.connection, worker.jobs = new.process, new.connection, deque()
        now = time.perf_counter()
        if stopped is not None and jobs and jobs[0].overdue(now) < 0:
            jobs[0].loaded = False  # the overdue chunk finished as it was stopped: rerun the next
            self._queue.extendleft(reversed(jobs))
        elif jobs:
            running = jobs.popleft()
            crash = WorkerCrash(reason, now - running.started) if stopped is None else stopped
            running.future.set_exception(WorkerDiedError(crash))
            self._queue.extendleft(reversed(jobs))  # never started: queued again, first

    def submit(self, message: tuple, time_limit: float | None = None) -> futures.Future:
        """Queue a chunk ``(token, payload, values, batched)``; its future gets the reply.

        A chunk still running ``time_limit`` s after its worker loaded the function is stopped
        (the worker terminated and replaced) and fails with a ``"time-limit"`` crash.
        """
        job = _Job(futures.Future(), message, time_limit=time_limit)
        self._queue.append(job)
        self._dispatch()
        return job.future

    def _take(self, ahead: bool) -> _Job | None:
        """The next queued chunk to send (None if none, or if it is too big to wait ahead)."""
        while self._queue:
            job = self._queue[0]
            if job.data is None:
                if not job.future.set_running_or_notify_cancel():
                    self._queue.popleft()
                    continue
                try:
                    job.data = bytes(ForkingPickler.dumps(job.message))
                except Exception as error:  # e.g. items that cannot be pickled
                    self._queue.popleft()
                    job.future.set_exception(error)
                    continue
            if ahead and len(job.data) > _AHEAD_BYTES:
                return None
            return self._queue.popleft()
        return None

    def _dispatch(self) -> None:
        """Give every idle worker a chunk, then each busy one a small chunk to hold ahead."""
        while self._queue:
            worker = min(self._workers, key=lambda candidate: len(candidate.jobs))
            if len(worker.jobs) > 1:
                return
            job = self._take(ahead=bool(worker.jobs))
            if job is None:
                return
            try:
                worker.connection.send_bytes(job.data)
            except (BrokenPipeError, ConnectionResetError):  # the worker has died
                self._queue.appendleft(job)
                self._replace(worker)
                continue
            if not worker.jobs:
                job.started = time.perf_counter()
            worker.jobs.append(job)

    def _receive_reply(self, worker: _Worker) -> bool:
        """Read the reply to ``worker``'s running chunk; False if the worker has gone."""
        try:
            reply = worker.connection.recv()
        except (EOFError, OSError):
            return False
        except Exception as error:  # a reply this process cannot unpickle
            reply = (False, error, traceback.format_exc())
        if reply == _LOADED:
            worker.jobs[0].started = time.perf_counter()
            worker.jobs[0].loaded = True
            return True
        job = worker.jobs.popleft()
        if worker.jobs:
            worker.jobs[0].started = time.perf_counter()
        if reply[0]:
            job.future.set_result(reply[1])
        else:
            error = reply[1]
            error.__cause__ = _RemoteTraceback(reply[2])
            job.future.set_exception(error)
        return True

    def wait_first(self, pending: list[futures.Future]) -> list[futures.Future]:
        """Block until at least one of ``pending`` is done; return the done ones."""
        self._dispatch()
        while True:
            done = [future for future in pending if future.done()]
            if done:
                return done
            busy = [worker for worker in self._workers if worker.jobs]
            if not busy:
                raise RuntimeError("waiting for chunks that were never submitted to this pool")
            handles = [worker.connection for worker in busy]
            handles += [worker.process.sentinel for worker in busy]
            now = time.perf_counter()
            most_overdue = max(worker.jobs[0].overdue(now) for worker in busy)
            timeout = None if most_overdue == -math.inf else max(-most_overdue, 0.0)
            ready = set(mp_connection.wait(handles, timeout))
            self._stop_overdue(busy)
            for worker in busy:
                if worker.connection in ready:
                    if not self._receive_reply(worker):
                        self._replace(worker)
                elif worker.process.sentinel in ready:
                    self._replace(worker)
            self._dispatch()  # feed freed workers before the caller handles the results

    def _stop_overdue(self, busy: list[_Worker]) -> None:
        """Terminate and replace each worker whose running chunk overran its time limit."""
        now = time.perf_counter()
        for worker in busy:
            job = worker.jobs[0]
            if job.overdue(now) < 0 or worker.connection.poll():  # done just in time: keep it
                continue
            worker.process.kill()
            elapsed = now - job.started
            reason = f"stopped after {elapsed:.3g} s, over its time limit of {job.time_limit:.3g} s"
            self._replace(worker, WorkerCrash(reason, elapsed, FailureKind.TIME_LIMIT))

    def close(self) -> None:
        """Stop every worker (busy ones at once) and cancel queued chunks."""
        for job in self._queue:
            job.future.cancel()
        self._queue.clear()
        self._finalizer()
