"""Suction accumulator: stores liquid and returns it to the compressor through a bleed hole.

The outlet J-tube draws vapour from the top; a bleed (oil-return) hole near its bottom meters
liquid (and oil) into that stream, the more the higher the liquid level. With ℓ the liquid
volume fraction of the tank and β_full the liquid mass fraction of the outflow with a full
tank, the outlet enthalpy is

    h_out = max(h_tank, h_v - β_full ℓ (h_v - h_l))        (smooth max)

so the suction gas is wetter, the suction superheat and discharge temperature lower, the more
liquid the tank holds: the charge held in the tank stays visible in the outputs.
"""

from __future__ import annotations

from numba import njit

from pymc_vcc.physics.components.smooth import smooth_max, smooth_pos


@njit(cache=True, error_model="numpy")
def liquid_level(rho: float, rho_liquid: float, rho_vapor: float) -> float:
    """Liquid volume fraction ℓ of a tank of homogeneous density ``rho`` (kg/m³): the lever
    rule (ρ - ρ_v)/(ρ_l - ρ_v), smoothly 0 for superheated content (width 1e-3)."""
    return smooth_pos((rho - rho_vapor) / (rho_liquid - rho_vapor), 1e-3)


@njit(cache=True, error_model="numpy")
def tank_outlet_enthalpy(
    h_tank: float,
    h_liquid: float,
    h_vapor: float,
    level: float,
    bleed_fraction_full: float,
    width: float,
) -> float:
    """Enthalpy leaving the tank, J/kg: its content when superheated; with liquid in it, vapour
    carrying the bleed liquid, a liquid mass fraction ``bleed_fraction_full`` · ``level``
    (smooth max over ``width`` J/kg, so the solver sees a C¹ function)."""
    bled = h_vapor - bleed_fraction_full * level * (h_vapor - h_liquid)
    return smooth_max(h_tank, bled, width)
