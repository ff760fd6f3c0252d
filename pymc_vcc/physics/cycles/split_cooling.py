"""Split air conditioner in cooling mode: the outdoor coil condenses, the indoor coil evaporates.

Two pressure zones (N = cells per heat exchanger):

* high side: the condenser's N cells, then the liquid line (one adiabatic cell); outflow: valve;
* low side: the evaporator's N cells, the vapour line and the suction tank; outflow: compressor.

The virtual PI charge controller (paper, section II-B) adds ṁ_src = Kp (M0 - M) + Ki z at the
compressor discharge, at the discharge enthalpy (leaving at the first condenser cell's own
enthalpy when negative), with ż = M0 - M. Lumped pressure drops: condenser (at its inlet, so
PD = PC + Δp), evaporator and vapour line (between the low-side zone and the compressor
suction, so PS = PE - Δp), liquid line (in series with the valve).
"""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from pymc_vcc.physics.components.compressor import compressor, protection_speed_factor
from pymc_vcc.physics.components.density import cell_state, fillet_memo
from pymc_vcc.physics.components.expansion_valve import valve_mass_flow
from pymc_vcc.physics.components.fan import air_inlet_temperature
from pymc_vcc.physics.components.heat_exchanger import zone_derivatives
from pymc_vcc.physics.components.heat_transfer import air_side_heat
from pymc_vcc.physics.components.moist_air import humidity_ratio, latent_heat
from pymc_vcc.physics.components.smooth import smooth_pos, upwind_weight
from pymc_vcc.physics.cycles.base import (
    N_PROPERTIES,
    Block,
    BlockKind,
    CycleModel,
    StateLayout,
    cell_properties,
    perturb,
    place_charge,
    quality_enthalpy,
    restore,
    stored_mass,
)
from pymc_vcc.physics.cycles.split_unit import (
    DIAGNOSTIC_INFO,
    DP_REG,
    FLOW_EPS,
    OPTIONAL_OUTPUT_IDS,
    OUTPUT_INFO,
    PARAMETERS,
    SRC_EPS,
    coil_cell_heat,
    coil_friction_density,
    filled_coils,
    flow_through_drops,
    lumped_drops,
    split_unit_constants,
    suction_outlet,
)
from pymc_vcc.physics.refrigerant import p_sat_from_T, saturation_point, state, state_at

if TYPE_CHECKING:
    from pymc_vcc.physics.unit import Unit

N_EVAL = len(OUTPUT_INFO) + len(DIAGNOSTIC_INFO)


@functools.cache
def layout(n_volumes: int) -> StateLayout:
    """The state: two zones (pressure, then cell enthalpies in flow order), walls, integral;
    one shared layout per size (see :func:`~.split_unit.split_unit_dtype`)."""
    return StateLayout(
        [
            Block("p_cond", 1, BlockKind.PRESSURE),
            Block("h_cond", n_volumes, BlockKind.ENTHALPY),
            Block("h_liquid_line", 1, BlockKind.ENTHALPY),
            Block("Tw_cond", n_volumes, BlockKind.TEMPERATURE),
            Block("p_evap", 1, BlockKind.PRESSURE),
            Block("h_evap", n_volumes, BlockKind.ENTHALPY),
            Block("h_vapor_line", 1, BlockKind.ENTHALPY),
            Block("h_tank", 1, BlockKind.ENTHALPY),
            Block("Tw_evap", n_volumes, BlockKind.TEMPERATURE),
            Block("z", 1, BlockKind.INTEGRAL),
        ]
    )


@njit(cache=True, error_model="numpy")
def cell_volumes(c):
    """Volume of every cell (numbered zone after zone), m³."""
    n = c.layout.h_liquid_line - c.layout.h_cond
    volumes = np.empty(2 * n + 3)
    volumes[:n] = c.condenser.cell_volume
    volumes[n] = c.liquid_line.volume
    volumes[n + 1 : 2 * n + 1] = c.evaporator.cell_volume
    volumes[2 * n + 1] = c.vapor_line.volume
    volumes[2 * n + 2] = c.tank.volume
    return volumes


@njit(cache=True, error_model="numpy")
def evaluate(y, u, constants, tables, dydt, out):
    """Right-hand side and outputs at state ``y`` under inputs ``u`` = (valve opening,
    compressor speed Hz, T_ambient K, T_indoor K, indoor relative humidity); see
    :class:`~.base.CycleModel`. With RH > 0 the indoor coil (the evaporator) condenses water
    where its wall is below the dew point: that latent heat adds to the wall's load."""
    c = constants[0]
    props = np.empty((N_PROPERTIES, c.layout.zones[:, 1].sum()))
    cell_properties(y, c.layout.zones, tables, props)
    return balances(y, u, c, tables, props, dydt, out)


@njit(cache=True, error_model="numpy")
def balances(y, u, c, tables, props, dydt, out, rates=True):
    """:func:`evaluate` given the cell properties ``props`` of every cell; with ``rates``
    False the outputs alone (walls and zones skipped: ``dydt`` untouched, the heats NaN)."""
    at = c.layout
    n = at.h_liquid_line - at.h_cond
    opening, speed, T_amb, T_ind, rh_ind = u[0], u[1], u[2], u[3], u[4]
    p_c = y[at.p_cond]
    p_e = y[at.p_evap]
    z = y[at.z]
    cond, evap, comp = c.condenser, c.evaporator, c.compressor

    # ---- cells of both zones: condenser + liquid line, evaporator + vapour line + tank
    nc = n + 1
    ne = n + 2
    h_zc = y[at.h_cond : at.h_cond + nc]
    h_ze = y[at.h_evap : at.h_evap + ne]
    volumes = cell_volumes(c)
    vol_c = volumes[:nc]
    vol_e = volumes[nc:]
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
    mass = stored_mass(volumes, props[1])
    if not math.isfinite(mass):
        out[:] = np.nan
        dydt[:] = np.nan
        return False
    # homogeneous friction along a coil goes with its mean specific volume
    rho_friction_c = coil_friction_density(rho_c, n)
    rho_friction_e = coil_friction_density(rho_e, n)

    # ---- suction tank (bleed), pressure drops at the compressor's own flow, compressor
    h_suc, level = suction_outlet(tables, p_e, h_ze[n + 1], rho_e[n + 1], c)
    outlet = state(tables, p_e, h_suc)
    rho_out = outlet[1]
    speed = speed * protection_speed_factor(p_c, comp.p_protection_start, comp.p_protection_stop)
    flow = flow_through_drops(
        p_c, p_e, rho_out, outlet[2], rho_out, rho_friction_c, rho_friction_e, speed, c, False
    )
    p_s, p_d, dp_cond, dp_evap, dp_vap = lumped_drops(
        flow, p_c, p_e, rho_out, rho_friction_c, rho_friction_e, c, False
    )
    T_s, rho_s = state(tables, p_s, h_suc)[:2]
    m_comp, h_d, w_comp, w_ref, w_is, q_comp_amb = compressor(
        tables, p_s, h_suc, rho_s, p_d, speed, T_amb, comp
    )
    T_d = state(tables, p_d, h_d)[0]
    if not (math.isfinite(T_d) and math.isfinite(T_s)):
        out[:] = np.nan
        dydt[:] = np.nan
        return False

    # ---- valve and charge controller
    m_valve = valve_mass_flow(
        opening,
        c.valve.flow_area,
        c.valve.cf_lev,
        rho_c[n],
        p_c - p_e,
        c.liquid_line.friction,
        DP_REG,
    )
    error = c.controller.m0 - mass
    m_src = c.controller.kp * error + c.controller.ki * z

    q_cond = q_evap = q_latent = q_sensible = np.nan
    if rates:
        # ---- walls and air: outdoor air over the condenser, indoor air over the evaporator
        T_air_c = air_inlet_temperature(T_amb, cond.fan_power, n * cond.air_capacity)
        T_air_e = air_inlet_temperature(T_ind, evap.fan_power, n * evap.air_capacity)
        src_c = np.zeros(nc)
        src_e = np.zeros(ne)
        q_cond = 0.0
        q_evap = 0.0
        q_sensible = 0.0
        q_latent = 0.0
        W_ind = humidity_ratio(T_ind, rh_ind)
        flow_c = abs(m_comp) / cond.nominal_mass_flow
        flow_e = abs(m_valve) / evap.nominal_mass_flow
        point_c = saturation_point(tables, p_c)
        point_e = saturation_point(tables, p_e)
        x_in_c = (h_d - point_c.h_l) / (point_c.h_v - point_c.h_l)  # qualities entering each coil
        x_in_e = (h_zc[n] - point_e.h_l) / (point_e.h_v - point_e.h_l)
        T_in_c = state_at(tables, point_c, p_c, h_d)[0]
        T_in_e = state_at(tables, point_e, p_e, h_zc[n])[0]
        for i in range(n):
            tw = y[at.Tw_cond + i]
            h_in, x_in, T_in = (
                (h_d, x_in_c, T_in_c) if i == 0 else (h_zc[i - 1], x_c[i - 1], T_c[i - 1])
            )
            q_ref = coil_cell_heat(
                tables, point_c, p_c, cond, tw, flow_c, h_in, x_in, T_in, h_zc[i], x_c[i], T_c[i]
            )
            q_air = air_side_heat(cond.air_capacity, T_air_c, tw, cond.htc_air, cond.air_area)
            dydt[at.Tw_cond + i] = (q_air - q_ref) / cond.wall_capacity
            src_c[i] = q_ref
            q_cond -= q_ref
            tw = y[at.Tw_evap + i]
            h_in, x_in, T_in = (
                (h_zc[n], x_in_e, T_in_e) if i == 0 else (h_ze[i - 1], x_e[i - 1], T_e[i - 1])
            )
            q_ref = coil_cell_heat(
                tables, point_e, p_e, evap, tw, flow_e, h_in, x_in, T_in, h_ze[i], x_e[i], T_e[i]
            )
            q_air = air_side_heat(evap.air_capacity, T_air_e, tw, evap.htc_air, evap.air_area)
            q_sensible += q_air
            if rh_ind > 0.0:
                q_wet = latent_heat(
                    evap.air_capacity, c.air_specific_heat, W_ind, tw, evap.htc_air, evap.air_area
                )
                q_latent += q_wet
                q_air += q_wet
            dydt[at.Tw_evap + i] = (q_air - q_ref) / evap.wall_capacity
            src_e[i] = q_ref
            q_evap += q_ref

        # ---- refrigerant zones
        src_c[0] += (m_comp + smooth_pos(m_src, SRC_EPS)) * (h_d - h_zc[0])
        src_e[0] += upwind_weight(m_valve, FLOW_EPS) * m_valve * (h_zc[n] - h_ze[0])
        src_e[n + 1] -= m_comp * (h_suc - h_ze[n + 1])
        dp_c = zone_derivatives(
            vol_c,
            rho_c,
            rp_c,
            rh_c,
            h_zc,
            src_c,
            m_comp + m_src,
            m_valve,
            FLOW_EPS,
            dydt[at.h_cond : at.h_cond + nc],
        )
        dp_e = zone_derivatives(
            vol_e,
            rho_e,
            rp_e,
            rh_e,
            h_ze,
            src_e,
            m_valve,
            m_comp,
            FLOW_EPS,
            dydt[at.h_evap : at.h_evap + ne],
        )
        dydt[at.p_cond] = dp_c
        dydt[at.p_evap] = dp_e
        dydt[at.z] = error

    # ---- outputs and diagnostics, in the order of OUTPUT_INFO and DIAGNOSTIC_INFO
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
    out[13] = cond.fan_power + evap.fan_power
    out[14] = mass
    out[15] = m_src
    out[16] = m_valve
    out[17] = w_is
    out[18] = q_comp_amb
    out[19] = cond.air_flow  # outdoor fan over the condenser
    out[20] = evap.air_flow
    out[21] = level
    out[22] = dp_cond
    out[23] = dp_evap
    out[24] = dp_vap
    out[25] = q_latent
    out[26] = q_sensible / (q_sensible + q_latent)
    return not rates or bool(np.isfinite(dydt).all())


@njit(cache=True, error_model="numpy")
def jacobian(y, u, constants, tables, f0):
    """Dense forward-difference Jacobian ∂f/∂y at ``y`` (``f0`` = f(y)); each column
    re-evaluates only the cell properties its variable touches."""
    c = constants[0]
    zones = c.layout.zones
    jac = np.empty((y.size, y.size))
    props = np.empty((N_PROPERTIES, zones[:, 1].sum()))
    cell_properties(y, zones, tables, props)
    saved = props.copy()
    work = y.copy()
    dydt = np.empty(y.size)
    out = np.empty(N_EVAL)
    for j in range(y.size):
        step = perturb(y, work, j, zones, tables, props)
        balances(work, u, c, tables, props, dydt, out)
        for i in range(y.size):
            jac[i, j] = (dydt[i] - f0[i]) / step
        restore(y, work, j, zones, props, saved)
    return jac


@njit(cache=True, error_model="numpy")
def outputs_along(ys, us, constants, tables, rates):
    """Outputs and diagnostics at each row of states ``ys`` with the matching inputs ``us``;
    with ``rates`` False the heats are NaN (see :func:`balances`), at half the cost."""
    c = constants[0]
    props = np.empty((N_PROPERTIES, c.layout.zones[:, 1].sum()))
    result = np.empty((ys.shape[0], N_EVAL))
    dydt = np.empty(ys.shape[1])
    out = np.empty(N_EVAL)
    for k in range(ys.shape[0]):
        cell_properties(ys[k], c.layout.zones, tables, props)
        balances(ys[k], us[k], c, tables, props, dydt, out, rates)
        result[k] = out
    return result


@njit(cache=True, error_model="numpy")
def total_mass(y, constants, tables):
    """Total refrigerant mass M(y), kg (NaN if a property left the tables). Summed coil cell by
    coil cell, then the lines and the tank: the order the regression reference was made with."""
    c = constants[0]
    at = c.layout
    n = at.h_liquid_line - at.h_cond
    p_c, p_e = y[at.p_cond], y[at.p_evap]
    sat_c, sat_e = saturation_point(tables, p_c), saturation_point(tables, p_e)
    memo_c, memo_e = fillet_memo(), fillet_memo()
    mass = 0.0
    for i in range(n):
        h_c, h_e = y[at.h_cond + i], y[at.h_evap + i]
        mass += c.condenser.cell_volume * cell_state(tables, sat_c, p_c, h_c, memo_c)[1]
        mass += c.evaporator.cell_volume * cell_state(tables, sat_e, p_e, h_e, memo_e)[1]
    h_liquid, h_vapor, h_tank = y[at.h_liquid_line], y[at.h_vapor_line], y[at.h_tank]
    mass += c.liquid_line.volume * cell_state(tables, sat_c, p_c, h_liquid, memo_c)[1]
    mass += c.vapor_line.volume * cell_state(tables, sat_e, p_e, h_vapor, memo_e)[1]
    mass += c.tank.volume * cell_state(tables, sat_e, p_e, h_tank, memo_e)[1]
    return mass


@njit(cache=True, error_model="numpy")
def filled_state(s, p_c, p_e, constants, tables):
    """:func:`~.split_unit.filled_coils` at fill level ``s``, the vapour line (low side)
    superheated."""
    at = constants[0].layout
    y = filled_coils(s, p_c, p_e, at, tables)
    y[at.h_vapor_line] = quality_enthalpy(tables, p_e, 1.05)
    return y


class SplitCooling(CycleModel):
    """The built-in 3.5 kW split air conditioner in cooling mode."""

    name = "split-cooling"
    description = "split air conditioner, cooling: outdoor coil condenses, indoor evaporates"
    parameters = PARAMETERS
    output_info = OUTPUT_INFO
    diagnostic_info = DIAGNOSTIC_INFO
    optional_output_ids = OPTIONAL_OUTPUT_IDS
    capacity = "Q_evap"
    evaluate = staticmethod(evaluate)
    jacobian = staticmethod(jacobian)
    outputs_along = staticmethod(outputs_along)
    total_mass = staticmethod(total_mass)

    def layout(self, n_volumes: int) -> StateLayout:
        return layout(n_volumes)

    def constants(
        self, unit: Unit, theta: np.ndarray, controller: bool | None = None
    ) -> np.ndarray:
        n = unit.discretisation.n_volumes
        return split_unit_constants(unit, theta, layout(n), controller, condenser_fan="outdoor")

    def initial_state(
        self, c: np.ndarray, n_volumes: int, inputs: np.ndarray, tables
    ) -> np.ndarray:
        """The paper's initialisation by M0 alone: condensing 12 K above the outdoor air,
        evaporating 18 K below the indoor air, the fill level of :func:`filled_state` found
        by bisection on the total mass."""
        p_c = p_sat_from_T(tables, inputs[2] + 12.0)
        p_e = p_sat_from_T(tables, inputs[3] - 18.0)
        return place_charge(
            lambda s: filled_state(s, p_c, p_e, c, tables),
            lambda y: total_mass(y, c, tables),
            self.charge(c),
        )
