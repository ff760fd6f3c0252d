"""Fans: the fan laws and the fan's motor heat picked up by the air stream."""

from __future__ import annotations

from numba import njit


@njit(cache=True, error_model="numpy")
def fan_operating_point(
    nominal_flow: float, nominal_power: float, nominal_speed: float, speed: float
) -> tuple[float, float]:
    """Volumetric flow (m³/s) and electric power (W) at ``speed`` by the fan laws:
    flow ∝ speed, power ∝ speed³ (same speed unit for ``speed`` and ``nominal_speed``)."""
    ratio = speed / nominal_speed
    return nominal_flow * ratio, nominal_power * ratio * ratio * ratio


@njit(cache=True, error_model="numpy")
def air_capacity_rate(flow: float, density: float, specific_heat: float) -> float:
    """Heat-capacity rate of an air stream, W/K."""
    return flow * density * specific_heat


@njit(cache=True, error_model="numpy")
def air_inlet_temperature(T_air: float, fan_power: float, capacity_rate: float) -> float:
    """Coil inlet air temperature (K) after the fan's motor heat is dissipated into the stream."""
    return T_air + fan_power / capacity_rate
