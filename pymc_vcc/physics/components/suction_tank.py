"""Suction accumulator: stores liquid, delivers vapour to the compressor."""

from __future__ import annotations

from numba import njit

from pymc_vcc.physics.components.smooth import smooth_max


@njit(cache=True, error_model="numpy")
def tank_outlet_enthalpy(h_tank: float, h_vapor: float, width: float) -> float:
    """Enthalpy leaving the tank, J/kg: its content when superheated, saturated vapour when it
    holds liquid (a smooth max, ``width`` J/kg, so the solver sees a C¹ function)."""
    return smooth_max(h_tank, h_vapor, width)
