"""Heat transfer: refrigerant-side HTC blended across phases, algebraic air side."""

from __future__ import annotations

import math

from numba import njit

from pymc_vcc.components.smooth import smooth_step


@njit(cache=True)
def refrigerant_htc(
    quality: float,
    htc_liquid: float,
    htc_two_phase: float,
    htc_vapor: float,
    flow_ratio: float,
    blend_width: float,
) -> float:
    """Refrigerant-side heat-transfer coefficient, W/(m² K).

    The nominal liquid / two-phase / vapour values are blended with C¹ steps of width
    ``blend_width`` (in quality) centred on x = 0 and x = 1 of the *unclipped* quality, and
    scaled by (ṁ/ṁ_nom)^0.8 (Dittus–Boelter), with ``flow_ratio`` = |ṁ|/ṁ_nom floored at 0.05
    so the wall never decouples from the fluid.
    """
    to_two_phase = smooth_step(quality / blend_width + 0.5)
    to_vapor = smooth_step((quality - 1.0) / blend_width + 0.5)
    nominal = (
        htc_liquid * (1.0 - to_two_phase)
        + htc_two_phase * (to_two_phase - to_vapor)
        + htc_vapor * to_vapor
    )
    ratio = math.sqrt(flow_ratio * flow_ratio + 0.05 * 0.05)
    return nominal * ratio**0.8


@njit(cache=True)
def air_side_heat(
    capacity_rate: float, T_air_in: float, T_wall: float, htc: float, area: float
) -> float:
    """Heat from an air stream to a wall at ``T_wall``, W (ε-NTU, wall isothermal):
    Q = C (T_in - T_w)(1 - exp(-hA/C)) with C the air capacity rate in W/K."""
    return capacity_rate * (T_air_in - T_wall) * (1.0 - math.exp(-htc * area / capacity_rate))


@njit(cache=True)
def wall_heat(htc: float, area: float, T_wall: float, T_fluid: float) -> float:
    """Convective heat from a wall to a fluid, W."""
    return htc * area * (T_wall - T_fluid)
