"""Variable-speed compressor: volumetric efficiency, shaft power, heat to refrigerant, shell loss.

The four Table III correction factors act here: ``cf_vol`` on the volumetric efficiency,
``cf_pow`` on the shaft power, ``cf_pref`` on the share of it reaching the refrigerant and
``cf_shell`` on the shell heat loss to the ambient.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from pymc_vcc.physics.components.smooth import smooth_max, smooth_min, smooth_pos, smooth_step
from pymc_vcc.physics.refrigerant import entropy, h_from_ps, h_from_pT, state

COMPRESSOR_RECORD = np.dtype(
    [
        ("displacement", np.float64),  # m³ per revolution
        ("clearance", np.float64),  # clearance ratio of the volumetric-efficiency model, -
        ("exponent", np.float64),  # polytropic re-expansion exponent, -
        ("isentropic_efficiency", np.float64),  # -
        ("refrigerant_fraction", np.float64),  # share of shaft power reaching the refrigerant, -
        ("shell_ua", np.float64),  # shell heat-loss conductance to ambient, W/K
        ("cf_vol", np.float64),  # Table III correction factors, -
        ("cf_pow", np.float64),
        ("cf_pref", np.float64),
        ("cf_shell", np.float64),
        ("T_discharge_max", np.float64),  # thermal limit of the discharge gas, K
        ("p_protection_start", np.float64),  # high-pressure protection: droop starts, Pa
        ("p_protection_stop", np.float64),  # ... and reaches 5 % speed, Pa
    ]
)
"""The compressor's parameters as one Numba record (a field of a cycle's constants record)."""


@njit(cache=True, error_model="numpy")
def volumetric_efficiency(
    pressure_ratio: float, clearance: float, exponent: float, cf_vol: float
) -> float:
    """cf · (1 - c (r^(1/n) - 1)), the clearance re-expansion model, smoothly floored at 0.02."""
    nominal = 1.0 - clearance * (pressure_ratio ** (1.0 / exponent) - 1.0)
    return cf_vol * smooth_max(nominal, 0.02, 0.01)


@njit(cache=True, error_model="numpy")
def compressor_mass_flow(
    rho_suction: float, speed: float, displacement: float, eta_vol: float
) -> float:
    """Mass flow, kg/s: η_v ρ_s V_disp n with speed n in rev/s and displacement in m³/rev."""
    return eta_vol * rho_suction * displacement * speed


@njit(cache=True, error_model="numpy")
def shaft_power(
    mass_flow: float, dh_isentropic: float, isentropic_efficiency: float, cf_pow: float
) -> float:
    """Electric/shaft power, W: cf ṁ Δh_s / η_s (Δh_s smoothly floored at 0)."""
    return cf_pow * mass_flow * smooth_pos(dh_isentropic, 100.0) / isentropic_efficiency


@njit(cache=True, error_model="numpy")
def shell_loss(ua: float, cf_shell: float, T_shell: float, T_ambient: float) -> float:
    """Heat lost through the shell to the ambient, W: cf UA (T_shell - T_amb)."""
    return cf_shell * ua * (T_shell - T_ambient)


@njit(cache=True, error_model="numpy")
def protection_speed_factor(pressure: float, p_start: float, p_stop: float) -> float:
    """High-pressure protection of inverter units: the drive lowers the speed smoothly from
    100 % at ``p_start`` to 5 % at ``p_stop`` (Pa) of high-side pressure."""
    return 1.0 - 0.95 * smooth_step((pressure - p_start) / (p_stop - p_start))


@njit(cache=True, error_model="numpy")
def compressor(
    tables,
    p_suction: float,
    h_suction: float,
    rho_suction: float,
    p_discharge: float,
    speed: float,
    T_ambient: float,
    params,
) -> tuple[float, float, float, float]:
    """(ṁ kg/s, discharge enthalpy J/kg, shaft power W, net power to the refrigerant W).

    Power to the refrigerant is cf_pref · fraction · shaft power, less the shell loss evaluated
    at the temperature the gas would reach without it. The shell loss grows smoothly (over
    2 kJ/kg) wherever the discharge would exceed ``T_discharge_max`` (K), the compressor's
    thermal limit, so the discharge state stays inside the property tables. Non-finite (NaN)
    results mean a property call left the tables. ``params`` is a :data:`COMPRESSOR_RECORD`.
    """
    eta_vol = volumetric_efficiency(
        p_discharge / p_suction, params.clearance, params.exponent, params.cf_vol
    )
    mass_flow = compressor_mass_flow(rho_suction, speed, params.displacement, eta_vol)
    s_suction = entropy(tables, p_suction, h_suction)
    h_isentropic = h_from_ps(tables, p_discharge, s_suction)
    power = shaft_power(
        mass_flow, h_isentropic - h_suction, params.isentropic_efficiency, params.cf_pow
    )
    to_refrigerant = params.cf_pref * params.refrigerant_fraction * power
    h_limit = h_from_pT(tables, p_discharge, params.T_discharge_max)
    h_adiabatic = smooth_min(h_suction + to_refrigerant / mass_flow, h_limit, 2e3)
    T_adiabatic = state(tables, p_discharge, h_adiabatic)[0]
    net = to_refrigerant - shell_loss(params.shell_ua, params.cf_shell, T_adiabatic, T_ambient)
    h_discharge = smooth_min(h_suction + net / mass_flow, h_limit, 2e3)
    return mass_flow, h_discharge, power, mass_flow * (h_discharge - h_suction)
