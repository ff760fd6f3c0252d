"""The split unit's right-hand side, Jacobian and outputs in either of its modes, and the base
class of its modes' cycle models.

Both modes have two pressure zones (N = cells per coil):

* high side: the condenser's N cells, then the liquid line (one adiabatic cell); outflow: the
  expansion valve;
* low side: the evaporator's N cells, then the suction tank; outflow: the compressor.

The reversing valve decides where the vapour line sits. Cooling: it carries the suction gas
from the indoor coil (the evaporator), after the evaporator's cells on the low side, and the
outdoor coil condenses. Heating: it carries the hot gas to the indoor coil (the condenser),
before the condenser's cells on the high side, and the outdoor coil evaporates. The cycle's
state layout says which (:func:`hot_gas_line`); everything else reads the layout.

The virtual PI charge controller (paper, section II-B) adds ṁ_src = Kp (M0 - M) + Ki z at the
compressor discharge, at the discharge enthalpy (leaving at the first high-side cell's own
enthalpy when negative), with ż = M0 - M. Lumped pressure drops: the condenser's (and the hot
gas line's) between the discharge and the high-side zone (PD = PC + Δp), the evaporator's (and
the suction line's) between the low-side zone and the suction (PS = PE - Δp), the liquid
line's in series with the valve; the compressor flow solves for the pressures its own flow
causes (:func:`~.split_unit.flow_through_drops`). Two faults (:data:`~.split_unit.FAULTS`,
none at their nominal 0): non-condensable gas adds its partial pressure to every pressure the
high side presents (the compressor's discharge, the valve's inlet, PD and PC) while the
refrigerant condenses at its own (the state's); a liquid-line restriction adds its flow
resistance to the line's in series with the valve. The indoor coil condenses water where it
evaporates below the dew point; where it condenses there is no latent load (``Q_latent`` = 0,
``SHR`` = 1).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import ClassVar, Literal, NamedTuple

import numpy as np
from numba import njit

from pymc_vcc.physics.components.compressor import compressor, protection_speed_factor
from pymc_vcc.physics.components.density import FILLET_MEMO_SHAPE
from pymc_vcc.physics.components.expansion_valve import valve_mass_flow
from pymc_vcc.physics.components.fan import air_inlet_temperature
from pymc_vcc.physics.components.heat_exchanger import zone_pair_derivatives
from pymc_vcc.physics.components.heat_transfer import (
    air_effectiveness,
    air_side_heat,
    flow_scale,
)
from pymc_vcc.physics.components.moist_air import humidity_ratio, latent_heat
from pymc_vcc.physics.components.smooth import smooth_pos, upwind_weight
from pymc_vcc.physics.cycles.base import (
    N_PROPERTIES,
    CycleModel,
    UnitDescription,
    cell_properties,
    perturb,
    restore,
    stored_mass,
)
from pymc_vcc.physics.cycles.split_unit import (
    DP_REG,
    FAULTS,
    FLOW_EPS,
    INPUTS,
    OUTPUTS,
    PARAMETERS,
    SRC_EPS,
    SplitUnitHardware,
    coil_cell_heat,
    coil_friction_density,
    flow_through_drops,
    lumped_drops,
    split_unit_constants,
    suction_outlet,
)
from pymc_vcc.physics.refrigerant import (
    SaturationPoint,
    saturation_point,
    saturation_state,
    state_at,
    state_values_at,
)
from pymc_vcc.physics.scratch import all_finite, borrowed, stack_empty, stack_full, uncounted

U = INPUTS.offsets
"""Where each input sits in ``u`` (``u[U.T_ambient]``), constants to Numba."""

OUT = OUTPUTS.offsets
"""Where each output and diagnostic sits in ``out`` (``out[OUT.TD]``), constants to Numba."""

N_EVAL = OUTPUTS.size

MEMO_COLUMNS = 10
"""A remembered coil cell heat: p, T_wall, flow scale, h_in, x_in, T_in, h, x, T, then the heat."""


@njit(cache=True, error_model="numpy")
def hot_gas_line(at):
    """Whether the vapour line carries the hot gas (heating): the layout ``at`` then holds it in
    the high-side zone, before the condenser's cells."""
    return at.h_vapor_line < at.h_cond


@njit(cache=True, error_model="numpy")
def cell_volumes(c, volumes):
    """Write the volume of every cell (numbered zone after zone, in flow order) into
    ``volumes``, m³."""
    at = c.layout
    n = at.h_liquid_line - at.h_cond
    first = 1 if hot_gas_line(at) else 0  # the condenser's first cell in the high-side zone
    if first:
        volumes[0] = c.vapor_line.volume
    volumes[first : first + n] = c.condenser.cell_volume
    volumes[first + n] = c.liquid_line.volume
    volumes[first + n + 1 : first + 2 * n + 1] = c.evaporator.cell_volume
    if not first:
        volumes[2 * n + 1] = c.vapor_line.volume
    volumes[2 * n + 2] = c.tank.volume


@njit(cache=True, error_model="numpy")
def evaluate(y, u, constants, tables, dydt, out):
    """Right-hand side and outputs at state ``y`` under inputs ``u`` = (valve opening,
    compressor speed Hz, T_ambient K, T_indoor K, indoor relative humidity); see
    :class:`~.base.CycleModel`. With RH > 0 an evaporating indoor coil condenses water where its
    wall is below the dew point: that latent heat adds to the wall's load."""
    y, u, constants, tables, dydt, out = borrowed((y, u, constants, tables, dydt, out))
    c = constants[0]
    props = stack_empty((N_PROPERTIES, c.layout.zones[:, 1].sum()))
    cell_properties(y, c.layout.zones, tables, props)
    return balances(y, u, c, tables, props, dydt, out)


@njit(cache=True, error_model="numpy", inline="always")
def remembered_cell_heat(memo, row, tables, sat, p, coil, T_wall, scale, h_in, x_in, T_in, h, x, T):
    """:func:`coil_cell_heat`, taken from row ``row`` of ``memo`` when the row holds these same
    arguments (the coil and tables aside) and worked out afresh otherwise. The heat is
    proportional to the flow ``scale`` (it multiplies the refrigerant-side HTC), so a row that
    differs in the scale alone gives its heat rescaled: a Jacobian column that moves only the
    flows (the cell sums, a zone's last cell) then works out no heat. With ``memo`` None it
    always works it out; a row of NaN matches nothing."""
    if memo is not None:
        m = memo[row]
        if (
            m[0] == p and m[1] == T_wall and m[3] == h_in and m[4] == x_in
            and m[5] == T_in and m[6] == h and m[7] == x and m[8] == T
        ):  # fmt: skip
            return m[9] if m[2] == scale else m[9] * (scale / m[2])
    return coil_cell_heat(tables, sat, p, coil, T_wall, scale, h_in, x_in, T_in, h, x, T)


@njit(cache=True, error_model="numpy")
def remember_cell_heat(memo, row, p, T_wall, scale, h_in, x_in, T_in, h, x, T, q):
    """Keep heat ``q`` and its arguments in row ``row`` of ``memo`` (None: nothing)."""
    if memo is not None:
        m = memo[row]
        m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7], m[8], m[9] = (
            p, T_wall, scale, h_in, x_in, T_in, h, x, T, q
        )  # fmt: skip


class Flows(NamedTuple):
    """What joins the cells of the two zones: the flows between them and their enthalpies, from
    :func:`flows`; with the pressures and the outputs that come with them (SI units)."""

    finite: bool  # False: a property left the tables (everything else may be NaN)
    mass: float  # total refrigerant mass, kg
    m_src: float  # charge-controller source, kg/s
    m_comp: float  # compressor flow, kg/s
    m_valve: float  # valve flow, kg/s
    h_d: float  # discharge enthalpy, J/kg
    h_suc: float  # enthalpy leaving the suction tank, J/kg
    level: float  # suction-tank liquid level, -
    sat_e: SaturationPoint  # of the low-side pressure
    p_s: float  # suction and discharge pressure, Pa
    p_d: float
    T_s: float  # suction and discharge temperature, K
    T_d: float
    dp_cond: float  # lumped pressure drops, Pa
    dp_evap: float
    dp_vap: float
    w_comp: float  # compressor electrical, net and isentropic power, W
    w_ref: float
    w_is: float
    q_comp_amb: float  # compressor heat to the ambient, W


N_SUMS = 3
"""Sums over many cells that the flows read (:func:`cell_sums`): the total mass and the two
coils' friction densities."""


@uncounted
def cell_sums(c, props):
    """(total mass kg, condenser and evaporator friction densities kg/m³): the flows' only
    reach into the cells beyond each zone's first and last ones (:func:`flows`)."""
    at = c.layout
    n = at.h_liquid_line - at.h_cond
    first = 1 if hot_gas_line(at) else 0
    nc = at.zones[0, 1]
    volumes = stack_empty(props.shape[1])
    cell_volumes(c, volumes)
    mass = stored_mass(volumes, props[1])
    # homogeneous friction along a coil goes with its mean specific volume
    return (
        mass,
        coil_friction_density(props[1, first : first + n], n),
        coil_friction_density(props[1, nc:], n),
    )


# flows and rates are inlined where they are called: as calls of their own they made a
# right-hand side 2.5 µs (a sixth) slower
@njit(cache=True, error_model="numpy", inline="always")
def flows(y, u, c, tables, props, sums):
    """The :class:`Flows` at state ``y`` (cell properties ``props``, :func:`cell_sums`
    ``sums``): suction tank, compressor through the lumped drops, valve and controller. Besides
    the sums they read the pressures, the integral and the zones' end cells only."""
    at = c.layout
    heating = hot_gas_line(at)
    speed, T_amb = u[U.compressor_speed], u[U.T_ambient]
    p_c = y[at.p_cond]
    p_e = y[at.p_evap]
    comp = c.compressor
    nc = at.zones[0, 1]
    ne = at.zones[1, 1]
    rho_c = props[1, :nc]
    rho_e = props[1, nc:]
    mass, rho_friction_c, rho_friction_e = sums
    point_e = saturation_point(tables, p_e)
    if not math.isfinite(mass):
        nan = np.nan
        return Flows(
            False, mass, nan, nan, nan, nan, nan, nan, point_e,
            nan, nan, nan, nan, nan, nan, nan, nan, nan, nan, nan,
        )  # fmt: skip

    # ---- suction tank (bleed), pressure drops at the compressor's own flow, compressor
    h_suc, level = suction_outlet(point_e, y[at.p_evap + ne], rho_e[ne - 1], c)
    outlet = state_at(tables, point_e, p_e, h_suc)
    rho_out = outlet[1]
    rho_vapor_line = rho_c[0] if heating else rho_out
    # what the high side presents to the compressor, valve and sensors: the refrigerant's
    # (saturation) pressure and the partial pressure of non-condensable gas in the condenser
    p_high = p_c + c.faults.noncondensable_pressure
    speed = speed * protection_speed_factor(p_high, comp.p_protection_start, comp.p_protection_stop)
    flow = flow_through_drops(
        p_high,
        p_e,
        rho_out,
        outlet[2],
        rho_vapor_line,
        rho_friction_c,
        rho_friction_e,
        speed,
        c,
        heating,
    )
    p_s, p_d, dp_cond, dp_evap, dp_vap = lumped_drops(
        flow, p_high, p_e, rho_vapor_line, rho_friction_c, rho_friction_e, c, heating
    )
    point_s = saturation_point(tables, p_s)
    point_d = saturation_point(tables, p_d)
    T_s, rho_s = state_values_at(tables, point_s, p_s, h_suc)[:2]
    m_comp, h_d, w_comp, w_ref, w_is, q_comp_amb = compressor(
        tables, p_s, point_s, h_suc, rho_s, p_d, point_d, speed, T_amb, comp
    )
    T_d = state_values_at(tables, point_d, p_d, h_d)[0]

    # ---- valve and charge controller
    m_valve = valve_mass_flow(
        u[U.valve_opening],
        c.valve.flow_area,
        c.valve.cf_lev,
        rho_c[nc - 1],
        p_high - p_e,
        c.liquid_line.friction + c.faults.restriction,  # the line and a restriction in series
        DP_REG,
    )
    m_src = c.controller.kp * (c.controller.m0 - mass) + c.controller.ki * y[at.z]
    return Flows(
        math.isfinite(T_d) and math.isfinite(T_s),
        mass,
        m_src,
        m_comp,
        m_valve,
        h_d,
        h_suc,
        level,
        point_e,
        p_s,
        p_d,
        T_s,
        T_d,
        dp_cond,
        dp_evap,
        dp_vap,
        w_comp,
        w_ref,
        w_is,
        q_comp_amb,
    )


@njit(cache=True, error_model="numpy", inline="always")
def coil_rates(y, u, c, tables, props, flow, dydt, memo, remember):
    """The coils' wall rates into ``dydt``, each coil under its own fan's air; returns the heat
    each zone cell takes from its wall (high side, low side; W) and (Q_cond, Q_evap, sensible
    and latent heat of the indoor coil), W. ``memo`` and ``remember`` as for :func:`rates`."""
    at = c.layout
    n = at.h_liquid_line - at.h_cond
    heating = hot_gas_line(at)
    first = 1 if heating else 0  # the condenser's first cell in the high-side zone
    T_amb, T_ind, rh_ind = u[U.T_ambient], u[U.T_indoor], u[U.RH_indoor]
    p_c = y[at.p_cond]
    p_e = y[at.p_evap]
    cond, evap = c.condenser, c.evaporator
    nc = at.zones[0, 1]  # high-side cells
    ne = at.zones[1, 1]
    h_zc = y[at.p_cond + 1 : at.p_cond + 1 + nc]
    h_ze = y[at.p_evap + 1 : at.p_evap + 1 + ne]
    T_c = props[0, :nc]
    x_c = props[4, :nc]
    T_e = props[0, nc:]
    x_e = props[4, nc:]
    m_comp, m_valve, h_d = flow.m_comp, flow.m_valve, flow.h_d
    point_e = flow.sat_e
    T_air_c = air_inlet_temperature(
        T_ind if heating else T_amb, cond.fan_power, n * cond.air_capacity
    )
    T_air_e = air_inlet_temperature(
        T_amb if heating else T_ind, evap.fan_power, n * evap.air_capacity
    )
    src_c = stack_full(nc, 0.0)
    src_e = stack_full(ne, 0.0)
    q_cond = 0.0
    q_evap = 0.0
    q_sensible = 0.0
    q_latent = 0.0
    W_ind = humidity_ratio(T_ind, rh_ind)
    scale_c = flow_scale(abs(m_comp) / cond.nominal_mass_flow)
    scale_e = flow_scale(abs(m_valve) / evap.nominal_mass_flow)
    air_c = air_effectiveness(cond.air_capacity, cond.htc_air, cond.air_area)
    air_e = air_effectiveness(evap.air_capacity, evap.htc_air, evap.air_area)
    point_c = saturation_point(tables, p_c)
    # what enters each coil: the discharge gas (or the hot gas line), the liquid line
    h_in_c, x_in_c, T_in_c = h_d, 0.0, 0.0
    if not heating:
        x_in_c = (h_d - point_c.h_l) / (point_c.h_v - point_c.h_l)
        T_in_c = state_values_at(tables, point_c, p_c, h_d)[0]
    x_in_e = (h_zc[nc - 1] - point_e.h_l) / (point_e.h_v - point_e.h_l)
    T_in_e = state_values_at(tables, point_e, p_e, h_zc[nc - 1])[0]
    for i in range(n):
        k = first + i  # condenser cell i in the high-side zone
        tw = y[at.Tw_cond + i]
        h_in, x_in, T_in = (
            (h_in_c, x_in_c, T_in_c) if k == 0 else (h_zc[k - 1], x_c[k - 1], T_c[k - 1])
        )
        h, x, T = h_zc[k], x_c[k], T_c[k]
        q_ref = remembered_cell_heat(
            memo, i, tables, point_c, p_c, cond, tw, scale_c, h_in, x_in, T_in, h, x, T
        )
        if remember:
            remember_cell_heat(memo, i, p_c, tw, scale_c, h_in, x_in, T_in, h, x, T, q_ref)
        q_air = air_side_heat(cond.air_capacity, T_air_c, tw, air_c)
        dydt[at.Tw_cond + i] = (q_air - q_ref) / cond.wall_capacity
        src_c[k] = q_ref
        q_cond -= q_ref
        tw = y[at.Tw_evap + i]
        h_in, x_in, T_in = (
            (h_zc[nc - 1], x_in_e, T_in_e) if i == 0 else (h_ze[i - 1], x_e[i - 1], T_e[i - 1])
        )
        h, x, T = h_ze[i], x_e[i], T_e[i]
        q_ref = remembered_cell_heat(
            memo, n + i, tables, point_e, p_e, evap, tw, scale_e, h_in, x_in, T_in, h, x, T
        )
        if remember:
            remember_cell_heat(memo, n + i, p_e, tw, scale_e, h_in, x_in, T_in, h, x, T, q_ref)
        q_air = air_side_heat(evap.air_capacity, T_air_e, tw, air_e)
        if not heating:  # the indoor coil evaporates: sensible and latent load
            q_sensible += q_air
            if rh_ind > 0.0:
                q_wet = latent_heat(
                    evap.air_capacity,
                    c.air_specific_heat,
                    W_ind,
                    tw,
                    evap.htc_air,
                    evap.air_area,
                )
                q_latent += q_wet
                q_air += q_wet
        dydt[at.Tw_evap + i] = (q_air - q_ref) / evap.wall_capacity
        src_e[i] = q_ref
        q_evap += q_ref
    return src_c, src_e, q_cond, q_evap, q_sensible, q_latent


@njit(cache=True, error_model="numpy", inline="always")
def zone_rates(y, c, props, flow, src_c, src_e, dydt):
    """The refrigerant zones' rates (pressure, enthalpies) and the controller integral's into
    ``dydt``, given the heat each cell takes from its wall (``src_c``, ``src_e``, W)."""
    at = c.layout
    nc = at.zones[0, 1]  # high-side cells
    ne = at.zones[1, 1]
    h_zc = y[at.p_cond + 1 : at.p_cond + 1 + nc]
    h_ze = y[at.p_evap + 1 : at.p_evap + 1 + ne]
    volumes = stack_empty(props.shape[1])
    cell_volumes(c, volumes)
    m_comp, m_src, m_valve, h_d = flow.m_comp, flow.m_src, flow.m_valve, flow.h_d
    src_c[0] += (m_comp + smooth_pos(m_src, SRC_EPS)) * (h_d - h_zc[0])
    src_e[0] += upwind_weight(m_valve, FLOW_EPS) * m_valve * (h_zc[nc - 1] - h_ze[0])
    src_e[ne - 1] -= m_comp * (flow.h_suc - h_ze[ne - 1])
    high = (
        volumes[:nc],
        props[1, :nc],
        props[2, :nc],
        props[3, :nc],
        h_zc,
        src_c,
        m_comp + m_src,
        m_valve,
        dydt[at.p_cond + 1 : at.p_cond + 1 + nc],
    )
    low = (
        volumes[nc:],
        props[1, nc:],
        props[2, nc:],
        props[3, nc:],
        h_ze,
        src_e,
        m_valve,
        m_comp,
        dydt[at.p_evap + 1 : at.p_evap + 1 + ne],
    )
    dydt[at.p_cond], dydt[at.p_evap] = zone_pair_derivatives(high, low, FLOW_EPS)
    dydt[at.z] = c.controller.m0 - flow.mass


@njit(cache=True, error_model="numpy", inline="always")
def rates(y, u, c, tables, props, flow, dydt, memo=None, remember=False):
    """The walls' and zones' rates into ``dydt`` given the cell properties ``props`` and the
    :class:`Flows` ``flow``; returns (Q_cond, Q_evap, sensible and latent heat of the indoor
    coil), W. Each zone's rates read its own cells and walls and ``flow`` alone.

    ``memo`` (2 N rows of :data:`MEMO_COLUMNS`: condenser cells, then evaporator cells) holds
    coil cell heats with their arguments: a cell whose arguments match its row reuses the heat,
    rescaled if the flow scale alone differs (a Jacobian column changes few cells); with
    ``remember`` the rows take this call's."""
    src_c, src_e, q_cond, q_evap, q_sensible, q_latent = coil_rates(
        y, u, c, tables, props, flow, dydt, memo, remember
    )
    zone_rates(y, c, props, flow, src_c, src_e, dydt)
    return q_cond, q_evap, q_sensible, q_latent


@uncounted
def held_rates(y, u, c, tables, props, flow, dydt, memo, remember):
    """:func:`rates` with a memo, for :func:`jacobian`: one compiled copy of the rates (and of
    the coil heats inlined in them) that its evaluations share, where an inlined copy at each
    of its calls doubled the cycle's compile time."""
    rates(y, u, c, tables, props, flow, dydt, memo, remember)


@njit(cache=True, error_model="numpy", inline="always")
def write_outputs(y, c, props, flow, q_cond, q_evap, q_sensible, q_latent, out):
    """The outputs and the diagnostics into ``out`` at their offsets (:data:`OUT`), from the
    state, the cell properties, the :class:`Flows` and the heats."""
    at = c.layout
    n = at.h_liquid_line - at.h_cond
    heating = hot_gas_line(at)
    first = 1 if heating else 0  # the condenser's first cell in the high-side zone
    cond, evap = c.condenser, c.evaporator
    outdoor, indoor = (evap, cond) if heating else (cond, evap)
    nc = at.zones[0, 1]
    out[OUT.TD] = flow.T_d
    out[OUT.PD] = flow.p_d
    out[OUT.TS] = flow.T_s
    out[OUT.PS] = flow.p_s
    out[OUT.TC] = props[0, first + n - 1]  # the condenser's last cell
    out[OUT.PC] = y[at.p_cond] + c.faults.noncondensable_pressure  # what a gauge reads
    out[OUT.TE] = props[0, nc + n - 1]
    out[OUT.PE] = y[at.p_evap]
    out[OUT.MDOT] = flow.m_comp
    out[OUT.Q_cond] = q_cond
    out[OUT.Q_evap] = q_evap
    out[OUT.W_comp] = flow.w_comp
    out[OUT.W_ref] = flow.w_ref
    out[OUT.W_fans] = cond.fan_power + evap.fan_power
    out[OUT.M] = flow.mass
    out[OUT.mdot_src] = flow.m_src
    out[OUT.mdot_valve] = flow.m_valve
    out[OUT.W_is] = flow.w_is
    out[OUT.Q_comp_amb] = flow.q_comp_amb
    out[OUT.V_air_out] = outdoor.air_flow
    out[OUT.V_air_in] = indoor.air_flow
    out[OUT.tank_level] = flow.level
    out[OUT.dp_cond] = flow.dp_cond
    out[OUT.dp_evap] = flow.dp_evap
    out[OUT.dp_vap] = flow.dp_vap
    out[OUT.Q_latent] = 0.0 if heating else q_latent  # the indoor coil condenses: no latent load
    out[OUT.SHR] = 1.0 if heating else q_sensible / (q_sensible + q_latent)


@uncounted
def balances(y, u, c, tables, props, dydt, out, rates_too=True):
    """:func:`evaluate` given the cell properties ``props`` of every cell; with ``rates_too``
    False the outputs alone (walls and zones skipped: ``dydt`` untouched, the heats NaN)."""
    flow = flows(y, u, c, tables, props, cell_sums(c, props))
    if not flow.finite:
        out[:] = np.nan
        dydt[:] = np.nan
        return False
    q_cond = q_evap = q_latent = q_sensible = np.nan
    if rates_too:
        q_cond, q_evap, q_sensible, q_latent = rates(y, u, c, tables, props, flow, dydt)
    write_outputs(y, c, props, flow, q_cond, q_evap, q_sensible, q_latent, out)
    return not rates_too or all_finite(dydt)


@njit(cache=True, error_model="numpy")
def coupled_columns(at):
    """The state variables that reach the :class:`Flows` other than through the
    :func:`cell_sums`: both pressures, the integral, each zone's last cell (the valve's and
    the tank's) and, heating, the high side's first (the hot gas line feeds the drops)."""
    last_c = at.p_cond + at.zones[0, 1]
    last_e = at.p_evap + at.zones[1, 1]
    if hot_gas_line(at):
        return np.array([at.p_cond, at.p_cond + 1, last_c, at.p_evap, last_e, at.z])
    return np.array([at.p_cond, last_c, at.p_evap, last_e, at.z])


@njit(cache=True, error_model="numpy")
def side_columns(at, coupled, zone, walls):
    """The state variables of one side (a zone's cells and its coil's walls) that reach no
    other side once the :class:`Flows` and the :func:`cell_sums` are held."""
    p_index, count = at.zones[zone, 0], at.zones[zone, 1]
    n = at.h_liquid_line - at.h_cond
    cells = np.arange(p_index + 1, p_index + 1 + count)
    return np.concatenate((cells[~np.isin(cells, coupled)], np.arange(walls, walls + n)))


@njit(cache=True, error_model="numpy")
def jacobian(y, u, constants, tables, f0):
    """Forward-difference Jacobian ∂f/∂y at ``y`` (``f0`` = f(y)); each column re-evaluates
    only the cell properties its variable touches.

    The two zones and their coils' walls meet only through the :class:`Flows`, which read
    the cells through three sums alone (:func:`cell_sums`) besides a few
    :func:`coupled_columns`. Those columns take a whole evaluation each. The rest are
    differenced with the flows held, one column of each side in one evaluation (their rows do
    not overlap), and the sums' part is added as ``∂f/∂s Δs``: ∂f/∂s by three evaluations with
    one sum moved, Δs from the column's own cells."""
    y, u, constants, tables, f0 = borrowed((y, u, constants, tables, f0))
    c = constants[0]
    at = c.layout
    zones = at.zones
    n = at.h_liquid_line - at.h_cond
    jac = np.zeros((y.size, y.size))
    props = stack_empty((N_PROPERTIES, zones[:, 1].sum()))
    cell_properties(y, zones, tables, props)
    saved = stack_empty(props.shape)
    saved[:] = props
    work = stack_empty(y.size)
    work[:] = y
    dydt = stack_empty(y.size)
    memo = stack_full((2 * n, MEMO_COLUMNS), np.nan)
    # enthalpy columns keep their zone's pressure and its fillet ends: one memo per zone
    # and a third for each coupled column
    fillets = stack_full((3, *FILLET_MEMO_SHAPE), np.nan)
    sums = cell_sums(c, props)
    held = flows(y, u, c, tables, props, sums)
    held_rates(y, u, c, tables, props, held, dydt, memo, True)  # the cells' heats at y

    # how f answers each sum, through the flows
    through_sums = stack_empty((N_SUMS, y.size))
    for k in range(N_SUMS):
        moved = np.array(sums)
        step = 1e-7 * abs(moved[k])
        moved[k] += step
        flow = flows(y, u, c, tables, props, (moved[0], moved[1], moved[2]))
        held_rates(y, u, c, tables, props, flow, dydt, memo, False)
        for i in range(y.size):
            through_sums[k, i] = (dydt[i] - f0[i]) / step

    coupled = coupled_columns(at)
    for j in coupled:
        fillets[2] = np.nan
        step = perturb(y, work, j, zones, tables, props, fillets[2])
        flow = flows(work, u, c, tables, props, cell_sums(c, props))
        held_rates(work, u, c, tables, props, flow, dydt, memo, False)
        for i in range(y.size):
            jac[i, j] = (dydt[i] - f0[i]) / step
        restore(y, work, j, zones, props, saved)

    sides = (side_columns(at, coupled, 0, at.Tw_cond), side_columns(at, coupled, 1, at.Tw_evap))
    walls = (at.Tw_cond, at.Tw_evap)
    steps = stack_empty(2)
    shifts = stack_empty((2, N_SUMS))
    for m in range(max(sides[0].size, sides[1].size)):
        steps[:] = 0.0
        shifts[:] = 0.0
        before = sums  # the mass adds up, each friction density reads one side: Δs separate
        for side in range(2):
            if m < sides[side].size:
                steps[side] = perturb(y, work, sides[side][m], zones, tables, props, fillets[side])
                after = cell_sums(c, props)
                for k in range(N_SUMS):
                    shifts[side, k] = after[k] - before[k]
                before = after
        held_rates(work, u, c, tables, props, held, dydt, memo, False)
        for side in range(2):
            if m >= sides[side].size:
                continue
            j = sides[side][m]
            step = steps[side]
            p_index, count = zones[side, 0], zones[side, 1]
            for i in range(p_index, p_index + count + 1):
                jac[i, j] = (dydt[i] - f0[i]) / step
            for i in range(walls[side], walls[side] + n):
                jac[i, j] = (dydt[i] - f0[i]) / step
            for k in range(N_SUMS):
                if shifts[side, k] != 0.0:
                    for i in range(y.size):
                        jac[i, j] += through_sums[k, i] * shifts[side, k] / step
            restore(y, work, j, zones, props, saved)
    return jac


@njit(cache=True, error_model="numpy")
def outputs_along(ys, us, constants, tables, rates):
    """Outputs and diagnostics at each row of states ``ys`` with the matching inputs ``us``;
    with ``rates`` False the heats are NaN (see :func:`balances`), at half the cost."""
    ys, us, constants, tables = borrowed((ys, us, constants, tables))
    c = constants[0]
    props = stack_empty((N_PROPERTIES, c.layout.zones[:, 1].sum()))
    result = np.empty((ys.shape[0], N_EVAL))
    dydt = stack_empty(ys.shape[1])
    out = stack_empty(N_EVAL)
    for k in range(ys.shape[0]):
        cell_properties(ys[k], c.layout.zones, tables, props, rates)
        balances(ys[k], us[k], c, tables, props, dydt, out, rates)
        result[k] = out
    return result


class SplitUnitCycle(CycleModel):
    """A mode of the split unit: its hardware, Table III and fault parameters, inputs, outputs
    and this module's kernels. A subclass gives the mode's state layout (where the vapour line
    sits), its charge and start-up state, which fan (``condenser_fan``) blows over the
    condensing coil and which heat is its useful one (``capacity``)."""

    hardware = SplitUnitHardware
    parameters = PARAMETERS
    faults = FAULTS
    inputs = INPUTS
    outputs = OUTPUTS
    evaluate = staticmethod(evaluate)
    jacobian = staticmethod(jacobian)
    outputs_along = staticmethod(outputs_along)
    condenser_fan: ClassVar[Literal["outdoor", "indoor"]]
    capacity: ClassVar[str]
    """The diagnostic that is the unit's useful heat, W (what its COP divides)."""

    def constants(
        self,
        unit: UnitDescription,
        theta: np.ndarray,
        controller: bool | None = None,
        faults: np.ndarray | None = None,
    ) -> np.ndarray:
        layout = self.layout(unit.discretisation.n_volumes)
        return split_unit_constants(
            unit, theta, layout, controller, condenser_fan=self.condenser_fan, faults=faults
        )

    def summary(self, final: Mapping[str, float], tables) -> dict[str, float]:
        """``superheat`` (K, at the suction), ``subcooling`` (K, condenser outlet),
        ``capacity`` (W: the evaporator's heat cooling, the condenser's heating), ``COP``
        (capacity over compressor and fan power) and ``energy_balance_error``
        ((Q_cond - Q_evap - W_ref) / Q_cond)."""
        capacity = final[self.capacity]
        return {
            "superheat": final["TS"] - saturation_state(tables, final["PS"])[0],
            "subcooling": saturation_state(tables, final["PC"])[0] - final["TC"],
            "capacity": capacity,
            "COP": capacity / (final["W_comp"] + final["W_fans"]),
            "energy_balance_error": (final["Q_cond"] - final["Q_evap"] - final["W_ref"])
            / final["Q_cond"],
        }

    def box_ranges(self, unit: UnitDescription) -> dict[str, tuple[float, float]]:
        """Air flow (m³/s) and fan power (W) over the box, by the fan laws at each fan's running
        speed (``speed_fraction`` of its rated speed)."""
        table = unit.parameters
        hw: SplitUnitHardware = unit.hardware
        out, ind = hw.outdoor_fan.speed_fraction, hw.indoor_fan.speed_fraction
        return {
            "V_air_out": (table["FO_FLOW"].low * out, table["FO_FLOW"].high * out),
            "V_air_in": (table["FI_FLOW"].low * ind, table["FI_FLOW"].high * ind),
            "W_fans": (
                table["FO_POW"].low * out**3 + table["FI_POW"].low * ind**3,
                table["FO_POW"].high * out**3 + table["FI_POW"].high * ind**3,
            ),
        }
