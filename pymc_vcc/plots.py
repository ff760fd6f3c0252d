"""The paper's figures from results: inputs (Fig. 4), prior vs posterior KDEs (Figs. 5, 7),
posterior predictive bands (Figs. 6, 8) and Sobol heatmaps (Figs. 9, 10).

Each function returns a matplotlib Figure; :func:`save_figure` writes it as PNG and SVG.
Temperatures are shown in °C, pressures in bar and mass flows in g/s, as engineers read them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import xarray as xr
from matplotlib.figure import Figure
from scipy.stats import gaussian_kde

from pymc_vcc.execution.output_folder import atomic_path
from pymc_vcc.inference.predictive import predictive_bands

_DISPLAY_UNITS = {
    "K": ("°C", lambda v: v - 273.15),
    "Pa": ("bar", lambda v: v / 1e5),
    "kg/s": ("g/s", lambda v: v * 1e3),
}


def display(values: np.ndarray, units: str) -> tuple[np.ndarray, str]:
    """Values converted from SI to the units engineers read (°C, bar, g/s), and those units."""
    label, convert = _DISPLAY_UNITS.get(units, (units, lambda v: v))
    return convert(np.asarray(values, dtype=float)), label


def in_display_units(
    tree: xr.DataTree, groups: Sequence[str] = ("posterior_predictive", "observed_data")
) -> xr.DataTree:
    """A copy of ``tree`` whose outputs in ``groups`` are in display units (°C, bar, g/s), their
    ``units`` attrs changed to match: for ArviZ figures such as ``az.plot_ppc_dist``."""
    result = tree.copy()
    for group in groups:
        if group not in result.children:
            continue
        dataset = result[group].to_dataset()
        for name, variable in dataset.data_vars.items():
            values, units = display(variable.values, variable.attrs.get("units", ""))
            dataset[name] = variable.copy(data=values).assign_attrs(units=units)
        result[group] = xr.DataTree(dataset)
    return result


def labeller(tree: xr.DataTree, parameters: Sequence | None = None):
    """An ArviZ labeller naming variables by long name and unit (on a second line), e.g.
    "Compressor discharge pressure (bar)": outputs from their attrs in ``tree``, parameters
    from ``parameters`` (specs with ``id``, ``name`` and ``unit``, e.g. ``unit.parameters``)."""
    from arviz_base.labels import MapLabeller

    names = {
        spec.id: f"{spec.name}\n({spec.unit})" if spec.unit not in ("", "1") else spec.name
        for spec in parameters or ()
    }
    for group in tree.children.values():
        for name, variable in group.to_dataset().data_vars.items():
            if "long_name" in variable.attrs:
                units = variable.attrs.get("units", "")
                names[name] = variable.attrs["long_name"] + (f"\n({units})" if units else "")
    return MapLabeller(var_name_map=names)


def save_figure(figure: Figure, path_stem: str | Path) -> list[Path]:
    """Write ``figure`` as ``<stem>.png`` and ``<stem>.svg``; returns the paths."""
    stem = Path(path_stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    paths = [stem.with_suffix(".png"), stem.with_suffix(".svg")]
    for path in paths:
        with atomic_path(path) as partial:  # a kill while writing never leaves half a figure
            figure.savefig(partial, dpi=150, bbox_inches="tight")
    plt.close(figure)
    return paths


def _grid(n_panels: int, n_columns: int, panel_size: tuple[float, float]):
    n_columns = min(n_columns, n_panels)
    n_rows = int(np.ceil(n_panels / n_columns))
    figure, axes = plt.subplots(
        n_rows,
        n_columns,
        figsize=(panel_size[0] * n_columns, panel_size[1] * n_rows),
        squeeze=False,
    )
    for ax in axes.flat[n_panels:]:
        ax.set_visible(False)
    return figure, axes.flat


def plot_inputs(inputs: xr.Dataset, *, calibration_end: float | None = None) -> Figure:
    """Fig. 4: each input over time, one panel each; the calibration window's end dashed."""
    names = list(inputs.data_vars)
    figure, axes = _grid(len(names), 2, (5.0, 2.4))
    time = inputs["time"].values
    for ax, name in zip(axes, names, strict=False):
        values, units = display(inputs[name].values, inputs[name].attrs.get("units", ""))
        ax.step(time, values, where="post", color="tab:blue")
        ax.set_title(inputs[name].attrs.get("long_name", name), fontsize=9)
        ax.set_ylabel(units)
        ax.set_xlabel("time (s)")
        if calibration_end is not None:
            ax.axvline(calibration_end, color="grey", linestyle="--", linewidth=1)
    figure.tight_layout()
    return figure


def _kde_line(ax, samples: np.ndarray, low: float, high: float, **style) -> None:
    samples = samples[np.isfinite(samples)]
    if samples.size < 2 or np.ptp(samples) == 0:
        if samples.size:
            ax.axvline(samples[0], **style)
        return
    grid = np.linspace(low, high, 200)
    ax.plot(grid, gaussian_kde(samples)(grid), **style)


def plot_prior_posterior(
    tree: xr.DataTree,
    parameters: Sequence[str] | None = None,
    *,
    truth: Mapping[str, float] | None = None,
    long_names: Mapping[str, str] | None = None,
    n_columns: int = 4,
    uniform: Mapping[str, tuple[float, float]] | None = None,
) -> Figure:
    """Figs. 5 and 7: KDEs of prior and posterior draws per parameter, true values marked.

    ``uniform`` gives the bounds of parameters whose prior is uniform: their prior is drawn
    as the flat density it is, not as a KDE of its draws (which bulges and sags at the ends).
    """
    prior = tree["prior"].to_dataset()
    posterior = tree["posterior"].to_dataset()
    names = list(parameters) if parameters is not None else list(posterior.data_vars)
    missing = [name for name in names if name not in posterior.data_vars]
    if missing:
        raise ValueError(f"parameters {missing} are not in the posterior {list(posterior)}")
    figure, axes = _grid(len(names), n_columns, (3.2, 2.4))
    for ax, name in zip(axes, names, strict=False):
        prior_draws = prior[name].values.ravel()
        posterior_draws = posterior[name].values.ravel()
        both = np.concatenate([prior_draws, posterior_draws])
        low, high = float(np.nanmin(both)), float(np.nanmax(both))
        if uniform is not None and name in uniform:
            lower, upper = uniform[name]
            ax.plot(
                [lower, lower, upper, upper],
                [0.0, 1.0 / (upper - lower), 1.0 / (upper - lower), 0.0],
                color="tab:grey",
                label="prior",
            )
        else:
            _kde_line(ax, prior_draws, low, high, color="tab:grey", label="prior")
        _kde_line(ax, posterior_draws, low, high, color="tab:blue", label="posterior")
        if truth is not None and name in truth:
            ax.axvline(truth[name], color="tab:red", linestyle="--", label="true")
        ax.set_title((long_names or {}).get(name, name), fontsize=8)
        ax.set_yticks([])
    axes[0].legend(fontsize=7)
    figure.tight_layout()
    return figure


UNTRUSTED_FRACTION = 0.5
"""A Sobol figure warns that the budget is too small when more than this fraction of its
indices have a 95 % interval wider than the index itself."""


def plot_sobol_heatmap(indices: xr.Dataset, order: str = "S1") -> Figure:
    """Figs. 9 and 10: Sobol indices of ``order`` ("S1" or "ST") as parameters × outputs.

    Each cell shows the index and its 95 % half-width (``<order>_conf``, if present); cells
    whose interval is wider than the index are hatched, values below 0 or above 1 (sampling
    error) get the colour bar's end colours and their value written, never clipped silently,
    and the figure says so when most indices cannot be trusted at this budget.
    """
    if order not in ("S1", "ST"):
        raise ValueError(f"order must be 'S1' or 'ST', got {order!r}")
    values = indices[order].transpose("parameter", "output").values
    conf_name = f"{order}_conf"
    conf = (
        indices[conf_name].transpose("parameter", "output").values
        if conf_name in indices
        else np.full_like(values, np.nan)
    )
    parameters = [str(p) for p in indices["parameter"].values]
    outputs = [str(o) for o in indices["output"].values]
    figure, ax = plt.subplots(figsize=(1.5 + 0.8 * len(outputs), 1.6 + 0.32 * len(parameters)))
    colours = plt.get_cmap("viridis").copy()
    colours.set_under("tab:blue")
    colours.set_over("tab:red")
    image = ax.imshow(values, cmap=colours, vmin=0.0, vmax=1.0, aspect="auto")
    uncertain = conf > np.abs(values)
    for (row, column), value in np.ndenumerate(values):
        text = (
            f"{value:.2f}"
            if np.isnan(conf[row, column])
            else (f"{value:.2f}\n±{conf[row, column]:.2f}")
        )
        dark = 0.0 <= value < 0.6
        ax.text(
            column,
            row,
            text,
            ha="center",
            va="center",
            fontsize=5,
            color="white" if dark else "black",
        )
        if uncertain[row, column]:
            ax.add_patch(
                plt.Rectangle(
                    (column - 0.5, row - 0.5),
                    1,
                    1,
                    fill=False,
                    hatch="///",
                    edgecolor="grey",
                    linewidth=0.0,
                )
            )
    ax.set_xticks(range(len(outputs)), outputs)
    ax.set_yticks(range(len(parameters)), parameters, fontsize=7)
    ax.set_title("first-order Sobol indices" if order == "S1" else "total-order Sobol indices")
    below, above = bool((values < 0).any()), bool((values > 1).any())
    extend = {(False, False): "neither", (True, False): "min", (False, True): "max"}.get(
        (below, above), "both"
    )
    figure.colorbar(image, ax=ax, fraction=0.05, extend=extend)
    notes = [
        f"hatched: 95 % interval wider than the index ({int(uncertain.sum())} of {values.size})"
    ]
    if below or above:
        notes.append(
            f"{int((values < 0).sum() + (values > 1).sum())} indices outside [0, 1] "
            f"(from {np.nanmin(values):.2f} to {np.nanmax(values):.2f}): sampling error"
        )
    if uncertain.mean() > UNTRUSTED_FRACTION:
        notes.append("budget too small to trust these indices: run a larger budget")
    figure.text(
        0.01,
        0.005,
        "\n".join(notes),
        fontsize=7,
        va="bottom",
        color="tab:red" if uncertain.mean() > UNTRUSTED_FRACTION else "black",
    )
    figure.tight_layout(rect=(0.0, 0.03 * len(notes), 1.0, 1.0))
    return figure


def plot_charge_posteriors(
    trees: Sequence[xr.DataTree], references: Sequence[float], parameter: str = "M0"
) -> Figure:
    """Table II as a figure: the charge posterior of each dataset with its reference value."""
    figure, ax = plt.subplots(figsize=(6.0, 3.0))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    draws = [tree["posterior"][parameter].values.ravel() for tree in trees]
    every = np.concatenate([np.asarray(references, dtype=float), *draws])
    low, high = float(every.min()), float(every.max())
    pad = 0.1 * (high - low)
    for index, (samples, reference) in enumerate(zip(draws, references, strict=True)):
        colour = colours[index % len(colours)]
        _kde_line(ax, samples, low - pad, high + pad, color=colour, label=f"{reference} kg")
        ax.axvline(reference, color=colour, linestyle="--", linewidth=1)
    ax.set_xlabel("total refrigerant mass M0 (kg)")
    ax.set_yticks([])
    ax.set_title("charge posteriors (dashed: reference)")
    ax.legend(fontsize=8)
    figure.tight_layout()
    return figure


def plot_predictive(
    tree: xr.DataTree,
    outputs: Sequence[str] | None = None,
    *,
    calibration_end: float | None = None,
    uncalibrated: xr.Dataset | None = None,
    n_columns: int = 3,
    interval: float = 0.9,
    reference_label: str = "observed",
) -> Figure:
    """Figs. 6 and 8: posterior predictive median and central band against the reference.

    Draws the :func:`~pymc_vcc.inference.predictive.predictive_bands` of the tree written by
    :func:`~pymc_vcc.inference.predictive.simulate_predictive` and its ``observed_data`` (the
    reference, labelled ``reference_label``: e.g. "measured" or "truth"); ``uncalibrated``
    adds the outputs of an uncalibrated model (Fig. 8). The calibration window's end is dashed.
    """
    bands = predictive_bands(tree, interval)
    reference = tree["observed_data"].to_dataset() if "observed_data" in tree.children else None
    names = list(outputs) if outputs is not None else list(bands.data_vars)
    figure, axes = _grid(len(names), n_columns, (4.0, 2.5))
    time = bands["time"].values
    percent = round(100 * float(bands.attrs.get("interval", 0.9)))
    for ax, name in zip(axes, names, strict=False):
        units = bands[name].attrs.get("units", "")
        lower, median, upper = (
            display(bands[name].sel(band=band).values, units)[0]
            for band in ("lower", "median", "upper")
        )
        ax.fill_between(time, lower, upper, color="tab:blue", alpha=0.25, label=f"{percent} % band")
        ax.plot(time, median, color="tab:blue", label="predictive median")
        if reference is not None and name in reference:
            truth, _ = display(reference[name].values, units)
            ax.plot(
                reference["time"].values,
                truth,
                color="black",
                linestyle=":",
                label=reference_label,
            )
        if uncalibrated is not None and name in uncalibrated:
            values, _ = display(uncalibrated[name].values, units)
            ax.plot(uncalibrated["time"].values, values, color="tab:red", label="uncalibrated")
        if calibration_end is not None:
            ax.axvline(calibration_end, color="grey", linestyle="--", linewidth=1)
        ax.set_title(name, fontsize=9)
        ax.set_ylabel(display(np.zeros(1), units)[1])
        ax.set_xlabel("time (s)")
    axes[0].legend(fontsize=6)
    figure.tight_layout()
    return figure
