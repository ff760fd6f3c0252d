"""What the refrigerant property tables cover and how they are laid out in arrays.

Shared by the builder, the cache and the kernels.

The (p, h) plane below the critical point is split by the saturation dome:

* saturation curves are cubic splines in p, stored in Hermite form (value and d/dp at each node
  of ``sat_p``): bubble and dew temperature, h_l, h_v, rho_l, rho_v, s_l, s_v, and the
  enthalpies of the two bounding isotherms ``T_min`` and ``T_max``;
* the liquid region [h(p, T_min), h_l(p)] and the vapour region [h_v(p), h(p, T_max)] each have a
  bicubic Hermite table in (p, xi), where xi in [0, 1] is the enthalpy normalised between the
  region's two boundary curves, so the saturation line is a grid line of both tables;
* the two-phase region uses the lever rule on the saturation curves (homogeneous density).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

# Columns of PropertyTables.sat_curves (axis 1).
T_BUBBLE, T_DEW, H_LIQ, H_VAP, RHO_LIQ, RHO_VAP, S_LIQ, S_VAP, H_MIN, H_MAX = range(10)
N_SAT_CURVES = 10

# Properties of the single-phase tables (axis 2) and their Hermite data (axis 3).
PROP_T, PROP_RHO, PROP_S = range(3)
N_PROPS = 3
VALUE, D_P, D_XI, D_P_XI = range(4)


class PropertyTables(NamedTuple):
    """Property tables of one refrigerant: plain floats and float64 arrays, passable to Numba.

    Units: Pa, K, J/kg, kg/m3, J/(kg K). Derivatives in ``sat_curves`` are d/dp along the curve
    (per Pa); those in ``liquid`` and ``vapour`` are d/dp at constant xi, d/dxi at constant p and
    the mixed derivative.
    """

    p_min: float
    """Lowest pressure of the tables, Pa."""
    p_max: float
    """Highest pressure of the tables (below the critical pressure), Pa."""
    p_crit: float
    """Critical pressure, Pa."""
    T_crit: float
    """Critical temperature, K."""
    T_min: float
    """The isotherm bounding the liquid region, K."""
    T_max: float
    """The isotherm bounding the vapour region, K."""
    sat_p: np.ndarray
    """Pressure nodes of the saturation splines, shape (n_sat,), Pa."""
    sat_curves: np.ndarray
    """Saturation and boundary curves at ``sat_p``, shape (n_sat, N_SAT_CURVES, 2): value, d/dp."""
    table_p: np.ndarray
    """Pressure nodes of the single-phase tables, shape (n_p,), Pa."""
    liquid_xi: np.ndarray
    """Normalised-enthalpy nodes of the liquid table, shape (n_liquid,); 1 is the bubble line."""
    vapour_xi: np.ndarray
    """Normalised-enthalpy nodes of the vapour table, shape (n_vapour,); 0 is the dew line."""
    liquid: np.ndarray
    """Liquid table, shape (n_p, n_liquid, N_PROPS, 4): T, rho, s with their Hermite data."""
    vapour: np.ndarray
    """Vapour table, shape (n_p, n_vapour, N_PROPS, 4): T, rho, s with their Hermite data."""


@dataclass(frozen=True)
class FluidSpec:
    """The valid region of one refrigerant's tables: p_min..p_max (Pa), T_min..T_max (K)."""

    name: str
    coolprop_name: str
    p_min: float
    p_max: float
    T_min: float
    T_max: float


@dataclass(frozen=True)
class TableResolution:
    """Node counts of the tables.

    ``n_sat`` saturation-spline nodes, ``n_p`` x (``n_liquid`` + ``n_vapour``) single-phase nodes.
    Pressure nodes are graded towards low pressure and towards the critical point; enthalpy
    nodes towards the saturation line (exponent ``xi_grading`` > 1).
    """

    n_sat: int = 300
    n_p: int = 150
    n_liquid: int = 30
    n_vapour: int = 40
    xi_grading: float = 1.6
