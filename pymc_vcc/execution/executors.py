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

Time limits. ``time_limit=`` (seconds per item) is enforced by stopping the work, where the
backend can. The local-process backend terminates a worker whose chunk overruns
``time_limit`` per item (plus a grace of :data:`TIME_LIMIT_GRACE`), starts a new one, reruns
the chunk's items one at a time, and returns an item that overruns alone as a
:class:`WorkerCrash` of kind ``"time-limit"``: a simulation stuck in compiled code or in a
system call is stopped too. Dask cannot stop a running task (its worker thread runs on, and
``Client.cancel`` only drops its result) and the serial backend cannot stop the calling
process: there the limit is only what the task itself enforces (see
:func:`pymc_vcc.execution.outcomes.time_limit`: an alarm signal in a main thread, an exception
at the next Python bytecode in a Dask thread), so a call stuck in compiled code is counted as
over time when it returns, not stopped.
"""

from __future__ import annotations

import hashlib
import logging
import multiprocessing
import os
import socket
import time
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Callable, Generator, Iterable, Iterator
from concurrent import futures
from dataclasses import dataclass
from itertools import islice
from typing import Any, ClassVar, Literal
from urllib.parse import urlsplit

import cloudpickle

from pymc_vcc.execution.worker_pool import WorkerCrash, WorkerDiedError, WorkerPool, run_chunk

ExecutorKind = Literal["serial", "processes", "dask"]
EXECUTOR_KINDS: tuple[str, ...] = ("serial", "processes", "dask")
TIME_LIMIT_GRACE = 1.0
"""Seconds a local worker gets beyond its chunk's time limit before it is terminated, s (the
task's own limit, where it has one, ends a Python-level overrun first)."""


def available_cores() -> int:
    """CPU cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # platforms without sched_getaffinity
        return os.cpu_count() or 1


def check_n_workers(n_workers: int | None) -> None:
    """Refuse a worker count that is not None or a positive integer."""
    if n_workers is not None and not (
        isinstance(n_workers, int) and not isinstance(n_workers, bool) and n_workers >= 1
    ):
        raise ValueError(f"n_workers must be a positive integer, got {n_workers!r}")


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
        self,
        fn: Callable[[Any], Any],
        items: Iterable[Any],
        *,
        chunksize: int | None = None,
        time_limit: float | None = None,
    ) -> list[Any]:
        """``[fn(item) for item in items]``, computed by the workers, in input order.

        An item whose run killed its worker process, or that a local worker was stopped for
        overrunning ``time_limit`` s, gives a :class:`WorkerCrash` instead.
        """
        items = list(items)
        results: list[Any] = [None] * len(items)
        for index, result in self.imap_unordered(
            fn, items, chunksize=chunksize, time_limit=time_limit
        ):
            results[index] = result
        return results

    def imap_unordered(
        self,
        fn: Callable[[Any], Any],
        items: Iterable[Any],
        *,
        chunksize: int | None = None,
        batched: bool = False,
        time_limit: float | None = None,
    ) -> Iterator[tuple[int, Any]]:
        """Yield ``(index, fn(item))`` as results finish; ``index`` is the item's position.

        An item whose run killed its worker process gives ``(index, WorkerCrash(...))``, as
        does one that a local worker was stopped for running longer than ``time_limit`` s (see
        the module docstring).

        Items are read lazily, a bounded number of chunks ahead, so closing the iterator early
        (``break`` in a ``for`` loop over ``contextlib.closing(...)``) leaves the rest unread
        and cancels what has not started. With ``batched=True``, ``fn`` takes a list of items
        and returns the list of their results (vectorised work per chunk).
        """
        chunks = self.imap_chunks(
            fn, items, chunksize=chunksize, batched=batched, time_limit=time_limit
        )
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
        time_limit: float | None = None,
    ) -> Generator[list[tuple[int, Any]], None, None]:
        """Like :meth:`imap_unordered`, but yield each finished chunk as one list of results.

        Lets a caller act once per chunk (e.g. persist a checkpoint) rather than per item.
        """
        if time_limit is not None and not time_limit > 0:
            raise ValueError(f"time_limit must be a positive number of seconds, got {time_limit}")
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
                    values = [value for _, value in chunk]
                    limit = None if time_limit is None else len(chunk) * time_limit
                    pending[self._submit(handle, values, batched, limit)] = chunk
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
    def _submit(self, handle: Any, values: list, batched: bool, time_limit: float | None) -> Any:
        """Start one chunk (stopped after ``time_limit`` s where the backend can); return a
        future whose result is ``(results, seconds)``."""

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

    def _submit(
        self, handle: Callable[..., Any], values: list, batched: bool, time_limit: float | None
    ) -> futures.Future:
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
        check_n_workers(n_workers)
        self.n_workers = available_cores() if n_workers is None else n_workers
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(["numpy", "xarray", "pymc_vcc.execution.executors"])
        self._pool = WorkerPool(context, self.n_workers)

    def _prepare(self, fn: Callable[..., Any]) -> tuple[str, bytes]:
        return self._serialise(fn)

    def _submit(
        self, handle: tuple[str, bytes], values: list, batched: bool, time_limit: float | None
    ) -> futures.Future:
        token, payload = handle
        limit = None if time_limit is None else time_limit + TIME_LIMIT_GRACE
        return self._pool.submit((token, payload, values, batched), limit)

    def _wait_first(self, pending: list) -> Iterable[Any]:
        return self._pool.wait_first(pending)

    def _crash(self, future: futures.Future) -> WorkerCrash | None:
        error = future.exception()
        return error.crash if isinstance(error, WorkerDiedError) else None

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
        connect_timeout: seconds to wait for the scheduler at ``address`` to answer, s.

    Raises:
        ConnectionError: no scheduler answers at ``address`` within ``connect_timeout``.
    """

    kind = "dask"
    _pins_crashes = False  # every task queued on a dying worker counts towards KilledWorker

    def __init__(
        self,
        address: Any = None,
        n_workers: int | None = None,
        timeout: float = 60.0,
        connect_timeout: float = 5.0,
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
        try:
            self._client = Client(
                address, timeout=timeout if self._cluster is not None else connect_timeout
            )
        except OSError as error:
            raise ConnectionError(
                f"no Dask scheduler answers at {address} within {connect_timeout:g} s ({error}); "
                "start one with `dask scheduler`, or check the address"
            ) from None
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

    def _submit(
        self, handle: _ScatteredFunction, values: list, batched: bool, time_limit: float | None
    ) -> Any:
        if handle.data is not None and handle.data.status != "finished":
            handle.data = None
        payload = handle.payload if handle.data is None else handle.data
        return self._client.submit(run_chunk, handle.token, payload, values, batched, pure=False)

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


def check_scheduler(address: str, timeout: float = 3.0) -> None:
    """Refuse at once a ``tcp://host:port`` Dask scheduler address where nothing listens.

    Raises:
        ConnectionError: no connection to ``address`` within ``timeout`` s.
    """
    parsed = urlsplit(address)
    if parsed.scheme != "tcp" or parsed.hostname is None or parsed.port is None:
        return  # other transports: left to the Dask client
    try:
        socket.create_connection((parsed.hostname, parsed.port), timeout=timeout).close()
    except OSError as error:
        raise ConnectionError(
            f"no Dask scheduler answers at {address} ({error.strerror or error}); start one "
            "with `dask scheduler`, or check the address"
        ) from None


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
    check_n_workers(n_workers)
    if kind == "serial":
        return SerialExecutor()
    if kind == "processes":
        return ProcessExecutor(n_workers)
    if kind == "dask":
        return DaskExecutor(address=address, n_workers=n_workers)
    raise ValueError(f"unknown executor kind {kind!r}; choose one of {list(EXECUTOR_KINDS)}")
