"""The simulator contract: checked once, with clear errors."""

import numpy as np
import pytest

from pymc_vcc.inference.simulator import Simulator, check_simulator
from pymc_vcc.physics.simulate import VCCSimulator
from pymc_vcc.testing import GaussianLocation


def _plain(theta, rng):
    return np.zeros((1, 3))


def test_a_plain_function_keeps_the_contract_and_says_nothing_more():
    assert isinstance(_plain, Simulator)
    info = check_simulator(_plain)
    assert info.parameter_names is None and info.output_names is None and info.bounds is None


def test_described_simulators_are_read_once():
    info = check_simulator(GaussianLocation(n_time=10, sigma=1.0, low=-1.0, high=1.0))
    assert info.parameter_names == ("mu",) and info.output_names == ("y",)
    assert info.bounds == {"mu": (-1.0, 1.0)}
    physical = check_simulator(VCCSimulator(parameters=["M0"], outputs=["PC", "PE"]))
    assert physical.parameter_names == ("M0",) and physical.output_names == ("PC", "PE")
    assert physical.bounds["M0"] == (0.9, 2.2) and len(physical.bounds) == 26


def test_breaking_the_contract_is_a_clear_error():
    with pytest.raises(TypeError, match="must be callable as simulator"):
        check_simulator(42)

    class Named:
        output_names = "PC"

        def __call__(self, theta, rng):
            return np.zeros((1, 3))

    with pytest.raises(TypeError, match=r"Named.output_names must be a sequence of names"):
        check_simulator(Named())
