"""The cycle: state layout, constants, right-hand side, outputs, total mass, charge controller.

Two pressure zones, one pressure each (N = volumes per heat exchanger):

* high side: condenser cells 0..N-1, then the liquid line (one adiabatic cell), outflow = valve;
* low side: evaporator cells 0..N-1, the vapour line and the suction tank, outflow = compressor.

State vector (length 4N + 6), SI units::

    [p_c, h_c[0..N-1], h_liquid_line, Tw_c[0..N-1],
     p_e, h_e[0..N-1], h_vapor_line, h_tank, Tw_e[0..N-1], z]

with ``z`` the integral of the mass error (kg s) of the virtual PI charge controller (paper,
section II-B): a source ṁ_src = Kp (M0 - M) + Ki z at the compressor discharge, entering at the
discharge enthalpy, or leaving at the first condenser cell's own enthalpy when negative.
Lumped pressure drops: condenser (at its inlet, so PD = PC + Δp), evaporator and vapour line
(between the low-side zone and the compressor suction, so PS = PE - Δp), liquid line (in series
with the valve).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from pymc_vcc.physics.components.compressor import (
    compressor,
    compressor_mass_flow,
    protection_speed_factor,
    volumetric_efficiency,
)
from pymc_vcc.physics.components.density import cell_state
from pymc_vcc.physics.components.expansion_valve import valve_mass_flow
from pymc_vcc.physics.components.fan import (
    air_capacity_rate,
    air_inlet_temperature,
    fan_operating_point,
)
from pymc_vcc.physics.components.heat_exchanger import zone_derivatives
from pymc_vcc.physics.components.heat_transfer import air_side_heat, cell_heat
from pymc_vcc.physics.components.moist_air import humidity_ratio, latent_heat
from pymc_vcc.physics.components.pipe import friction_coefficient, pipe_volume, pressure_drop
from pymc_vcc.physics.components.smooth import smooth_pos, upwind_weight
from pymc_vcc.physics.components.suction_tank import liquid_level, tank_outlet_enthalpy
from pymc_vcc.physics.parameters import PARAMETER_IDS
from pymc_vcc.physics.refrigerant import saturation_state, state
from pymc_vcc.physics.unit import Unit

OUTPUT_IDS: tuple[str, ...] = ("TD", "PD", "TS", "PS", "TC", "PC", "TE", "PE", "MDOT")
"""The nine model outputs of the paper, in order."""

OUTPUT_INFO: dict[str, tuple[str, str]] = {
    "TD": ("Compressor discharge temperature", "K"),
    "PD": ("Compressor discharge pressure", "Pa"),
    "TS": ("Compressor suction temperature", "K"),
    "PS": ("Compressor suction pressure", "Pa"),
    "TC": ("Condenser outlet refrigerant temperature", "K"),
    "PC": ("Condenser pressure", "Pa"),
    "TE": ("Evaporator outlet refrigerant temperature", "K"),
    "PE": ("Evaporator pressure", "Pa"),
    "MDOT": ("Compressor mass flow", "kg/s"),
}
"""Long name and unit of each output."""

DIAGNOSTIC_INFO: dict[str, tuple[str, str]] = {
    "Q_cond": ("Heat rejected by the condenser refrigerant", "W"),
    "Q_evap": ("Heat absorbed by the evaporator refrigerant", "W"),
    "W_comp": ("Compressor electrical power", "W"),
    "W_ref": ("Net compressor power to the refrigerant", "W"),
    "W_fans": ("Fan power", "W"),
    "M": ("Total refrigerant mass", "kg"),
    "mdot_src": ("Charge-controller mass source", "kg/s"),
    "mdot_valve": ("Expansion-valve mass flow", "kg/s"),
    "W_is": ("Compressor isentropic power", "W"),
    "Q_comp_amb": ("Compressor heat to the ambient (shell, drive, thermal limit)", "W"),
    "V_air_out": ("Outdoor-coil air flow", "m3/s"),
    "V_air_in": ("Indoor-coil air flow", "m3/s"),
    "tank_level": ("Suction-tank liquid volume fraction", "1"),
    "dp_cond": ("Condenser pressure drop", "Pa"),
    "dp_evap": ("Evaporator pressure drop", "Pa"),
    "dp_vap": ("Vapour-line pressure drop", "Pa"),
    "Q_latent": ("Latent heat of the indoor coil (condensation)", "W"),
    "SHR": ("Sensible heat ratio of the indoor coil", "1"),
}
"""Further quantities available from :func:`evaluate` (index = 9 + position)."""

INERT_PARAMETERS: tuple[str, ...] = ("FO_SPEED", "FI_SPEED")
"""Table III parameters that change no output, by design: each fan runs at a fixed fraction of
its rated ("nominal") speed (``speed_fraction`` in the unit file), so the fan laws give its
flow and power from FO_FLOW/FO_POW (FI_...) alone. A separate rated speed against a fixed
running speed would only rescale those two parameters again, which made the box span
0.16-4.8 m³/s of outdoor air and 1.6 W-16 kW of fan power (models/README.md)."""

OPTIONAL_OUTPUT_IDS: tuple[str, ...] = ("W_comp",)
"""Diagnostics that field loggers measure and a simulator may return as outputs (the
compressor's electrical power makes CF_POW observable)."""

N_EVAL = len(OUTPUT_IDS) + len(DIAGNOSTIC_INFO)

# ---- constants vector layout ---------------------------------------------------------------
(
    C_V_COND,  # condenser cell volume, m3
    C_V_LIQ,  # liquid line volume, m3
    C_V_EVAP,  # evaporator cell volume, m3
    C_V_VAP,  # vapour line volume, m3
    C_V_TANK,  # suction tank volume, m3
    C_AR_COND,  # refrigerant-side area per condenser cell, m2
    C_AR_EVAP,
    C_AA_COND,  # air-side area per cell, m2
    C_AA_EVAP,
    C_CW_COND,  # wall heat capacity per cell, J/K
    C_CW_EVAP,
    C_HTC_CL,
    C_HTC_CTP,
    C_HTC_CV,
    C_HTC_EL,
    C_HTC_ETP,
    C_HTC_EV,
    C_HTC_CA,
    C_HTC_EA,
    C_MNOM_COND,  # nominal refrigerant flows of the HTC scaling, kg/s
    C_MNOM_EVAP,
    C_CAP_COND,  # air capacity rate per cell, W/K
    C_CAP_EVAP,
    C_FLOW_OUT,  # air flows, m3/s
    C_FLOW_IN,
    C_P_FAN_OUT,  # fan powers, W
    C_P_FAN_IN,
    C_DISPLACEMENT,
    C_CLEARANCE,
    C_EXPONENT,
    C_ETA_IS,
    C_LOSS_SHARE,
    C_SHELL_UA,
    C_CF_VOL,
    C_CF_POW,
    C_CF_PREF,
    C_CF_SHELL,
    C_VALVE_AREA,
    C_CF_LEV,
    C_K_LIQ,  # friction coefficients Δp = K ṁ|ṁ|/ρ, 1/m4 (correction factors included)
    C_K_COND,
    C_K_EVAP,
    C_K_VAP,
    C_KP,
    C_KI,
    C_M0,
    C_T_DIS_MAX,  # compressor thermal limit, K
    C_P_PROT_START,  # high-pressure protection, Pa
    C_P_PROT_STOP,
    C_BLEED_FULL,  # liquid mass fraction of the tank outflow when full, -
    C_CP_AIR,  # specific heat of air, J/(kg K)
    N_CONSTANTS,
) = range(52)

# regularisation widths
_FLOW_EPS = 1e-4  # kg/s, upwind weights and |ṁ| in pressure drops
_SRC_EPS = 1e-5  # kg/s, sign of the charge-controller source
_DP_REG = 2e4  # Pa, valve square root
_TANK_WIDTH = 2e3  # J/kg, tank outlet smooth max
_DP_ITERATIONS = 4  # secant steps for the flow through the lumped pressure drops


def n_states(n_volumes: int) -> int:
    """Length of the state vector for ``n_volumes`` cells per heat exchanger."""
    return 4 * n_volumes + 6


def state_slices(n_volumes: int) -> dict[str, slice | int]:
    """Where each part of the state lives (see the module docstring)."""
    n = n_volumes
    return {
        "p_cond": 0,
        "h_cond": slice(1, n + 1),
        "h_liquid_line": n + 1,
        "Tw_cond": slice(n + 2, 2 * n + 2),
        "p_evap": 2 * n + 2,
        "h_evap": slice(2 * n + 3, 3 * n + 3),
        "h_vapor_line": 3 * n + 3,
        "h_tank": 3 * n + 4,
        "Tw_evap": slice(3 * n + 5, 4 * n + 5),
        "z": 4 * n + 5,
    }


def build_constants(unit: Unit, theta: np.ndarray, controller: bool | None = None) -> np.ndarray:
    """The constants vector of the right-hand side from a unit and a Table III vector ``theta``
    (ordered as :data:`PARAMETER_IDS`). ``controller`` overrides the unit's on/off switch."""
    p = dict(zip(PARAMETER_IDS, np.asarray(theta, dtype=float), strict=True))
    n = unit.discretisation.n_volumes
    cond, evap = unit.condenser, unit.evaporator
    c = np.zeros(N_CONSTANTS)
    c[C_V_COND] = pipe_volume(p["L_COND"], cond.tube_inner_diameter, cond.n_paths) / n
    c[C_V_EVAP] = pipe_volume(p["L_EVAP"], evap.tube_inner_diameter, evap.n_paths) / n
    c[C_V_LIQ] = pipe_volume(p["L_LIQ"], unit.liquid_line.inner_diameter)
    c[C_V_VAP] = pipe_volume(p["L_VAP"], unit.vapor_line.inner_diameter)
    c[C_V_TANK] = unit.suction_tank.volume
    for hx, length, ar, aa, cw in (
        (cond, p["L_COND"], C_AR_COND, C_AA_COND, C_CW_COND),
        (evap, p["L_EVAP"], C_AR_EVAP, C_AA_EVAP, C_CW_EVAP),
    ):
        tube = length * hx.n_paths
        c[ar] = math.pi * hx.tube_inner_diameter * tube / n
        c[aa] = hx.air_side_area_per_length * tube / n
        c[cw] = hx.wall_heat_capacity_per_length * tube / n
    for key, pid in (
        (C_HTC_CL, "HTC_CL"),
        (C_HTC_CTP, "HTC_CTP"),
        (C_HTC_CV, "HTC_CV"),
        (C_HTC_EL, "HTC_EL"),
        (C_HTC_ETP, "HTC_ETP"),
        (C_HTC_EV, "HTC_EV"),
        (C_HTC_CA, "HTC_CA"),
        (C_HTC_EA, "HTC_EA"),
        (C_CF_VOL, "CF_VOL"),
        (C_CF_POW, "CF_POW"),
        (C_CF_PREF, "CF_PREF"),
        (C_CF_SHELL, "CF_SHELL"),
        (C_CF_LEV, "CF_LEV"),
        (C_M0, "M0"),
    ):
        c[key] = p[pid]
    c[C_MNOM_COND] = cond.nominal_mass_flow
    c[C_MNOM_EVAP] = evap.nominal_mass_flow
    air = unit.air
    flow_out, power_out = fan_operating_point(
        p["FO_FLOW"], p["FO_POW"], p["FO_SPEED"], p["FO_SPEED"] * unit.outdoor_fan.speed_fraction
    )
    flow_in, power_in = fan_operating_point(
        p["FI_FLOW"], p["FI_POW"], p["FI_SPEED"], p["FI_SPEED"] * unit.indoor_fan.speed_fraction
    )
    c[C_FLOW_OUT] = flow_out
    c[C_FLOW_IN] = flow_in
    c[C_CAP_COND] = air_capacity_rate(flow_out, air.density, air.specific_heat) / n
    c[C_CAP_EVAP] = air_capacity_rate(flow_in, air.density, air.specific_heat) / n
    c[C_CP_AIR] = air.specific_heat
    c[C_P_FAN_OUT] = power_out
    c[C_P_FAN_IN] = power_in
    comp = unit.compressor
    c[C_DISPLACEMENT] = comp.displacement
    c[C_CLEARANCE] = comp.clearance
    c[C_EXPONENT] = comp.polytropic_exponent
    c[C_ETA_IS] = comp.isentropic_efficiency
    c[C_LOSS_SHARE] = comp.loss_share_to_refrigerant
    c[C_SHELL_UA] = comp.shell_ua
    c[C_T_DIS_MAX] = comp.max_discharge_temperature
    c[C_P_PROT_START] = comp.protection_pressure_start
    c[C_P_PROT_STOP] = comp.protection_pressure_stop
    c[C_VALVE_AREA] = unit.expansion_valve.flow_area
    c[C_BLEED_FULL] = unit.suction_tank.bleed_fraction_full
    f = unit.pressure_drop.darcy_friction_factor
    c[C_K_LIQ] = friction_coefficient(f, p["L_LIQ"], unit.liquid_line.inner_diameter)
    c[C_K_VAP] = friction_coefficient(f, p["L_VAP"], unit.vapor_line.inner_diameter)
    coil = f * unit.pressure_drop.coil_multiplier
    c[C_K_COND] = p["CF_DPC"] * friction_coefficient(
        coil, p["L_COND"], cond.tube_inner_diameter, cond.n_paths
    )
    c[C_K_EVAP] = p["CF_DPE"] * friction_coefficient(
        coil, p["L_EVAP"], evap.tube_inner_diameter, evap.n_paths
    )
    enabled = unit.controller.enabled if controller is None else controller
    kp = unit.controller.kp if enabled else 0.0
    c[C_KP] = kp
    c[C_KI] = kp * kp / 4.0
    return c


@njit(cache=True, error_model="numpy")
def cell_properties(y, tables, props):
    """Fill ``props`` (shape (5, 2N + 3): T, ρ, ∂ρ/∂p, ∂ρ/∂h, quality) for every cell: columns
    0..N of the high-side zone, then N + 1 columns of the low-side zone. Returns False if a
    property left the tables."""
    n = (y.size - 6) // 4
    for i in range(2 * n + 3):
        _cell_row(y, n, i, tables, props)
    return bool(np.isfinite(props[1]).all())


@njit(cache=True, error_model="numpy")
def _cell_row(y, n, i, tables, props):
    """Properties of cell ``i`` (numbered as in :func:`cell_properties`)."""
    if i <= n:
        p = y[0]
        h = y[1 + i] if i < n else y[n + 1]
    else:
        k = i - n - 1
        p = y[2 * n + 2]
        h = y[2 * n + 3 + k] if k < n else y[3 * n + 3 + (k - n)]
    T, rho, drho_dp, drho_dh, x = cell_state(tables, p, h)
    props[0, i] = T
    props[1, i] = rho
    props[2, i] = drho_dp
    props[3, i] = drho_dh
    props[4, i] = x


@njit(cache=True, error_model="numpy")
def evaluate(y, u, c, tables, dydt, out):
    """Right-hand side and outputs at state ``y`` under inputs ``u``.

    ``u`` = (valve opening, compressor speed Hz, T_ambient K, T_indoor K, indoor relative
    humidity). Writes dy/dt into
    ``dydt`` and the nine outputs then the diagnostics into ``out`` (length :data:`N_EVAL`).
    Returns False when a property evaluation left the tables (outputs then hold NaN).
    """
    n = (y.size - 6) // 4
    props = np.empty((5, 2 * n + 3))
    cell_properties(y, tables, props)
    return balances(y, u, c, tables, props, dydt, out)


@njit(cache=True, error_model="numpy")
def _drops(flow, p_c, p_e, rho_out, rho_friction_c, rho_friction_e, c):
    """(p_s, p_d, Δp_cond, Δp_evap, Δp_vap), Pa, when ``flow`` (kg/s) passes the lumped drops:
    condenser before the condensing pressure, evaporator and vapour line after the evaporating
    one."""
    dp_cond = pressure_drop(c[C_K_COND], flow, rho_friction_c, _FLOW_EPS)
    dp_evap = pressure_drop(c[C_K_EVAP], flow, rho_friction_e, _FLOW_EPS)
    dp_vap = pressure_drop(c[C_K_VAP], flow, rho_out, _FLOW_EPS)
    return p_e - dp_evap - dp_vap, p_c + dp_cond, dp_cond, dp_evap, dp_vap


@njit(cache=True, error_model="numpy")
def _flow_through_drops(p_c, p_e, rho_out, drho_dp_out, rho_friction_c, rho_friction_e, speed, c):
    """The compressor flow that, passing the lumped drops, sets the suction and discharge
    pressures that give that flow, kg/s: the secant method on g(ṁ) - ṁ from ṁ = 0, with g the
    compressor's flow at the pressures ṁ causes (g decreases with ṁ, so the root is unique).
    The suction density is ρ at the tank outlet, linear in the drop (second-order error)."""

    def compressor_flow(flow):
        p_s, p_d = _drops(flow, p_c, p_e, rho_out, rho_friction_c, rho_friction_e, c)[:2]
        eta = volumetric_efficiency(p_d / p_s, c[C_CLEARANCE], c[C_EXPONENT], c[C_CF_VOL])
        rho_s = rho_out + drho_dp_out * (p_s - p_e)
        return compressor_mass_flow(rho_s, speed, c[C_DISPLACEMENT], eta)

    m_a = 0.0
    r_a = compressor_flow(m_a)
    m_b = r_a
    r_b = compressor_flow(m_b) - m_b
    for _ in range(_DP_ITERATIONS):
        if m_b == m_a or r_b == r_a:
            break
        m_a, r_a, m_b = m_b, r_b, m_b - r_b * (m_b - m_a) / (r_b - r_a)
        r_b = compressor_flow(m_b) - m_b
    return m_b


@njit(cache=True, error_model="numpy")
def balances(y, u, c, tables, props, dydt, out):
    """:func:`evaluate` given the cell properties ``props`` of :func:`cell_properties`."""
    n = (y.size - 6) // 4
    opening, speed, T_amb, T_ind, rh_ind = u[0], u[1], u[2], u[3], u[4]
    i_pe = 2 * n + 2
    p_c = y[0]
    p_e = y[i_pe]
    z = y[4 * n + 5]

    # ---- cells of both zones
    nc = n + 1
    ne = n + 2
    h_zc = np.empty(nc)
    h_ze = np.empty(ne)
    for i in range(n):
        h_zc[i] = y[1 + i]
        h_ze[i] = y[i_pe + 1 + i]
    h_zc[n] = y[n + 1]
    h_ze[n] = y[3 * n + 3]
    h_ze[n + 1] = y[3 * n + 4]
    vol_c = np.full(nc, c[C_V_COND])
    vol_c[n] = c[C_V_LIQ]
    vol_e = np.full(ne, c[C_V_EVAP])
    vol_e[n] = c[C_V_VAP]
    vol_e[n + 1] = c[C_V_TANK]
    T_c = props[0, :nc]
    rho_c = props[1, :nc]
    rp_c = props[2, :nc]
    rh_c = props[3, :nc]
    x_c = props[4, :nc]
    T_e = props[0, nc:]
    rho_e = props[1, nc:]
    rp_e = props[2, nc:]
    rh_e = props[3, nc:]
    x_e = props[4, nc:]
    mass = 0.0
    volume_c = 0.0  # Σ 1/ρ over the coil cells, m3/kg
    volume_e = 0.0
    for i in range(nc):
        mass += vol_c[i] * rho_c[i]
        if i < n:
            volume_c += 1.0 / rho_c[i]
    for i in range(ne):
        mass += vol_e[i] * rho_e[i]
        if i < n:
            volume_e += 1.0 / rho_e[i]
    if not math.isfinite(mass):
        out[:] = np.nan
        dydt[:] = np.nan
        return False
    # homogeneous friction along a coil goes with its mean specific volume
    rho_friction_c = n / volume_c
    rho_friction_e = n / volume_e

    # ---- suction tank (bleed), pressure drops at the compressor's own flow, compressor
    sat_e = saturation_state(tables, p_e)
    level = liquid_level(rho_e[n + 1], sat_e[3], sat_e[4])
    h_suc = tank_outlet_enthalpy(
        h_ze[n + 1], sat_e[1], sat_e[2], level, c[C_BLEED_FULL], _TANK_WIDTH
    )
    outlet = state(tables, p_e, h_suc)
    rho_out = outlet[1]
    speed = speed * protection_speed_factor(p_c, c[C_P_PROT_START], c[C_P_PROT_STOP])
    flow = _flow_through_drops(
        p_c, p_e, rho_out, outlet[2], rho_friction_c, rho_friction_e, speed, c
    )
    p_s, p_d, dp_cond, dp_evap, dp_vap = _drops(
        flow, p_c, p_e, rho_out, rho_friction_c, rho_friction_e, c
    )
    T_s, rho_s = state(tables, p_s, h_suc)[:2]
    m_comp, h_d, w_comp, w_ref, w_is, q_comp_amb = compressor(
        tables,
        p_s,
        h_suc,
        rho_s,
        p_d,
        speed,
        T_amb,
        c[C_DISPLACEMENT],
        c[C_CLEARANCE],
        c[C_EXPONENT],
        c[C_ETA_IS],
        c[C_LOSS_SHARE],
        c[C_SHELL_UA],
        c[C_CF_VOL],
        c[C_CF_POW],
        c[C_CF_PREF],
        c[C_CF_SHELL],
        c[C_T_DIS_MAX],
    )
    T_d = state(tables, p_d, h_d)[0]
    if not (math.isfinite(T_d) and math.isfinite(T_s)):
        out[:] = np.nan
        dydt[:] = np.nan
        return False

    # ---- valve and charge controller
    m_valve = valve_mass_flow(
        opening, c[C_VALVE_AREA], c[C_CF_LEV], rho_c[n], p_c - p_e, c[C_K_LIQ], _DP_REG
    )
    error = c[C_M0] - mass
    m_src = c[C_KP] * error + c[C_KI] * z

    # ---- walls and air
    cap_c = c[C_CAP_COND]
    cap_e = c[C_CAP_EVAP]
    T_air_c = air_inlet_temperature(T_amb, c[C_P_FAN_OUT], n * cap_c)
    T_air_e = air_inlet_temperature(T_ind, c[C_P_FAN_IN], n * cap_e)
    src_c = np.zeros(nc)
    src_e = np.zeros(ne)
    q_cond = 0.0
    q_evap = 0.0
    q_sensible = 0.0
    q_latent = 0.0
    W_ind = humidity_ratio(T_ind, rh_ind)
    flow_c = abs(m_comp) / c[C_MNOM_COND]
    flow_e = abs(m_valve) / c[C_MNOM_EVAP]
    sat_c = saturation_state(tables, p_c)
    x_in_c = (h_d - sat_c[1]) / (sat_c[2] - sat_c[1])  # qualities entering each coil
    x_in_e = (h_zc[n] - sat_e[1]) / (sat_e[2] - sat_e[1])
    T_in_c = state(tables, p_c, h_d)[0]
    T_in_e = state(tables, p_e, h_zc[n])[0]
    for i in range(n):
        tw = y[n + 2 + i]
        x_in, T_in, h_in = (
            (x_in_c, T_in_c, h_d) if i == 0 else (x_c[i - 1], T_c[i - 1], h_zc[i - 1])
        )
        T_mid = state(tables, p_c, 0.5 * (h_in + h_zc[i]))[0]
        q_ref = cell_heat(
            tw,
            c[C_AR_COND],
            x_in,
            x_c[i],
            T_in,
            T_mid,
            T_c[i],
            c[C_HTC_CL],
            c[C_HTC_CTP],
            c[C_HTC_CV],
            flow_c,
        )
        q_air = air_side_heat(cap_c, T_air_c, tw, c[C_HTC_CA], c[C_AA_COND])
        dydt[n + 2 + i] = (q_air - q_ref) / c[C_CW_COND]
        src_c[i] = q_ref
        q_cond -= q_ref
        tw = y[3 * n + 5 + i]
        x_in, T_in, h_in = (
            (x_in_e, T_in_e, h_zc[n]) if i == 0 else (x_e[i - 1], T_e[i - 1], h_ze[i - 1])
        )
        T_mid = state(tables, p_e, 0.5 * (h_in + h_ze[i]))[0]
        q_ref = cell_heat(
            tw,
            c[C_AR_EVAP],
            x_in,
            x_e[i],
            T_in,
            T_mid,
            T_e[i],
            c[C_HTC_EL],
            c[C_HTC_ETP],
            c[C_HTC_EV],
            flow_e,
        )
        q_air = air_side_heat(cap_e, T_air_e, tw, c[C_HTC_EA], c[C_AA_EVAP])
        q_sensible += q_air
        if rh_ind > 0.0:
            q_wet = latent_heat(cap_e, c[C_CP_AIR], W_ind, tw, c[C_HTC_EA], c[C_AA_EVAP])
            q_latent += q_wet
            q_air += q_wet
        dydt[3 * n + 5 + i] = (q_air - q_ref) / c[C_CW_EVAP]
        src_e[i] = q_ref
        q_evap += q_ref

    # ---- refrigerant zones
    src_c[0] += (m_comp + smooth_pos(m_src, _SRC_EPS)) * (h_d - h_zc[0])
    src_e[0] += upwind_weight(m_valve, _FLOW_EPS) * m_valve * (h_zc[n] - h_ze[0])
    src_e[n + 1] -= m_comp * (h_suc - h_ze[n + 1])
    dh_c = np.empty(nc)
    dh_e = np.empty(ne)
    dp_c = zone_derivatives(
        vol_c, rho_c, rp_c, rh_c, h_zc, src_c, m_comp + m_src, m_valve, _FLOW_EPS, dh_c
    )
    dp_e = zone_derivatives(vol_e, rho_e, rp_e, rh_e, h_ze, src_e, m_valve, m_comp, _FLOW_EPS, dh_e)
    dydt[0] = dp_c
    dydt[i_pe] = dp_e
    for i in range(n):
        dydt[1 + i] = dh_c[i]
        dydt[i_pe + 1 + i] = dh_e[i]
    dydt[n + 1] = dh_c[n]
    dydt[3 * n + 3] = dh_e[n]
    dydt[3 * n + 4] = dh_e[n + 1]
    dydt[4 * n + 5] = error

    # ---- outputs and diagnostics
    out[0] = T_d
    out[1] = p_d
    out[2] = T_s
    out[3] = p_s
    out[4] = T_c[n - 1]
    out[5] = p_c
    out[6] = T_e[n - 1]
    out[7] = p_e
    out[8] = m_comp
    out[9] = q_cond
    out[10] = q_evap
    out[11] = w_comp
    out[12] = w_ref
    out[13] = c[C_P_FAN_OUT] + c[C_P_FAN_IN]
    out[14] = mass
    out[15] = m_src
    out[16] = m_valve
    out[17] = w_is
    out[18] = q_comp_amb
    out[19] = c[C_FLOW_OUT]
    out[20] = c[C_FLOW_IN]
    out[21] = level
    out[22] = dp_cond
    out[23] = dp_evap
    out[24] = dp_vap
    out[25] = q_latent
    out[26] = q_sensible / (q_sensible + q_latent)
    return bool(np.isfinite(dydt).all())


@njit(cache=True, error_model="numpy")
def jacobian(y, u, c, tables, f0):
    """Dense forward-difference Jacobian ∂f/∂y at ``y`` (``f0`` = f(y)), computed in Numba.

    Each column re-evaluates only the cell properties its variable touches: none for wall
    temperatures and the controller integral, one cell for an enthalpy, one zone for a
    pressure; the balances are always recomputed.
    """
    size = y.size
    n = (size - 6) // 4
    nc = n + 1
    i_pe = 2 * n + 2
    jac = np.empty((size, size))
    props = np.empty((5, 2 * n + 3))
    cell_properties(y, tables, props)
    base = props.copy()
    work = y.copy()
    dydt = np.empty(size)
    out = np.empty(N_EVAL)
    for j in range(size):
        step = 1e-7 * max(abs(y[j]), 1.0)
        work[j] = y[j] + step
        first, last = 0, -1  # the cells whose properties this variable changes
        if j == 0:
            first, last = 0, n
        elif j <= n + 1:
            first = last = j - 1
        elif j == i_pe:
            first, last = nc, 2 * n + 2
        elif i_pe < j <= 3 * n + 4:
            first = last = nc + (j - i_pe - 1)
        for i in range(first, last + 1):
            _cell_row(work, n, i, tables, props)
        balances(work, u, c, tables, props, dydt, out)
        for i in range(size):
            jac[i, j] = (dydt[i] - f0[i]) / step
        for i in range(first, last + 1):
            for k in range(5):
                props[k, i] = base[k, i]
        work[j] = y[j]
    return jac


@njit(cache=True, error_model="numpy")
def outputs_along(ys, us, c, tables):
    """Outputs and diagnostics (columns of :data:`N_EVAL`) at each row of states ``ys`` with the
    matching inputs ``us``."""
    m = ys.shape[0]
    result = np.empty((m, N_EVAL))
    dydt = np.empty(ys.shape[1])
    out = np.empty(N_EVAL)
    for k in range(m):
        evaluate(ys[k], us[k], c, tables, dydt, out)
        result[k] = out
    return result


@njit(cache=True, error_model="numpy")
def total_mass(y, c, tables):
    """Total refrigerant mass M(y), kg (NaN if a property left the tables)."""
    n = (y.size - 6) // 4
    i_pe = 2 * n + 2
    mass = 0.0
    for i in range(n):
        mass += c[C_V_COND] * cell_state(tables, y[0], y[1 + i])[1]
        mass += c[C_V_EVAP] * cell_state(tables, y[i_pe], y[i_pe + 1 + i])[1]
    mass += c[C_V_LIQ] * cell_state(tables, y[0], y[n + 1])[1]
    mass += c[C_V_VAP] * cell_state(tables, y[i_pe], y[3 * n + 3])[1]
    mass += c[C_V_TANK] * cell_state(tables, y[i_pe], y[3 * n + 4])[1]
    return mass


@njit(cache=True, error_model="numpy")
def _quality_enthalpy(tables, p, x):
    sat = saturation_state(tables, p)
    return sat[1] + x * (sat[2] - sat[1])


@njit(cache=True, error_model="numpy")
def filled_state(s, p_c, p_e, n, tables):
    """A running-cycle state at pressures p_c, p_e whose charge grows monotonically with the fill
    level ``s`` in [-1, 2]: s < 0 leaves the condenser outlet and liquid line two-phase (up to
    quality 0.3), s in [0, 1] moves the end of condensation from the outlet to a fifth of the
    coil, s > 1 fills the suction tank with liquid. Walls start at the fluid temperature."""
    y = np.zeros(4 * n + 6)
    x_end = -0.08 + 0.38 * max(-s, 0.0)
    reach = 1.0 - 0.8 * min(max(s, 0.0), 1.0)
    y[0] = p_c
    for i in range(n):
        xi = (i + 0.5) / n
        x = max(1.05 - (1.05 - x_end) * xi / reach, x_end)
        y[1 + i] = _quality_enthalpy(tables, p_c, x)
        y[n + 2 + i] = state(tables, p_c, y[1 + i])[0]
    y[n + 1] = _quality_enthalpy(tables, p_c, x_end)
    i_pe = 2 * n + 2
    y[i_pe] = p_e
    sat_e = saturation_state(tables, p_e)
    x_in = (y[n + 1] - sat_e[1]) / (sat_e[2] - sat_e[1])
    for i in range(n):
        xi = (i + 0.5) / n
        y[i_pe + 1 + i] = _quality_enthalpy(tables, p_e, x_in + (1.05 - x_in) * xi)
        y[3 * n + 5 + i] = state(tables, p_e, y[i_pe + 1 + i])[0]
    y[3 * n + 3] = _quality_enthalpy(tables, p_e, 1.05)
    y[3 * n + 4] = _quality_enthalpy(tables, p_e, 1.05 - 1.1 * min(max(s - 1.0, 0.0), 1.0))
    return y


def initial_state(
    c: np.ndarray, n_volumes: int, T_ambient: float, T_indoor: float, tables
) -> np.ndarray:
    """The initial state holding exactly the charge M0 (``c[C_M0]``), the paper's
    initialisation by M0 alone: condensing 12 K above ambient, evaporating 18 K below indoor,
    and the fill level of :func:`filled_state` found by bisection on the total mass.

    Raises ``ValueError`` if the unit cannot hold M0 in such a state.
    """
    from pymc_vcc.physics.refrigerant import p_sat_from_T

    p_c = p_sat_from_T(tables, T_ambient + 12.0)
    p_e = p_sat_from_T(tables, T_indoor - 18.0)
    target = c[C_M0]
    low, high = -1.0, 2.0
    m_low = total_mass(filled_state(low, p_c, p_e, n_volumes, tables), c, tables)
    m_high = total_mass(filled_state(high, p_c, p_e, n_volumes, tables), c, tables)
    if not m_low <= target <= m_high:
        raise ValueError(
            f"charge M0 = {target} kg cannot be placed in this unit at start-up: it holds "
            f"{m_low:.3f} to {m_high:.3f} kg"
        )
    for _ in range(60):
        mid = 0.5 * (low + high)
        if total_mass(filled_state(mid, p_c, p_e, n_volumes, tables), c, tables) < target:
            low = mid
        else:
            high = mid
    y = filled_state(0.5 * (low + high), p_c, p_e, n_volumes, tables)
    return y
