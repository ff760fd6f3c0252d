"""The paper's figures from results: inputs (Fig. 4), prior vs posterior densities (Figs. 5,
7), posterior predictive bands (Figs. 6, 8), Sobol heatmaps (Figs. 9, 10) and Table II's
charge posteriors.

Densities and the charge forest are drawn by ArviZ (``arviz_plots``: ``plot_prior_posterior``,
``plot_forest``); time series and heatmaps, which ArviZ does not draw, by matplotlib. Each
function returns a matplotlib Figure; :func:`save_figure` writes it as PNG and SVG.
Temperatures are shown in °C, pressures in bar and mass flows in g/s, as engineers read them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib.pyplot as plt
import numpy as np
import xarray as xr
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from pymc_vcc.execution.output_folder import atomic_path
from pymc_vcc.inference.predictive import predictive_bands

if TYPE_CHECKING:
    from arviz_base.labels import BaseLabeller, MapLabeller

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


def labeller(tree: xr.DataTree, parameters: Sequence | None = None) -> MapLabeller:
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


SPIKE_POINTS = 512
"""Points of a spike where no KDE sets the grid (ArviZ's default length)."""


def _spike(value: float, n_points: int) -> xr.DataArray:
    """A unit-area triangle of half-width 1e-6·|value| (or 1e-9) on ``value``: the density
    figure of draws that all coincide, where a KDE has no bandwidth."""
    half_width = 1e-6 * abs(value) or 1e-9
    x = np.linspace(value - half_width, value + half_width, n_points)
    y = (1 - np.abs(x - value) / half_width) / half_width
    return xr.DataArray(
        np.stack([x, y]), dims=("plot_axis", "kde_dim"), coords={"plot_axis": ["x", "y"]}
    )


def _densities(
    tree: xr.DataTree, names: Sequence[str], uniform: Mapping[str, tuple[float, float]]
) -> xr.Dataset:
    """ArviZ's KDE of the prior and posterior draws of ``names``, stacked along ``group``, as
    ``plot_prior_posterior`` takes precomputed densities; the prior of a parameter in
    ``uniform`` is its exact density instead, flat on [low, high] and 0 outside."""
    from arviz_stats import kde

    groups = []
    for group in ("prior", "posterior"):
        draws = tree[group].to_dataset()[list(names)]
        spread = [name for name in names if np.ptp(draws[name].values) > 0]
        found = xr.Dataset()
        if spread:
            found = kde(draws[spread], dim=[d for d in ("chain", "draw") if d in draws.dims])
        for name in (name for name in names if name not in spread):
            points = found.sizes.get("kde_dim", SPIKE_POINTS)
            found[name] = _spike(float(draws[name].values.flat[0]), points)
        groups.append(found)
    density = xr.concat(groups, dim="group", coords="minimal", compat="override")
    density = density.drop_vars([c for c in density.coords if c.startswith("bw_")])
    density = density.assign_coords(group=["prior", "posterior"])
    n_points = density.sizes["kde_dim"]
    for name in (name for name in names if name in uniform):
        low, high = uniform[name]
        x = np.concatenate([[low], np.linspace(low, high, n_points - 2), [high]])
        y = np.concatenate([[0.0], np.full(n_points - 2, 1.0 / (high - low)), [0.0]])
        density[name].loc[{"group": "prior"}] = np.stack([x, y])
    for name in density.data_vars:
        density[name].attrs["kind"] = "kde"
    return density


def plot_prior_posterior(
    tree: xr.DataTree,
    parameters: Sequence[str] | None = None,
    *,
    truth: Mapping[str, float] | None = None,
    labels: BaseLabeller | None = None,
    n_columns: int = 4,
    uniform: Mapping[str, tuple[float, float]] | None = None,
) -> Figure:
    """Figs. 5 and 7 with ArviZ's ``plot_prior_posterior``: prior and posterior density of
    each parameter, true values dashed.

    Args:
        tree: a result with ``prior`` and ``posterior`` groups (one variable per parameter).
        parameters: the parameters drawn, in order (default: every posterior variable).
        truth: true values, drawn as dashed lines labelled "true value".
        labels: an ArviZ labeller for the panel titles, e.g. :func:`labeller` (long names
            and units).
        n_columns: panels per row.
        uniform: bounds of parameters whose prior is uniform: their prior is drawn as its
            exact flat density, not as a KDE of its draws (which bulges and sags at the ends).
    """
    import arviz_plots as azp

    posterior = tree["posterior"].to_dataset()
    names = list(parameters) if parameters is not None else list(posterior.data_vars)
    missing = [n for n in names if n not in posterior.data_vars or n not in tree["prior"]]
    if missing:
        raise ValueError(
            f"parameters {missing} are not in the posterior and prior; the posterior has "
            f"{list(posterior.data_vars)}"
        )
    n_cols = min(n_columns, len(names))
    n_rows = -(-len(names) // n_cols)
    collection = azp.plot_prior_posterior(
        tree,
        var_names=names,
        kind="kde",
        labeller=labels,
        col_wrap=n_cols,
        figure_kwargs={"figsize": (3.2 * n_cols, 2.4 * n_rows)},
        color=["tab:grey", "tab:blue"],
        stats={"dist": _densities(tree, names, uniform or {})},
        visuals={"title": {"size": 8}},
    )
    lines = collection.viz["dist"]
    shown = {name: value for name, value in (truth or {}).items() if name in names}
    if shown:
        azp.add_lines(collection, shown, visuals={"ref_line": {"color": "tab:red"}})
        for line in collection.viz["ref_line"].to_dataset().data_vars.values():
            np.ravel(line.values)[0].set_label("true value")
    for name in names:
        for group in ("prior", "posterior"):
            lines[name].sel(group=group).item().set_label(group)
    collection.viz["legend"]["group"].item().remove()  # ArviZ's, at the figure's edge
    figure = collection.viz["figure"].item()
    figure.axes[0].legend(fontsize=7)
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
    colours = plt.get_cmap("viridis").with_extremes(under="tab:blue", over="tab:red")
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
    """Table II as ArviZ's ``plot_forest``: one row per dataset, the posterior median of the
    charge with its 50 % and 95 % intervals, the dataset's reference charge marked.

    Datasets with more posterior draws than the smallest are thinned evenly to its count.
    """
    import arviz_plots as azp
    from arviz_base.labels import MapLabeller

    if len(trees) != len(references) or not trees:
        raise ValueError(
            f"give one reference per tree: {len(trees)} trees, {len(references)} references"
        )
    draws = [tree["posterior"][parameter].values.ravel() for tree in trees]
    n_draws = min(len(d) for d in draws)
    thinned = [d[np.linspace(0, len(d) - 1, n_draws).round().astype(int)] for d in draws]
    rows = [f"dataset {k + 1}: {reference:g} kg" for k, reference in enumerate(references)]
    posterior = xr.Dataset(
        {parameter: (("dataset", "chain", "draw"), np.stack(thinned)[:, np.newaxis, :])},
        coords={"dataset": rows},
    )
    collection = azp.plot_forest(
        xr.DataTree.from_dict({"posterior": posterior}),
        combined=True,
        labels=["dataset"],
        ci_probs=[0.5, 0.95],
        point_estimate="median",
        labeller=MapLabeller(var_name_map={parameter: f"{parameter} (kg)"}),
        figure_kwargs={"figsize": (7.0, 1.0 + 0.45 * len(rows))},
    )
    figure = collection.viz["figure"].item()
    forest = figure.axes[-1]
    for row, reference in zip(rows, references, strict=True):
        marker = collection.viz["point_estimate"][parameter].sel(dataset=row).item()
        height = marker.get_offsets()[0][1]
        forest.plot(reference, height, marker="x", color="tab:red", markersize=8, linestyle="")
    forest.set_xlabel(f"total refrigerant mass {parameter} (kg)")
    forest.legend(
        [
            Line2D([], [], marker="o", color="C0", markerfacecolor="white"),
            Line2D([], [], marker="x", color="tab:red", linestyle=""),
        ],
        ["posterior median, 50 % and 95 % intervals", "reference charge"],
        fontsize=7,
        loc="lower left",
        bbox_to_anchor=(0.0, 1.0),
        ncols=2,
        frameon=False,
    )
    return figure


def plot_predictive(
    tree: xr.DataTree,
    outputs: Sequence[str] | None = None,
    *,
    calibration_end: float | None = None,
    uncalibrated: xr.Dataset | None = None,
    n_columns: int = 3,
    interval: float = 0.9,
) -> Figure:
    """Figs. 6 and 8: posterior predictive median and central band against the measured data.

    Draws the :func:`~pymc_vcc.inference.predictive.predictive_bands` of the tree written by
    :func:`~pymc_vcc.inference.predictive.simulate_predictive` (smooth with ``noise=False``,
    which the legend says) and its ``observed_data``, labelled "measured";
    ``uncalibrated`` adds the outputs of an uncalibrated model (Fig. 8). Panels are titled by
    the outputs' long names, in °C, bar and g/s; the calibration window's end is dashed.
    """
    bands = predictive_bands(tree, interval)
    reference = tree["observed_data"].to_dataset() if "observed_data" in tree.children else None
    names = list(outputs) if outputs is not None else list(bands.data_vars)
    figure, axes = _grid(len(names), n_columns, (4.0, 2.5))
    time = bands["time"].values
    percent = round(100 * float(bands.attrs.get("interval", 0.9)))
    noisy = bool(tree["posterior_predictive"].attrs.get("noise", 0))
    band_label = f"{percent} % band" + (" (with output noise)" if noisy else " (noise-free)")
    for ax, name in zip(axes, names, strict=False):
        units = bands[name].attrs.get("units", "")
        lower, median, upper = (
            display(bands[name].sel(band=band).values, units)[0]
            for band in ("lower", "median", "upper")
        )
        ax.fill_between(time, lower, upper, color="tab:blue", alpha=0.25, label=band_label)
        ax.plot(time, median, color="tab:blue", label="predictive median")
        if reference is not None and name in reference:
            measured, _ = display(reference[name].values, units)
            ax.plot(
                reference["time"].values,
                measured,
                color="black",
                linewidth=0.6,
                label="measured",
            )
        if uncalibrated is not None and name in uncalibrated:
            values, _ = display(uncalibrated[name].values, units)
            ax.plot(uncalibrated["time"].values, values, color="tab:red", label="uncalibrated")
        if calibration_end is not None:
            ax.axvline(
                calibration_end,
                color="grey",
                linestyle="--",
                linewidth=1,
                label="end of calibration data",
            )
        ax.set_title(bands[name].attrs.get("long_name", name), fontsize=9)
        ax.set_ylabel(f"{name} ({display(np.zeros(1), units)[1]})")
        ax.set_xlabel("time (s)")
    handles, labels = axes[0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="lower center", ncols=len(labels), fontsize=8)
    figure.tight_layout(rect=(0.0, 0.35 / figure.get_size_inches()[1], 1.0, 1.0))  # 0.35 in
    return figure


def plot_fault_intensities(scaled: Mapping[str, np.ndarray], title: str = "") -> Figure:
    """ArviZ's ``plot_forest`` of fault intensities, each in units of its detection threshold
    (1: the threshold; 0: as at commissioning): median with 50 % and 95 % intervals.

    Args:
        scaled: row label -> posterior draws of a fault's intensity / its threshold.
        title: drawn above the forest (e.g. the verdict).
    """
    import arviz_plots as azp

    posterior = xr.Dataset(
        {"intensity": (("fault", "chain", "draw"), np.stack(list(scaled.values()))[:, None, :])},
        coords={"fault": list(scaled)},
    )
    collection = azp.plot_forest(
        xr.DataTree.from_dict({"posterior": posterior}),
        combined=True,
        labels=["fault"],
        ci_probs=[0.5, 0.95],
        point_estimate="median",
        figure_kwargs={"figsize": (9.0, 1.0 + 0.6 * len(scaled))},
    )
    figure = collection.viz["figure"].item()
    forest = figure.axes[-1]
    forest.axvline(1.0, color="tab:red", linestyle="--", linewidth=1)
    forest.axvline(0.0, color="grey", linewidth=0.8)
    forest.set_xlabel("intensity / detection threshold (dashed: the threshold)")
    forest.set_title(title, fontsize=9)
    return figure
