"""The split unit as a heat pump in heating mode: conservation, plausibility, directions, and a
charge calibration with the same samplers as the cooling unit."""

import numpy as np
import pytest

from pymc_vcc.execution.options import RunOptions
from pymc_vcc.inference.priors import UniformPrior
from pymc_vcc.inference.rejection import abc_rejection
from pymc_vcc.physics.inputs import WINTER_PROFILE, builtin_inputs, window
from pymc_vcc.physics.refrigerant import load_refrigerant, saturation_state
from pymc_vcc.physics.simulate import VCCSimulator, operating_point, simulate
from pymc_vcc.physics.unit import HEAT_PUMP_UNIT, load_unit


@pytest.fixture(scope="module")
def unit():
    return load_unit(HEAT_PUMP_UNIT)


@pytest.fixture(scope="module")
def points(unit):
    """Steady heating at the rating point (8 °C outdoor) and at -7 °C, same speed and valve."""
    return {T: operating_point(unit, T_ambient=T + 273.15) for T in (8.0, -7.0)}


def test_the_unit_names_its_cycle_and_the_indoor_coil_condenses(unit):
    assert unit.cycle == "heat-pump-heating" and unit.cycle_model.capacity == "Q_cond"
    cooling = load_unit()
    assert unit.hardware.condenser == cooling.hardware.evaporator
    assert unit.hardware.evaporator == cooling.hardware.condenser


def test_mass_is_held_over_the_winter_day(unit):
    run = simulate(unit, inputs=builtin_inputs(WINTER_PROFILE), diagnostics=True)
    assert run.attrs["status"] == "ok", run.attrs["failure_reason"]
    assert run.attrs["mass_error"] < 1e-4
    assert run.attrs["source_integral"] < 1e-3  # kg moved by the controller in 2400 s
    T_out = builtin_inputs(WINTER_PROFILE)["T_ambient"].values - 273.15
    assert T_out.min() == -7.0 and T_out.max() == 8.0


def test_energy_balance_closes_at_steady_state(points):
    for point in points.values():
        assert point["status"] == "ok", point["failure_reason"]
        assert point["drift"] < 1e-3
        assert abs(point["energy_balance_error"]) < 1e-3


def test_capacity_and_cop_are_plausible_for_the_class(points):
    rated, cold = points[8.0], points[-7.0]
    assert 3500.0 <= rated["capacity"] <= 4500.0
    assert 2.5 <= rated["COP"] <= 4.0
    assert rated["capacity"] == pytest.approx(rated["Q_cond"])
    assert 2.0 < rated["superheat"] < 15.0 and rated["subcooling"] > 0.0
    assert cold["capacity"] < 0.8 * rated["capacity"] and cold["COP"] < rated["COP"]


def test_colder_outdoors_lowers_evaporating_pressure_and_capacity(unit, points):
    tables = load_refrigerant(unit.refrigerant).tables
    rated, cold = points[8.0], points[-7.0]
    assert cold["PE"] < rated["PE"] and cold["capacity"] < rated["capacity"]
    for T, point in points.items():  # the outdoor coil evaporates below the outdoor air
        assert saturation_state(tables, point["PE"])[0] < T + 273.15
    # the indoor coil condenses above the indoor air
    assert saturation_state(tables, rated["PC"])[0] > unit.rating["T_indoor"] + 10.0


def test_faster_compressor_heats_more(unit, points):
    fast = operating_point(unit, compressor_speed=80.0)
    assert fast["capacity"] > points[8.0]["capacity"] and fast["MDOT"] > points[8.0]["MDOT"]
    assert fast["PE"] < points[8.0]["PE"] and fast["PC"] > points[8.0]["PC"]


@pytest.mark.slow
def test_charge_calibrates_with_the_rejection_sampler(unit):
    inputs = window(builtin_inputs(WINTER_PROFILE), 400.0)
    simulator = VCCSimulator(unit, inputs, t_window=(20.0, 400.0), parameters=["M0"])
    observed = simulator({"M0": 1.1}, None)
    prior = UniformPrior({"M0": (unit.parameters["M0"].low, unit.parameters["M0"].high)})
    tree = abc_rejection(
        simulator,
        prior,
        observed,
        n_pilot=24,
        quantile=0.2,
        n_main=24,
        n_desired=24,
        run=RunOptions(executor="serial", seed=3, progress=False),
    )
    charge = tree.posterior["M0"].values.ravel()
    assert charge.size >= 3
    assert abs(np.mean(charge) - 1.1) < 0.1
    assert np.std(charge) < 0.5 * (2.2 - 0.9) / np.sqrt(12)
