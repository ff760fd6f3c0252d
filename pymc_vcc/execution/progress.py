"""A progress bar for sampling phases: simulations done, accepted, failed, time left.

Shown on standard error when it is a terminal (or when asked), silent otherwise.
"""

from __future__ import annotations

import sys

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)


def progress_enabled(requested: bool | None) -> bool:
    """``requested`` if given, else whether standard error is a terminal."""
    return sys.stderr.isatty() if requested is None else bool(requested)


class PhaseProgress:
    """One bar per sampling phase; a no-op when disabled."""

    def __init__(self, enabled: bool) -> None:
        self._progress = None
        if enabled:
            self._progress = Progress(
                TextColumn("{task.description}"),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn("accepted {task.fields[accepted]}  failed {task.fields[failed]}"),
                TimeElapsedColumn(),
                TextColumn("ETA"),
                TimeRemainingColumn(),
                console=Console(stderr=True),
            )
            self._progress.start()
        self._task = None

    def start_phase(self, description: str, total: int, done: int = 0) -> None:
        """Begin a bar of ``total`` simulations, ``done`` of them already finished."""
        if self._progress is not None:
            self._task = self._progress.add_task(
                description, total=total, completed=done, accepted=0, failed=0
            )

    def update(self, done: int, accepted: int, failed: int) -> None:
        """Show the phase's counts so far."""
        if self._progress is not None and self._task is not None:
            self._progress.update(self._task, completed=done, accepted=accepted, failed=failed)

    def close(self) -> None:
        """Stop drawing."""
        if self._progress is not None:
            self._progress.stop()

    def __enter__(self) -> PhaseProgress:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
