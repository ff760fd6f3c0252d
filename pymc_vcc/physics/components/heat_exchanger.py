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
"""

from __future__ import annotations

import numpy as np

from pymc_vcc.physics.components.smooth import upwind_weight
from pymc_vcc.physics.scratch import stack_empty, uncounted


@uncounted
def _sweep(
    per_stored,
    specific_volume,
    mass_by_p,
    mass_by_h,
    h,
    source,
    inflow,
    dp_guess,
    flow_eps,
    alpha,
    beta,
):
    """One sweep with the upwind weights at ``dp_guess``: each cell's dh/dt as
    ``alpha + beta dp/dt`` into ``alpha`` and ``beta``; returns the zone outflow as
    ``(a, b)``, outflow = a + b dp/dt. Per cell, what both sweeps share (computed outside the
    chain from cell to cell): ``per_stored`` 1/(V ρ), ``specific_volume`` 1/ρ and
    ``mass_by_p``, ``mass_by_h`` V ∂ρ/∂p, V ∂ρ/∂h."""
    n = h.size
    a_flow = inflow
    b_flow = 0.0
    for i in range(n):
        if i == 0:
            transport_a = 0.0
            transport_b = 0.0
        else:
            w = upwind_weight(a_flow + b_flow * dp_guess, flow_eps)
            transport_a = w * a_flow * (h[i - 1] - h[i])
            transport_b = w * b_flow * (h[i - 1] - h[i])
        alpha[i] = (transport_a + source[i]) * per_stored[i]
        beta[i] = transport_b * per_stored[i] + specific_volume[i]
        a_flow = a_flow - mass_by_h[i] * alpha[i]
        b_flow = b_flow - (mass_by_h[i] * beta[i] + mass_by_p[i])
    return a_flow, b_flow


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
    n = h.size
    beta = stack_empty(n)  # dh_dt holds the alphas
    per_stored = stack_empty(n)
    specific_volume = stack_empty(n)
    mass_by_p = stack_empty(n)
    mass_by_h = stack_empty(n)
    for i in range(n):
        per_stored[i] = 1.0 / (volume[i] * rho[i])
        specific_volume[i] = 1.0 / rho[i]
        mass_by_p[i] = volume[i] * drho_dp[i]
        mass_by_h[i] = volume[i] * drho_dh[i]
    shared = (per_stored, specific_volume, mass_by_p, mass_by_h, h, source, inflow)
    a_out, b_out = _sweep(*shared, 0.0, flow_eps, dh_dt, beta)
    dp_dt = (outflow - a_out) / b_out
    a_out, b_out = _sweep(*shared, dp_dt, flow_eps, dh_dt, beta)
    dp_dt = (outflow - a_out) / b_out
    for i in range(h.size):
        dh_dt[i] += beta[i] * dp_dt
    return dp_dt
