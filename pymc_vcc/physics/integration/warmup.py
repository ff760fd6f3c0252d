"""Compile the cycle model once per process, before any simulation's wall clock starts.

The cycle's Numba kernels compile on their first call (``cache=True`` keeps the machine code on
disk, so later processes only load it), the refrigerant tables are built from CoolProp on the
first use of a fluid, and xarray imports its optional array backends (Dask) on its first Dataset.
None of it is part of a simulation: :func:`ensure_compiled` does it all ahead of time, so that
a wall-clock or sampler time limit never counts it and a run's result never depends on whether
the caches were warm. A compile (no cached code yet) that takes long is announced on standard
error, in the main process only (worker processes load the code it cached).

Numba checks a cached kernel against its own source file only: after an edit, a branch switch or
a ``git pull`` that changes a kernel it calls in another file, it would load stale machine code
and silently compute the old physics. :func:`drop_stale_cache` guards against that with one
digest of every source file of the physics package.
"""

from __future__ import annotations

import multiprocessing
import sys
import threading
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr
from numba.core.dispatcher import Dispatcher

from pymc_vcc import physics
from pymc_vcc.physics import source_digest
from pymc_vcc.physics.cycles import CycleModel
from pymc_vcc.physics.inputs import constant_inputs, input_segments
from pymc_vcc.physics.integration.callbacks import BoundCycle
from pymc_vcc.physics.integration.sundials import compile_output_loop
from pymc_vcc.physics.unit import Unit

ANNOUNCE_AFTER_SECONDS = 2.0
"""A warm-up still running after this long is a first compile: say so on screen, s."""

TYPICAL_COMPILE_SECONDS = 50
"""CPU time of a cold compile of the cycle model, s (37 s measured before the property lookups
and coil heats were inlined into the right-hand side, which added a third: 95 against 70 s side
by side on a loaded machine; the wall time grows with the machine's load: 62 to 500 s on a
shared 2-core machine)."""

PHYSICS_PACKAGE = physics.__name__
"""Every cached Numba kernel of the package is defined in the modules of this package."""

STAMP_NAME = "pymc_vcc-physics-sources.digest"
"""File beside the cycle's cached kernels: the digest of the sources they were compiled from."""

_READY: set[tuple[str, str, int]] = set()  # (cycle, refrigerant, cells per heat exchanger)


def _announce() -> None:
    print(
        f"compiling the cycle model, once: ~{TYPICAL_COMPILE_SECONDS} s on an idle core, "
        "longer on a busy machine (Numba; later runs load it from its cache)",
        file=sys.stderr,
        flush=True,
    )


def _is_cached(model: CycleModel) -> bool:
    """Whether Numba's disk cache holds the cycle's kernels (then they load, not compile)."""
    kernel: Any = model.evaluate  # a Numba dispatcher
    try:
        return Path(kernel._cache._cache_file._index_path).exists()
    except AttributeError:  # Numba internals changed: assume a compile
        return False


def _loaded_cache_indexes() -> list[Path]:
    """The disk-cache index files of every cached kernel in the loaded physics modules."""
    indexes = set()
    for name, module in list(sys.modules.items()):
        if not name.startswith(PHYSICS_PACKAGE) or module is None:
            continue
        for value in vars(module).values():
            cache_file = getattr(getattr(value, "_cache", None), "_cache_file", None)
            if isinstance(value, Dispatcher) and cache_file is not None:
                indexes.add(Path(cache_file._index_path))
    return sorted(indexes)


def drop_stale_cache(stamp: Path) -> bool:
    """Delete the disk-cache index of every loaded physics kernel, so that it compiles afresh,
    when the sources differ from the digest ``stamp`` records (or there is none); then record
    the current digest. Returns whether it dropped the cache."""
    digest = source_digest()
    if stamp.exists() and stamp.read_text() == digest:
        return False
    for index in _loaded_cache_indexes():
        index.unlink(missing_ok=True)
    stamp.parent.mkdir(parents=True, exist_ok=True)
    stamp.write_text(digest)
    return True


def _stamp(model: CycleModel) -> Path | None:
    """Where the digest of the sources of ``model``'s cached kernels is kept."""
    kernel: Any = model.evaluate  # a Numba dispatcher
    try:
        return Path(kernel._cache._cache_path) / STAMP_NAME
    except AttributeError:  # Numba internals changed: no guard
        return None


def _run_kernels(unit: Unit) -> None:
    """Call every kernel the driver calls, at the unit's rating point and nominal parameters."""
    from pymc_vcc.physics.refrigerant import load_refrigerant

    tables = load_refrigerant(unit.refrigerant).tables
    model = unit.cycle_model
    n = unit.discretisation.n_volumes
    rating = constant_inputs(1.0, **unit.rating)
    u = input_segments(rating, model.inputs)[1][0]  # every input, optional ones at default
    c = model.constants(unit, unit.parameters.nominal)
    y = model.initial_state(c, n, u, tables)
    dydt = np.empty(y.size)
    model.evaluate(y, u, c, tables, dydt, np.empty(model.n_eval))
    model.jacobian(y, u, c, tables, dydt.copy())
    BoundCycle(model, y, u, c, tables).c_callbacks()  # CVODE's C callbacks
    compile_output_loop()  # and its loop over the output times
    model.outputs_along(y[np.newaxis, :], u[np.newaxis, :], c, tables, False)
    xr.Dataset({"y": ("time", y)})  # xarray imports its array backends on first use (seconds)


def ensure_compiled(unit: Unit) -> None:
    """Load ``unit``'s refrigerant tables and compile (or load) the cycle kernels, once."""
    key = (unit.cycle_model.name, unit.refrigerant, unit.discretisation.n_volumes)
    if key in _READY:
        return
    timer = threading.Timer(ANNOUNCE_AFTER_SECONDS, _announce)
    timer.daemon = True
    if multiprocessing.parent_process() is None:  # workers load what the main process cached
        stamp = _stamp(unit.cycle_model)
        if stamp is not None:
            drop_stale_cache(stamp)
        if not _is_cached(unit.cycle_model):
            timer.start()
    try:
        _run_kernels(unit)
    finally:
        timer.cancel()
    _READY.add(key)
