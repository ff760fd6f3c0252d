"""Building the property tables from CoolProp's Helmholtz equation of state (HEOS).

Importing CoolProp takes seconds, so only this module imports it, and only to build tables.
"""

from __future__ import annotations

import CoolProp.CoolProp as CP
import numpy as np
from scipy.interpolate import CubicSpline

from pymc_vcc.physics.refrigerant.tables import (
    D_P,
    D_P_XI,
    D_XI,
    H_LIQ,
    H_MAX,
    H_MIN,
    H_VAP,
    N_PROPS,
    N_SAT_CURVES,
    PROP_RHO,
    PROP_S,
    PROP_T,
    RHO_LIQ,
    RHO_VAP,
    S_LIQ,
    S_VAP,
    T_BUBBLE,
    T_DEW,
    VALUE,
    FluidSpec,
    PropertyTables,
    TableResolution,
)


def pressure_nodes(p_min: float, p_max: float, p_crit: float, n: int) -> np.ndarray:
    """``n`` pressures from p_min to p_max, uniform in u = ln(p / (p_crit - p)), Pa.

    The node density is proportional to 1/p + 1/(p_crit - p): logarithmic at low pressure and
    refined towards the critical point, where the saturation curves steepen.
    """
    u = np.linspace(np.log(p_min / (p_crit - p_min)), np.log(p_max / (p_crit - p_max)), n)
    nodes = p_crit / (1.0 + np.exp(-u))
    nodes[0], nodes[-1] = p_min, p_max
    return nodes


def xi_nodes(n: int, grading: float, dense_at_one: bool) -> np.ndarray:
    """``n`` normalised enthalpies in [0, 1], refined towards 1 (liquid) or 0 (vapour)."""
    s = np.linspace(0.0, 1.0, n)
    xi = s**grading
    return 1.0 - xi[::-1] if dense_at_one else xi


def _saturation_values(state: CP.AbstractState, spec: FluidSpec, p: np.ndarray) -> np.ndarray:
    """Saturation and bounding-isotherm values at pressures ``p``, shape (len(p), N_SAT_CURVES)."""
    values = np.empty((p.size, N_SAT_CURVES))
    for i, pressure in enumerate(p):
        state.unspecify_phase()
        state.update(CP.PQ_INPUTS, pressure, 0.0)
        values[i, T_BUBBLE] = state.T()
        values[i, H_LIQ] = state.hmass()
        values[i, RHO_LIQ] = state.rhomass()
        values[i, S_LIQ] = state.smass()
        state.update(CP.PQ_INPUTS, pressure, 1.0)
        values[i, T_DEW] = state.T()
        values[i, H_VAP] = state.hmass()
        values[i, RHO_VAP] = state.rhomass()
        values[i, S_VAP] = state.smass()
        state.specify_phase(CP.iphase_liquid)
        state.update(CP.PT_INPUTS, pressure, spec.T_min)
        values[i, H_MIN] = state.hmass()
        state.specify_phase(CP.iphase_gas)
        state.update(CP.PT_INPUTS, pressure, spec.T_max)
        values[i, H_MAX] = state.hmass()
    state.unspecify_phase()
    return values


def _solve_rho_T(
    state: CP.AbstractState, p: float, h: float, rho: float, T: float
) -> tuple[float, float]:
    """Density and temperature of the single-phase state (p, h), by Newton from (rho, T).

    ``state`` must have its phase imposed: each step is an explicit evaluation of the equation
    of state, so the liquid and vapour tables reach the saturation line (and just past the
    spline's estimate of it) without CoolProp's phase determination getting in the way.
    """
    for _ in range(50):
        state.update(CP.DmassT_INPUTS, rho, T)
        r_p = state.p() - p
        r_h = state.hmass() - h
        p_rho = state.first_partial_deriv(CP.iP, CP.iDmass, CP.iT)
        p_T = state.first_partial_deriv(CP.iP, CP.iT, CP.iDmass)
        h_rho = state.first_partial_deriv(CP.iHmass, CP.iDmass, CP.iT)
        h_T = state.first_partial_deriv(CP.iHmass, CP.iT, CP.iDmass)
        det = p_rho * h_T - p_T * h_rho
        d_rho = (r_p * h_T - r_h * p_T) / det
        d_T = (p_rho * r_h - h_rho * r_p) / det
        # damp steps that would change the state by more than a few per cent
        scale = min(1.0, 0.05 * rho / max(abs(d_rho), 1e-300), 5.0 / max(abs(d_T), 1e-300))
        rho -= scale * d_rho
        T -= scale * d_T
        if abs(d_rho) < 1e-11 * rho and abs(d_T) < 1e-11 * T:
            state.update(CP.DmassT_INPUTS, rho, T)
            return rho, T
    raise RuntimeError(f"no single-phase state found at p = {p} Pa, h = {h} J/kg")


def _node_properties(state: CP.AbstractState) -> np.ndarray:
    """T, rho, s of ``state`` with d/dp|h, d/dh|p, d2/dh2 and d2/dp dh, shape (N_PROPS, 5)."""
    out = np.empty((N_PROPS, 5))
    for k, key in ((PROP_T, CP.iT), (PROP_RHO, CP.iDmass)):
        out[k, 0] = state.keyed_output(key)
        out[k, 1] = state.first_partial_deriv(key, CP.iP, CP.iHmass)
        out[k, 2] = state.first_partial_deriv(key, CP.iHmass, CP.iP)
        out[k, 3] = state.second_partial_deriv(key, CP.iHmass, CP.iP, CP.iHmass, CP.iP)
        out[k, 4] = state.second_partial_deriv(key, CP.iHmass, CP.iP, CP.iP, CP.iHmass)
    T, T_p, T_h = out[PROP_T, :3]
    rho = out[PROP_RHO, 0]
    # Gibbs: ds = dh / T - dp / (rho T)
    out[PROP_S] = (state.smass(), -1.0 / (rho * T), 1.0 / T, -T_h / T**2, -T_p / T**2)
    return out


def _region_table(
    state: CP.AbstractState,
    liquid: bool,
    p: np.ndarray,
    xi: np.ndarray,
    lower: CubicSpline,
    upper: CubicSpline,
) -> np.ndarray:
    """Bicubic Hermite data on (p, xi) with h = lower(p) + xi (upper(p) - lower(p)).

    Each isobar is solved from the saturation line outwards, every node starting Newton from
    its neighbour.
    """
    a, a_p = lower(p), lower(p, 1)
    w, w_p = upper(p) - a, upper(p, 1) - a_p
    table = np.empty((p.size, xi.size, N_PROPS, 4))
    order = range(xi.size - 1, -1, -1) if liquid else range(xi.size)
    for i in range(p.size):
        state.unspecify_phase()
        state.update(CP.PQ_INPUTS, p[i], 0.0 if liquid else 1.0)
        rho, T = state.rhomass(), state.T()
        state.specify_phase(CP.iphase_liquid if liquid else CP.iphase_gas)
        for j in order:
            rho, T = _solve_rho_T(state, p[i], a[i] + xi[j] * w[i], rho, T)
            f, f_p, f_h, f_hh, f_ph = _node_properties(state).T
            h_p_at_xi = a_p[i] + xi[j] * w_p[i]
            table[i, j, :, VALUE] = f
            table[i, j, :, D_P] = f_p + f_h * h_p_at_xi
            table[i, j, :, D_XI] = f_h * w[i]
            table[i, j, :, D_P_XI] = w[i] * (f_ph + f_hh * h_p_at_xi) + f_h * w_p[i]
    state.unspecify_phase()
    return table


def build_tables(spec: FluidSpec, resolution: TableResolution) -> PropertyTables:
    """Tabulate ``spec``'s fluid from CoolProp HEOS at ``resolution`` (about half a second)."""
    state = CP.AbstractState("HEOS", spec.coolprop_name)
    p_crit, T_crit = state.p_critical(), state.T_critical()
    if not spec.p_max < p_crit:
        raise ValueError(f"p_max = {spec.p_max} Pa must be below the critical pressure {p_crit} Pa")

    sat_p = pressure_nodes(spec.p_min, spec.p_max, p_crit, resolution.n_sat)
    splines = [CubicSpline(sat_p, column) for column in _saturation_values(state, spec, sat_p).T]
    sat_curves = np.stack([np.stack([s(sat_p), s(sat_p, 1)], axis=-1) for s in splines], axis=1)

    table_p = pressure_nodes(spec.p_min, spec.p_max, p_crit, resolution.n_p)
    liquid_xi = xi_nodes(resolution.n_liquid, resolution.xi_grading, dense_at_one=True)
    vapour_xi = xi_nodes(resolution.n_vapour, resolution.xi_grading, dense_at_one=False)
    liquid = _region_table(state, True, table_p, liquid_xi, splines[H_MIN], splines[H_LIQ])
    vapour = _region_table(state, False, table_p, vapour_xi, splines[H_VAP], splines[H_MAX])
    return PropertyTables(
        p_min=float(spec.p_min),
        p_max=float(spec.p_max),
        p_crit=float(p_crit),
        T_crit=float(T_crit),
        T_min=float(spec.T_min),
        T_max=float(spec.T_max),
        sat_p=sat_p,
        sat_curves=sat_curves,
        table_p=table_p,
        liquid_xi=liquid_xi,
        vapour_xi=vapour_xi,
        liquid=liquid,
        vapour=vapour,
    )
