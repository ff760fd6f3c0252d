"""Table III and fault parameters: ids, validation of specs and of user parameter mappings."""

from importlib.resources import files

import numpy as np
import pytest

from pymc_vcc.physics.cycles import CYCLE_MODELS
from pymc_vcc.physics.cycles.base import CycleModel
from pymc_vcc.physics.cycles.split_unit import FAULTS, PARAMETERS
from pymc_vcc.physics.parameters import ParameterSpec, parameter_table
from pymc_vcc.physics.simulate import simulate
from pymc_vcc.physics.unit import HEAT_PUMP_UNIT, load_unit


def test_table_iii_has_26_unique_ids_starting_with_charge():
    ids = [pid for pid, _ in PARAMETERS]
    assert len(ids) == 26
    assert len(set(ids)) == 26
    assert ids[0] == "M0"
    assert load_unit().parameters.ids == tuple(ids)


def test_builtin_bounds_are_those_of_table_iii():
    table = load_unit().parameters
    assert (table["M0"].low, table["M0"].high) == (0.9, 2.2)
    assert (table["HTC_CTP"].low, table["HTC_CTP"].high) == (500.0, 20000.0)
    assert (table["L_LIQ"].low, table["L_LIQ"].high) == (14.0, 30.0)
    assert np.all(table.lows <= table.nominal) and np.all(table.nominal <= table.highs)
    assert table["FO_SPEED"].unit == "Hz" and table["HTC_EA"].unit == "W/(m2 K)"


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"low": 2.0, "high": 1.0}, "low < high"),
        ({"low": 1.0, "high": 1.0}, "low < high"),
        ({"nominal": 5.0}, "outside its bounds"),
        ({"nominal": float("nan")}, "finite"),
        ({"tolerance": 0.0}, "tolerance must be a fraction"),
        ({"tolerance": 1.5}, "tolerance must be a fraction"),
    ],
)
def test_bad_specs_are_clear_errors(changes, message):
    values = {"id": "M0", "name": "charge", "unit": "kg", "low": 0.9, "high": 2.2}
    values |= {"nominal": 1.3} | changes
    with pytest.raises(ValueError, match=message):
        ParameterSpec(**values)


@pytest.mark.parametrize(
    ("changes", "message"),
    [({"unit": "g"}, "expected 'kg'"), ({"id": "M_TOTAL"}, "unknown parameter id")],
)
def test_specs_are_checked_against_the_cycle_models_ids(changes, message):
    specs = {spec.id: spec for spec in load_unit().parameters}
    values = {"id": "M0", "name": "charge", "unit": "kg", "low": 0.9, "high": 2.2, "nominal": 1.3}
    specs["M0"] = ParameterSpec(**(values | changes))
    with pytest.raises(ValueError, match=message):
        parameter_table(specs.values(), PARAMETERS)


def test_missing_parameter_is_named():
    specs = [spec for spec in load_unit().parameters if spec.id != "CF_LEV"]
    with pytest.raises(ValueError, match="CF_LEV"):
        parameter_table(specs, PARAMETERS)


def test_vector_fills_nominal_and_checks_ids_and_bounds():
    table = load_unit().parameters
    vector = table.vector({"M0": 1.5})
    assert vector[0] == 1.5
    np.testing.assert_array_equal(vector[1:], table.nominal[1:])
    with pytest.raises(ValueError, match="unknown parameter id 'm0'"):
        table.vector({"m0": 1.0})
    with pytest.raises(ValueError, match="outside its bounds"):
        table.vector({"M0": 3.0}, check_bounds=True)
    with pytest.raises(ValueError, match="finite"):
        table.vector({"M0": float("inf")})


def test_uniform_draws_stay_in_the_box():
    table = load_unit().parameters
    draws = table.sample_uniform(50, np.random.default_rng(1))
    values = np.array([[d[pid] for pid in table.ids] for d in draws])
    assert np.all(values >= table.lows) and np.all(values <= table.highs)
    assert values.std(axis=0).min() > 0


def test_a_stated_tolerance_is_read_and_kept_by_changes(tmp_path):
    unit = load_unit()
    assert unit.parameters["L_COND"].tolerance == 0.01
    assert unit.parameters["CF_LEV"].tolerance is None
    finer = unit.with_changes(discretisation={"n_volumes": 20})
    assert finer.parameters["L_LIQ"].tolerance == unit.parameters["L_LIQ"].tolerance
    text = (files("pymc_vcc") / "data" / "split_3p5kw_r410a.toml").read_text()
    bad = tmp_path / "unit.toml"
    bad.write_text(text.replace("tolerance = 0.01", 'tolerance = "1 %"', 1))
    with pytest.raises(ValueError, match=r"L_COND\] tolerance: expected a number"):
        load_unit(bad)


def test_the_fault_table_is_declared_apart_from_table_iii():
    assert FAULTS.ids == ("DP_RESTR", "P_NCG", "F_LEAK")
    assert [spec.unit for spec in FAULTS] == ["Pa", "Pa", "1"]
    assert np.all(FAULTS.nominal == 0.0) and np.all(FAULTS.lows == 0.0)
    assert FAULTS["DP_RESTR"].high == 3.0e5 and FAULTS["P_NCG"].high == 2.0e5
    assert FAULTS["F_LEAK"].high == 0.5
    assert all(spec.name for spec in FAULTS)  # a one-line meaning each
    for unit in (load_unit(), load_unit(HEAT_PUMP_UNIT)):  # both modes share the physics
        assert unit.faults is FAULTS
        assert not set(unit.faults.ids) & set(unit.parameters.ids)
        assert len(unit.parameters) == 26
    assert {model.faults.ids for model in CYCLE_MODELS.values()} == {FAULTS.ids}
    assert len(CycleModel.faults) == 0  # a new cycle declares none unless it says so


def test_one_mapping_reaches_both_tables():
    unit = load_unit()
    theta, faults = unit.parameter_vectors({"M0": 1.5, "P_NCG": 5e4})
    assert theta[0] == 1.5 and np.all(theta[1:] == unit.parameters.nominal[1:])
    np.testing.assert_array_equal(faults, [0.0, 5e4, 0.0])
    np.testing.assert_array_equal(unit.parameter_vectors()[1], [0.0, 0.0, 0.0])
    assert unit.parameter_spec("DP_RESTR").unit == "Pa" and unit.parameter_spec("M0").unit == "kg"
    with pytest.raises(KeyError, match=r"unknown parameter id 'P_AIR'.*fault ids"):
        unit.parameter_spec("P_AIR")
    with pytest.raises(ValueError, match="outside its bounds"):
        unit.parameter_vectors({"DP_RESTR": -1.0}, check_bounds=True)


def test_an_unknown_fault_id_is_one_line_naming_it_and_the_allowed_ones():
    with pytest.raises(ValueError) as refused:
        simulate(params={"P_AIR": 1e5}, t_end=1.0)
    message = str(refused.value)
    assert "\n" not in message
    assert message.startswith("unknown parameter id(s) ['P_AIR']; allowed are calibration ids")
    assert "fault ids ['DP_RESTR', 'P_NCG', 'F_LEAK']" in message and "'M0'" in message
