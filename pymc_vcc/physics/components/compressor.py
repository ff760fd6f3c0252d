"""Variable-speed hermetic compressor: mass flow, electrical power, heat to the refrigerant.

Energy flows (W), with ṁ the mass flow and Δh_s the isentropic enthalpy rise:

    W_s   = ṁ Δh_s                              isentropic work
    W     = W_s (1 + cf_pow (1/η_s - 1))        electrical power; losses L = W - W_s >= 0
    Q_in  = W_s + φ L                           reaches the refrigerant (φ in (0, 1))
    Q_sh  = cap(cf_shell UA (T_ad - T_amb)⁺, φ L)   shell loss, 0 <= Q_sh <= φ L
    h_d   = h_s + (Q_in - Q_sh) / ṁ             so h_d >= h_s,is and ṁ (h_d - h_s) <= W

The four Table III correction factors are mapped so that every value of their range is
physical (first law: power to the refrigerant never above the electrical power; second law:
discharge enthalpy never below the isentropic one; shell loss never negative):

* ``cf_vol`` scales the volumetric *losses*: η_v = 1 - cf_vol (1 - η_v0), never above 1;
* ``cf_pow`` scales the compressor's losses L (motor, drive, friction, irreversibility), so the
  electrical power is never below the isentropic work;
* ``cf_pref`` scales the *odds* that a watt of loss ends in the refrigerant rather than in the
  ambient: φ/(1 - φ) = cf_pref φ₀/(1 - φ₀), so φ stays in (0, 1);
* ``cf_shell`` scales the shell conductance UA; the loss is capped smoothly at φ L.

A fault, apart from Table III: leaking valves (``valve_leakage`` f, a share of the displaced
gas) return f ṁ_disp from the discharge to the suction, so the compressor delivers
ṁ = (1 - f) ṁ_disp while it compresses all of ṁ_disp. The work on the returned gas ends in the
gas it delivers (an extra loss f W_s, all to the refrigerant): a leaking compressor delivers
less and hotter gas for the same power, and its isentropic power (of the gas delivered, what
the laws are checked against) falls below the work it does. At f = 0 every result is unchanged
bit for bit.

CF_POW thus changes the electrical power (an optional output) and the discharge temperature,
CF_PREF the discharge temperature only.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from pymc_vcc.physics.components.smooth import smooth_max, smooth_pos, smooth_step, soft_cap
from pymc_vcc.physics.refrigerant import (
    SaturationPoint,
    entropy_at,
    h_from_ps_at,
    h_from_pT_at,
    state_values_at,
)

COMPRESSOR_RECORD = np.dtype(
    [
        ("displacement", np.float64),  # m³ per revolution
        ("clearance", np.float64),  # clearance ratio of the volumetric-efficiency model, -
        ("exponent", np.float64),  # polytropic re-expansion exponent, -
        ("isentropic_efficiency", np.float64),  # -
        ("loss_share", np.float64),  # nominal share φ₀ of the losses heating the refrigerant, -
        ("shell_ua", np.float64),  # shell heat-loss conductance to ambient, W/K
        ("cf_vol", np.float64),  # Table III correction factors, -
        ("cf_pow", np.float64),
        ("cf_pref", np.float64),
        ("cf_shell", np.float64),
        ("valve_leakage", np.float64),  # share of the displaced gas leaking back (a fault), -
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
    """η_v = 1 - cf (c (r^(1/n) - 1)): the clearance re-expansion loss scaled by ``cf_vol``,
    smoothly floored at 0.02 (so η_v < 1 for every cf >= 0)."""
    loss = clearance * (pressure_ratio ** (1.0 / exponent) - 1.0)
    return smooth_max(1.0 - cf_vol * loss, 0.02, 0.01)


@njit(cache=True, error_model="numpy")
def compressor_mass_flow(
    rho_suction: float, speed: float, displacement: float, eta_vol: float
) -> float:
    """Displaced mass flow, kg/s: η_v ρ_s V_disp n with speed n in rev/s and displacement in
    m³/rev."""
    return eta_vol * rho_suction * displacement * speed


@njit(cache=True, error_model="numpy")
def delivered_mass_flow(displaced: float, valve_leakage: float) -> float:
    """Mass flow the compressor delivers, kg/s: the displaced flow less the share leaking back
    through its valves."""
    return displaced * (1.0 - valve_leakage)


@njit(cache=True, error_model="numpy")
def electrical_power(isentropic_work: float, isentropic_efficiency: float, cf_pow: float) -> float:
    """Electrical power, W: W_s (1 + cf (1/η_s - 1)), the losses above W_s scaled by ``cf_pow``
    (η_s is the nominal overall isentropic efficiency)."""
    return isentropic_work * (1.0 + cf_pow * (1.0 / isentropic_efficiency - 1.0))


@njit(cache=True, error_model="numpy")
def loss_share_to_refrigerant(nominal_share: float, cf_pref: float) -> float:
    """φ in (0, 1): share of the losses heating the refrigerant, odds φ₀/(1-φ₀) scaled by cf."""
    odds = cf_pref * nominal_share / (1.0 - nominal_share)
    return odds / (1.0 + odds)


@njit(cache=True, error_model="numpy")
def shell_loss(
    ua: float, cf_shell: float, T_shell: float, T_ambient: float, available: float
) -> float:
    """Heat lost through the shell to the ambient, W: cf UA (T_shell - T_amb)⁺ (1 K smoothing),
    capped smoothly at ``available`` (the loss heat in the gas), so 0 <= loss <= available."""
    return soft_cap(cf_shell * ua * smooth_pos(T_shell - T_ambient, 1.0), available)


@njit(cache=True, error_model="numpy")
def protection_speed_factor(pressure: float, p_start: float, p_stop: float) -> float:
    """High-pressure protection of inverter units: the drive lowers the speed smoothly from
    100 % at ``p_start`` to 5 % at ``p_stop`` (Pa) of high-side pressure."""
    return 1.0 - 0.95 * smooth_step((pressure - p_start) / (p_stop - p_start))


@njit(cache=True, error_model="numpy")
def compressor(
    tables,
    p_suction: float,
    suction: SaturationPoint,
    h_suction: float,
    rho_suction: float,
    p_discharge: float,
    discharge: SaturationPoint,
    speed: float,
    T_ambient: float,
    params,
) -> tuple[float, float, float, float, float, float]:
    """(delivered ṁ kg/s, discharge enthalpy J/kg, electrical power W, net power to the
    refrigerant W, isentropic power of the delivered gas W, heat to the ambient W) — see the
    module docstring. ``suction`` and ``discharge`` are the
    :func:`~pymc_vcc.physics.refrigerant.saturation_point` of the two pressures.

    ``params`` is a :data:`COMPRESSOR_RECORD`; its ``loss_share`` is φ₀, the nominal share of
    the losses heating the refrigerant. The discharge enthalpy's excess over the isentropic one
    is capped smoothly where the discharge would pass ``T_discharge_max`` (K), the thermal limit
    (the excess then leaves through shell and oil), so the state stays inside the property
    tables. NaN results mean a property call left them.
    """
    eta_vol = volumetric_efficiency(
        p_discharge / p_suction, params.clearance, params.exponent, params.cf_vol
    )
    displaced = compressor_mass_flow(rho_suction, speed, params.displacement, eta_vol)
    mass_flow = delivered_mass_flow(displaced, params.valve_leakage)
    s_suction = entropy_at(tables, suction, p_suction, h_suction)
    dh_isentropic = smooth_pos(
        h_from_ps_at(tables, discharge, p_discharge, s_suction) - h_suction, 100.0
    )
    h_isentropic = h_suction + dh_isentropic
    work_isentropic = displaced * dh_isentropic
    power = electrical_power(work_isentropic, params.isentropic_efficiency, params.cf_pow)
    loss_in_gas = (
        loss_share_to_refrigerant(params.loss_share, params.cf_pref) * (power - work_isentropic)
        + params.valve_leakage * work_isentropic
    )
    headroom = smooth_pos(
        h_from_pT_at(tables, discharge, p_discharge, params.T_discharge_max) - h_isentropic, 2e3
    )
    h_adiabatic = h_isentropic + soft_cap(loss_in_gas / mass_flow, headroom)
    T_adiabatic = state_values_at(tables, discharge, p_discharge, h_adiabatic)[0]
    shell = shell_loss(params.shell_ua, params.cf_shell, T_adiabatic, T_ambient, loss_in_gas)
    h_discharge = h_isentropic + soft_cap((loss_in_gas - shell) / mass_flow, headroom)
    to_refrigerant = mass_flow * (h_discharge - h_suction)
    return (
        mass_flow,
        h_discharge,
        power,
        to_refrigerant,
        mass_flow * dh_isentropic,
        power - to_refrigerant,
    )
