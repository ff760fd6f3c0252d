"""The paper's figures render from results and are written as PNG and SVG."""

import numpy as np
import pytest
import xarray as xr

from pymc_vcc.plots import (
    display,
    plot_inputs,
    plot_prior_posterior,
    plot_sobol_heatmap,
    save_figure,
)


def _tree(rng):
    def group(scale):
        return xr.Dataset(
            {
                "M0": (("chain", "draw"), rng.normal(1.5, scale, (1, 300))),
                "cf_lev": (("chain", "draw"), rng.normal(1.0, scale, (1, 300))),
            }
        )

    return xr.DataTree.from_dict({"prior": group(0.3), "posterior": group(0.05)})


def test_display_units():
    values, units = display(np.array([273.15, 300.15]), "K")
    np.testing.assert_allclose(values, [0.0, 27.0])
    assert units == "°C"
    assert display(np.array([2e5]), "Pa")[0][0] == pytest.approx(2.0)
    assert display(np.array([0.02]), "kg/s") == (pytest.approx(20.0), "g/s")


def test_figures_are_written(tmp_path):
    rng = np.random.default_rng(0)
    figure = plot_prior_posterior(_tree(rng), truth={"M0": 1.5})
    paths = save_figure(figure, tmp_path / "kde")
    assert [p.suffix for p in paths] == [".png", ".svg"]
    assert all(p.stat().st_size > 1000 for p in paths)

    inputs = xr.Dataset(
        {"T_ambient": ("time", [308.15, 303.15], {"units": "K"})}, coords={"time": [0.0, 100.0]}
    )
    save_figure(plot_inputs(inputs, calibration_end=50.0), tmp_path / "inputs")

    indices = xr.Dataset(
        {"S1": (("parameter", "output"), rng.random((3, 2)))},
        coords={"parameter": ["a", "b", "c"], "output": ["TD", "PD"]},
    )
    save_figure(plot_sobol_heatmap(indices, "S1"), tmp_path / "sobol")
    assert (tmp_path / "sobol.png").exists()


def test_unknown_parameter_is_a_clear_error():
    with pytest.raises(ValueError, match="not in the posterior"):
        plot_prior_posterior(_tree(np.random.default_rng(1)), ["nope"])


def test_sobol_heatmap_shows_intervals_and_never_clips_silently(tmp_path):
    rng = np.random.default_rng(2)
    s1 = rng.uniform(0.0, 1.0, (4, 3))
    s1[0, 0], s1[1, 2] = -2.3, 4.3  # what a smoke budget gives
    indices = xr.Dataset(
        {
            "S1": (("parameter", "output"), s1),
            "S1_conf": (("parameter", "output"), np.full((4, 3), 1.5)),
        },
        coords={"parameter": ["a", "b", "c", "d"], "output": ["TD", "PD", "MDOT"]},
    )
    figure = plot_sobol_heatmap(indices, "S1")
    (image,) = figure.axes[0].images
    np.testing.assert_array_equal(image.get_array(), s1)  # not clipped
    notes = " ".join(text.get_text() for text in figure.texts)
    assert "2 indices outside [0, 1] (from -2.30 to 4.30)" in notes
    wide = int((np.abs(s1) < 1.5).sum())
    assert wide > 6
    assert f"hatched: 95 % interval wider than the index ({wide} of 12)" in notes
    assert "budget too small to trust" in notes
    cells = [text.get_text() for text in figure.axes[0].texts]
    assert "-2.30\n±1.50" in cells
    assert figure.axes[1].get_label() == "<colorbar>"
    save_figure(figure, tmp_path / "sobol_smoke")


def _uniform_tree(rng):
    return xr.DataTree.from_dict(
        {
            "prior": xr.Dataset({"M0": (("chain", "draw"), rng.uniform(0.9, 2.2, (1, 300)))}),
            "posterior": xr.Dataset({"M0": (("chain", "draw"), rng.normal(1.5, 0.05, (1, 300)))}),
        }
    )


def test_a_uniform_prior_is_drawn_flat_by_arviz():
    from pymc_vcc.physics.unit import load_unit
    from pymc_vcc.plots import labeller

    tree = _uniform_tree(np.random.default_rng(3))
    names = labeller(tree, [load_unit().parameters["M0"]])
    figure = plot_prior_posterior(tree, uniform={"M0": (0.9, 2.2)}, truth={"M0": 1.5}, labels=names)
    (ax,) = figure.axes
    prior, posterior = (line for line in ax.lines if line.get_label() in ("prior", "posterior"))
    x, y = prior.get_xdata(), prior.get_ydata()
    assert (x.min(), x.max()) == (0.9, 2.2)
    inside = (x > 0.9) & (x < 2.2)
    np.testing.assert_allclose(y[inside], 1.0 / 1.3, rtol=0.01)  # flat within 1 %
    assert y[0] == y[-1] == 0.0  # and falls to 0 at the bounds, not before
    assert posterior.get_ydata().max() > 5 * y.max()
    assert ax.get_title() == "Total refrigerant mass\n(kg)"
    legend = [text.get_text() for text in ax.get_legend().get_texts()]
    assert legend == ["prior", "posterior", "true value"]
    assert any(np.allclose(line.get_xdata(), 1.5) for line in ax.lines)


def test_a_kde_of_uniform_draws_would_not_be_flat():
    figure = plot_prior_posterior(_uniform_tree(np.random.default_rng(3)))
    prior = next(line for line in figure.axes[0].lines if line.get_label() == "prior")
    y = prior.get_ydata()
    assert np.ptp(y) / np.max(y) > 0.1  # what the exact density replaces


def test_charge_posteriors_are_a_forest_with_one_row_per_dataset():
    from pymc_vcc.plots import plot_charge_posteriors

    rng = np.random.default_rng(4)
    references = [1.5, 1.35, 1.2]
    trees = [
        xr.DataTree.from_dict(
            {"posterior": xr.Dataset({"M0": (("chain", "draw"), rng.normal(r, 0.05, (1, n)))})}
        )
        for r, n in zip(references, [200, 150, 180], strict=True)
    ]
    figure = plot_charge_posteriors(trees, references)
    labels, forest = figure.axes
    rows = [text.get_text() for text in labels.texts]
    assert rows == ["dataset 1: 1.5 kg", "dataset 2: 1.35 kg", "dataset 3: 1.2 kg"]
    assert forest.get_xlabel() == "total refrigerant mass M0 (kg)"
    marks = [line for line in forest.lines if line.get_marker() == "x"]
    assert sorted(float(line.get_xdata()[0]) for line in marks) == sorted(references)
    legend = [text.get_text() for text in forest.get_legend().get_texts()]
    assert legend[1] == "reference charge"
    with pytest.raises(ValueError, match="one reference per tree"):
        plot_charge_posteriors(trees, references[:2])


def test_predictive_figure_says_measured_and_units():
    from pymc_vcc.plots import plot_predictive

    rng = np.random.default_rng(5)
    time = np.arange(4.0)
    attrs = {"units": "Pa", "long_name": "Compressor discharge pressure"}
    predictive = xr.Dataset(
        {"PD": (("chain", "draw", "time"), 27e5 + 1e4 * rng.standard_normal((1, 50, 4)), attrs)},
        coords={"time": time},
        attrs={"noise": 0},
    )
    observed = xr.Dataset({"PD": ("time", np.full(4, 27e5), attrs)}, coords={"time": time})
    tree = xr.DataTree.from_dict({"posterior_predictive": predictive, "observed_data": observed})
    figure = plot_predictive(tree, calibration_end=2.0)
    ax = figure.axes[0]
    assert ax.get_title() == "Compressor discharge pressure"
    assert ax.get_ylabel() == "PD (bar)"
    (legend,) = figure.legends
    legend = [text.get_text() for text in legend.get_texts()]
    assert legend == [
        "90 % band (noise-free)",
        "predictive median",
        "measured",
        "end of calibration data",
    ]
    assert "truth" not in " ".join(legend)


def test_arviz_labels_and_display_units():
    from pymc_vcc.physics.unit import load_unit
    from pymc_vcc.plots import in_display_units, labeller

    observed = xr.Dataset(
        {"PD": ("time", [27e5, 28e5], {"units": "Pa", "long_name": "Discharge pressure"})}
    )
    tree = xr.DataTree.from_dict({"observed_data": observed})
    shown = in_display_units(tree)
    np.testing.assert_allclose(shown["observed_data"]["PD"].values, [27.0, 28.0])
    assert shown["observed_data"]["PD"].attrs["units"] == "bar"
    names = labeller(shown, [load_unit().parameters["M0"]])
    assert names.var_name_to_str("PD") == "Discharge pressure\n(bar)"
    assert names.var_name_to_str("M0") == "Total refrigerant mass\n(kg)"


def test_a_posterior_whose_draws_all_coincide_is_drawn_as_a_spike():
    tree = _tree(np.random.default_rng(4))
    tree["posterior"] = xr.DataTree(
        tree["posterior"].to_dataset().assign(M0=(("chain", "draw"), np.full((1, 300), 1.42)))
    )
    figure = plot_prior_posterior(tree, ["M0", "cf_lev"])
    spike = next(line for line in figure.axes[0].lines if line.get_label() == "posterior")
    x, y = spike.get_xdata(), spike.get_ydata()
    assert x[np.argmax(y)] == pytest.approx(1.42) and np.ptp(x) < 1e-5
    assert np.trapezoid(y, x) == pytest.approx(1.0, rel=0.01)
