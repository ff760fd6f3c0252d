"""Heat transfer: refrigerant-side HTC blended across phases, algebraic air side."""

from __future__ import annotations

import math

from numba import njit

from pymc_vcc.physics.components.smooth import smooth_step

LIQUID_BLEND = (-0.05, 0.4)
"""Quality range over which the HTC rises from the liquid to the two-phase value (the liquid
film dominates at low quality, in evaporation and condensation alike)."""

VAPOR_BLEND = (0.6, 1.1)
"""Quality range of dry-out, from the two-phase to the vapour value. As wide as the data on
dry-out onset allow (x 0.6-0.9 by heat flux): with [0.9, 1.05], a cell holding the dew point
in a coil whose two-phase HTC is 10-16 times its vapour HTC excited a limit cycle at N = 10."""

FLUX_KINKS = (LIQUID_BLEND[0], 0.0, LIQUID_BLEND[1], VAPOR_BLEND[0], 1.0, VAPOR_BLEND[1])
"""Qualities, ascending, where the local flux α(x)(T_w - T) has a kink: the blend edges and
the saturation lines (where T(h) has one). Between them it is smooth."""


@njit(cache=True, error_model="numpy")
def flow_scale(flow_ratio: float) -> float:
    """Factor on the refrigerant-side HTC at ``flow_ratio`` = |ṁ|/ṁ_nom: (ṁ/ṁ_nom)^0.8
    (Dittus–Boelter), the ratio softly floored at 0.05 so the wall never decouples from the
    fluid. One value per coil and right-hand side."""
    ratio = math.sqrt(flow_ratio * flow_ratio + 0.05 * 0.05)
    return ratio**0.8


@njit(cache=True, error_model="numpy")
def refrigerant_htc(
    quality: float,
    htc_liquid: float,
    htc_two_phase: float,
    htc_vapor: float,
    scale: float,
) -> float:
    """Refrigerant-side heat-transfer coefficient, W/(m² K).

    The nominal liquid / two-phase / vapour values are blended with C¹ steps in the *unclipped*
    quality over :data:`LIQUID_BLEND` and :data:`VAPOR_BLEND`, and multiplied by the flow's
    ``scale`` (:func:`flow_scale`).
    """
    to_two_phase = smooth_step((quality - LIQUID_BLEND[0]) / (LIQUID_BLEND[1] - LIQUID_BLEND[0]))
    to_vapor = smooth_step((quality - VAPOR_BLEND[0]) / (VAPOR_BLEND[1] - VAPOR_BLEND[0]))
    nominal = (
        htc_liquid * (1.0 - to_two_phase)
        + htc_two_phase * (to_two_phase - to_vapor)
        + htc_vapor * to_vapor
    )
    return nominal * scale


@njit(cache=True, error_model="numpy")
def air_effectiveness(capacity_rate: float, htc: float, area: float) -> float:
    """Effectiveness 1 - exp(-hA/C) of an air stream of capacity rate C (W/K) over a wall of
    area A (m²) and HTC h (W/(m² K)); one value per coil."""
    return 1.0 - math.exp(-htc * area / capacity_rate)


@njit(cache=True, error_model="numpy")
def air_side_heat(
    capacity_rate: float, T_air_in: float, T_wall: float, effectiveness: float
) -> float:
    """Heat from an air stream to a wall at ``T_wall``, W (ε-NTU, wall isothermal):
    Q = C (T_in - T_w) ε, with C the air capacity rate in W/K and ε its
    :func:`air_effectiveness`."""
    return capacity_rate * (T_air_in - T_wall) * effectiveness


@njit(cache=True, error_model="numpy")
def cell_heat(
    T_wall: float,
    area: float,
    quality_in: float,
    quality_out: float,
    T_in: float,
    T_mid: float,
    T_out: float,
    htc_liquid: float,
    htc_two_phase: float,
    htc_vapor: float,
    scale: float,
) -> float:
    """Heat from the wall to a stretch of refrigerant, W: the local flux α(x) (T_w - T)
    averaged over it, its enthalpy running linearly from inlet to outlet (Simpson's rule on
    inlet, middle and outlet; ``T_mid`` at the middle enthalpy). Exact to the order of the rule
    only where the flux is smooth, i.e. between two of :data:`FLUX_KINKS`. ``scale``: the
    flow's :func:`flow_scale`."""
    middle = 0.5 * (quality_in + quality_out)
    a_in = refrigerant_htc(quality_in, htc_liquid, htc_two_phase, htc_vapor, scale)
    a_mid = refrigerant_htc(middle, htc_liquid, htc_two_phase, htc_vapor, scale)
    a_out = refrigerant_htc(quality_out, htc_liquid, htc_two_phase, htc_vapor, scale)
    flux = a_in * (T_wall - T_in) + 4.0 * a_mid * (T_wall - T_mid) + a_out * (T_wall - T_out)
    return area * flux / 6.0
