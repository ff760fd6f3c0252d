"""Fixtures shared by the test modules."""

import logging
import warnings

import pytest


@pytest.fixture
def quiet_pymc(caplog):
    """PyMC's stage-by-stage log and PyTensor's object-mode notice, silenced."""
    caplog.set_level(logging.WARNING, logger="pymc")
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Numba will use object mode")
        yield
