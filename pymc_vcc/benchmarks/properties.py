"""Cost of refrigerant properties: tables (vectorised and scalar Numba) against CoolProp HEOS.

The property set is what the heat-exchanger cell balances need at (p, h): T, rho, drho/dp|h,
drho/dh|p and quality.
"""

from __future__ import annotations

import time
from statistics import median

import numpy as np
from numba import njit

from pymc_vcc.physics.refrigerant import PropertyTables, load_refrigerant, state, state_array
from pymc_vcc.physics.refrigerant.cache import cache_directory, cache_path
from pymc_vcc.physics.refrigerant.fluid import DEFAULT_RESOLUTION, SUPPORTED_FLUIDS
from pymc_vcc.physics.refrigerant.validation import random_states

N_CELLS = 15


@njit(cache=True)
def _sum_states(tables: PropertyTables, p: np.ndarray, h: np.ndarray, repeats: int) -> float:
    """Call the scalar kernel at every point ``repeats`` times from inside Numba."""
    total = 0.0
    for _ in range(repeats):
        for k in range(p.size):
            T, rho, drho_dp, drho_dh, x = state(tables, p[k], h[k])
            total += T + rho + drho_dp + drho_dh + x
    return total


def _per_call(function, calls: int, runs: int) -> float:
    """Median over ``runs`` of the mean time of ``calls`` calls of ``function``, s."""
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        for _ in range(calls):
            function()
        times.append((time.perf_counter() - start) / calls)
    return median(times)


def _heos_seconds_per_point(p: np.ndarray, h: np.ndarray, runs: int) -> float:
    import CoolProp.CoolProp as CP

    heos = CP.AbstractState("HEOS", "R410A")

    def all_points() -> None:
        for pressure, enthalpy in zip(p, h, strict=True):
            heos.update(CP.HmassP_INPUTS, enthalpy, pressure)
            heos.T()
            heos.rhomass()
            heos.first_partial_deriv(CP.iDmass, CP.iP, CP.iHmass)
            heos.first_partial_deriv(CP.iDmass, CP.iHmass, CP.iP)
            heos.Q()

    return _per_call(all_points, 1, runs) / p.size


def run(quick: bool) -> dict[str, float | int | str]:
    """Build time, cache size and per-point costs for R410A; ``quick`` uses fewer repetitions."""
    from pymc_vcc.physics.refrigerant.build import build_tables

    runs = 3 if quick else 7
    spec = SUPPORTED_FLUIDS["R410A"]
    build_times = []
    for _ in range(1 if quick else 3):
        start = time.perf_counter()
        build_tables(spec, DEFAULT_RESOLUTION)
        build_times.append(time.perf_counter() - start)

    fluid = load_refrigerant("R410A")
    tables = fluid.tables
    cache_file = cache_path(cache_directory().expanduser().resolve(), spec, DEFAULT_RESOLUTION)

    rng = np.random.default_rng(0)
    p, h = random_states(fluid, 2000, rng)
    # one heat exchanger: a common pressure, cells from subcooled liquid to superheated vapour
    p_hx = np.full(N_CELLS, 27e5)
    h_hx = np.linspace(2.6e5, 4.6e5, N_CELLS)
    state_array(tables, p_hx, h_hx)
    fluid.props(p_hx, h_hx)
    _sum_states(tables, p, h, 1)

    calls = 300 if quick else 2000
    vector_api = _per_call(lambda: fluid.props(p_hx, h_hx), calls, runs) / N_CELLS
    vector_kernel = _per_call(lambda: state_array(tables, p_hx, h_hx), calls, runs) / N_CELLS
    repeats = 20 if quick else 200
    scalar = _per_call(lambda: _sum_states(tables, p, h, repeats), 1, runs) / (repeats * p.size)
    heos = _heos_seconds_per_point(p[: 300 if quick else 2000], h[: 300 if quick else 2000], runs)
    return {
        "properties_build_s": round(median(build_times), 3),
        "properties_cache_bytes": cache_file.stat().st_size,
        "properties_hx_cells": N_CELLS,
        "properties_vectorised_api_us_per_point": round(vector_api * 1e6, 3),
        "properties_vectorised_kernel_us_per_point": round(vector_kernel * 1e6, 3),
        "properties_numba_scalar_us_per_point": round(scalar * 1e6, 4),
        "properties_heos_us_per_point": round(heos * 1e6, 2),
        "properties_speedup_numba_scalar": round(heos / scalar, 1),
        "properties_speedup_vectorised_kernel": round(heos / vector_kernel, 1),
    }
