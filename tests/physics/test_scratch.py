"""The kernels' arrays without reference counts: views of the caller's arrays and stack arrays."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from typing import NamedTuple

import numpy as np
from numba import njit

from pymc_vcc.physics.scratch import borrowed, stack_empty, stack_full


class _Pair(NamedTuple):
    scale: float
    values: np.ndarray


@njit
def _write_through_views(a, pair):
    """Write through borrowed views of ``a`` and of a named tuple nested in a tuple."""
    (view, (scale, values)) = borrowed((a, pair))
    view[0] = 5.0
    values[1] = scale * view[1]
    return view.shape[0], view.strides[0]


def test_borrowed_views_see_and_change_the_callers_arrays() -> None:
    a = np.arange(6.0)
    pair = _Pair(2.0, np.zeros(3))
    size, stride = _write_through_views(a, pair)
    assert (size, stride) == (6, 8)
    assert a[0] == 5.0
    assert pair.values[1] == 2.0
    assert list(pair.values) == [0.0, 2.0, 0.0]


@njit
def _stack_sums(rows, cols):
    """Fill a stack array row-major with 0, 1, ...; return its layout and sums."""
    grid = stack_empty((rows, cols))
    line = stack_empty(cols)
    for i in range(rows):
        for j in range(cols):
            grid[i, j] = i * cols + j
    line[:] = grid[rows - 1]
    return grid.shape, grid.strides, grid.sum(), line.sum(), grid.flags.c_contiguous


def test_a_stack_array_has_its_shape_and_c_order() -> None:
    shape, strides, total, last_row, c_order = _stack_sums(3, 4)
    assert shape == (3, 4)
    assert strides == (32, 8)
    assert total == sum(range(12))
    assert last_row == 8 + 9 + 10 + 11
    assert c_order


@njit
def _filled(rows, cols):
    """A 2-D stack array of NaN and a 1-D one of an integer fill, as heap copies."""
    return stack_full((rows, cols), np.nan).copy(), stack_full(cols, 3).copy()


def test_a_full_stack_array_holds_its_value_everywhere() -> None:
    grid, line = _filled(5, 7)
    assert grid.shape == (5, 7)
    assert np.isnan(grid).all()
    assert line.dtype == np.float64
    assert (line == 3.0).all()


@njit
def _stack_in_a_loop(n):
    """Call a function that takes a stack array many times: its stack is given back."""
    total = 0.0
    for k in range(n):
        total += _scratch_call(k)
    return total


@njit
def _scratch_call(k):
    work = stack_empty(4096)
    work[:] = k
    return work[4095]


def test_a_function_with_a_stack_array_gives_its_stack_back() -> None:
    # 100 000 calls of 32 kB each would overflow any stack that was not given back
    assert _stack_in_a_loop(100_000) == sum(range(100_000))


_COUNT_ALLOCATIONS = """
import gc, json
from numba.core.runtime import rtsys
from pymc_vcc.physics.simulate import VCCSimulator
held = []
for solver in ("cvode", "radau"):
    simulator = VCCSimulator(t_window=(0.0, 120.0), solver=solver)
    for _ in range(2):
        outputs = simulator({}, None)
        del outputs
        gc.collect()
        stats = rtsys.get_allocation_stats()
        held.append([stats.alloc, stats.alloc - stats.free, stats.mi_alloc - stats.mi_free])
print(json.dumps(held))
"""


def test_simulations_give_back_every_array_numba_allocated() -> None:
    """The kernels compiled without reference counts neither leak nor free early: after each
    run, under both solvers, every array Numba allocated is freed."""
    result = subprocess.run(
        [sys.executable, "-c", _COUNT_ALLOCATIONS],
        env=os.environ | {"NUMBA_NRT_STATS": "1"},
        capture_output=True,
        text=True,
        check=True,
    )
    held = json.loads(result.stdout.strip().splitlines()[-1])
    assert held[-1][0] > held[0][0] > 0  # the runs allocated: the counts are on
    assert all(alive == 0 and meminfos == 0 for _, alive, meminfos in held)
