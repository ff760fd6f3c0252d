"""Accuracy of the tables against CoolProp HEOS at random states (for the demo and reports)."""

from __future__ import annotations

from typing import NamedTuple

import CoolProp.CoolProp as CP
import numpy as np
from numpy.typing import NDArray

from pymc_vcc.physics.refrigerant.fluid import Refrigerant
from pymc_vcc.physics.refrigerant.kernels import state_array

FD_RELATIVE_PRESSURE_STEP = 2e-4
"""Central-difference step in p, relative to p."""
FD_ENTHALPY_STEP = 20.0
"""Central-difference step in h, J/kg."""


class Errors(NamedTuple):
    """Table errors at random states against HEOS; derivative errors are NaN where the
    finite-difference stencil leaves the state's phase region or the tables."""

    p: NDArray[np.float64]
    """Pressures, Pa."""
    h: NDArray[np.float64]
    """Enthalpies, J/kg."""
    T: NDArray[np.float64]
    """Absolute temperature error, K."""
    rho: NDArray[np.float64]
    """Relative density error."""
    drho_dp: NDArray[np.float64]
    """Relative error of drho/dp|h against central differences of HEOS density."""
    drho_dh: NDArray[np.float64]
    """Relative error of drho/dh|p against central differences of HEOS density."""

    def summary(self) -> dict[str, float]:
        """Maximum and 99th percentile of each error."""
        out: dict[str, float] = {}
        for name in ("T", "rho", "drho_dp", "drho_dh"):
            values = np.abs(getattr(self, name))
            values = values[np.isfinite(values)]
            out[f"{name}_max"] = float(values.max())
            out[f"{name}_p99"] = float(np.percentile(values, 99))
        return out


def random_states(
    fluid: Refrigerant,
    n: int,
    rng: np.random.Generator,
    p_range: tuple[float, float] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """n states: p log-uniform over ``p_range`` (Pa, default the valid range), h uniform
    between the enthalpy bounds at p."""
    p_low, p_high = (fluid.p_min, fluid.p_max) if p_range is None else p_range
    p = np.exp(rng.uniform(np.log(p_low), np.log(p_high), n))
    h_min, h_max = fluid.h_min(p), fluid.h_max(p)
    return p, h_min + rng.uniform(0.0, 1.0, n) * (h_max - h_min)


def _phase_region(fluid: Refrigerant, p: NDArray[np.float64], h: NDArray[np.float64]) -> NDArray:
    """0 liquid, 1 two-phase, 2 vapour, 3 outside the tables."""
    quality = state_array(fluid.tables, p, h)[4]
    return np.where(np.isnan(quality), 3, np.digitize(quality, [0.0, 1.0]))


def compare_with_heos(
    fluid: Refrigerant, n: int, seed: int = 0, p_range: tuple[float, float] | None = None
) -> Errors:
    """Errors of ``fluid``'s tables at n random states (5 HEOS flashes a state: ~0.3 ms);
    ``p_range`` (Pa) narrows the pressures, e.g. to the band below the critical point."""
    p, h = random_states(fluid, n, np.random.default_rng(seed), p_range)
    heos = CP.AbstractState("HEOS", fluid.name)

    def density(pressure: float, enthalpy: float) -> float:
        heos.update(CP.HmassP_INPUTS, enthalpy, pressure)
        return heos.rhomass()

    reference = np.empty((n, 4))
    dp = FD_RELATIVE_PRESSURE_STEP * p
    dh = FD_ENTHALPY_STEP
    for k in range(n):
        heos.update(CP.HmassP_INPUTS, h[k], p[k])
        T, rho = heos.T(), heos.rhomass()
        d_p = (density(p[k] + dp[k], h[k]) - density(p[k] - dp[k], h[k])) / (2 * dp[k])
        d_h = (density(p[k], h[k] + dh) - density(p[k], h[k] - dh)) / (2 * dh)
        reference[k] = T, rho, d_p, d_h
    centre = _phase_region(fluid, p, h)
    usable = centre < 3
    for p_step, h_step in ((dp, 0.0), (-dp, 0.0), (0.0, dh), (0.0, -dh)):
        usable &= _phase_region(fluid, p + p_step, h + h_step) == centre
    got = fluid.props(p, h)
    return Errors(
        p=p,
        h=h,
        T=got.T - reference[:, 0],
        rho=got.rho / reference[:, 1] - 1.0,
        drho_dp=np.where(usable, got.drho_dp / reference[:, 2] - 1.0, np.nan),
        drho_dh=np.where(usable, got.drho_dh / reference[:, 3] - 1.0, np.nan),
    )
