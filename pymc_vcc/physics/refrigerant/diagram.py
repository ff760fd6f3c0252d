"""Property tables against CoolProp: a p–h diagram and error maps (part of ``pymc-vcc demo``)."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import LogNorm

from pymc_vcc.physics.refrigerant import Refrigerant, load_refrigerant

ISOTHERMS_C = (-40, -20, 0, 20, 40, 60, 80, 100, 120, 140)
"""Isotherms drawn on the p–h diagram, °C."""


def _table_isotherm(
    fluid: Refrigerant, temperature: float, p: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(h, p) along an isotherm (K) from the tables, crossing the dome flat at p_sat."""
    T_sat = fluid.saturation(p).T_sat
    liquid, vapour = p[temperature < T_sat], p[temperature > T_sat]
    if liquid.size == 0 or vapour.size == 0:
        return fluid.h_pT(p, temperature), p
    p_sat = fluid.p_sat(temperature)
    sat = fluid.saturation(p_sat)
    h = np.concatenate(
        [fluid.h_pT(vapour, temperature), [sat.h_v, sat.h_l], fluid.h_pT(liquid, temperature)]
    )
    return h, np.concatenate([vapour, [p_sat, p_sat], liquid])


def _heos_isotherm(heos, fluid: Refrigerant, temperature: float, p: np.ndarray) -> np.ndarray:
    """(h, p) of HEOS states on an isotherm (K) at pressures p more than 1 K from saturation."""
    import CoolProp.CoolProp as CP

    points = []
    for pressure, T_sat in zip(p, fluid.saturation(p).T_sat, strict=True):
        if abs(temperature - T_sat) > 1.0:
            heos.specify_phase(CP.iphase_liquid if temperature < T_sat else CP.iphase_gas)
            heos.update(CP.PT_INPUTS, pressure, temperature)
            points.append((heos.hmass(), pressure))
    heos.unspecify_phase()
    return np.array(points).reshape(-1, 2)


def _error_map(
    axis, errors, values: np.ndarray, fluid: Refrigerant, tolerance: float, title: str
) -> None:
    """Scatter of |values| over the p–h plane on a log colour scale, with the dome and the
    tolerance marked on the colour bar."""
    p_line = np.geomspace(fluid.p_min, fluid.p_max, 200)
    sat = fluid.saturation(p_line)
    shown = np.isfinite(values)
    magnitude = np.maximum(np.abs(values[shown]), 1e-12)
    points = axis.scatter(
        errors.h[shown] / 1e3,
        errors.p[shown] / 1e5,
        c=magnitude,
        s=6,
        norm=LogNorm(vmin=1e-10, vmax=1e-2),
        cmap="magma_r",
    )
    axis.plot(sat.h_l / 1e3, p_line / 1e5, "k", lw=1)
    axis.plot(sat.h_v / 1e3, p_line / 1e5, "k", lw=1)
    axis.set(yscale="log", xlabel="h [kJ/kg]", ylabel="p [bar]", title=title)
    bar = plt.colorbar(points, ax=axis, label="relative error (red line: tolerance)")
    bar.ax.axhline(tolerance, color="C3", lw=2)


def save_property_diagram(out: Path, n_points: int = 2000) -> Path:
    """Build or load the R410A tables, compare them with CoolProp HEOS at ``n_points`` random
    states, print the largest errors and save ``out/refrigerant_R410A.png``; returns its path."""
    import CoolProp.CoolProp as CP

    from pymc_vcc.physics.refrigerant.validation import compare_with_heos

    fluid = load_refrigerant("R410A")
    errors = compare_with_heos(fluid, n_points, seed=0)
    summary = errors.summary()
    print(
        f"R410A tables vs CoolProp HEOS at {n_points} random (p, h) states, "
        f"{fluid.p_min / 1e5:g} to {fluid.p_max / 1e5:g} bar, {fluid.T_min:g} to {fluid.T_max:g} K:"
    )
    print(f"  T        max {summary['T_max']:.1e} K  (99th percentile {summary['T_p99']:.1e} K)")
    for name in ("rho", "drho_dp", "drho_dh"):
        print(
            f"  {name:8s} max {summary[name + '_max']:.1e}    "
            f"(99th percentile {summary[name + '_p99']:.1e}), relative"
        )

    heos = CP.AbstractState("HEOS", "R410A")
    p_line = np.geomspace(fluid.p_min, fluid.p_max, 300)
    p_marks = np.geomspace(fluid.p_min, fluid.p_max, 12)
    figure, axes = plt.subplots(1, 3, figsize=(18, 5.5), constrained_layout=True)
    diagram = axes[0]
    sat = fluid.saturation(p_line)
    diagram.plot(sat.h_l / 1e3, p_line / 1e5, "k", lw=2, label="dome (tables)")
    diagram.plot(sat.h_v / 1e3, p_line / 1e5, "k", lw=2)
    for quality, marker in ((0.0, "o"), (1.0, "o")):
        h_heos = []
        for p in p_marks:
            heos.update(CP.PQ_INPUTS, p, quality)
            h_heos.append(heos.hmass())
        diagram.plot(
            np.array(h_heos) / 1e3,
            p_marks / 1e5,
            marker,
            mfc="none",
            mec="k",
            ms=7,
            label="CoolProp HEOS" if quality == 0.0 else None,
        )
    colours = plt.cm.turbo(np.linspace(0.05, 0.95, len(ISOTHERMS_C)))
    for T_c, colour in zip(ISOTHERMS_C, colours, strict=True):
        h, p = _table_isotherm(fluid, T_c + 273.15, p_line)
        diagram.plot(
            h / 1e3,
            p / 1e5,
            color=colour,
            lw=1.2,
            label="isotherms (tables)" if T_c == ISOTHERMS_C[0] else None,
        )
        diagram.annotate(
            f"{T_c}",
            (h[-1] / 1e3, p[-1] / 1e5),
            xytext=(0, 4),
            textcoords="offset points",
            ha="center",
            fontsize=8,
            color=colour,
        )
        marks = _heos_isotherm(heos, fluid, T_c + 273.15, p_marks)
        diagram.plot(
            marks[:, 0] / 1e3,
            marks[:, 1] / 1e5,
            "x",
            color=colour,
            ms=5,
            label="isotherms (HEOS)" if T_c == ISOTHERMS_C[0] else None,
        )
    diagram.axhline(
        fluid.p_crit / 1e5,
        color="grey",
        ls=":",
        lw=1,
        label=f"p_crit = {fluid.p_crit / 1e5:.1f} bar (tables stop at {fluid.p_max / 1e5:g} bar)",
    )
    diagram.set(
        yscale="log",
        xlabel="h [kJ/kg]",
        ylabel="p [bar]",
        title="R410A: tables (lines), CoolProp HEOS (markers); isotherms in °C",
    )
    diagram.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2)
    _error_map(
        axes[1],
        errors,
        errors.rho,
        fluid,
        1e-3,
        f"density error vs HEOS (max {summary['rho_max']:.1e})",
    )
    worst_derivative = np.fmax(np.abs(errors.drho_dp), np.abs(errors.drho_dh))
    _error_map(
        axes[2],
        errors,
        worst_derivative,
        fluid,
        1e-2,
        "derivative error, max of dρ/dp|h and dρ/dh|p\nvs finite differences of HEOS "
        f"(max {np.nanmax(worst_derivative):.1e})",
    )
    out.mkdir(parents=True, exist_ok=True)
    path = out / "refrigerant_R410A.png"
    figure.savefig(path, dpi=110)
    plt.close(figure)
    print(f"saved {path}")
    return path
