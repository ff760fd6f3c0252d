"""Electronic expansion valve: orifice flow with a regularised square root."""

from __future__ import annotations

import math

from numba import njit

from pymc_vcc.physics.components.smooth import signed_sqrt


@njit(cache=True, error_model="numpy")
def valve_mass_flow(
    opening: float,
    flow_area: float,
    flow_coefficient_cf: float,
    rho_in: float,
    dp: float,
    line_coefficient: float,
    dp_reg: float,
) -> float:
    """Mass flow through the valve, kg/s, for a pressure difference ``dp`` (Pa) from the
    condenser to the evaporator that also drives the liquid line in series.

    Orifice ṁ = cf a A sqrt(2 ρ Δp_valve) and line loss Δp_line = K ṁ²/ρ solved together:
    ṁ = C sqrt(ρ Δp) with C = c / sqrt(1 + c² K), c = cf a A sqrt(2). Reverse pressure
    differences give reverse flow; the square root is regularised below ``dp_reg`` Pa.
    """
    c = flow_coefficient_cf * opening * flow_area * math.sqrt(2.0)
    conductance = c / math.sqrt(1.0 + c * c * line_coefficient)
    return conductance * math.sqrt(rho_in) * signed_sqrt(dp, dp_reg)
