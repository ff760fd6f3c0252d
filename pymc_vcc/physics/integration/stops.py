"""Where a solver stops over a piecewise-constant input profile: each segment's output times and
its end, the rows of the output grid they fill, and the row at each segment's start.

Both solvers read one :class:`StopPlan`: CVODE's compiled loop walks it stop by stop
(:mod:`.sundials`), Radau segment by segment (:mod:`.segments`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class StopPlan(NamedTuple):
    """Where CVODE stops over a piecewise-constant input profile (:func:`stop_plan`)."""

    times: np.ndarray
    """Every stop in order, s: the output times and the end of each segment."""
    rows: np.ndarray
    """The output row of each stop; -1 for a segment's end that is no output time."""
    starts: np.ndarray
    """The segment each stop is the first of; -1 for the others."""
    held: np.ndarray
    """Each segment's inputs, a row each."""
    edges: np.ndarray
    """The segments' bounds, s (one more than segments)."""
    start_rows: np.ndarray
    """The output row at each segment's start time; -1 where none falls there."""
    u: np.ndarray
    """The inputs the right-hand side reads (the compiled loop writes each segment's there)."""


def stop_plan(edges: np.ndarray, held: np.ndarray, times: np.ndarray, u: np.ndarray) -> StopPlan:
    """The :class:`StopPlan` of segments ``edges`` (s) holding inputs ``held`` and output
    ``times`` (s, sorted, from ``edges[0]`` to ``edges[-1]``): an output time on a segment's
    start is that segment's (the last segment also takes its end)."""
    stops, rows, starts, start_rows = [], [], [], []
    last = len(held) - 1
    for k in range(len(held)):
        t0, t1 = edges[k], edges[k + 1]
        lo = int(np.searchsorted(times, t0, side="left"))
        hi = int(np.searchsorted(times, t1, side="right" if k == last else "left"))
        at_start = lo < hi and times[lo] == t0
        start_rows.append(lo if at_start else -1)
        inside = np.arange(lo + at_start, hi)
        if not inside.size or times[inside[-1]] != t1:
            inside = np.append(inside, -1)  # the segment's end, no output time
        starts += [k] + [-1] * (inside.size - 1)
        rows.append(inside)
        stops.append(np.where(inside >= 0, times[np.maximum(inside, 0)], t1))
    return StopPlan(
        np.concatenate(stops),
        np.concatenate(rows).astype(np.int64),
        np.array(starts, dtype=np.int64),
        np.ascontiguousarray(held, dtype=np.float64),
        np.ascontiguousarray(edges, dtype=np.float64),
        np.array(start_rows, dtype=np.int64),
        u,
    )


def segment_stops(plan: StopPlan, k: int) -> tuple[np.ndarray, np.ndarray]:
    """(times s, output rows) of segment ``k``'s stops that are output times."""
    first = np.flatnonzero(plan.starts == k)[0]
    later = np.flatnonzero(plan.starts > k)
    end = later[0] if later.size else plan.times.size
    rows = plan.rows[first:end]
    return plan.times[first:end][rows >= 0], rows[rows >= 0]
