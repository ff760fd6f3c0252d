"""Finite-volume pressure zone: the refrigerant side of a heat exchanger and its lines.

A zone is a chain of cells sharing one pressure p (static momentum; friction is lumped at the
zone's ends). Each cell i has volume V_i and enthalpy h_i; its balances, upwinded in the flow
direction, are

    V ρ dh/dt = w(F_i) F_i (h_{i-1} - h_i) + S_i + V dp/dt           (energy)
    F_{i+1}   = F_i - V (∂ρ/∂h dh/dt + ∂ρ/∂p dp/dt)                   (mass)

with F_i the mass flow entering through face i, w a smooth forward-flow indicator (a reversed
face carries the downstream cell's own enthalpy out of it, which leaves h_i unchanged) and S_i
all other heat and enthalpy flows into the cell (wall heat; at the first cell, the inflow). The
downstream component fixes the zone outflow F_n, which closes one scalar equation for dp/dt:
one O(n) sweep carrying every quantity as an affine function a + b dp/dt.

Each cell's step waits for the previous one's outflow, a chain of dependent divisions and
square roots; a cycle's two zones are independent, so :func:`zone_pair_derivatives` steps
both in one loop, and the processor runs the two chains side by side.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from pymc_vcc.physics.components.smooth import upwind_weight
from pymc_vcc.physics.scratch import stack_empty, uncounted


@njit(cache=True, error_model="numpy", inline="always")
def _shared(volume, rho, drho_dp, drho_dh):
    """What a zone's two sweeps share, per cell (computed outside the chain from cell to cell):
    1/(V ρ), 1/ρ, V ∂ρ/∂p and V ∂ρ/∂h, as stack arrays of the caller."""
    n = rho.size
    per_stored = stack_empty(n)
    specific_volume = stack_empty(n)
    mass_by_p = stack_empty(n)
    mass_by_h = stack_empty(n)
    for i in range(n):
        per_stored[i] = 1.0 / (volume[i] * rho[i])
        specific_volume[i] = 1.0 / rho[i]
        mass_by_p[i] = volume[i] * drho_dp[i]
        mass_by_h[i] = volume[i] * drho_dh[i]
    return per_stored, specific_volume, mass_by_p, mass_by_h


@njit(cache=True, error_model="numpy", inline="always")
def _cell_step(i, flow, dp_guess, shared, h, source, flow_eps, alpha, beta):
    """Cell ``i`` of a sweep with the upwind weights at ``dp_guess``: its dh/dt as
    ``alpha[i] + beta[i] dp/dt``, given the flow entering it as ``flow`` = (a, b), flow =
    a + b dp/dt; returns the flow leaving it likewise."""
    per_stored, specific_volume, mass_by_p, mass_by_h = shared
    a_flow, b_flow = flow
    if i == 0:
        transport_a = 0.0
        transport_b = 0.0
    else:
        w = upwind_weight(a_flow + b_flow * dp_guess, flow_eps)
        transport_a = w * a_flow * (h[i - 1] - h[i])
        transport_b = w * b_flow * (h[i - 1] - h[i])
    alpha[i] = (transport_a + source[i]) * per_stored[i]
    beta[i] = transport_b * per_stored[i] + specific_volume[i]
    return (
        a_flow - mass_by_h[i] * alpha[i],
        b_flow - (mass_by_h[i] * beta[i] + mass_by_p[i]),
    )


@njit(cache=True, error_model="numpy", inline="always")
def _close(outflow, flow):
    """dp/dt at which the zone's outflow a + b dp/dt is ``outflow``."""
    return (outflow - flow[0]) / flow[1]


@njit(cache=True, error_model="numpy", inline="always")
def _add_pressure_term(dh_dt, beta, dp_dt):
    """dh/dt = alpha + beta dp/dt, in place (``dh_dt`` holds the alphas)."""
    for i in range(dh_dt.size):
        dh_dt[i] += beta[i] * dp_dt


@uncounted
def zone_derivatives(
    volume: np.ndarray,
    rho: np.ndarray,
    drho_dp: np.ndarray,
    drho_dh: np.ndarray,
    h: np.ndarray,
    source: np.ndarray,
    inflow: float,
    outflow: float,
    flow_eps: float,
    dh_dt: np.ndarray,
) -> float:
    """dp/dt of the zone (Pa/s), writing dh/dt (J/(kg s)) of each cell into ``dh_dt``.

    ``inflow`` enters the first cell (its enthalpy flow is part of ``source[0]``), ``outflow``
    leaves the last one. The upwind weights are evaluated at a first estimate of dp/dt and the
    affine solve repeated once with them, a fixed two-pass scheme (so the result is a smooth
    function of the state). Total mass is conserved exactly: Σ V dρ/dt = inflow - outflow.
    """
    shared = _shared(volume, rho, drho_dp, drho_dh)
    beta = stack_empty(h.size)  # dh_dt holds the alphas
    dp_dt = 0.0
    for _ in range(2):
        flow = (inflow, 0.0)
        for i in range(h.size):
            flow = _cell_step(i, flow, dp_dt, shared, h, source, flow_eps, dh_dt, beta)
        dp_dt = _close(outflow, flow)
    _add_pressure_term(dh_dt, beta, dp_dt)
    return dp_dt


@uncounted
def zone_pair_derivatives(first, second, flow_eps: float) -> tuple[float, float]:
    """:func:`zone_derivatives` of two zones at once, the same numbers: each zone a tuple
    ``(volume, rho, drho_dp, drho_dh, h, source, inflow, outflow, dh_dt)`` of that function's
    arguments; returns both dp/dt (Pa/s). Their cells are stepped in one loop."""
    v1, rho1, rp1, rh1, h1, s1, in1, out1, dh1 = first
    v2, rho2, rp2, rh2, h2, s2, in2, out2, dh2 = second
    shared1 = _shared(v1, rho1, rp1, rh1)
    shared2 = _shared(v2, rho2, rp2, rh2)
    beta1 = stack_empty(h1.size)
    beta2 = stack_empty(h2.size)
    dp1 = 0.0
    dp2 = 0.0
    for _ in range(2):
        flow1 = (in1, 0.0)
        flow2 = (in2, 0.0)
        for i in range(max(h1.size, h2.size)):
            if i < h1.size:
                flow1 = _cell_step(i, flow1, dp1, shared1, h1, s1, flow_eps, dh1, beta1)
            if i < h2.size:
                flow2 = _cell_step(i, flow2, dp2, shared2, h2, s2, flow_eps, dh2, beta2)
        dp1 = _close(out1, flow1)
        dp2 = _close(out2, flow2)
    _add_pressure_term(dh1, beta1, dp1)
    _add_pressure_term(dh2, beta2, dp2)
    return dp1, dp2
