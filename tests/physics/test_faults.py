"""The split unit's faults: a liquid-line restriction, non-condensable gas in the condenser and
leaking compressor valves.

The directions a service engineer knows, on the running cycle at the built-in unit's rating
point, each fault at its upper bound; the laws of the Table III box with each fault there; the
kernel's mass balance with both. The figures are in models/README.md ("Faults").
"""

import numpy as np
import pytest

from pymc_vcc.physics.cycles import CYCLE_MODELS
from pymc_vcc.physics.cycles.split_unit import FAULTS
from pymc_vcc.physics.probes import check_draw
from pymc_vcc.physics.refrigerant import load_refrigerant
from pymc_vcc.physics.simulate import VCCSimulator, operating_point
from pymc_vcc.physics.unit import HEAT_PUMP_UNIT, load_unit

RESTRICTION = FAULTS["DP_RESTR"].high
NCG = FAULTS["P_NCG"].high
LEAK = FAULTS["F_LEAK"].high


@pytest.fixture(scope="module")
def unit():
    return load_unit()


def _point(unit, theta=None, **conditions):
    point = operating_point(unit, theta, solver="cvode", **conditions)
    assert point["status"] == "ok" and point["drift"] < 1e-4, point
    return point


@pytest.fixture(scope="module")
def nominal(unit):
    return _point(unit)


def test_a_liquid_line_restriction_starves_the_evaporator(unit, nominal):
    """Less flow, more superheat, a lower evaporating pressure and less capacity (measured:
    -7 % flow, superheat 7.2 -> 14.8 K, PE -28 kPa, capacity -2.6 %); the charge the starved
    evaporator gives up leaves the subcooling where it was."""
    restricted = _point(unit, {"DP_RESTR": RESTRICTION})
    assert -0.12 < restricted["MDOT"] / nominal["MDOT"] - 1 < -0.03
    assert 4.0 < restricted["superheat"] - nominal["superheat"] < 12.0
    assert restricted["TS"] - nominal["TS"] > 4.0  # suction up, evaporating temperature down
    assert -60e3 < restricted["PE"] - nominal["PE"] < -10e3
    assert -0.06 < restricted["capacity"] / nominal["capacity"] - 1 < -0.01
    assert restricted["TD"] > nominal["TD"] + 3.0
    assert abs(restricted["subcooling"] - nominal["subcooling"]) < 1.0


def test_non_condensable_gas_raises_the_high_side_by_its_partial_pressure(unit, nominal):
    """PD and PC up by about the partial pressure, the compressor's power with them; at the
    same valve opening the higher pressure difference overfeeds the evaporator (superheat
    down), and at the same superheat (the valve closed as a superheat controller would) the
    discharge is hotter (measured: PC +195 kPa, W_comp +5.7 %; TD +4 K at the same
    superheat)."""
    gas = _point(unit, {"P_NCG": NCG})
    for pressure in ("PD", "PC"):
        assert 0.9 * NCG < gas[pressure] - nominal[pressure] < 1.2 * NCG, pressure
    assert 0.03 < gas["W_comp"] / nominal["W_comp"] - 1 < 0.12
    assert gas["superheat"] < nominal["superheat"] - 3.0
    # the apparent subcooling (from the gauge's PC) grows: the gas raises the reading alone
    assert gas["subcooling"] > nominal["subcooling"] + 1.5
    # the valve closed around the nominal superheat: the discharge temperature there
    wide, narrow = (_point(unit, {"P_NCG": NCG}, valve_opening=v) for v in (0.38, 0.37))
    assert wide["superheat"] < nominal["superheat"] < narrow["superheat"]
    share = (nominal["superheat"] - wide["superheat"]) / (narrow["superheat"] - wide["superheat"])
    td = wide["TD"] + share * (narrow["TD"] - wide["TD"])
    assert 2.0 < td - nominal["TD"] < 8.0


def test_leaking_compressor_valves_lift_the_suction_pressure_and_cut_the_capacity(unit, nominal):
    """Less refrigerant pumped: the suction pressure rises and the discharge pressure falls,
    the flow and the capacity fall, and at the same valve opening the evaporator is overfed
    (superheat down; measured at 20 % leakage: MDOT -5 %, capacity -11 %, PE +68 kPa, PD
    -3 %, superheat -7 K; at the bound, 50 %: MDOT -24 %, capacity -37 %)."""
    leaking = _point(unit, {"F_LEAK": 0.2})
    assert -0.10 < leaking["MDOT"] / nominal["MDOT"] - 1 < -0.02
    assert -0.16 < leaking["capacity"] / nominal["capacity"] - 1 < -0.06
    assert 30e3 < leaking["PE"] - nominal["PE"] < 120e3
    assert -0.06 < leaking["PD"] / nominal["PD"] - 1 < -0.01
    assert leaking["superheat"] < nominal["superheat"] - 3.0
    assert leaking["W_comp"] < nominal["W_comp"]  # less flow to compress at a lower ratio


@pytest.mark.parametrize("fault", list(FAULTS.ids))
def test_the_box_laws_hold_with_a_fault_at_its_upper_bound(unit, fault):
    """Three Table III box draws (those of the box probe's test, seed 7) with the fault at its
    upper bound: success, the compressor's first and second laws, air in range, PC still,
    the charge held, and the cycle's energy balance at the end."""
    draws = unit.parameters.sample_uniform(3, np.random.default_rng(7))
    for theta in draws:
        report = check_draw(unit, {**theta, fault: FAULTS[fault].high}, solver="cvode")
        assert report.holds, report
        assert abs(report.energy_balance) < 1e-3, report


@pytest.mark.parametrize("name", sorted(CYCLE_MODELS))
def test_mass_changes_only_by_the_controller_source_with_every_fault(name):
    """The faults change flows and pressures, never the mass balance: the rate of the total
    mass is the controller's source, every fault at its upper bound (both cycles)."""
    unit = load_unit(None if name == "split-cooling" else HEAT_PUMP_UNIT)
    model = unit.cycle_model
    tables = load_refrigerant(unit.refrigerant).tables
    c = model.constants(unit, unit.parameters.nominal, faults=unit.faults.highs)
    assert c[0]["faults"]["noncondensable_pressure"] == NCG
    assert c[0]["faults"]["restriction"] > 0.0
    assert c[0]["compressor"]["valve_leakage"] == LEAK
    u = np.array([unit.rating.get(i, model.inputs.defaults.get(i)) for i in model.inputs.ids])
    y = model.initial_state(c, unit.discretisation.n_volumes, u, tables)
    c[0]["controller"]["m0"] *= 1.01  # a mass error, so the source is non-zero
    y[-1] = 0.3  # and an integral term
    dydt, out = np.empty(y.size), np.empty(model.n_eval)
    assert model.evaluate(y, u, c, tables, dydt, out)
    at = model.outputs.offsets
    assert out[at.PC] == y[model.layout(unit.discretisation.n_volumes).start("p_cond")] + NCG
    eps = 1e-3
    rate = (
        model.total_mass(y + eps * dydt, c, tables) - model.total_mass(y - eps * dydt, c, tables)
    ) / (2 * eps)
    assert abs(out[at.mdot_src]) > 1e-5
    assert rate == pytest.approx(out[at.mdot_src], abs=1e-6 * out[at.MDOT])


def test_a_simulator_calibrates_a_fault_with_the_charge(unit):
    simulator = VCCSimulator(unit, parameters=["M0", "P_NCG"], fixed={"DP_RESTR": 1e5})
    assert simulator.parameter_bounds == {"M0": (0.9, 2.2), "P_NCG": (0.0, NCG)}
    assert simulator.bounds["P_NCG"] == (0.0, NCG) and "DP_RESTR" not in simulator.bounds
    assert len(VCCSimulator(unit).bounds) == len(unit.parameters)  # faults only when named
    with pytest.raises(ValueError, match="outside its bounds"):
        VCCSimulator(unit, fixed={"P_NCG": -1.0})
