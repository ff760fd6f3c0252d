"""Refrigerant density made C¹ across the saturation lines, for the cell mass balances.

Homogeneous two-phase density has a kink at the bubble and dew lines: ∂ρ/∂h jumps (about
fourteenfold at the bubble line at 27 bar). A stiff solver cannot resolve a state crossing such a
kink within a step, and the total mass Σ V ρ then jumps by up to 1e-4 of the charge at every
crossing. Within ±``band`` (in quality) of each line, the density is replaced by the cubic Hermite
fillet matching the tabulated value and ∂ρ/∂h at both band edges; ∂ρ/∂p of the blended density
is a forward difference (relative step 1e-6), so the balances stay consistent with M = Σ V ρ.
"""

from __future__ import annotations

from numba import njit

from pymc_vcc.physics.refrigerant import saturation_state, state

QUALITY_BAND = 0.04
"""Half-width of the fillet in quality on either side of the bubble (x = 0) and dew (x = 1)."""


@njit(cache=True, error_model="numpy")
def _fillet(tables, p: float, h: float, centre: float, band: float) -> tuple[float, float]:
    sat = saturation_state(tables, p)
    latent = sat[2] - sat[1]
    width = 2.0 * band * latent
    start = sat[1] + (centre - band) * latent
    start_state = state(tables, p, start)
    rho_a, drho_a = start_state[1], start_state[3]
    end_state = state(tables, p, start + width)
    rho_b, drho_b = end_state[1], end_state[3]
    t = (h - start) / width
    t2 = t * t
    t3 = t2 * t
    rho = (
        (2.0 * t3 - 3.0 * t2 + 1.0) * rho_a
        + (t3 - 2.0 * t2 + t) * width * drho_a
        + (-2.0 * t3 + 3.0 * t2) * rho_b
        + (t3 - t2) * width * drho_b
    )
    drho_dh = (
        (6.0 * t2 - 6.0 * t) * rho_a
        + (3.0 * t2 - 4.0 * t + 1.0) * width * drho_a
        + (-6.0 * t2 + 6.0 * t) * rho_b
        + (3.0 * t2 - 2.0 * t) * width * drho_b
    ) / width
    return rho, drho_dh


@njit(cache=True, error_model="numpy")
def _band_centre(x: float, band: float) -> float:
    if abs(x) < band:
        return 0.0
    if abs(x - 1.0) < band:
        return 1.0
    return -1.0


@njit(cache=True, error_model="numpy")
def cell_state(tables, p: float, h: float) -> tuple[float, float, float, float, float]:
    """(T K, ρ kg/m³, ∂ρ/∂p s²/m², ∂ρ/∂h kg² s²/m⁵... i.e. (kg/m³)/(J/kg), unclipped quality)
    like ``refrigerant.state`` but with the C¹ density near the saturation lines."""
    T, rho, drho_dp, drho_dh, x = state(tables, p, h)
    centre = _band_centre(x, QUALITY_BAND)
    if centre < 0.0:
        return T, rho, drho_dp, drho_dh, x
    rho, drho_dh = _fillet(tables, p, h, centre, QUALITY_BAND)
    dp = 1e-6 * p
    up = _fillet(tables, p + dp, h, centre, QUALITY_BAND)[0]
    return T, rho, (up - rho) / dp, drho_dh, x
