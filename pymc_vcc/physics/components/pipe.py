"""Connecting lines and lumped pressure drops: inventory volume and friction loss."""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, error_model="numpy")
def pipe_volume(length: float, inner_diameter: float, n_paths: float = 1.0) -> float:
    """Internal volume of ``n_paths`` parallel tubes, m³."""
    return n_paths * length * 0.25 * math.pi * inner_diameter * inner_diameter


@njit(cache=True, error_model="numpy")
def friction_coefficient(
    friction_factor: float, length: float, inner_diameter: float, n_paths: float = 1.0
) -> float:
    """K of the lumped loss Δp = K ṁ|ṁ|/ρ for ``n_paths`` parallel tubes (Darcy–Weisbach):
    K = f (L/D) / (2 A²) with A the total flow area, 1/m⁴."""
    area = n_paths * 0.25 * math.pi * inner_diameter * inner_diameter
    return friction_factor * length / inner_diameter / (2.0 * area * area)


@njit(cache=True, error_model="numpy")
def pressure_drop(coefficient: float, mass_flow: float, density: float, eps: float) -> float:
    """Friction pressure drop in the flow direction, Pa: K ṁ sqrt(ṁ² + eps²) / ρ (regularised
    ṁ|ṁ| so the slope at zero flow is finite)."""
    return coefficient * mass_flow * math.sqrt(mass_flow * mass_flow + eps * eps) / density


@njit(cache=True, error_model="numpy")
def rated_drop_coefficient(rated_drop: float, rated_flow: float, rated_density: float) -> float:
    """K of the lumped loss Δp = K ṁ|ṁ|/ρ (1/m⁴) of a restriction that drops ``rated_drop`` Pa
    when ``rated_flow`` kg/s of fluid of density ``rated_density`` kg/m³ passes it: the same
    restriction drops Δp_r (ṁ/ṁ_r)² ρ_r/ρ at any other flow and density."""
    return rated_drop * rated_density / (rated_flow * rated_flow)
