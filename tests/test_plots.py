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


def test_a_uniform_prior_is_drawn_flat():
    rng = np.random.default_rng(3)
    tree = xr.DataTree.from_dict(
        {
            "prior": xr.Dataset({"M0": (("chain", "draw"), rng.uniform(0.9, 2.2, (1, 300)))}),
            "posterior": xr.Dataset({"M0": (("chain", "draw"), rng.normal(1.5, 0.05, (1, 300)))}),
        }
    )
    figure = plot_prior_posterior(tree, uniform={"M0": (0.9, 2.2)})
    prior_line = next(line for line in figure.axes[0].lines if line.get_label() == "prior")
    np.testing.assert_allclose(prior_line.get_xdata(), [0.9, 0.9, 2.2, 2.2])
    np.testing.assert_allclose(prior_line.get_ydata()[1:3], 1.0 / 1.3)


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
