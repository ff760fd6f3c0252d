"""Everything the package advertises can be imported from ``pymc_vcc``."""

import subprocess
import sys

import pytest

import pymc_vcc


@pytest.mark.parametrize("name", sorted(set(pymc_vcc.__all__) - {"__version__"}))
def test_every_exported_name_resolves(name):
    assert getattr(pymc_vcc, name) is not None


def test_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        pymc_vcc.nope  # noqa: B018


def test_simulating_does_not_import_pymc():
    code = (
        "import sys, pymc_vcc; pymc_vcc.VCCSimulator; "
        "assert 'pymc' not in sys.modules, 'importing the simulator pulled in PyMC'"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
