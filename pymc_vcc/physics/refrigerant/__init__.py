"""Refrigerant properties at (p, h) from fast tables built from CoolProp.

``load_refrigerant(name)`` gives a :class:`Refrigerant` with a vectorised, range-checked Python
API and its :class:`PropertyTables`, which the Numba kernels below take as first argument from
inside ``@njit`` code (they return NaN outside the tables).
"""

from pymc_vcc.physics.refrigerant.fluid import (
    DEFAULT_RESOLUTION,
    SUPPORTED_FLUIDS,
    Properties,
    Refrigerant,
    Saturation,
    load_refrigerant,
)
from pymc_vcc.physics.refrigerant.kernels import (
    SaturationPoint,
    density_h_derivatives,
    density_h_derivatives_along,
    density_h_derivatives_at,
    enthalpy_bounds,
    entropy,
    entropy_at,
    h_from_ps,
    h_from_ps_at,
    h_from_pT,
    h_from_pT_at,
    p_sat_from_T,
    saturation_point,
    saturation_state,
    state,
    state_array,
    state_at,
    state_values,
    state_values_at,
)
from pymc_vcc.physics.refrigerant.tables import FluidSpec, PropertyTables, TableResolution

__all__ = [
    "DEFAULT_RESOLUTION",
    "SUPPORTED_FLUIDS",
    "FluidSpec",
    "Properties",
    "PropertyTables",
    "Refrigerant",
    "Saturation",
    "SaturationPoint",
    "TableResolution",
    "density_h_derivatives",
    "density_h_derivatives_along",
    "density_h_derivatives_at",
    "enthalpy_bounds",
    "entropy",
    "entropy_at",
    "h_from_pT",
    "h_from_pT_at",
    "h_from_ps",
    "h_from_ps_at",
    "load_refrigerant",
    "p_sat_from_T",
    "saturation_point",
    "saturation_state",
    "state",
    "state_array",
    "state_at",
    "state_values",
    "state_values_at",
]
