"""C¹ regularisations used throughout the right-hand side (a stiff solver needs smoothness)."""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, error_model="numpy")
def smooth_pos(x: float, eps: float) -> float:
    """A smooth max(x, 0): 0.5 (x + sqrt(x² + eps²)); exact to eps²/(4|x|) away from 0."""
    return 0.5 * (x + math.sqrt(x * x + eps * eps))


@njit(cache=True, error_model="numpy")
def smooth_max(a: float, b: float, eps: float) -> float:
    """A smooth max(a, b) with transition width ``eps``; always >= max(a, b)."""
    return b + smooth_pos(a - b, eps)


@njit(cache=True, error_model="numpy")
def smooth_min(a: float, b: float, eps: float) -> float:
    """A smooth min(a, b) with transition width ``eps``; always <= min(a, b)."""
    return a - smooth_pos(a - b, eps)


@njit(cache=True, error_model="numpy")
def upwind_weight(flow: float, eps: float) -> float:
    """Smooth indicator of forward flow: 0.5 (1 + flow / sqrt(flow² + eps²)), in [0, 1]."""
    return 0.5 * (1.0 + flow / math.sqrt(flow * flow + eps * eps))


@njit(cache=True, error_model="numpy")
def signed_sqrt(x: float, eps: float) -> float:
    """sign(x) sqrt(|x|) with a finite slope at 0: x / (x² + eps²)^(1/4) (two square roots:
    a third of ``pow``'s time)."""
    return x / math.sqrt(math.sqrt(x * x + eps * eps))


@njit(cache=True, error_model="numpy")
def smooth_step(t: float) -> float:
    """C¹ step from 0 (t <= 0) to 1 (t >= 1): 3t² - 2t³ in between."""
    if t <= 0.0:
        return 0.0
    if t >= 1.0:
        return 1.0
    return t * t * (3.0 - 2.0 * t)


@njit(cache=True, error_model="numpy")
def soft_cap(x: float, cap: float) -> float:
    """A smooth min(x, cap) for x >= 0 and cap > 0: x / (1 + (x/cap)⁴)^(1/4), never above
    either and within 1 % of x for x < 0.44 cap."""
    r = x / cap
    return x / math.sqrt(math.sqrt(1.0 + r * r * r * r))
