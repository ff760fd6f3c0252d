"""Refrigerant density made C² across the saturation lines, for the cell mass balances.

Homogeneous two-phase density has a kink at the bubble and dew lines: ∂ρ/∂h jumps (about
fourteenfold at the bubble line at 27 bar). A stiff solver cannot resolve a state crossing such a
kink within a step, and the total mass Σ V ρ then jumps by up to 1e-4 of the charge at every
crossing. Within ±``band`` (in quality) of each line, the density is replaced by the quintic
Hermite fillet matching the tabulated ρ, ∂ρ/∂h and ∂²ρ/∂h² at both band edges. C² matters, not
only C¹: ∂ρ/∂h enters the right-hand side (the cells' mass flows), so with a C¹ (cubic) fillet
the right-hand side has a kink at each band edge, and a condenser cell stepping through the
bubble-line band in one solver step left up to 1.9e-4 of the charge as integration error that
the step-size control did not see. ∂ρ/∂p of the blended density is a central difference
(relative step 1e-6), so the balances stay consistent with M = Σ V ρ (a forward difference
missed the mass rate by 2e-4 of the source in the wider quintic band).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from pymc_vcc.physics.refrigerant import (
    SaturationPoint,
    density_h_derivatives_at,
    saturation_point,
    state_at,
)

QUALITY_BAND = 0.1
"""Half-width of the fillet in quality on either side of the bubble (x = 0) and dew (x = 1)."""

FILLET_ENDS = 9
"""Numbers describing one fillet at one pressure: p (the memo's key, Pa), the band's start
enthalpy and width (J/kg), and ρ, ∂ρ/∂t, ∂²ρ/∂t² at both band edges, t = (h - start)/width."""


@njit(cache=True, error_model="numpy")
def fillet_memo() -> np.ndarray:
    """An empty memo for :func:`cell_state`: the fillet ends of both saturation lines (bubble,
    dew) at p, p + dp and p - dp. The ends depend on the pressure alone, so all cells of a zone
    share them; a memo is valid for one set of tables."""
    return np.full((2, 3, FILLET_ENDS), np.nan)


@njit(cache=True, error_model="numpy")
def _fillet_ends(
    tables, sat: SaturationPoint, p: float, centre: float, band: float, ends: np.ndarray
) -> None:
    """Write the fillet ends around the saturation line ``centre`` (quality 0 or 1) at ``p``,
    whose :func:`saturation_point` is ``sat``."""
    latent = sat.h_v - sat.h_l
    width = 2.0 * band * latent
    start = sat.h_l + (centre - band) * latent
    rho_a, d_a, c_a = density_h_derivatives_at(tables, sat, p, start)
    rho_b, d_b, c_b = density_h_derivatives_at(tables, sat, p, start + width)
    ends[0] = p
    ends[1] = start
    ends[2] = width
    ends[3] = rho_a
    ends[4] = d_a * width  # derivatives in t = (h - start) / width
    ends[5] = c_a * (width * width)
    ends[6] = rho_b
    ends[7] = d_b * width
    ends[8] = c_b * (width * width)


@njit(cache=True, error_model="numpy")
def _fillet(ends: np.ndarray, h: float) -> tuple[float, float]:
    """(ρ, ∂ρ/∂h) of the quintic Hermite fillet with these ends at enthalpy ``h``."""
    start, width = ends[1], ends[2]
    rho_a, d_a, c_a, rho_b, d_b, c_b = ends[3], ends[4], ends[5], ends[6], ends[7], ends[8]
    t = (h - start) / width
    t2 = t * t
    t3 = t2 * t
    t4 = t3 * t
    t5 = t4 * t
    rho = (
        (1.0 - 10.0 * t3 + 15.0 * t4 - 6.0 * t5) * rho_a
        + (t - 6.0 * t3 + 8.0 * t4 - 3.0 * t5) * d_a
        + 0.5 * (t2 - 3.0 * t3 + 3.0 * t4 - t5) * c_a
        + 0.5 * (t3 - 2.0 * t4 + t5) * c_b
        + (-4.0 * t3 + 7.0 * t4 - 3.0 * t5) * d_b
        + (10.0 * t3 - 15.0 * t4 + 6.0 * t5) * rho_b
    )
    drho_dt = (
        (-30.0 * t2 + 60.0 * t3 - 30.0 * t4) * (rho_a - rho_b)
        + (1.0 - 18.0 * t2 + 32.0 * t3 - 15.0 * t4) * d_a
        + 0.5 * (2.0 * t - 9.0 * t2 + 12.0 * t3 - 5.0 * t4) * c_a
        + 0.5 * (3.0 * t2 - 8.0 * t3 + 5.0 * t4) * c_b
        + (-12.0 * t2 + 28.0 * t3 - 15.0 * t4) * d_b
    )
    return rho, drho_dt / width


@njit(cache=True, error_model="numpy")
def _band_centre(x: float, band: float) -> float:
    if abs(x) < band:
        return 0.0
    if abs(x - 1.0) < band:
        return 1.0
    return -1.0


@njit(cache=True, error_model="numpy")
def cell_state(
    tables,
    sat: SaturationPoint,
    p: float,
    h: float,
    memo: np.ndarray,
    pressure_slope: bool = True,
) -> tuple[float, float, float, float, float]:
    """(T K, ρ kg/m³, ∂ρ/∂p s²/m², ∂ρ/∂h kg² s²/m⁵... i.e. (kg/m³)/(J/kg), unclipped quality)
    like ``refrigerant.state`` but with the C² density near the saturation lines. ``sat`` is the
    :func:`~pymc_vcc.physics.refrigerant.saturation_point` of ``p``; ``memo`` (from
    :func:`fillet_memo`) keeps the fillet ends of the latest pressure. Without
    ``pressure_slope`` a cell in a fillet band skips the ends at p ± dp and its ∂ρ/∂p is NaN
    (two thirds of the fillet's cost, for callers that need the state alone)."""
    T, rho, drho_dp, drho_dh, x = state_at(tables, sat, p, h)
    centre = _band_centre(x, QUALITY_BAND)
    if centre < 0.0:
        return T, rho, drho_dp, drho_dh, x
    ends = memo[int(centre)]
    if ends[0, 0] != p:
        _fillet_ends(tables, sat, p, centre, QUALITY_BAND, ends[0])
        ends[1, 0] = np.nan  # the ends at p ± dp belong to another pressure now
    rho, drho_dh = _fillet(ends[0], h)
    if not pressure_slope:
        return T, rho, np.nan, drho_dh, x
    dp = 1e-6 * p
    above, below = p + dp, p - dp
    if ends[1, 0] != above:
        _fillet_ends(tables, saturation_point(tables, above), above, centre, QUALITY_BAND, ends[1])
        _fillet_ends(tables, saturation_point(tables, below), below, centre, QUALITY_BAND, ends[2])
    up = _fillet(ends[1], h)[0]
    down = _fillet(ends[2], h)[0]
    return T, rho, (up - down) / (2.0 * dp), drho_dh, x
