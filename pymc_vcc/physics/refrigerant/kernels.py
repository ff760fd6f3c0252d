"""Numba kernels: refrigerant properties at (p, h) from :class:`PropertyTables`.

Scalar floats in, floats out, SI units. Every kernel returns NaN (all of its outputs) when its
input lies outside the tables, so a caller inside Numba can flag the failure; nothing is
extrapolated.

The lookups a right-hand side makes dozens of times (:func:`state_at`, :func:`state_values_at`)
are inlined into their callers: as calls of their own, each passing the tables and the
saturation point, they made a cycle's right-hand side 17 % slower.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from pymc_vcc.physics.refrigerant.tables import (
    D_P,
    D_P_XI,
    D_XI,
    H_LIQ,
    H_MAX,
    H_MIN,
    H_VAP,
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
    PropertyTables,
)
from pymc_vcc.physics.scratch import uncounted

NAN = math.nan


class SaturationPoint(NamedTuple):
    """What every property lookup at one pressure shares (SI units; ``_p``: d/dp), from
    :func:`saturation_point`: the cells of a pressure zone share one."""

    inside: bool  # the pressure lies inside the tables (else every other field is NaN)
    interval: int  # saturation-node interval holding p, its width and p's local coordinate
    width: float
    t: float
    h_min: float  # enthalpy span of the tables at p
    h_min_p: float
    h_max: float
    h_max_p: float
    h_l: float  # bubble and dew enthalpies
    h_l_p: float
    h_v: float
    h_v_p: float
    T_b: float  # bubble and dew temperatures
    T_d: float
    rho_l: float  # bubble and dew densities
    rho_l_p: float
    rho_v: float
    rho_v_p: float
    table_interval: int  # the single-phase tables' pressure interval holding p, its width and
    table_width: float  # p's local coordinate (every lookup at p shares them)
    table_t: float


_MAX_ITERATIONS = 60


@njit(cache=True)
def _interval(grid: np.ndarray, x: float) -> int:
    """Index i with grid[i] <= x <= grid[i + 1] for grid[0] <= x <= grid[-1] (bisection)."""
    lo = 0
    hi = grid.size - 1
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if x < grid[mid]:
            hi = mid
        else:
            lo = mid
    return lo


@njit(cache=True)
def _hermite_basis(t: float) -> tuple[float, float, float, float, float, float, float, float]:
    """Cubic Hermite basis h00, h10, h01, h11 at t in [0, 1] and their derivatives in t."""
    t2 = t * t
    t3 = t2 * t
    return (
        2.0 * t3 - 3.0 * t2 + 1.0,
        t3 - 2.0 * t2 + t,
        -2.0 * t3 + 3.0 * t2,
        t3 - t2,
        6.0 * t2 - 6.0 * t,
        3.0 * t2 - 4.0 * t + 1.0,
        -6.0 * t2 + 6.0 * t,
        3.0 * t2 - 2.0 * t,
    )


@njit(cache=True)
def _hermite_second(t: float) -> tuple[float, float, float, float]:
    """Second derivatives in t of the cubic Hermite basis h00, h10, h01, h11."""
    return 12.0 * t - 6.0, 6.0 * t - 4.0, 6.0 - 12.0 * t, 6.0 * t - 2.0


@njit(cache=True)
def _sat_locate(tables: PropertyTables, p: float) -> tuple[int, float, float]:
    """Interval, width and local coordinate of p on the saturation nodes."""
    i = _interval(tables.sat_p, p)
    width = tables.sat_p[i + 1] - tables.sat_p[i]
    return i, width, (p - tables.sat_p[i]) / width


@njit(cache=True)
def _sat_curve(
    tables: PropertyTables, k: int, i: int, width: float, t: float
) -> tuple[float, float]:
    """Value and d/dp of saturation curve ``k`` at local coordinate t of interval i."""
    h00, h10, h01, h11, d00, d10, d01, d11 = _hermite_basis(t)
    c = tables.sat_curves
    f0 = c[i, k, 0]
    m0 = c[i, k, 1] * width
    f1 = c[i + 1, k, 0]
    m1 = c[i + 1, k, 1] * width
    value = h00 * f0 + h10 * m0 + h01 * f1 + h11 * m1
    slope = (d00 * f0 + d10 * m0 + d01 * f1 + d11 * m1) / width
    return value, slope


@njit(cache=True)
def _bicubic(
    table: np.ndarray, k: int, i: int, j: int, dp: float, dxi: float, t: float, r: float
) -> tuple[float, float, float]:
    """Property k of a single-phase table: value, d/dp at constant xi, d/dxi at constant p."""
    a00, a10, a01, a11, da00, da10, da01, da11 = _hermite_basis(t)
    b00, b10, b01, b11, db00, db10, db01, db11 = _hermite_basis(r)
    value = 0.0
    d_p = 0.0
    d_xi = 0.0
    for corner_p in range(2):
        if corner_p == 0:
            hp, gp, dhp, dgp = a00, a10 * dp, da00 / dp, da10
        else:
            hp, gp, dhp, dgp = a01, a11 * dp, da01 / dp, da11
        for corner_xi in range(2):
            if corner_xi == 0:
                hx, gx, dhx, dgx = b00, b10 * dxi, db00 / dxi, db10
            else:
                hx, gx, dhx, dgx = b01, b11 * dxi, db01 / dxi, db11
            node = table[i + corner_p, j + corner_xi, k]
            f = node[VALUE]
            f_p = node[D_P]
            f_x = node[D_XI]
            f_px = node[D_P_XI]
            value += hp * hx * f + gp * hx * f_p + hp * gx * f_x + gp * gx * f_px
            d_p += dhp * hx * f + dgp * hx * f_p + dhp * gx * f_x + dgp * gx * f_px
            d_xi += hp * dhx * f + gp * dhx * f_p + hp * dgx * f_x + gp * dgx * f_px
    return value, d_p, d_xi


@njit(cache=True)
def _bicubic_value(
    table: np.ndarray, k: int, i: int, j: int, dp: float, dxi: float, t: float, r: float
) -> float:
    """Property k of a single-phase table: the value of :func:`_bicubic` alone."""
    a00, a10, a01, a11 = _hermite_basis(t)[:4]
    b00, b10, b01, b11 = _hermite_basis(r)[:4]
    value = 0.0
    for corner_p in range(2):
        hp, gp = (a00, a10 * dp) if corner_p == 0 else (a01, a11 * dp)
        for corner_xi in range(2):
            hx, gx = (b00, b10 * dxi) if corner_xi == 0 else (b01, b11 * dxi)
            node = table[i + corner_p, j + corner_xi, k]
            f, f_p, f_x, f_px = node[VALUE], node[D_P], node[D_XI], node[D_P_XI]
            value += hp * hx * f + gp * hx * f_p + hp * gx * f_x + gp * gx * f_px
    return value


@njit(cache=True)
def _bicubic_jet(
    table: np.ndarray, k: int, i: int, j: int, dp: float, dxi: float, t: float, r: float
) -> tuple[float, float, float, float, float, float, float]:
    """Property k of a single-phase table: value R and R_xi, R_xixi, R_xixixi, R_p, R_pxi,
    R_pxixi (p-derivatives at constant xi)."""
    a00, a10, a01, a11, da00, da10, da01, da11 = _hermite_basis(t)
    b00, b10, b01, b11, db00, db10, db01, db11 = _hermite_basis(r)
    e00, e10, e01, e11 = _hermite_second(r)
    value = d_x = d_xx = d_xxx = d_p = d_px = d_pxx = 0.0
    for corner_p in range(2):
        if corner_p == 0:
            hp, gp, dhp, dgp = a00, a10 * dp, da00 / dp, da10
        else:
            hp, gp, dhp, dgp = a01, a11 * dp, da01 / dp, da11
        for corner_xi in range(2):
            # the xi basis of this node (value, slope), its xi-derivatives (the second in r)
            if corner_xi == 0:
                hx, dhx, ehx, thx = b00, db00 / dxi, e00, 12.0 / dxi**3
                gx, dgx, egx = b10 * dxi, db10, e10
            else:
                hx, dhx, ehx, thx = b01, db01 / dxi, e01, -12.0 / dxi**3
                gx, dgx, egx = b11 * dxi, db11, e11
            tgx = 6.0 / dxi**2
            node = table[i + corner_p, j + corner_xi, k]
            along = hp * node[VALUE] + gp * node[D_P]  # value and xi-slope at this xi node
            slope = hp * node[D_XI] + gp * node[D_P_XI]
            along_p = dhp * node[VALUE] + dgp * node[D_P]  # and their p-derivatives
            slope_p = dhp * node[D_XI] + dgp * node[D_P_XI]
            value += hx * along + gx * slope
            d_x += dhx * along + dgx * slope
            d_xx += (ehx * along / dxi + egx * slope) / dxi
            d_xxx += thx * along + tgx * slope
            d_p += hx * along_p + gx * slope_p
            d_px += dhx * along_p + dgx * slope_p
            d_pxx += (ehx * along_p / dxi + egx * slope_p) / dxi
    return value, d_x, d_xx, d_xxx, d_p, d_px, d_pxx


@njit(cache=True)
def _region(
    tables: PropertyTables,
    sat: SaturationPoint,
    h: float,
    a: float,
    a_p: float,
    b: float,
    b_p: float,
    liquid: bool,
) -> tuple[np.ndarray, int, int, float, float, float, float, float, float]:
    """Locate h at the pressure of ``sat`` in the liquid or vapour table, whose enthalpy span
    at that pressure runs from ``a`` to ``b`` (with their slopes d/dp ``a_p`` and ``b_p``).

    Returns the table, cell indices, cell sizes, local coordinates, the width w of the region
    at p and the derivative d xi/dp at constant h.
    """
    if liquid:
        table = tables.liquid
        xi_nodes = tables.liquid_xi
    else:
        table = tables.vapour
        xi_nodes = tables.vapour_xi
    w = b - a
    xi = (h - a) / w
    xi_p = -(a_p + xi * (b_p - a_p)) / w
    jx = _interval(xi_nodes, xi)
    dxi = xi_nodes[jx + 1] - xi_nodes[jx]
    rx = (xi - xi_nodes[jx]) / dxi
    return table, sat.table_interval, jx, sat.table_width, dxi, sat.table_t, rx, w, xi_p


@njit(cache=True)
def _single_phase(
    tables: PropertyTables, sat: SaturationPoint, h: float
) -> tuple[np.ndarray, int, int, float, float, float, float, float, float]:
    """:func:`_region` of h at the pressure of ``sat`` (its :func:`saturation_point`) outside
    the dome: liquid below h_l, vapour above h_v."""
    if h < sat.h_l:
        return _region(tables, sat, h, sat.h_min, sat.h_min_p, sat.h_l, sat.h_l_p, True)
    return _region(tables, sat, h, sat.h_v, sat.h_v_p, sat.h_max, sat.h_max_p, False)


@njit(cache=True, inline="always")
def _in_range(tables: PropertyTables, p: float) -> bool:
    """Whether the tables hold pressure ``p`` (inlined: a call of its own cost 1 % of a run)."""
    return p >= tables.p_min and p <= tables.p_max


@uncounted
def saturation_point(tables: PropertyTables, p: float) -> SaturationPoint:
    """The :class:`SaturationPoint` of pressure ``p``; pass it to :func:`state_at` and
    :func:`density_h_derivatives_at` for every lookup at ``p``."""
    if not _in_range(tables, p):
        return SaturationPoint(
            False, 0, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN,
            NAN, NAN, 0, NAN, NAN,
        )  # fmt: skip
    i, width, t = _sat_locate(tables, p)
    ip = _interval(tables.table_p, p)
    dp = tables.table_p[ip + 1] - tables.table_p[ip]
    h_min, h_min_p = _sat_curve(tables, H_MIN, i, width, t)
    h_max, h_max_p = _sat_curve(tables, H_MAX, i, width, t)
    h_l, h_l_p = _sat_curve(tables, H_LIQ, i, width, t)
    h_v, h_v_p = _sat_curve(tables, H_VAP, i, width, t)
    T_b, _ = _sat_curve(tables, T_BUBBLE, i, width, t)
    T_d, _ = _sat_curve(tables, T_DEW, i, width, t)
    rho_l, rho_l_p = _sat_curve(tables, RHO_LIQ, i, width, t)
    rho_v, rho_v_p = _sat_curve(tables, RHO_VAP, i, width, t)
    return SaturationPoint(
        True, i, width, t, h_min, h_min_p, h_max, h_max_p, h_l, h_l_p, h_v, h_v_p, T_b, T_d,
        rho_l, rho_l_p, rho_v, rho_v_p, ip, dp, (p - tables.table_p[ip]) / dp,
    )  # fmt: skip


@njit(cache=True)
def state(tables: PropertyTables, p: float, h: float) -> tuple[float, float, float, float, float]:
    """(T, rho, drho_dp, drho_dh, x) at (p, h).

    K, kg/m3, kg/m3/Pa at constant h, kg/m3/(J/kg) at constant p, and the unclipped quality
    x = (h - h_l)/(h_v - h_l). NaNs outside the tables.
    """
    return state_at(tables, saturation_point(tables, p), p, h)


@njit(cache=True, inline="always")
def state_at(
    tables: PropertyTables, sat: SaturationPoint, p: float, h: float
) -> tuple[float, float, float, float, float]:
    """:func:`state` given ``sat``, the :func:`saturation_point` of ``p``."""
    h_l, h_l_p, h_v, h_v_p = sat.h_l, sat.h_l_p, sat.h_v, sat.h_v_p
    rho_l, rho_l_p, rho_v, rho_v_p = sat.rho_l, sat.rho_l_p, sat.rho_v, sat.rho_v_p
    if not (sat.inside and h >= sat.h_min and h <= sat.h_max):
        return NAN, NAN, NAN, NAN, NAN
    x = (h - h_l) / (h_v - h_l)
    if h < h_l or h > h_v:
        table, ip, jx, dp, dxi, tp, rx, w, xi_p = _single_phase(tables, sat, h)
        T, _, _ = _bicubic(table, PROP_T, ip, jx, dp, dxi, tp, rx)
        rho, rho_p, rho_xi = _bicubic(table, PROP_RHO, ip, jx, dp, dxi, tp, rx)
        return T, rho, rho_p + rho_xi * xi_p, rho_xi / w, x
    v_l = 1.0 / rho_l
    v_v = 1.0 / rho_v
    v_l_p = -rho_l_p * v_l * v_l
    v_v_p = -rho_v_p * v_v * v_v
    dh = h_v - h_l
    x_p = -(h_l_p + x * (h_v_p - h_l_p)) / dh
    v = v_l + x * (v_v - v_l)
    rho = 1.0 / v
    v_p = v_l_p + x * (v_v_p - v_l_p) + (v_v - v_l) * x_p
    v_h = (v_v - v_l) / dh
    return sat.T_b + x * (sat.T_d - sat.T_b), rho, -rho * rho * v_p, -rho * rho * v_h, x


@njit(cache=True)
def state_values(tables: PropertyTables, p: float, h: float) -> tuple[float, float, float]:
    """(T, ρ, x) at (p, h): :func:`state` without the derivatives."""
    return state_values_at(tables, saturation_point(tables, p), p, h)


@njit(cache=True, inline="always")
def state_values_at(
    tables: PropertyTables, sat: SaturationPoint, p: float, h: float
) -> tuple[float, float, float]:
    """(T, ρ, x) of :func:`state_at` without the derivatives, at about half the cost in
    single phase."""
    if not (sat.inside and h >= sat.h_min and h <= sat.h_max):
        return NAN, NAN, NAN
    x = (h - sat.h_l) / (sat.h_v - sat.h_l)
    if h < sat.h_l or h > sat.h_v:
        table, ip, jx, dp, dxi, tp, rx, _, _ = _single_phase(tables, sat, h)
        T = _bicubic_value(table, PROP_T, ip, jx, dp, dxi, tp, rx)
        return T, _bicubic_value(table, PROP_RHO, ip, jx, dp, dxi, tp, rx), x
    rho = 1.0 / (1.0 / sat.rho_l + x * (1.0 / sat.rho_v - 1.0 / sat.rho_l))
    return sat.T_b + x * (sat.T_d - sat.T_b), rho, x


@njit(cache=True)
def density_h_derivatives(tables: PropertyTables, p: float, h: float) -> tuple[float, float, float]:
    """(ρ, ∂ρ/∂h, ∂²ρ/∂h²) at constant p: kg/m³, (kg/m³)/(J/kg), (kg/m³)/(J/kg)².

    Single phase from the bicubic table; two-phase, v is linear in h, so ∂²ρ/∂h² =
    2 (∂ρ/∂h)² / ρ. NaNs outside the tables.
    """
    return density_h_derivatives_at(tables, saturation_point(tables, p), p, h)


@njit(cache=True)
def density_h_derivatives_at(
    tables: PropertyTables, sat: SaturationPoint, p: float, h: float
) -> tuple[float, float, float]:
    """:func:`density_h_derivatives` given ``sat``, the :func:`saturation_point` of ``p``."""
    rho, drho_dh, curvature, _, _, _ = density_h_derivatives_along(tables, sat, p, h, 0.0)
    return rho, drho_dh, curvature


@njit(cache=True)
def density_h_derivatives_along(
    tables: PropertyTables, sat: SaturationPoint, p: float, h: float, h_p: float
) -> tuple[float, float, float, float, float, float]:
    """:func:`density_h_derivatives_at` (ρ, ∂ρ/∂h, ∂²ρ/∂h²) and the derivative of each in p
    along the path h(p) through (p, h) with slope ``h_p`` = dh/dp (J/kg/Pa): the p-derivatives
    come in the same units per Pa. NaNs outside the tables."""
    h_l, h_v, rho_l, rho_v = sat.h_l, sat.h_v, sat.rho_l, sat.rho_v
    if not (sat.inside and h >= sat.h_min and h <= sat.h_max):
        return NAN, NAN, NAN, NAN, NAN, NAN
    if h < h_l or h > h_v:
        table, ip, jx, dp, dxi, tp, rx, w, xi_p = _single_phase(tables, sat, h)
        w_p = sat.h_l_p - sat.h_min_p if h < h_l else sat.h_max_p - sat.h_v_p
        R, R_x, R_xx, R_xxx, R_p, R_px, R_pxx = _bicubic_jet(
            table, PROP_RHO, ip, jx, dp, dxi, tp, rx
        )
        xi_along = xi_p + h_p / w  # dxi/dp along the path
        return (
            R,
            R_x / w,
            R_xx / (w * w),
            R_p + R_x * xi_along,
            (R_px + R_xx * xi_along) / w - R_x * w_p / (w * w),
            (R_pxx + R_xxx * xi_along) / (w * w) - 2.0 * R_xx * w_p / (w * w * w),
        )
    latent = h_v - h_l
    latent_p = sat.h_v_p - sat.h_l_p
    v_l_p = -sat.rho_l_p / (rho_l * rho_l)
    v_v_p = -sat.rho_v_p / (rho_v * rho_v)
    gap = 1.0 / rho_v - 1.0 / rho_l
    v_h = gap / latent
    v_h_p = ((v_v_p - v_l_p) * latent - gap * latent_p) / (latent * latent)
    rho = 1.0 / (1.0 / rho_l + (h - h_l) * v_h)
    v_along = v_l_p + (h_p - sat.h_l_p) * v_h + (h - h_l) * v_h_p
    rho_along = -rho * rho * v_along
    drho_dh = -rho * rho * v_h
    drho_dh_along = -2.0 * rho * rho_along * v_h - rho * rho * v_h_p
    curvature = 2.0 * drho_dh * drho_dh / rho
    curvature_along = 4.0 * drho_dh * drho_dh_along / rho - 2.0 * drho_dh * drho_dh * rho_along / (
        rho * rho
    )
    return rho, drho_dh, curvature, rho_along, drho_dh_along, curvature_along


@njit(cache=True)
def saturation_state(tables: PropertyTables, p: float) -> tuple[float, float, float, float, float]:
    """(T_sat, h_l, h_v, rho_l, rho_v) at p; T_sat is the mid-glide temperature.

    For a pure fluid bubble and dew temperatures coincide; CoolProp's pseudo-pure R410A has a
    glide of about 0.1 K, and T_sat is their mean. NaNs outside the tables.
    """
    sat = saturation_point(tables, p)
    return 0.5 * (sat.T_b + sat.T_d), sat.h_l, sat.h_v, sat.rho_l, sat.rho_v


@njit(cache=True)
def enthalpy_bounds(tables: PropertyTables, p: float) -> tuple[float, float]:
    """(h_min, h_max): the enthalpies of the T_min and T_max isotherms at p, J/kg; NaN outside."""
    if not _in_range(tables, p):
        return NAN, NAN
    i, width, t = _sat_locate(tables, p)
    h_min, _ = _sat_curve(tables, H_MIN, i, width, t)
    h_max, _ = _sat_curve(tables, H_MAX, i, width, t)
    return h_min, h_max


@njit(cache=True)
def entropy(tables: PropertyTables, p: float, h: float) -> float:
    """Specific entropy at (p, h), J/(kg K); NaN outside the tables."""
    return entropy_at(tables, saturation_point(tables, p), p, h)


@njit(cache=True)
def entropy_at(tables: PropertyTables, sat: SaturationPoint, p: float, h: float) -> float:
    """:func:`entropy` given ``sat``, the :func:`saturation_point` of ``p``."""
    i, width, t, h_l, h_v = sat.interval, sat.width, sat.t, sat.h_l, sat.h_v
    if not (sat.inside and h >= sat.h_min and h <= sat.h_max):
        return NAN
    if h < h_l or h > h_v:
        table, ip, jx, dp, dxi, tp, rx, _, _ = _single_phase(tables, sat, h)
        return _bicubic_value(table, PROP_S, ip, jx, dp, dxi, tp, rx)
    s_l, _ = _sat_curve(tables, S_LIQ, i, width, t)
    s_v, _ = _sat_curve(tables, S_VAP, i, width, t)
    return s_l + (h - h_l) / (h_v - h_l) * (s_v - s_l)


@njit(cache=True)
def _along_xi_node(
    table: np.ndarray, k: int, ip: int, j: int, hp0: float, gp0: float, hp1: float, gp1: float
) -> tuple[float, float]:
    """Property k and its xi-slope at xi node j, at the pressure whose Hermite weights in p are
    ``hp0, gp0`` (node ip) and ``hp1, gp1`` (node ip + 1, the slope weights times dp)."""
    low = table[ip, j, k]
    high = table[ip + 1, j, k]
    value = hp0 * low[VALUE] + gp0 * low[D_P] + hp1 * high[VALUE] + gp1 * high[D_P]
    slope = hp0 * low[D_XI] + gp0 * low[D_P_XI] + hp1 * high[D_XI] + gp1 * high[D_P_XI]
    return value, slope


@njit(cache=True)
def _invert_region(
    tables: PropertyTables, sat: SaturationPoint, k: int, target: float, liquid: bool
) -> float:
    """The xi in [0, 1] of the liquid or vapour table where property k equals target at the
    pressure of ``sat``.

    Property k must increase with xi (T and s do); NaN when target lies outside its values at
    xi = 0 and xi = 1 (beyond round-off). At p the table is a cubic Hermite curve in xi: the
    node interval holding ``target`` is found by bisection on the node values, then Newton
    steps on that interval's cubic, bisection when a step leaves the bracket.
    """
    table = tables.liquid if liquid else tables.vapour
    xi_nodes = tables.liquid_xi if liquid else tables.vapour_xi
    ip, dp = sat.table_interval, sat.table_width
    a00, a10, a01, a11, _, _, _, _ = _hermite_basis(sat.table_t)
    weights = (a00, a10 * dp, a01, a11 * dp)
    last = xi_nodes.size - 1
    f_lo = _along_xi_node(table, k, ip, 0, *weights)[0]
    f_hi = _along_xi_node(table, k, ip, last, *weights)[0]
    slack = 1e-8 * (abs(f_lo) + abs(f_hi))  # T at xi = 0, 1 is T_min, T_max to ~1e-7 K
    if not (target >= f_lo - slack and target <= f_hi + slack):
        return NAN
    if target <= f_lo:
        return 0.0
    if target >= f_hi:
        return 1.0
    lo_node = 0
    hi_node = last
    while hi_node - lo_node > 1:
        mid = (lo_node + hi_node) >> 1
        if _along_xi_node(table, k, ip, mid, *weights)[0] <= target:
            lo_node = mid
        else:
            hi_node = mid
    dxi = xi_nodes[hi_node] - xi_nodes[lo_node]
    f0, m0 = _along_xi_node(table, k, ip, lo_node, *weights)
    f1, m1 = _along_xi_node(table, k, ip, hi_node, *weights)
    m0 *= dxi
    m1 *= dxi
    lo = 0.0
    hi = 1.0
    r = (target - f0) / (f1 - f0) if f1 > f0 else 0.5
    for _ in range(_MAX_ITERATIONS):
        h00, h10, h01, h11, d00, d10, d01, d11 = _hermite_basis(r)
        residual = h00 * f0 + h10 * m0 + h01 * f1 + h11 * m1 - target
        slope = d00 * f0 + d10 * m0 + d01 * f1 + d11 * m1
        if residual > 0.0:
            hi = r
        else:
            lo = r
        new = r - residual / slope if slope > 0.0 else 0.5 * (lo + hi)
        if not (new >= lo and new <= hi):
            new = 0.5 * (lo + hi)
        if abs(new - r) * dxi < 1e-13:
            return xi_nodes[lo_node] + new * dxi
        r = new
    return xi_nodes[lo_node] + r * dxi


@njit(cache=True)
def _h_from_property(
    tables: PropertyTables, sat: SaturationPoint, p: float, k: int, target: float
) -> float:
    """Enthalpy at p (saturation point ``sat``) where property k (T or s, both increasing with
    h) equals target; NaN if none.

    Between the bubble and dew values (two-phase) the enthalpy follows the lever rule, which is
    how HEOS spreads CoolProp's pseudo-pure temperature glide and the entropy across the dome.
    """
    if not sat.inside:
        return NAN
    if k == PROP_T:
        low, high = sat.T_b, sat.T_d
    else:
        low, _ = _sat_curve(tables, S_LIQ, sat.interval, sat.width, sat.t)
        high, _ = _sat_curve(tables, S_VAP, sat.interval, sat.width, sat.t)
    h_l, h_v = sat.h_l, sat.h_v
    if target < low:
        return sat.h_min + _invert_region(tables, sat, k, target, True) * (h_l - sat.h_min)
    if target < high:
        return h_l + (target - low) / (high - low) * (h_v - h_l)
    if target == high:
        return h_v
    return h_v + _invert_region(tables, sat, k, target, False) * (sat.h_max - h_v)


@njit(cache=True)
def h_from_pT(tables: PropertyTables, p: float, T: float) -> float:
    """Enthalpy at (p, T), J/kg: liquid below the bubble point, vapour from the dew point up.

    For a pure fluid T = T_sat gives the saturated vapour; within CoolProp's ~0.1 K R410A glide
    it gives the two-phase state at that temperature. NaN outside [T_min, T_max] or the
    pressure range.
    """
    return h_from_pT_at(tables, saturation_point(tables, p), p, T)


@njit(cache=True)
def h_from_pT_at(tables: PropertyTables, sat: SaturationPoint, p: float, T: float) -> float:
    """:func:`h_from_pT` given ``sat``, the :func:`saturation_point` of ``p``."""
    return _h_from_property(tables, sat, p, PROP_T, T)


@njit(cache=True)
def h_from_ps(tables: PropertyTables, p: float, s: float) -> float:
    """Enthalpy at (p, s), J/kg (e.g. the isentropic compressor outlet); NaN outside the tables."""
    return h_from_ps_at(tables, saturation_point(tables, p), p, s)


@njit(cache=True)
def h_from_ps_at(tables: PropertyTables, sat: SaturationPoint, p: float, s: float) -> float:
    """:func:`h_from_ps` given ``sat``, the :func:`saturation_point` of ``p``."""
    return _h_from_property(tables, sat, p, PROP_S, s)


@njit(cache=True)
def _t_sat_node(curves: np.ndarray, i: int, column: int) -> float:
    """Mid-glide saturation temperature (column 0) or its d/dp (column 1) at saturation node i."""
    return 0.5 * (curves[i, T_BUBBLE, column] + curves[i, T_DEW, column])


@njit(cache=True)
def p_sat_from_T(tables: PropertyTables, T: float) -> float:
    """Saturation pressure at T (the mid-glide temperature of saturation_state), Pa; NaN outside."""
    c = tables.sat_curves
    if not (_t_sat_node(c, 0, 0) <= T <= _t_sat_node(c, c.shape[0] - 1, 0)):
        return NAN
    lo = 0
    hi = c.shape[0] - 1
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if _t_sat_node(c, mid, 0) > T:
            hi = mid
        else:
            lo = mid
    width = tables.sat_p[lo + 1] - tables.sat_p[lo]
    f0 = _t_sat_node(c, lo, 0)
    f1 = _t_sat_node(c, lo + 1, 0)
    m0 = _t_sat_node(c, lo, 1) * width
    m1 = _t_sat_node(c, lo + 1, 1) * width
    a = 0.0
    b = 1.0
    r = (T - f0) / (f1 - f0)
    for _ in range(_MAX_ITERATIONS):
        h00, h10, h01, h11, d00, d10, d01, d11 = _hermite_basis(r)
        residual = h00 * f0 + h10 * m0 + h01 * f1 + h11 * m1 - T
        slope = d00 * f0 + d10 * m0 + d01 * f1 + d11 * m1
        if residual > 0.0:
            b = r
        else:
            a = r
        new = r - residual / slope if slope > 0.0 else 0.5 * (a + b)
        if not (new >= a and new <= b):
            new = 0.5 * (a + b)
        if abs(new - r) < 1e-14:
            r = new
            break
        r = new
    return tables.sat_p[lo] + r * width


@njit(cache=True)
def state_array(tables: PropertyTables, p: np.ndarray, h: np.ndarray) -> np.ndarray:
    """:func:`state` over 1-D arrays p and h of equal length: rows T, rho, drho_dp, drho_dh, x.

    Shape (5, n); NaN columns where (p, h) is outside the tables.
    """
    out = np.empty((5, p.size))
    for k in range(p.size):
        out[0, k], out[1, k], out[2, k], out[3, k], out[4, k] = state(tables, p[k], h[k])
    return out


@njit(cache=True)
def props_array(tables: PropertyTables, p: np.ndarray, h: np.ndarray) -> np.ndarray:
    """:func:`state` and :func:`entropy` over 1-D arrays: rows T, rho, drho_dp, drho_dh, x, s.

    Shape (6, n); NaN columns where (p, h) is outside the tables.
    """
    out = np.empty((6, p.size))
    for k in range(p.size):
        out[0, k], out[1, k], out[2, k], out[3, k], out[4, k] = state(tables, p[k], h[k])
        out[5, k] = entropy(tables, p[k], h[k])
    return out


@njit(cache=True)
def entropy_array(tables: PropertyTables, p: np.ndarray, h: np.ndarray) -> np.ndarray:
    """:func:`entropy` over 1-D arrays of equal length, J/(kg K)."""
    out = np.empty(p.size)
    for k in range(p.size):
        out[k] = entropy(tables, p[k], h[k])
    return out


@njit(cache=True)
def h_from_pT_array(tables: PropertyTables, p: np.ndarray, T: np.ndarray) -> np.ndarray:
    """:func:`h_from_pT` over 1-D arrays of equal length, J/kg."""
    out = np.empty(p.size)
    for k in range(p.size):
        out[k] = h_from_pT(tables, p[k], T[k])
    return out


@njit(cache=True)
def h_from_ps_array(tables: PropertyTables, p: np.ndarray, s: np.ndarray) -> np.ndarray:
    """:func:`h_from_ps` over 1-D arrays of equal length, J/kg."""
    out = np.empty(p.size)
    for k in range(p.size):
        out[k] = h_from_ps(tables, p[k], s[k])
    return out


@njit(cache=True)
def p_sat_from_T_array(tables: PropertyTables, T: np.ndarray) -> np.ndarray:
    """:func:`p_sat_from_T` over a 1-D array, Pa."""
    out = np.empty(T.size)
    for k in range(T.size):
        out[k] = p_sat_from_T(tables, T[k])
    return out


@njit(cache=True)
def enthalpy_bounds_array(tables: PropertyTables, p: np.ndarray) -> np.ndarray:
    """:func:`enthalpy_bounds` over a 1-D array: rows h_min, h_max, shape (2, n), J/kg."""
    out = np.empty((2, p.size))
    for k in range(p.size):
        out[0, k], out[1, k] = enthalpy_bounds(tables, p[k])
    return out


@njit(cache=True)
def saturation_array(tables: PropertyTables, p: np.ndarray) -> np.ndarray:
    """:func:`saturation_state` over a 1-D array: rows T_sat, h_l, h_v, rho_l, rho_v; (5, n)."""
    out = np.empty((5, p.size))
    for k in range(p.size):
        out[0, k], out[1, k], out[2, k], out[3, k], out[4, k] = saturation_state(tables, p[k])
    return out
