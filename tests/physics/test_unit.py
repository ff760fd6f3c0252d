"""Unit descriptions: the built-in unit loads; every kind of bad file is a clear error."""

import tomllib
from importlib import resources

import pytest

from pymc_vcc.physics.unit import BUILTIN_UNIT, load_unit, unit_from_dict, unit_to_dict


def _builtin_dict():
    text = resources.files("pymc_vcc").joinpath("data", BUILTIN_UNIT).read_text()
    return tomllib.loads(text)


def test_builtin_unit_loads_with_its_numbers():
    unit = load_unit()
    assert unit.refrigerant == "R410A"
    assert unit.discretisation.n_volumes >= 5
    assert unit.hardware.liquid_line.inner_diameter == pytest.approx(4.83e-3)
    assert len(unit.parameters) == 26


def test_round_trip_through_dict():
    unit = load_unit()
    assert unit_from_dict(unit_to_dict(unit)) == unit
    assert hash(unit_from_dict(unit_to_dict(unit))) == hash(unit)  # a unit is hashable


def test_load_from_a_file(tmp_path):
    path = tmp_path / "unit.toml"
    path.write_text(resources.files("pymc_vcc").joinpath("data", BUILTIN_UNIT).read_text())
    assert load_unit(path) == load_unit()
    with pytest.raises(FileNotFoundError):
        load_unit(tmp_path / "absent.toml")


def _mutated(mutate):
    data = _builtin_dict()
    mutate(data)
    return data


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d["condenser"].update(fins=3), r"\[condenser\]: unknown key\(s\) \['fins'\]"),
        (lambda d: d.update(extra={}), r"unknown key\(s\) \['extra'\]"),
        (lambda d: d["discretisation"].update(n_volumes=0), "positive integer"),
        (lambda d: d["suction_tank"].update(volume=-1.0), "finite positive"),
        (lambda d: d["compressor"].update(isentropic_efficiency=1.2), r"fraction in \(0, 1\)"),
        (lambda d: d["controller"].update(enabled="yes"), "true or false"),
        (
            lambda d: d["rating"].update(T_ambient=400.0),
            r"\[rating\] T_ambient: 400.0 K is outside the allowed range \[253.15, 323.15\]",
        ),
        (
            lambda d: d["rating"].pop("T_indoor"),
            r"\[rating\]: missing value\(s\) for \['T_indoor'\]",
        ),
        (lambda d: d["rating"].update(fan=1.0), r"\[rating\]: unknown key\(s\) \['fan'\]"),
        (lambda d: d["parameters"]["M0"].update(bounds=[2.2, 0.9]), "low < high"),
        (lambda d: d["parameters"]["M0"].update(nominal=3.0), "outside its bounds"),
        (lambda d: d["parameters"]["M0"].pop("nominal"), r"missing value\(s\) for \['nominal'\]"),
        (lambda d: d["parameters"].pop("L_VAP"), "L_VAP"),
        (lambda d: d["parameters"].update(X1={}), "X1"),
        (lambda d: d["unit"].update(refrigerant="R999"), "R999"),
        (
            lambda d: d["unit"].update(cycle="chiller"),
            r"\[unit\] cycle: unknown cycle 'chiller'; allowed cycles are",
        ),
        (lambda d: d["unit"].update(cycle=3), r"\[unit\] cycle: expected a name, got 3"),
    ],
)
def test_bad_unit_descriptions_are_clear_errors(mutate, message):
    with pytest.raises(ValueError, match=message):
        unit_from_dict(_mutated(mutate))


def test_invalid_toml_is_reported(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("[unit\nname = 1")
    with pytest.raises(ValueError, match="not valid TOML"):
        load_unit(path)


def test_a_solver_table_is_refused_in_one_line_saying_where_it_goes():
    table = {"method": "cvode", "rtol": 1e-5, "atol_enthalpy": 20.0, "output_interval": 1.0}
    data = _builtin_dict() | {"solver": table}
    with pytest.raises(ValueError) as refused:
        unit_from_dict(data, source="my.toml")
    message = str(refused.value)
    assert "\n" not in message
    assert message.startswith("my.toml [solver]: a unit holds no solver settings any more")
    # the table's own values where they differ from the method's default (CVODE's rtol is 1e-5)
    assert "simulate(..., solver=get_solver('cvode', atol_enthalpy=20.0))" in message
    assert "['radau', 'cvode']" in message and "output_interval and max_wall_time" in message
    assert "--solver cvode" in message


def test_with_changes_validates():
    unit = load_unit()
    assert unit.with_changes(discretisation={"n_volumes": 6}).discretisation.n_volumes == 6
    with pytest.raises(ValueError, match="positive integer"):
        unit.with_changes(discretisation={"n_volumes": -2})
    with pytest.raises(ValueError, match="unknown section"):
        unit.with_changes(nonsense={"a": 1})


def test_the_worked_example_of_models_readme_loads_and_runs():
    from pathlib import Path

    from pymc_vcc.physics.simulate import operating_point

    unit = load_unit(Path(__file__).parents[2] / "models" / "r32_heat_pump_3kw.toml")
    assert (unit.cycle, unit.refrigerant, unit.hardware.condenser.n_paths) == (
        "heat-pump-heating",
        "R32",
        3,
    )
    point = operating_point(unit, T_ambient=275.15)
    assert point["status"] == "ok" and 2000.0 < point["capacity"] < 4500.0


def test_the_rating_gives_the_cycles_inputs_optional_ones_too():
    data = _builtin_dict()
    assert set(unit_from_dict(data).rating) == set(load_unit().cycle_model.inputs.required_ids)
    data["rating"]["RH_indoor"] = 0.5
    assert unit_from_dict(data).rating["RH_indoor"] == 0.5


def test_a_unit_without_a_cycle_runs_the_split_cooling_cycle():
    data = unit_to_dict(load_unit())
    del data["unit"]["cycle"]
    assert unit_from_dict(data).cycle == "split-cooling"
