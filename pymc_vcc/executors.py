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
"""

from __future__ import annotations

import hashlib
import logging
import multiprocessing
import os
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Iterator
from concurrent import futures
from contextlib import contextmanager
from itertools import islice
from typing import Any, ClassVar, Literal

import cloudpickle

ExecutorKind = Literal["serial", "processes", "dask"]
EXECUTOR_KINDS: tuple[str, ...] = ("serial", "processes", "dask")

_FUNCTION_CACHE: dict[str, Callable[..., Any]] = {}
_FUNCTION_CACHE_SIZE = 4


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

    def map(
        self, fn: Callable[[Any], Any], items: Iterable[Any], *, chunksize: int | None = None
    ) -> list[Any]:
        """``[fn(item) for item in items]``, computed by the workers, in input order."""
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
        pending: dict[Any, tuple[int, ...]] = {}
        exhausted = False
        try:
            while True:
                while not exhausted and len(pending) < self._max_in_flight():
                    chunk = list(islice(numbered, sizer.size))
                    if not chunk:
                        exhausted = True
                        break
                    indices = tuple(index for index, _ in chunk)
                    values = [value for _, value in chunk]
                    pending[self._submit(handle, values, batched)] = indices
                if not pending:
                    return
                for future in self._wait_first(list(pending)):
                    indices = pending.pop(future)
                    results, seconds = future.result()
                    if len(results) != len(indices):
                        raise ValueError(
                            f"batched function returned {len(results)} results for "
                            f"{len(indices)} items"
                        )
                    sizer.record(len(indices), seconds)
                    yield list(zip(indices, results, strict=True))
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
        self._pool = futures.ProcessPoolExecutor(max_workers=self.n_workers, mp_context=context)

    def _prepare(self, fn: Callable[..., Any]) -> tuple[str, bytes]:
        return self._serialise(fn)

    def _submit(self, handle: tuple[str, bytes], values: list, batched: bool) -> futures.Future:
        token, payload = handle
        return self._pool.submit(_run_chunk, token, payload, values, batched)

    def _wait_first(self, pending: list) -> Iterable[Any]:
        done, _ = futures.wait(pending, return_when=futures.FIRST_COMPLETED)
        return done

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)


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

    def _prepare(self, fn: Callable[..., Any]) -> tuple[str, Any]:
        token, payload = self._serialise(fn)
        return token, self._client.scatter(payload, broadcast=True, hash=False)

    def _submit(self, handle: tuple[str, Any], values: list, batched: bool) -> Any:
        token, payload = handle
        return self._client.submit(_run_chunk, token, payload, values, batched, pure=False)

    def _wait_first(self, pending: list) -> Iterable[Any]:
        from distributed import wait

        return wait(pending, return_when="FIRST_COMPLETED").done

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
