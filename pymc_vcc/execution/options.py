"""How a run executes: where its simulations run, how many at once, its checkpoint and seed.

Every sampler and simulation batch takes these as one :class:`RunOptions` (``run=``), so that
a study, the command line or a notebook states them once::

    run = RunOptions(executor="processes", n_workers=4, seed=1, time_limit=60.0)
    abc_rejection(simulator, prior, observed, run=run)
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pymc_vcc.execution.executors import (
    EXECUTOR_KINDS,
    Executor,
    ExecutorKind,
    check_n_workers,
    make_executor,
)


@dataclass(frozen=True)
class RunOptions:
    """Where and how a run's simulations execute.

    Attributes:
        executor: an :class:`~pymc_vcc.execution.executors.Executor` (used, left open), or
            ``"serial"``, ``"processes"`` (default: local worker processes) or ``"dask"`` (a
            new local cluster), opened for the run and closed after it.
        n_workers: workers of an executor opened for the run (default: every core).
        checkpoint: where finished simulations persist (a file or a folder, as the entry point
            says); a run started again with the same arguments resumes there. None: nowhere.
        seed: integer or SeedSequence; the same seed gives the same result on any executor.
            None: fresh entropy.
        time_limit: wall-time limit of one simulation, s; a slower run counts as failed (a
            local worker process that overruns it is stopped and replaced). None: no limit.
        progress: show a progress bar (default: when standard error is a terminal).
        max_failure_rate: fraction of a phase's simulations that may fail before a sampler
            stops with an error, in (0, 1].
    """

    executor: Executor | ExecutorKind = "processes"
    n_workers: int | None = None
    checkpoint: str | Path | None = None
    seed: int | np.random.SeedSequence | None = None
    time_limit: float | None = None
    progress: bool | None = None
    max_failure_rate: float = 0.5

    def __post_init__(self) -> None:
        if not isinstance(self.executor, Executor) and self.executor not in EXECUTOR_KINDS:
            raise ValueError(
                f"executor must be an Executor or one of {list(EXECUTOR_KINDS)}, "
                f"got {self.executor!r}"
            )
        check_n_workers(self.n_workers)
        if self.time_limit is not None and not self.time_limit > 0:
            raise ValueError(
                f"time_limit must be a positive number of seconds, got {self.time_limit!r}"
            )
        if not 0.0 < self.max_failure_rate <= 1.0:
            raise ValueError(f"max_failure_rate must lie in (0, 1], got {self.max_failure_rate}")

    def seed_sequence(self) -> np.random.SeedSequence:
        """The run's :attr:`seed` as a SeedSequence (fresh entropy for None)."""
        if isinstance(self.seed, np.random.SeedSequence):
            return self.seed
        return np.random.SeedSequence(self.seed)

    def refuse_checkpoint(self, entry: str) -> None:
        """Refuse a checkpoint where ``entry`` (a function's name) keeps none.

        Raises:
            ValueError: :attr:`checkpoint` is set.
        """
        if self.checkpoint is not None:
            raise ValueError(f"{entry} keeps no checkpoint; give RunOptions(checkpoint=None)")

    @contextmanager
    def open_executor(self) -> Iterator[Executor]:
        """The executor given, left open; or a new one of the kind given, closed on exit."""
        if isinstance(self.executor, Executor):
            yield self.executor
            return
        with make_executor(self.executor, n_workers=self.n_workers) as made:
            yield made
