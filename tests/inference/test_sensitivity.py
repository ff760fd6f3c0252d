"""Sobol indices against the Ishigami function's exact values, with and without failures."""

import sqlite3
from dataclasses import replace

import numpy as np
import pytest
import xarray as xr

from pymc_vcc.execution.options import RunOptions
from pymc_vcc.inference.sensitivity import WindowMean, sobol_indices

A, B = 7.0, 0.1
BOUNDS = {name: (-np.pi, np.pi) for name in ("x1", "x2", "x3")}
# Exact indices of the Ishigami function with a = 7, b = 0.1 (Sobol' & Levitan 1999).
_VAR = A**2 / 8 + B * np.pi**4 / 5 + B**2 * np.pi**8 / 18 + 0.5
_V1 = 0.5 * (1 + B * np.pi**4 / 5) ** 2
_V2 = A**2 / 8
_V13 = B**2 * np.pi**8 * (1 / 18 - 1 / 50)
EXACT_S1 = np.array([_V1, _V2, 0.0]) / _VAR
EXACT_ST = np.array([_V1 + _V13, _V2, _V13]) / _VAR


def ishigami(theta, rng):
    """Two outputs over 'time': the Ishigami function (constant) and a linear one with noise."""
    y = (
        np.sin(theta["x1"])
        + A * np.sin(theta["x2"]) ** 2
        + B * theta["x3"] ** 4 * np.sin(theta["x1"])
    )
    linear = 2.0 * theta["x3"] + 0.0 * theta["x1"]
    time = np.arange(5.0)
    return xr.Dataset(
        {"ishigami": ("time", np.full(5, y)), "linear": ("time", np.full(5, linear))},
        coords={"time": time},
    )


def sometimes_failing_ishigami(theta, rng):
    """Fails in 3 % of runs, independently of the parameters."""
    if rng.random() < 0.03:
        return xr.Dataset(attrs={"status": "failed", "failure_reason": "solver gave up"})
    return ishigami(theta, rng)


def test_ishigami_indices_match_exact_values():
    result = sobol_indices(
        ishigami,
        BOUNDS,
        ["ishigami", "linear"],
        n_base=1024,
        window=None,
        run=RunOptions(executor="serial", seed=0),
    )
    s1 = result["S1"].sel(output="ishigami").values
    st = result["ST"].sel(output="ishigami").values
    np.testing.assert_allclose(s1, EXACT_S1, atol=0.05)
    np.testing.assert_allclose(st, EXACT_ST, atol=0.05)
    # The linear output depends on x3 alone.
    np.testing.assert_allclose(result["ST"].sel(output="linear").values, [0, 0, 1], atol=0.02)
    assert result.attrs["n_simulations"] == 1024 * 5
    assert result.attrs["n_failed"] == 0


def test_failed_runs_drop_whole_blocks_and_keep_estimates():
    result = sobol_indices(
        sometimes_failing_ishigami,
        BOUNDS,
        ["ishigami"],
        n_base=1024,
        window=None,
        run=RunOptions(executor="serial", seed=3),
    )
    n_failed = result.attrs["n_failed"]
    assert 0.01 * 5120 < n_failed < 0.05 * 5120
    assert n_failed >= result.attrs["n_dropped_base_samples"] > 0
    assert "solver gave up" in result.attrs["failure_reasons"]
    np.testing.assert_allclose(result["ST"].sel(output="ishigami").values, EXACT_ST, atol=0.06)


def test_window_mean_averages_inside_the_window():
    def ramp(theta, rng):
        time = np.arange(0.0, 11.0)
        return xr.Dataset({"y": ("time", time * theta["k"])}, coords={"time": time})

    reduced = WindowMean(ramp, ("y",), (2.0, 4.0))
    assert reduced({"k": 2.0}, np.random.default_rng(0))[0, 0] == pytest.approx(6.0)


def test_bad_arguments_are_clear_errors():
    with pytest.raises(ValueError, match="low"):
        sobol_indices(ishigami, {"x1": (1.0, 0.0)}, ["ishigami"], run=RunOptions(executor="serial"))
    with pytest.raises(ValueError, match="outputs is empty"):
        sobol_indices(ishigami, BOUNDS, [], run=RunOptions(executor="serial"))
    with pytest.raises(ValueError, match="window"):
        sobol_indices(
            ishigami, BOUNDS, ["ishigami"], window=(5.0, 1.0), run=RunOptions(executor="serial")
        )


class CountingIshigami:
    """The Ishigami model counting its runs; raises KeyboardInterrupt (Ctrl-C) at run ``stop``."""

    def __init__(self, stop=None):
        self.stop, self.runs = stop, 0

    def __call__(self, theta, rng):
        self.runs += 1
        if self.runs == self.stop:
            raise KeyboardInterrupt
        return sometimes_failing_ishigami(theta, rng)


def test_an_interrupted_sobol_run_resumes_without_rerunning_and_gives_the_same_indices(tmp_path):
    arguments = dict(n_base=64, window=None)
    serial = RunOptions(executor="serial", seed=3)
    reference = sobol_indices(CountingIshigami(), BOUNDS, ["ishigami"], run=serial, **arguments)
    checkpoint = tmp_path / "sobol.sqlite"
    with pytest.raises(KeyboardInterrupt):
        sobol_indices(
            CountingIshigami(stop=200),
            BOUNDS,
            ["ishigami"],
            run=replace(serial, checkpoint=checkpoint),
            **arguments,
        )
    connection = sqlite3.connect(checkpoint)
    (persisted,) = connection.execute("SELECT COUNT(*) FROM results").fetchone()
    connection.close()
    assert 0 < persisted < 200
    resumed_model = CountingIshigami()
    resumed = sobol_indices(
        resumed_model, BOUNDS, ["ishigami"], run=replace(serial, checkpoint=checkpoint), **arguments
    )
    assert resumed_model.runs == 64 * 5 - persisted  # none of the persisted runs ran again
    xr.testing.assert_identical(resumed, reference)
