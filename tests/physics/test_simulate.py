"""End-to-end simulation: charge control, energy balance, engineering directions, rated point,
parameter influence, failure capture, the sampler-facing simulator and robustness, each with
both ODE solvers."""

import pickle

import numpy as np
import pytest

from pymc_vcc.physics.cycles import OUTPUT_IDS
from pymc_vcc.physics.cycles.split_unit import INERT_PARAMETERS
from pymc_vcc.physics.failures import FailureKind
from pymc_vcc.physics.inputs import builtin_inputs, constant_inputs
from pymc_vcc.physics.integration.solver import METHODS
from pymc_vcc.physics.simulate import VCCSimulator, operating_point, simulate
from pymc_vcc.physics.unit import load_unit

RATED_CAPACITY = 3500.0  # W


@pytest.fixture(scope="module")
def unit():
    return load_unit()


@pytest.fixture(scope="module", params=METHODS)
def solver(request):
    return request.param


@pytest.fixture(scope="module")
def rated(unit, solver):
    return operating_point(unit, solver=solver)


@pytest.fixture(scope="module")
def full_runs(unit, solver):
    # a generous wall-clock limit: on a busy machine Radau's 2120 s can take 20 s
    on = simulate(unit, diagnostics=True, solver=solver, max_wall_time=600.0)
    off = simulate(unit, diagnostics=True, controller=False, solver=solver, max_wall_time=600.0)
    return on, off


def test_full_profile_runs_with_units_and_diagnostics(full_runs, solver):
    run, _ = full_runs
    assert run.attrs["status"] == "ok", run.attrs["failure_reason"]
    assert run.attrs["solver"] == solver
    assert run.sizes["time"] == 2121 and float(run.time[1] - run.time[0]) == 1.0
    for name in OUTPUT_IDS:
        assert "units" in run[name].attrs
        assert np.isfinite(run[name].values).all()
    for key in ("n_rhs", "n_steps", "wall_time", "mass_error", "source_integral"):
        assert key in run.attrs
    # work budgets: a silent slowdown shows here (measured: Radau ~300 steps of order 5, CVODE
    # 2089 short steps of order <= 3, each with ~1.2 right-hand sides)
    assert 0 < run.attrs["n_rhs"] < 6000 and 0 < run.attrs["n_jac"] < 400
    assert 0 < run.attrs["n_steps"] < {"radau": 2000, "cvode": 4000}[solver]


def test_the_solver_states_come_back_named_with_units(unit):
    run = simulate(unit, t_end=30.0, solver="cvode", states=True)
    plain = simulate(unit, t_end=30.0, solver="cvode")
    layout = unit.cycle_model.layout(unit.discretisation.n_volumes)
    assert run["states"].dims == ("time", "state") and run.sizes["state"] == layout.size
    labels = list(run["state"].values)
    assert labels[layout.start("p_cond")] == "p_cond" and "h_cond[0]" in labels
    units = dict(zip(labels, run["state_units"].values, strict=True))
    assert units["p_cond"] == "Pa" and units["h_cond[0]"] == "J/kg" and units["Tw_cond[0]"] == "K"
    # the condenser pressure output is the state itself; the outputs are unchanged
    np.testing.assert_array_equal(run["PC"].values, run["states"].sel(state="p_cond").values)
    for name in plain.data_vars:
        np.testing.assert_array_equal(run[name].values, plain[name].values)


@pytest.mark.parametrize("unit_name", ["split_3p5kw_r410a.toml", "heat_pump_3p5kw_r410a.toml"])
def test_outputs_alone_equal_those_computed_with_the_diagnostics(unit_name):
    """Without diagnostics the outputs skip the walls' and zones' balances; they stay bit for
    bit those of a run with diagnostics, and the mass check still sees the whole charge."""
    unit = load_unit(unit_name)
    alone = simulate(unit, t_end=120.0, solver="cvode")
    full = simulate(unit, t_end=120.0, solver="cvode", diagnostics=True)
    assert set(alone.data_vars) == set(unit.cycle_model.output_ids)
    for name in alone.data_vars:
        np.testing.assert_array_equal(alone[name].values, full[name].values)
    assert alone.attrs["mass_error"] == full.attrs["mass_error"] < 1e-4
    assert np.isfinite(full["Q_cond"].values).all()


def test_pi_loop_holds_the_charge_and_switching_it_off_drifts(full_runs, unit):
    on, off = full_runs
    m0 = unit.parameters["M0"].nominal
    error_on = np.abs(on.M.values - m0) / m0
    error_off = np.abs(off.M.values - m0) / m0
    assert error_on.max() < 1e-4
    assert on.attrs["mass_error"] == pytest.approx(error_on.max())
    # without the loop, integration errors accumulate: at the end the error is several times
    # larger (measured at atol_enthalpy 5 J/kg: 4.2e-6 against 4.8e-7)
    assert error_off[-1] > 3 * error_on[-1]
    assert off.attrs["source_integral"] == 0.0 < on.attrs["source_integral"]


def test_rated_point_capacity_cop_and_plausible_state(rated):
    assert rated["status"] == "ok" and rated["drift"] < 1e-4
    assert rated["capacity"] == pytest.approx(RATED_CAPACITY, rel=0.15)
    assert 3.0 < rated["COP"] < 5.0
    assert 22e5 < rated["PC"] < 32e5 and 8e5 < rated["PE"] < 12.5e5
    assert rated["PS"] < rated["PE"] < rated["PC"] < rated["PD"]
    assert 330.0 < rated["TD"] < 370.0
    assert 2.0 < rated["superheat"] < 12.0 and 2.0 < rated["subcooling"] < 12.0


def test_steady_energy_balance(rated):
    assert abs(rated["energy_balance_error"]) < 0.01
    closure = rated["Q_cond"] - rated["Q_evap"] - rated["W_ref"]
    assert abs(closure) < 0.01 * rated["Q_cond"]


def test_higher_compressor_speed(unit, rated, solver):
    faster = operating_point(unit, compressor_speed=65.0, solver=solver)
    assert faster["MDOT"] > rated["MDOT"]
    assert faster["PD"] > rated["PD"]
    assert faster["PS"] < rated["PS"]


def test_higher_ambient_temperature(unit, rated, solver):
    hotter = operating_point(unit, T_ambient=311.15, solver=solver)
    assert hotter["PC"] > rated["PC"] and hotter["PD"] > rated["PD"]


def test_more_valve_opening(unit, rated, solver):
    opened = operating_point(unit, valve_opening=0.44, solver=solver)
    assert opened["superheat"] < rated["superheat"]
    assert opened["PE"] > rated["PE"]


def test_lower_charge(unit, rated, solver):
    smaller = operating_point(unit, {"M0": 1.1}, solver=solver)
    assert smaller["subcooling"] < rated["subcooling"]
    assert smaller["PC"] < rated["PC"]


def test_every_parameter_changes_an_output(unit, solver):
    inputs = builtin_inputs()
    t_end = 300.0

    def means(theta):
        run = simulate(unit, theta, inputs, t_end=t_end, output_interval=5.0, solver=solver)
        assert run.attrs["status"] == "ok", (theta, run.attrs["failure_reason"])
        return np.array([run[name].values[4:].mean() for name in OUTPUT_IDS])

    nominal = means({})
    for spec in unit.parameters:
        bound = spec.low if spec.nominal - spec.low > spec.high - spec.nominal else spec.high
        moved = means({spec.id: bound})
        change = np.max(np.abs(moved - nominal) / np.abs(nominal))
        if spec.id in INERT_PARAMETERS:
            assert change == 0.0, spec.id
        else:
            assert change > 1e-4, spec.id


def test_failures_are_flagged_not_raised(unit, solver):
    inputs = constant_inputs(
        600.0, valve_opening=0.4, compressor_speed=55.0, T_ambient=308.15, T_indoor=300.15
    )
    slow = simulate(unit, None, inputs, max_wall_time=1e-3, solver=solver)
    assert slow.attrs["status"] == "failed" and "wall-clock" in slow.attrs["failure_reason"]
    assert slow.attrs["failure_kind"] == FailureKind.TIME_LIMIT
    assert slow.sizes["time"] == 601 and np.isnan(slow.PD.values[-1])
    too_much = simulate(unit, {"M0": 9.0}, inputs, solver=solver)
    assert too_much.attrs["status"] == "failed"
    assert "initial state" in too_much.attrs["failure_reason"]
    assert too_much.attrs["failure_kind"] == FailureKind.INITIAL_STATE
    # zero flow, no volume
    degenerate = simulate(unit, {"CF_VOL": 0.0, "L_COND": 0.0}, inputs, solver=solver)
    assert degenerate.attrs["status"] == "failed" and degenerate.attrs["failure_reason"]
    assert degenerate.attrs["failure_kind"] in set(FailureKind)
    with pytest.raises(ValueError, match="unknown parameter id"):
        simulate(unit, {"charge": 1.0}, inputs)
    with pytest.raises(ValueError, match="solver must be one of"):
        simulate(unit, None, inputs, solver="euler")


def test_simulator_interface_for_samplers(unit):
    simulator = VCCSimulator(unit, outputs=["PD", "MDOT"], t_window=(20.0, 200.0))
    assert simulator.parameter_names[0] == "M0" and len(simulator.parameter_names) == 26
    assert simulator.output_names == ("PD", "MDOT")
    clone = pickle.loads(pickle.dumps(simulator))
    result = clone({"M0": 1.2}, np.random.default_rng(0))
    assert list(result.data_vars) == ["PD", "MDOT"]
    assert float(result.time[0]) == 20.0 and float(result.time[-1]) == 200.0
    assert result.attrs["status"] == "ok"
    again = simulator({"M0": 1.2}, np.random.default_rng(1))
    np.testing.assert_array_equal(result.PD.values, again.PD.values)  # deterministic
    with pytest.raises(ValueError, match="unknown output"):
        VCCSimulator(unit, outputs=["XX"])
    with pytest.raises(ValueError, match="t_window"):
        VCCSimulator(unit, t_window=(100.0, 5000.0))


def test_electrical_power_is_an_optional_output(unit):
    simulator = VCCSimulator(unit, outputs=["TD", "W_comp"], t_window=(0.0, 100.0))
    result = simulator({"CF_POW": 1.5}, None)
    assert list(result.data_vars) == ["TD", "W_comp"] and result.W_comp.attrs["units"] == "W"
    nominal = simulator({}, None)
    assert float(result.W_comp[-1]) > 1.1 * float(nominal.W_comp[-1])  # losses x 1.5: +14 %


def test_humid_indoor_air_dehumidifies(unit, rated):
    humid = operating_point(unit, RH_indoor=0.5)  # 27 degC / 50 % RH indoor
    assert humid["status"] == "ok" and humid["drift"] < 1e-4
    assert 0.65 <= humid["SHR"] <= 0.85
    assert humid["capacity"] > rated["capacity"] and humid["PE"] > rated["PE"]
    assert rated["Q_latent"] == 0.0 and rated["SHR"] == 1.0  # dry by default, as in the paper
    assert abs(humid["energy_balance_error"]) < 0.01


@pytest.mark.parametrize("charge", [0.9, 2.2])
def test_whole_charge_range_simulates(unit, charge, solver):
    run = simulate(unit, {"M0": charge}, t_end=1060.0, diagnostics=True, solver=solver)
    assert run.attrs["status"] == "ok", run.attrs["failure_reason"]
    assert run.attrs["mass_error"] < 1e-4
    assert run.PC.values.max() < 47e5  # the flooded condenser stays below the critical point


@pytest.mark.slow
def test_robust_over_the_table_iii_box(unit):
    """200 uniform draws from the Table III box: >= 95 % must simulate the 1060 s window."""
    simulator = VCCSimulator(unit, t_window=(0.0, 1060.0))
    draws = unit.parameters.sample_uniform(200, np.random.default_rng(2024))
    failures = []
    for theta in draws:
        result = simulator(theta, None)
        if result.attrs["status"] != "ok":
            failures.append((theta, result.attrs["failure_reason"]))
    assert len(failures) <= 10, failures
