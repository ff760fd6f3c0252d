"""Regression: the built-in cooling unit gives the stored reference outputs.

The reference (``tests/data/cycle_reference.npz``) holds the nine outputs and the diagnostics on
the Fig. 4 profile at nominal parameters and at 20 fixed Table III box draws, written by
``tests/data/make_cycle_reference.py``. Refactoring must not move them (max relative difference
1e-9 of each
variable's largest magnitude); a deliberate physics change regenerates the file with that script.
"""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).with_name("data")
_spec = importlib.util.spec_from_file_location(
    "make_cycle_reference", DATA / "make_cycle_reference.py"
)
reference = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(reference)

STORED = np.load(reference.REFERENCE)
CASES = reference.reference_parameters()


@pytest.mark.slow
@pytest.mark.parametrize(
    "case", range(len(CASES)), ids=["nominal", *map(str, range(1, len(CASES)))]
)
def test_outputs_match_the_stored_reference(case):
    run = reference.simulate_reference(CASES[case])
    assert run.attrs["status"] == STORED["status"][case]
    np.testing.assert_array_equal(run["time"].values, STORED["time"])
    for k, name in enumerate(STORED["names"]):
        expected = STORED["values"][case, k]
        scale = np.nanmax(np.abs(expected), initial=0.0)  # relative to the variable's size
        np.testing.assert_allclose(
            run[str(name)].values,
            expected,
            rtol=0.0,
            atol=1e-9 * scale,
            equal_nan=True,
            err_msg=str(name),
        )
