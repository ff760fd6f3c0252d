"""A VCCSimulator that calibrates a subset of the parameters, the others nominal or fixed."""

import numpy as np
import pytest

from pymc_vcc.inference.pymc.model import simulator_bounds
from pymc_vcc.physics.simulate import VCCSimulator


def test_subset_simulator_names_only_its_parameters_and_bounds():
    model = VCCSimulator(t_window=(0.0, 60.0), parameters=["M0", "CF_LEV"], fixed={"CF_VOL": 1.1})
    assert model.parameter_names == ("M0", "CF_LEV")
    assert simulator_bounds(model) == {"M0": (0.9, 2.2), "CF_LEV": (0.3, 1.5)}


def test_fixed_values_reach_the_simulation():
    nominal = VCCSimulator(t_window=(0.0, 60.0), parameters=["M0"])
    lossier = VCCSimulator(t_window=(0.0, 60.0), parameters=["M0"], fixed={"CF_VOL": 1.3})
    rng = np.random.default_rng(0)
    flow = nominal({"M0": 1.3}, rng)["MDOT"].values[-1]
    # CF_VOL scales the volumetric losses (models/README.md): more losses, less flow
    assert lossier({"M0": 1.3}, rng)["MDOT"].values[-1] < flow


def test_unknown_or_out_of_bounds_ids_are_clear_errors():
    with pytest.raises(ValueError, match="unknown parameters id"):
        VCCSimulator(parameters=["M1"])
    with pytest.raises(ValueError, match="unknown fixed id"):
        VCCSimulator(fixed={"nope": 1.0})
    with pytest.raises(ValueError, match="outside its bounds"):
        VCCSimulator(fixed={"M0": 5.0})
