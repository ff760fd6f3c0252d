"""The Python face of the property tables: :func:`load_refrigerant` and :class:`Refrigerant`."""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pymc_vcc.physics.refrigerant import kernels
from pymc_vcc.physics.refrigerant.cache import cache_directory, cache_path, load_tables, save_tables
from pymc_vcc.physics.refrigerant.tables import FluidSpec, PropertyTables, TableResolution

_T_MIN = 220.0
_T_MAX = 430.0

SUPPORTED_FLUIDS: dict[str, FluidSpec] = {
    # CoolProp's pseudo-pure R410A saturation fails to converge above ~48.6 bar (p_crit 49.0 bar)
    # and its (p, h) flash fails on liquid states above ~48.4 bar: the tables stop at 48 bar.
    "R410A": FluidSpec("R410A", "R410A", 1.0e5, 48.0e5, _T_MIN, _T_MAX),
    # Pure fluids: tables verified to 0.99 p_crit; they stop at about 0.985 p_crit.
    "R32": FluidSpec("R32", "R32", 1.0e5, 57.0e5, _T_MIN, _T_MAX),
    "R134a": FluidSpec("R134a", "R134a", 1.0e5, 40.0e5, _T_MIN, _T_MAX),
}
"""Refrigerants with tables: valid pressures p_min..p_max (Pa), enthalpies between the
T_min = 220 K and T_max = 430 K isotherms."""

DEFAULT_RESOLUTION = TableResolution()
"""Node counts of the default tables (about half a second to build, 1.1 MB on disk)."""


class Properties(NamedTuple):
    """Properties at (p, h), arrays of the broadcast input shape (SI units)."""

    T: NDArray[np.float64]
    """Temperature, K."""
    rho: NDArray[np.float64]
    """Density (homogeneous in two-phase), kg/m3."""
    drho_dp: NDArray[np.float64]
    """d rho / d p at constant h, kg/m3/Pa."""
    drho_dh: NDArray[np.float64]
    """d rho / d h at constant p, kg/m3/(J/kg)."""
    quality: NDArray[np.float64]
    """Unclipped quality (h - h_l)/(h_v - h_l): < 0 subcooled, > 1 superheated."""
    s: NDArray[np.float64]
    """Specific entropy, J/(kg K)."""


class Saturation(NamedTuple):
    """Saturation properties at p, arrays of the input shape (SI units)."""

    T_sat: NDArray[np.float64]
    """Saturation temperature, K (mid-glide for CoolProp's pseudo-pure R410A)."""
    h_l: NDArray[np.float64]
    """Saturated-liquid enthalpy, J/kg."""
    h_v: NDArray[np.float64]
    """Saturated-vapour enthalpy, J/kg."""
    rho_l: NDArray[np.float64]
    """Saturated-liquid density, kg/m3."""
    rho_v: NDArray[np.float64]
    """Saturated-vapour density, kg/m3."""


def _flat(*values: ArrayLike) -> tuple[tuple[int, ...], list[NDArray[np.float64]]]:
    """Broadcast ``values`` and return their shape and contiguous 1-D float64 arrays."""
    ready = [v for v in values if isinstance(v, np.ndarray)]
    if len(ready) == len(values) and all(
        v.dtype == np.float64 and v.ndim == 1 and v.shape == ready[0].shape and v.flags.c_contiguous
        for v in ready
    ):
        return ready[0].shape, ready
    arrays = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in values))
    return arrays[0].shape, [np.ascontiguousarray(a).ravel() for a in arrays]


def _shaped(values: NDArray[np.float64], shape: tuple[int, ...]) -> NDArray[np.float64]:
    """``values`` (n,) or rows (k, n) reshaped to ``shape`` or (k, *shape); scalars for ()."""
    return values.reshape(values.shape[:-1] + shape)[()]


def _require(ok: NDArray[np.bool_], message: Callable[[int], str]) -> None:
    """Raise ValueError with ``message(i)`` for the first index i where ``ok`` is False."""
    if not ok.all():
        bad = np.flatnonzero(~ok)
        raise ValueError(f"{message(int(bad[0]))} ({bad.size} of {ok.size} values out of range)")


class Refrigerant:
    """One refrigerant's property tables with a vectorised, range-checked Python API.

    ``tables`` is the :class:`PropertyTables` to pass to the Numba kernels of
    :mod:`pymc_vcc.physics.refrigerant`. The methods take array-likes (broadcast together), return
    arrays of the broadcast shape, and raise ValueError naming the offending input and the
    valid range instead of extrapolating.

    Parameters
    ----------
    name
        Refrigerant name (``R410A``, ``R32``, ``R134a``).
    tables
        Its property tables (:func:`load_refrigerant` builds them).
    """

    def __init__(self, name: str, tables: PropertyTables) -> None:
        self.name = name
        self.tables = tables

    def __repr__(self) -> str:
        return (
            f"Refrigerant({self.name!r}, p {self.p_min / 1e5:g}-{self.p_max / 1e5:g} bar, "
            f"T {self.T_min:g}-{self.T_max:g} K)"
        )

    @property
    def p_min(self) -> float:
        """Lowest valid pressure, Pa."""
        return self.tables.p_min

    @property
    def p_max(self) -> float:
        """Highest valid pressure (below the critical pressure), Pa."""
        return self.tables.p_max

    @property
    def p_crit(self) -> float:
        """Critical pressure, Pa."""
        return self.tables.p_crit

    @property
    def T_crit(self) -> float:
        """Critical temperature, K."""
        return self.tables.T_crit

    @property
    def T_min(self) -> float:
        """The isotherm bounding the valid region on the liquid side, K."""
        return self.tables.T_min

    @property
    def T_max(self) -> float:
        """The isotherm bounding the valid region on the vapour side, K."""
        return self.tables.T_max

    def _check_pressure(self, p: NDArray[np.float64]) -> None:
        _require(
            (p >= self.p_min) & (p <= self.p_max),
            lambda i: (
                f"p = {p[i]:.6g} Pa is outside the valid range [{self.p_min:.6g}, "
                f"{self.p_max:.6g}] Pa of the {self.name} tables (they stop below the critical "
                f"pressure {self.p_crit:.6g} Pa)"
            ),
        )

    def _check_enthalpy(self, p: NDArray[np.float64], h: NDArray[np.float64]) -> None:
        self._check_pressure(p)
        h_min, h_max = kernels.enthalpy_bounds_array(self.tables, p)
        _require(
            (h >= h_min) & (h <= h_max),
            lambda i: (
                f"h = {h[i]:.6g} J/kg at p = {p[i]:.6g} Pa is outside the valid range "
                f"[{h_min[i]:.6g}, {h_max[i]:.6g}] J/kg of the {self.name} tables (between the "
                f"T_min = {self.T_min:g} K and T_max = {self.T_max:g} K isotherms)"
            ),
        )

    def h_min(self, p: ArrayLike) -> NDArray[np.float64]:
        """Lowest valid enthalpy at p (the T_min isotherm), J/kg."""
        shape, (p_flat,) = _flat(p)
        self._check_pressure(p_flat)
        return _shaped(kernels.enthalpy_bounds_array(self.tables, p_flat)[0], shape)

    def h_max(self, p: ArrayLike) -> NDArray[np.float64]:
        """Highest valid enthalpy at p (the T_max isotherm), J/kg."""
        shape, (p_flat,) = _flat(p)
        self._check_pressure(p_flat)
        return _shaped(kernels.enthalpy_bounds_array(self.tables, p_flat)[1], shape)

    def props(self, p: ArrayLike, h: ArrayLike) -> Properties:
        """T, rho, drho_dp, drho_dh, quality and s at pressure p (Pa) and enthalpy h (J/kg)."""
        shape, (p_flat, h_flat) = _flat(p, h)
        rows = kernels.props_array(self.tables, p_flat, h_flat)
        if math.isnan(rows[0].sum()):  # the kernels flag states outside the tables with NaN
            self._check_enthalpy(p_flat, h_flat)
        return Properties(*_shaped(rows, shape))

    def saturation(self, p: ArrayLike) -> Saturation:
        """T_sat, h_l, h_v, rho_l, rho_v at pressure p (Pa)."""
        shape, (p_flat,) = _flat(p)
        self._check_pressure(p_flat)
        return Saturation(*_shaped(kernels.saturation_array(self.tables, p_flat), shape))

    def p_sat(self, T: ArrayLike) -> NDArray[np.float64]:
        """Saturation pressure at temperature T (K), Pa: the inverse of ``saturation(p).T_sat``."""
        shape, (T_flat,) = _flat(T)
        T_low = self.saturation(self.p_min).T_sat
        T_high = self.saturation(self.p_max).T_sat
        _require(
            (T_flat >= T_low) & (T_flat <= T_high),
            lambda i: (
                f"T = {T_flat[i]:.6g} K is outside the saturation range [{T_low:.6g}, "
                f"{T_high:.6g}] K of the {self.name} tables (p_min to p_max)"
            ),
        )
        return _shaped(kernels.p_sat_from_T_array(self.tables, T_flat), shape)

    def h_pT(self, p: ArrayLike, T: ArrayLike) -> NDArray[np.float64]:
        """Enthalpy at pressure p (Pa) and temperature T (K), J/kg.

        Liquid below the bubble point, vapour from the dew point up (saturated vapour at T_sat
        for a pure fluid).
        """
        shape, (p_flat, T_flat) = _flat(p, T)
        self._check_pressure(p_flat)
        _require(
            (T_flat >= self.T_min) & (T_flat <= self.T_max),
            lambda i: (
                f"T = {T_flat[i]:.6g} K is outside the valid range [{self.T_min:g}, "
                f"{self.T_max:g}] K of the {self.name} tables"
            ),
        )
        return _shaped(kernels.h_from_pT_array(self.tables, p_flat, T_flat), shape)

    def h_ps(self, p: ArrayLike, s: ArrayLike) -> NDArray[np.float64]:
        """Enthalpy at pressure p (Pa) and entropy s (J/(kg K)), J/kg."""
        shape, (p_flat, s_flat) = _flat(p, s)
        self._check_pressure(p_flat)
        h_min, h_max = kernels.enthalpy_bounds_array(self.tables, p_flat)
        s_min = kernels.entropy_array(self.tables, p_flat, h_min)
        s_max = kernels.entropy_array(self.tables, p_flat, h_max)
        _require(
            (s_flat >= s_min) & (s_flat <= s_max),
            lambda i: (
                f"s = {s_flat[i]:.6g} J/(kg K) at p = {p_flat[i]:.6g} Pa is outside the valid "
                f"range [{s_min[i]:.6g}, {s_max[i]:.6g}] J/(kg K) of the {self.name} tables"
            ),
        )
        return _shaped(kernels.h_from_ps_array(self.tables, p_flat, s_flat), shape)


_LOADED: dict[Path, Refrigerant] = {}


def load_refrigerant(
    name: str = "R410A",
    cache_dir: str | os.PathLike[str] | None = None,
    resolution: TableResolution = DEFAULT_RESOLUTION,
) -> Refrigerant:
    """The property tables of refrigerant ``name``, built from CoolProp or loaded from the cache.

    ``name`` is one of :data:`SUPPORTED_FLUIDS` (case-insensitive). The cache directory is
    ``cache_dir``, else ``$PYMC_VCC_CACHE``, else ``~/.cache/pymc_vcc``; the first call builds
    the tables (about a second) and writes them there, later calls and other processes read
    them. Within a process the result is memoised.

    Parameters
    ----------
    name
        Refrigerant name, one of :data:`SUPPORTED_FLUIDS`.
    cache_dir
        Folder of the table cache (default: ``$PYMC_VCC_CACHE``, else ``~/.cache/pymc_vcc``).
    resolution
        Table nodes (saturation, pressure, liquid and vapour enthalpy).
    """
    canonical = {key.lower(): key for key in SUPPORTED_FLUIDS}.get(str(name).lower())
    if canonical is None:
        raise ValueError(
            f"unknown refrigerant {name!r}; supported refrigerants: {', '.join(SUPPORTED_FLUIDS)}"
        )
    spec = SUPPORTED_FLUIDS[canonical]
    path = cache_path(cache_directory(cache_dir).expanduser().resolve(), spec, resolution)
    fluid = _LOADED.get(path)
    if fluid is None:
        tables = load_tables(path)
        if tables is None:
            from pymc_vcc.physics.refrigerant.build import build_tables  # imports CoolProp: seconds

            tables = build_tables(spec, resolution)
            save_tables(path, tables)
        fluid = _LOADED[path] = Refrigerant(canonical, tables)
    return fluid
