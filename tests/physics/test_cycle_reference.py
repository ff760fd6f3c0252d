"""Regression: the built-in cooling unit gives the stored reference outputs.

The reference (``tests/physics/data/cycle_reference.npz``) holds the nine outputs and the
diagnostics on the Fig. 4 profile at nominal parameters and at 20 fixed Table III box draws,
written by ``tests/physics/data/make_cycle_reference.py``; a deliberate physics change
regenerates the file with that script.

Compiled code and linear algebra differ between CPUs (Numba compiles for the host, OpenBLAS
picks its kernels by CPU), so a run is reproducible bit for bit on one machine only. Across
machines the runs agree far inside the solver's error (4e-7 relative, TD by 1.4e-4 K, between
two machines: under 1 % of the tolerance below), so each variable is compared at the solver's
own tolerance, ``rtol × its scale + the state's atol`` (Pa and K variables take the default
solver's pressure and temperature atols). Near-zero diagnostics take the scale of what they act
on: the charge controller's source that of the compressor flow, the latent heat that of the
coil's heat, a fraction that of 1; the coil heats carry the temperatures' error magnified
(:data:`WALL_TO_REFRIGERANT`). A 0.1 % change of one parameter fails it
(:func:`test_a_small_physical_change_fails`).
"""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from pymc_vcc.physics.integration.solver import get_solver
from pymc_vcc.physics.unit import load_unit

DATA = Path(__file__).with_name("data")
_spec = importlib.util.spec_from_file_location(
    "make_cycle_reference", DATA / "make_cycle_reference.py"
)
reference = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(reference)

STORED = np.load(reference.REFERENCE)
CASES = reference.reference_parameters()
NAMES = [str(name) for name in STORED["names"]]

SCALE_OF = {"mdot_src": "MDOT", "Q_latent": "Q_evap"}
"""Near-zero diagnostics, and the variable whose size sets their scale."""

COIL_HEATS = ("Q_cond", "Q_evap", "Q_latent")
WALL_TO_REFRIGERANT = 30.0
"""A coil's heat is a conductance times a wall-to-refrigerant difference of ~10 K, so it
carries the temperatures' relative error magnified ~300 K / 10 K: its relative tolerance is
this multiple of rtol (a wall 1e-5 K apart moved Q_evap by 0.15 W, 0.4 rtol, with OpenBLAS on
another core type)."""


def tolerances(run, case: int) -> dict[str, float]:
    """Absolute tolerance of each variable of one reference case (the default solver's)."""
    solver = get_solver()
    state_atol = {"Pa": solver.atol_pressure, "K": solver.atol_temperature}
    units = {name: run[name].attrs["units"] for name in NAMES}
    values = dict(zip(NAMES, STORED["values"][case], strict=True))
    tol = {}
    for name in NAMES:
        scale = np.nanmax(np.abs(values[SCALE_OF.get(name, name)]), initial=0.0)
        if units[name] == "1":
            scale = max(scale, 1.0)
        rtol = solver.rtol * (WALL_TO_REFRIGERANT if name in COIL_HEATS else 1.0)
        tol[name] = rtol * scale + state_atol.get(units[name], 0.0)
    return tol


def mismatches(run, case: int) -> dict[str, float]:
    """Variables outside their tolerance, with their largest difference in tolerances."""
    found = {}
    for k, (name, tol) in enumerate(tolerances(run, case).items()):
        expected = STORED["values"][case, k]
        actual = run[name].values
        if not np.array_equal(np.isnan(actual), np.isnan(expected)):
            found[name] = np.inf
            continue
        worst = np.nanmax(np.abs(actual - expected), initial=0.0) / tol
        if worst > 1.0:
            found[name] = float(worst)
    return found


@pytest.mark.slow
@pytest.mark.parametrize(
    "case", range(len(CASES)), ids=["nominal", *map(str, range(1, len(CASES)))]
)
def test_outputs_match_the_stored_reference(case):
    run = reference.simulate_reference(CASES[case])
    assert run.attrs["status"] == STORED["status"][case]
    np.testing.assert_array_equal(run["time"].values, STORED["time"])
    assert mismatches(run, case) == {}


def test_a_small_physical_change_fails():
    """The tolerance still catches physics: the valve's flow coefficient 0.1 % above nominal
    moves every pressure, the superheats and the flow by 4-50 tolerances."""
    valve = load_unit().parameters["CF_LEV"].nominal
    run = reference.simulate_reference({"CF_LEV": 1.001 * valve})
    assert {"TD", "PD", "TS", "PS", "PC", "PE", "MDOT"} <= set(mismatches(run, case=0))
