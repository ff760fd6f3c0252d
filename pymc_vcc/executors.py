"""Where simulations run: in this process, in local worker processes, or on a Dask cluster.

All backends share one interface::

    with make_executor("processes") as ex:          # or "serial", or "dask"
        results = ex.map(fn, items)                 # in input order
        for index, result in ex.imap_unordered(fn, items):
            ...                                     # as they finish

``fn`` is serialised once per call with cloudpickle (so functions defined in a notebook work in
worker processes too) and items travel in chunks sized from measured run times (about
``target_chunk_seconds`` of work each), which keeps per-item overhead small for fast functions
and gives single-item chunks for slow ones. Results never depend on the backend: randomness must
come with the items (e.g. a seed per item), never from worker state.

Worker processes start with ``forkserver`` (safe in programs that run threads, as PyMC, Dask and
BLAS do): a script using the ``"processes"`` executor needs the usual
``if __name__ == "__main__":`` guard around its main code, as any multiprocessing script does.

Worker crashes. A worker process that dies while running a chunk (a segfault in compiled code,
``os._exit``, the out-of-memory killer) never stops the stream: the chunk's items run again, one
item per chunk, and an item whose lone run kills its worker too is the culprit: it comes back as a
:class:`WorkerCrash` instead of a result (``map`` puts it at the item's position). Nothing already
finished is lost. The local-process backend gives each worker its own pipe, so a death is pinned on
the chunk that worker was running, a new worker takes its place at once and the other workers go on
undisturbed; a crash costs the start of that worker (with the imports of the main script and of
``fn``'s modules: a fraction of a second to a few seconds). On Dask the scheduler retries a task
whose worker died and gives up after ``distributed.scheduler.allowed-failures`` more deaths
(``KilledWorker``); it counts a death against every task queued on that worker, so the items of a
chunk that gave up are rerun one at a time with nothing else in flight, and one that gives up alone
is the culprit. Dask workers started without a nanny are not restarted: once all have died, the run
waits for new ones. The serial backend runs items in the calling process: a crash there ends the
caller.
"""

from __future__ import annotations

import hashlib
import logging
import multiprocessing
import os
import signal
import time
import traceback
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent import futures
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from itertools import islice
from multiprocessing import connection as mp_connection
from multiprocessing import util as mp_util
from multiprocessing.connection import Connection
from multiprocessing.context import BaseContext
from multiprocessing.process import BaseProcess
from multiprocessing.reduction import ForkingPickler
from typing import Any, ClassVar, Literal

import cloudpickle

ExecutorKind = Literal["serial", "processes", "dask"]
EXECUTOR_KINDS: tuple[str, ...] = ("serial", "processes", "dask")

_FUNCTION_CACHE: dict[str, Callable[..., Any]] = {}
_FUNCTION_CACHE_SIZE = 4
_STOP_SECONDS = 5.0
_AHEAD_BYTES = 4096  # a chunk message this small may wait in a busy worker's pipe (never blocks)


@dataclass(frozen=True, slots=True)
class WorkerCrash:
    """Stands in for the result of an item whose run killed the worker process running it.

    Attributes:
        reason: what happened, e.g. ``"worker process died (exit code -11 / signal SIGSEGV)"``.
        elapsed: wall time from the start of the item's lone run to the death, s (0 if unknown).
    """

    reason: str
    elapsed: float = 0.0


class _WorkerDiedError(Exception):
    """Set on the future of a chunk whose worker process died while running it."""

    def __init__(self, crash: WorkerCrash) -> None:
        super().__init__(crash.reason)
        self.crash = crash


class _RemoteTraceback(Exception):
    """The traceback of an exception raised in a worker process, shown as its cause."""

    def __init__(self, text: str) -> None:
        super().__init__(text)
        self.text = text

    def __str__(self) -> str:
        return f'\n"""\n{self.text}"""'


def available_cores() -> int:
    """CPU cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # platforms without sched_getaffinity
        return os.cpu_count() or 1


def _load_function(token: str, payload: bytes) -> Callable[..., Any]:
    function = _FUNCTION_CACHE.get(token)
    if function is None:
        function = cloudpickle.loads(payload)
        if len(_FUNCTION_CACHE) >= _FUNCTION_CACHE_SIZE:
            _FUNCTION_CACHE.pop(next(iter(_FUNCTION_CACHE)))
        _FUNCTION_CACHE[token] = function
    return function


def _run_chunk(token: str, payload: bytes, values: list, batched: bool) -> tuple[list, float]:
    """Worker side: apply the function to one chunk; returns (results, seconds spent)."""
    function = _load_function(token, payload)
    start = time.perf_counter()
    results = function(values) if batched else [function(value) for value in values]
    return list(results), time.perf_counter() - start


def _worker_main(connection: Connection) -> None:
    """A local worker process: run the chunks received on ``connection`` until told to stop.

    Replies ``(True, (results, seconds))`` or ``(False, exception, traceback text)``. Ctrl-C is
    left to the parent, which stops the workers; a ``SystemExit`` ends the worker like a crash.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    while True:
        try:
            job = connection.recv()
        except EOFError:  # the parent has gone
            return
        if job is None:
            return
        try:
            reply: tuple = (True, _run_chunk(*job))
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


class _WorkerPool:
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

    def _replace(self, worker: _Worker) -> None:
        """Start a new process in place of ``worker``'s dead one; fail the chunk it was running."""
        while worker.jobs and worker.connection.poll():  # replies sent before it died count
            if not self._receive_reply(worker):
                break
        worker.process.join(_STOP_SECONDS)
        if worker.process.exitcode is None:  # its pipe broke, yet it runs: end it
            worker.process.kill()
            worker.process.join()
        reason = _death_reason(worker.process.exitcode)
        worker.connection.close()
        jobs = worker.jobs
        new = self._start_worker()
        worker.process, worker.connection, worker.jobs = new.process, new.connection, deque()
        if jobs:
            running = jobs.popleft()
            elapsed = time.perf_counter() - running.started
            running.future.set_exception(_WorkerDiedError(WorkerCrash(reason, elapsed)))
            self._queue.extendleft(reversed(jobs))  # never started: queued again, first

    def submit(self, message: tuple) -> futures.Future:
        """Queue a chunk ``(token, payload, values, batched)``; its future gets the reply."""
        job = _Job(futures.Future(), message)
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
            ready = set(mp_connection.wait(handles))
            for worker in busy:
                if worker.connection in ready:
                    if not self._receive_reply(worker):
                        self._replace(worker)
                elif worker.process.sentinel in ready:
                    self._replace(worker)
            self._dispatch()  # feed freed workers before the caller handles the results

    def close(self) -> None:
        """Stop every worker (busy ones at once) and cancel queued chunks."""
        for job in self._queue:
            job.future.cancel()
        self._queue.clear()
        self._finalizer()


class _ChunkSizer:
    """Chunk sizes aiming at ``target_seconds`` of work, from measured seconds per item."""

    def __init__(self, fixed: int | None, target_seconds: float, max_size: int = 4096):
        if fixed is not None and fixed < 1:
            raise ValueError(f"chunksize must be a positive integer, got {fixed}")
        self._fixed = fixed
        self._target = target_seconds
        self._max = max_size
        self._items = 0
        self._seconds = 0.0

    @property
    def size(self) -> int:
        if self._fixed is not None:
            return self._fixed
        if self._items == 0:
            return 1
        per_item = max(self._seconds / self._items, 1e-7)
        return int(min(max(self._target / per_item, 1), self._max))

    def record(self, n_items: int, seconds: float) -> None:
        self._items += n_items
        self._seconds += seconds


class Executor(ABC):
    """Runs a picklable function over items; see the module docstring.

    Attributes:
        n_workers: how many items run at the same time.
        target_chunk_seconds: work per chunk the automatic chunk size aims at, s.
    """

    kind: ClassVar[str]
    n_workers: int
    target_chunk_seconds: float = 0.05
    # True when a dying worker fails only the chunk it was running; else the items of a crashed
    # chunk are rerun one at a time with nothing else in flight, so that a crash names its item
    _pins_crashes: ClassVar[bool] = True

    def map(
        self, fn: Callable[[Any], Any], items: Iterable[Any], *, chunksize: int | None = None
    ) -> list[Any]:
        """``[fn(item) for item in items]``, computed by the workers, in input order.

        An item whose run killed its worker process gives a :class:`WorkerCrash` instead.
        """
        items = list(items)
        results: list[Any] = [None] * len(items)
        for index, result in self.imap_unordered(fn, items, chunksize=chunksize):
            results[index] = result
        return results

    def imap_unordered(
        self,
        fn: Callable[[Any], Any],
        items: Iterable[Any],
        *,
        chunksize: int | None = None,
        batched: bool = False,
    ) -> Iterator[tuple[int, Any]]:
        """Yield ``(index, fn(item))`` as results finish; ``index`` is the item's position.

        An item whose run killed its worker process gives ``(index, WorkerCrash(...))``.

        Items are read lazily, a bounded number of chunks ahead, so closing the iterator early
        (``break`` in a ``for`` loop over ``contextlib.closing(...)``) leaves the rest unread
        and cancels what has not started. With ``batched=True``, ``fn`` takes a list of items
        and returns the list of their results (vectorised work per chunk).
        """
        chunks = self.imap_chunks(fn, items, chunksize=chunksize, batched=batched)
        try:
            for chunk in chunks:
                yield from chunk
        finally:
            chunks.close()

    def imap_chunks(
        self,
        fn: Callable[[Any], Any],
        items: Iterable[Any],
        *,
        chunksize: int | None = None,
        batched: bool = False,
    ) -> Iterator[list[tuple[int, Any]]]:
        """Like :meth:`imap_unordered`, but yield each finished chunk as one list of results.

        Lets a caller act once per chunk (e.g. persist a checkpoint) rather than per item.
        """
        handle = self._prepare(fn)
        numbered = enumerate(items)
        sizer = _ChunkSizer(chunksize, self.target_chunk_seconds)
        pending: dict[Any, list[tuple[int, Any]]] = {}
        again: deque[list[tuple[int, Any]]] = deque()  # chunks to submit before new ones
        suspects: set[int] = set()  # items of crashed chunks, rerun alone to find the culprit
        exhausted = False
        try:
            while True:
                isolate = bool(suspects) and not self._pins_crashes
                while len(pending) < (1 if isolate else self._max_in_flight()):
                    if again:
                        chunk = again.popleft()
                    elif not exhausted:
                        chunk = list(islice(numbered, sizer.size))
                        exhausted = not chunk
                        if exhausted:
                            break
                    else:
                        break
                    pending[self._submit(handle, [value for _, value in chunk], batched)] = chunk
                if not pending:
                    return
                for future in self._wait_first(list(pending)):
                    chunk = pending.pop(future)
                    crash = self._crash(future)
                    if crash is not None:
                        if len(chunk) == 1:
                            suspects.discard(chunk[0][0])
                            yield [(chunk[0][0], crash)]
                        else:
                            suspects.update(index for index, _ in chunk)
                            again.extend([item] for item in chunk)
                        continue
                    try:
                        results, seconds = future.result()
                    except futures.CancelledError:  # the backend lost the chunk or its inputs
                        again.appendleft(chunk)
                        continue
                    if len(results) != len(chunk):
                        raise ValueError(
                            f"batched function returned {len(results)} results for "
                            f"{len(chunk)} items"
                        )
                    sizer.record(len(chunk), seconds)
                    suspects.difference_update(index for index, _ in chunk)
                    yield [
                        (index, result) for (index, _), result in zip(chunk, results, strict=True)
                    ]
        finally:
            if pending:
                self._cancel(list(pending))

    def _max_in_flight(self) -> int:
        return 2 * self.n_workers

    @abstractmethod
    def _prepare(self, fn: Callable[..., Any]) -> Any:
        """Make ``fn`` ready to send (once per imap call)."""

    @abstractmethod
    def _submit(self, handle: Any, values: list, batched: bool) -> Any:
        """Start one chunk; return a future whose result is ``(results, seconds)``."""

    @abstractmethod
    def _wait_first(self, pending: list) -> Iterable[Any]:
        """Block until at least one pending future is done; return the done ones."""

    def _crash(self, future: Any) -> WorkerCrash | None:
        """The crash that ended a done chunk, if its worker died running it."""
        return None

    def _cancel(self, pending: list) -> None:
        for future in pending:
            future.cancel()

    @abstractmethod
    def close(self) -> None:
        """Release the workers."""

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"{type(self).__name__}(n_workers={self.n_workers})"


class SerialExecutor(Executor):
    """Everything in the calling process, one item after another."""

    kind = "serial"

    def __init__(self) -> None:
        self.n_workers = 1

    def _max_in_flight(self) -> int:
        return 1

    def _prepare(self, fn: Callable[..., Any]) -> Callable[..., Any]:
        return fn

    def _submit(self, handle: Callable[..., Any], values: list, batched: bool) -> futures.Future:
        start = time.perf_counter()
        results = handle(values) if batched else [handle(value) for value in values]
        future: futures.Future = futures.Future()
        future.set_result((list(results), time.perf_counter() - start))
        return future

    def _wait_first(self, pending: list) -> Iterable[Any]:
        return pending

    def close(self) -> None:
        """Nothing to release."""


class _PickledFunctionExecutor(Executor):
    """Backends that ship the function as cloudpickle bytes, identified by their hash."""

    @staticmethod
    def _serialise(fn: Callable[..., Any]) -> tuple[str, bytes]:
        payload = cloudpickle.dumps(fn)
        return hashlib.sha1(payload).hexdigest(), payload


class ProcessExecutor(_PickledFunctionExecutor):
    """A pool of local worker processes (forkserver start: safe in threaded programs).

    A worker that dies is replaced at once, and its chunk rerun item by item (see the module
    docstring).

    Args:
        n_workers: number of processes (default: every core this process may use).
    """

    kind = "processes"

    def __init__(self, n_workers: int | None = None) -> None:
        self.n_workers = available_cores() if n_workers is None else n_workers
        if self.n_workers < 1:
            raise ValueError(f"n_workers must be >= 1, got {self.n_workers}")
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(["numpy", "xarray", "pymc_vcc.executors"])
        self._pool = _WorkerPool(context, self.n_workers)

    def _prepare(self, fn: Callable[..., Any]) -> tuple[str, bytes]:
        return self._serialise(fn)

    def _submit(self, handle: tuple[str, bytes], values: list, batched: bool) -> futures.Future:
        token, payload = handle
        return self._pool.submit((token, payload, values, batched))

    def _wait_first(self, pending: list) -> Iterable[Any]:
        return self._pool.wait_first(pending)

    def _crash(self, future: futures.Future) -> WorkerCrash | None:
        error = future.exception()
        return error.crash if isinstance(error, _WorkerDiedError) else None

    def close(self) -> None:
        self._pool.close()


@dataclass
class _ScatteredFunction:
    """A function sent to every Dask worker once: its hash, its bytes and their scattered copy.

    ``data`` becomes None once every worker holding the copy has died: the bytes then travel
    with each chunk, so that a chunk whose worker dies is retried (and counted towards
    ``KilledWorker``) rather than cancelled for a lost input.
    """

    token: str
    payload: bytes
    data: Any | None


class DaskExecutor(_PickledFunctionExecutor):
    """Dask distributed: a running scheduler, a cluster object, or a new local cluster.

    Args:
        address: scheduler address (``"tcp://host:port"``) or a cluster object (e.g.
            ``distributed.LocalCluster``); None starts a local cluster of single-threaded
            worker processes, closed with the executor.
        n_workers: workers of a new local cluster (default: every core); with an address, wait
            until this many worker threads have joined.
        timeout: seconds to wait for workers to join, s.
    """

    kind = "dask"
    _pins_crashes = False  # every task queued on a dying worker counts towards KilledWorker

    def __init__(
        self, address: Any = None, n_workers: int | None = None, timeout: float = 60.0
    ) -> None:
        from distributed import Client, LocalCluster

        self._cluster = None
        if address is None:
            self._cluster = LocalCluster(
                n_workers=available_cores() if n_workers is None else n_workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.ERROR,
            )
            address = self._cluster
        self._client = Client(address, timeout=timeout)
        self._client.wait_for_workers(n_workers or 1, timeout=timeout)
        self.n_workers = sum(self._client.nthreads().values())

    @property
    def client(self) -> Any:
        """The ``distributed.Client`` in use."""
        return self._client

    def _prepare(self, fn: Callable[..., Any]) -> _ScatteredFunction:
        token, payload = self._serialise(fn)
        return _ScatteredFunction(
            token, payload, self._client.scatter(payload, broadcast=True, hash=False)
        )

    def _submit(self, handle: _ScatteredFunction, values: list, batched: bool) -> Any:
        if handle.data is not None and handle.data.status != "finished":
            handle.data = None
        payload = handle.payload if handle.data is None else handle.data
        return self._client.submit(_run_chunk, handle.token, payload, values, batched, pure=False)

    def _wait_first(self, pending: list) -> Iterable[Any]:
        from distributed import wait

        try:
            return wait(pending, return_when="FIRST_COMPLETED").done
        except futures.CancelledError:  # the scheduler cancels chunks whose inputs were lost
            return [future for future in pending if future.status != "pending"]

    def _crash(self, future: Any) -> WorkerCrash | None:
        if future.status != "error":
            return None
        from distributed import KilledWorker

        error = future.exception()
        if not isinstance(error, KilledWorker):
            return None
        return WorkerCrash(
            f"Dask worker process died running it, on each of {error.allowed_failures + 1} "
            "workers tried (KilledWorker; see distributed.scheduler.allowed-failures)"
        )

    def _cancel(self, pending: list) -> None:
        self._client.cancel(pending)

    def close(self) -> None:
        self._client.close()
        if self._cluster is not None:
            self._cluster.close()


def make_executor(
    kind: ExecutorKind = "processes",
    n_workers: int | None = None,
    address: Any = None,
) -> Executor:
    """An executor of the given kind.

    Args:
        kind: ``"serial"`` (this process), ``"processes"`` (local worker processes, default) or
            ``"dask"`` (a Dask cluster).
        n_workers: worker processes for ``"processes"`` and a new local Dask cluster (default:
            every core this process may use).
        address: for ``"dask"``: scheduler address or cluster object (None: start a local one).
    """
    if kind == "serial":
        return SerialExecutor()
    if kind == "processes":
        return ProcessExecutor(n_workers)
    if kind == "dask":
        return DaskExecutor(address=address, n_workers=n_workers)
    raise ValueError(f"unknown executor kind {kind!r}; choose one of {list(EXECUTOR_KINDS)}")


@contextmanager
def executor_scope(
    executor: Executor | ExecutorKind, n_workers: int | None = None
) -> Iterator[Executor]:
    """Use ``executor`` if it is one (left open), else make one of that kind and close it after."""
    if isinstance(executor, Executor):
        yield executor
        return
    with make_executor(executor, n_workers=n_workers) as made:
        yield made
