"""Moist air on the indoor coil: humidity ratio and the latent heat of a wet coil.

Where the coil surface is below the air's dew point, water condenses on it. With the Lewis
analogy (Le = 1) the enthalpy-potential method splits a cell's air-side heat into the dry
(sensible) part of :func:`~.heat_transfer.air_side_heat` and a latent part driven by the
humidity-ratio difference between the air and saturated air at the wall temperature,

    Q_lat = ṁ_a h_fg (W_air - W_sat(T_w))⁺ (1 - exp(-hA/C)),   ṁ_a = C / c_p,

with the same effectiveness as the sensible heat. Dry air (RH = 0, the paper's case) gives
Q_lat = 0.
"""

from __future__ import annotations

import math

from numba import njit

from pymc_vcc.physics.components.smooth import smooth_pos

ATMOSPHERIC_PRESSURE = 101325.0
"""Standard atmospheric pressure, Pa: the moist air's, and the ambient pressure a gauge pressure
is read against unless told otherwise."""

LATENT_HEAT_WATER = 2.45e6
"""Heat of condensation of water vapour near 10-20 °C, J/kg."""

_WATER_PER_AIR = 0.621945
"""Ratio of the molar masses of water and dry air."""


@njit(cache=True, error_model="numpy")
def saturation_pressure_water(T: float) -> float:
    """Saturation pressure of water vapour over liquid water, Pa (Magnus–Alduchov–Eskridge,
    within 0.4 % from -40 to 50 °C)."""
    celsius = T - 273.15
    return 610.94 * math.exp(17.625 * celsius / (celsius + 243.04))


@njit(cache=True, error_model="numpy")
def humidity_ratio(T: float, relative_humidity: float) -> float:
    """Humidity ratio W of air at ``T`` (K) and relative humidity in [0, 1], kg water / kg dry
    air, at atmospheric pressure."""
    p_water = relative_humidity * saturation_pressure_water(T)
    return _WATER_PER_AIR * p_water / (ATMOSPHERIC_PRESSURE - p_water)


@njit(cache=True, error_model="numpy")
def latent_heat(
    capacity_rate: float,
    specific_heat: float,
    W_air: float,
    T_wall: float,
    htc: float,
    area: float,
) -> float:
    """Latent heat from the air to a wall at ``T_wall`` by condensation, W (>= 0; smoothed
    over 1e-5 kg/kg of humidity-ratio difference)."""
    drive = smooth_pos(W_air - humidity_ratio(T_wall, 1.0), 1e-5)
    effectiveness = 1.0 - math.exp(-htc * area / capacity_rate)
    return capacity_rate / specific_heat * LATENT_HEAT_WATER * drive * effectiveness
