"""Refrigerant density made C² across the saturation lines, for the cell mass balances.

Homogeneous two-phase density has a kink at the bubble and dew lines: ∂ρ/∂h jumps (about
fourteenfold at the bubble line at 27 bar). A stiff solver cannot resolve a state crossing such a
kink within a step, and the total mass Σ V ρ then jumps by up to 1e-4 of the charge at every
crossing. Within ±``band`` (in quality) of each line, the density is replaced by the quintic
Hermite fillet matching the tabulated ρ, ∂ρ/∂h and ∂²ρ/∂h² at both band edges. C² matters, not
only C¹: ∂ρ/∂h enters the right-hand side (the cells' mass flows), so with a C¹ (cubic) fillet
the right-hand side has a kink at each band edge, and a condenser cell stepping through the
bubble-line band in one solver step left up to 1.9e-4 of the charge as integration error that
the step-size control did not see. ∂ρ/∂p of the blended density is exact: the ends' own
derivatives in p, taken along the moving band edges
(:func:`~pymc_vcc.physics.refrigerant.density_h_derivatives_along`), carried through the
fillet. So the balances stay consistent with M = Σ V ρ (a forward difference missed the mass
rate by 2e-4 of the source in the wider quintic band), at a third of the cost of the central
difference used before, which needed the ends at p ± dp as well.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from pymc_vcc.physics.refrigerant import (
    SaturationPoint,
    density_h_derivatives_along,
    state_at,
    state_values_at,
)

QUALITY_BAND = 0.1
"""Half-width of the fillet in quality on either side of the bubble (x = 0) and dew (x = 1)."""

FILLET_ENDS = 9
"""Numbers describing one fillet at one pressure: p (the memo's key, Pa), the band's start
enthalpy and width (J/kg), and ρ, ∂ρ/∂t, ∂²ρ/∂t² at both band edges, t = (h - start)/width.
The memo's second row holds the derivative of each in p (the first of them dp/dp = 1)."""

FILLET_MEMO_SHAPE = (2, 2, FILLET_ENDS)
"""A :func:`fillet_memo`'s shape: saturation line (bubble, dew), the ends or their slopes in p,
the ends' numbers. Empty, it is NaN."""


@njit(cache=True, error_model="numpy")
def fillet_memo() -> np.ndarray:
    """An empty memo for :func:`cell_state`: for each saturation line (bubble, dew) the fillet
    ends at one pressure and their derivatives in p. The ends depend on the pressure alone, so
    all cells of a zone share them; a memo is valid for one set of tables."""
    return np.full(FILLET_MEMO_SHAPE, np.nan)


@njit(cache=True, error_model="numpy")
def _fillet_ends(
    tables,
    sat: SaturationPoint,
    p: float,
    centre: float,
    band: float,
    ends: np.ndarray,
    slopes: np.ndarray,
) -> None:
    """Write the fillet ends around the saturation line ``centre`` (quality 0 or 1) at ``p``,
    whose :func:`saturation_point` is ``sat``, and their derivatives in p (per Pa)."""
    latent = sat.h_v - sat.h_l
    latent_p = sat.h_v_p - sat.h_l_p
    width = 2.0 * band * latent
    width_p = 2.0 * band * latent_p
    start = sat.h_l + (centre - band) * latent
    start_p = sat.h_l_p + (centre - band) * latent_p
    ends[0] = p
    ends[1] = start
    ends[2] = width
    slopes[0] = 1.0
    slopes[1] = start_p
    slopes[2] = width_p
    for side in range(2):  # the band's start and end; the end moves with start + width
        rho, d, c, rho_p, d_p, c_p = density_h_derivatives_along(
            tables, sat, p, start + side * width, start_p + side * width_p
        )
        at = 3 + 3 * side
        ends[at] = rho
        ends[at + 1] = d * width  # derivatives in t = (h - start) / width
        ends[at + 2] = c * (width * width)
        slopes[at] = rho_p
        slopes[at + 1] = d_p * width + d * width_p
        slopes[at + 2] = c_p * (width * width) + 2.0 * c * width * width_p


@njit(cache=True, error_model="numpy")
def _fillet_basis(t: float) -> tuple[float, float, float, float, float, float]:
    """The quintic Hermite basis at t of ρ_a, ∂ρ/∂t_a, ∂²ρ/∂t²_a, ∂²ρ/∂t²_b, ∂ρ/∂t_b, ρ_b."""
    t2 = t * t
    t3 = t2 * t
    t4 = t3 * t
    t5 = t4 * t
    return (
        1.0 - 10.0 * t3 + 15.0 * t4 - 6.0 * t5,
        t - 6.0 * t3 + 8.0 * t4 - 3.0 * t5,
        0.5 * (t2 - 3.0 * t3 + 3.0 * t4 - t5),
        0.5 * (t3 - 2.0 * t4 + t5),
        -4.0 * t3 + 7.0 * t4 - 3.0 * t5,
        10.0 * t3 - 15.0 * t4 + 6.0 * t5,
    )


@njit(cache=True, error_model="numpy")
def _fillet_sum(basis: tuple[float, float, float, float, float, float], ends: np.ndarray) -> float:
    """The fillet's ρ (or, given the ends' p-slopes, its p-derivative at constant t)."""
    b_rho_a, b_d_a, b_c_a, b_c_b, b_d_b, b_rho_b = basis
    return (
        b_rho_a * ends[3]
        + b_d_a * ends[4]
        + b_c_a * ends[5]
        + b_c_b * ends[8]
        + b_d_b * ends[7]
        + b_rho_b * ends[6]
    )


@njit(cache=True, error_model="numpy")
def _fillet(ends: np.ndarray, slopes: np.ndarray, h: float) -> tuple[float, float, float]:
    """(ρ, ∂ρ/∂h, ∂ρ/∂p) of the quintic Hermite fillet with these ends and p-slopes at
    enthalpy ``h``."""
    start, width = ends[1], ends[2]
    t = (h - start) / width
    t2 = t * t
    t3 = t2 * t
    t4 = t3 * t
    basis = _fillet_basis(t)
    drho_dt = (
        (-30.0 * t2 + 60.0 * t3 - 30.0 * t4) * (ends[3] - ends[6])
        + (1.0 - 18.0 * t2 + 32.0 * t3 - 15.0 * t4) * ends[4]
        + 0.5 * (2.0 * t - 9.0 * t2 + 12.0 * t3 - 5.0 * t4) * ends[5]
        + 0.5 * (3.0 * t2 - 8.0 * t3 + 5.0 * t4) * ends[8]
        + (-12.0 * t2 + 28.0 * t3 - 15.0 * t4) * ends[7]
    )
    # in p at constant h: the ends move, and t with the band
    t_p = -(slopes[1] + t * slopes[2]) / width
    drho_dp = _fillet_sum(basis, slopes) + drho_dt * t_p
    return _fillet_sum(basis, ends), drho_dt / width, drho_dp


@njit(cache=True, error_model="numpy")
def _band_centre(x: float, band: float) -> float:
    if abs(x) < band:
        return 0.0
    if abs(x - 1.0) < band:
        return 1.0
    return -1.0


@njit(cache=True, error_model="numpy", inline="always")
def cell_state(
    tables, sat: SaturationPoint, p: float, h: float, memo: np.ndarray
) -> tuple[float, float, float, float, float]:
    """(T K, ρ kg/m³, ∂ρ/∂p s²/m², ∂ρ/∂h kg² s²/m⁵... i.e. (kg/m³)/(J/kg), unclipped quality)
    like ``refrigerant.state`` but with the C² density near the saturation lines. ``sat`` is the
    :func:`~pymc_vcc.physics.refrigerant.saturation_point` of ``p``; ``memo`` (from
    :func:`fillet_memo`) keeps the fillet ends of the latest pressure."""
    T, rho, drho_dp, drho_dh, x = state_at(tables, sat, p, h)
    centre = _band_centre(x, QUALITY_BAND)
    if centre < 0.0:
        return T, rho, drho_dp, drho_dh, x
    ends, slopes = memo[int(centre), 0], memo[int(centre), 1]
    if ends[0] != p:
        _fillet_ends(tables, sat, p, centre, QUALITY_BAND, ends, slopes)
    rho, drho_dh, drho_dp = _fillet(ends, slopes, h)
    return T, rho, drho_dp, drho_dh, x


@njit(cache=True, error_model="numpy", inline="always")
def cell_values(
    tables, sat: SaturationPoint, p: float, h: float, memo: np.ndarray
) -> tuple[float, float, float]:
    """(T K, ρ kg/m³, unclipped quality) of :func:`cell_state` without the derivatives, for
    the outputs and the charge."""
    T, rho, x = state_values_at(tables, sat, p, h)
    centre = _band_centre(x, QUALITY_BAND)
    if centre < 0.0:
        return T, rho, x
    ends, slopes = memo[int(centre), 0], memo[int(centre), 1]
    if ends[0] != p:
        _fillet_ends(tables, sat, p, centre, QUALITY_BAND, ends, slopes)
    return T, _fillet_sum(_fillet_basis((h - ends[1]) / ends[2]), ends), x
