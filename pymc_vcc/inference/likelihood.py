"""Exact log-likelihood of observed series given a deterministic simulation and a noise model.

With a deterministic simulator ŷ(θ) and sensor errors as stated by
:class:`~pymc_vcc.inference.noise.SensorNoise`, observed = ŷ + σ·e, the likelihood of the
observed series is known: no ABC tolerance is needed. Per output, with standardised residuals
r_t = (y_t − ŷ_t)/σ_t and lag-1 coefficient φ, the innovations are w_1 = r_1 and
w_t = (r_t − φ r_{t−1}) / √(1 − φ²), and

    log p(y | θ) = Σ_t log f(w_t) − Σ_t log σ_t − (n − 1) · ½ log(1 − φ²),

with f the standard normal density, or the Student-t density with ν degrees of freedom (then σ
is the t scale, not the standard deviation). φ = 0 gives independent errors.
"""

from __future__ import annotations

import numpy as np
from scipy.special import gammaln

from pymc_vcc.inference.noise import OutputNoise


def innovations(residuals: np.ndarray, correlation: float) -> np.ndarray:
    """Unit-scale innovations of AR(1) standardised residuals (n_outputs, n_time)."""
    if correlation == 0.0:
        return residuals
    whitened = np.empty_like(residuals)
    whitened[:, 0] = residuals[:, 0]
    whitened[:, 1:] = (residuals[:, 1:] - correlation * residuals[:, :-1]) / np.sqrt(
        1.0 - correlation**2
    )
    return whitened


def log_likelihood(
    observed: np.ndarray,
    simulated: np.ndarray,
    noise: OutputNoise,
    scales: np.ndarray | None = None,
) -> float:
    """log p(observed | simulated) under ``noise``, summed over outputs and time.

    Args:
        observed: measured outputs (n_outputs, n_time), SI units.
        simulated: noise-free simulated outputs on the same grid, SI units.
        noise: the resolved noise model of these rows.
        scales: scales replacing ``noise.scales`` (learnable scales), in their kinds' terms.

    Returns:
        The log-likelihood; −inf for a non-finite simulation or a zero scale.
    """
    observed = np.asarray(observed, dtype=float)
    simulated = np.asarray(simulated, dtype=float)
    if observed.shape != simulated.shape:
        raise ValueError(
            f"observed {observed.shape} and simulated {simulated.shape} outputs must share one "
            "(outputs, time) grid for a likelihood"
        )
    if not np.isfinite(simulated).all():
        return -np.inf
    sigma = noise.std(simulated, scales)
    if not (sigma > 0).all():
        return -np.inf
    whitened = innovations((observed - simulated) / sigma, noise.correlation)
    if noise.dof is None:
        density = -0.5 * whitened**2 - 0.5 * np.log(2 * np.pi)
    else:
        nu = noise.dof
        density = (
            gammaln((nu + 1) / 2)
            - gammaln(nu / 2)
            - 0.5 * np.log(nu * np.pi)
            - (nu + 1) / 2 * np.log1p(whitened**2 / nu)
        )
    n_time = observed.shape[1]
    jacobian = 0.5 * (n_time - 1) * np.log1p(-(noise.correlation**2)) * observed.shape[0]
    return float(density.sum() - np.log(sigma).sum() - jacobian)
