"""Input profiles: the built-in step profile, CSV loading and its validation."""

import numpy as np
import pytest

from pymc_vcc.physics.inputs import (
    INPUT_IDS,
    builtin_inputs,
    constant_inputs,
    input_segments,
    load_inputs_csv,
    make_inputs,
    window,
)

HEADER = "time [s],valve_opening [1],compressor_speed [Hz],T_ambient [degC],T_indoor [degC]\n"


def test_builtin_profile_steps_every_input_several_times_over_2120_s():
    inputs = builtin_inputs()
    assert float(inputs.time[-1]) == 2120.0
    for name in INPUT_IDS:
        values = inputs[name].values
        assert np.count_nonzero(np.diff(values)) >= 3, name
        assert "units" in inputs[name].attrs
    assert inputs.T_ambient.attrs["units"] == "K"
    assert 300.0 < float(inputs.T_ambient[0]) < 315.0
    first_half = window(inputs, 1060.0)
    for name in INPUT_IDS:
        assert np.count_nonzero(np.diff(first_half[name].values)) >= 2, name


def test_segments_merge_repeated_rows():
    inputs = make_inputs(
        np.array([0.0, 10.0, 20.0, 30.0]),
        valve_opening=[0.4, 0.4, 0.5, 0.5],
        compressor_speed=50.0,
        T_ambient=308.15,
        T_indoor=300.15,
    )
    edges, values = input_segments(inputs)
    np.testing.assert_array_equal(edges, [0.0, 20.0, 30.0])
    assert values.shape == (2, 5) and values[1, 0] == 0.5
    np.testing.assert_array_equal(values[:, 4], 0.0)  # RH_indoor absent: dry air


def test_window_cuts_and_keeps_the_held_value():
    cut = window(builtin_inputs(), 500.0)
    assert float(cut.time[-1]) == 500.0
    assert float(cut.valve_opening[-1]) == float(cut.valve_opening[-2])
    with pytest.raises(ValueError, match="must lie in"):
        window(builtin_inputs(), 5000.0)


def test_a_window_from_a_later_start_counts_its_time_from_there():
    """The profile's second half as a record of its own: it begins with the inputs held at its
    start (58 Hz from 1060 s), its steps keep their spacing, it ends with the last held ones."""
    profile = builtin_inputs()
    second = window(profile, 2120.0, 1060.0)
    assert float(second.time[0]) == 0.0 and float(second.time[-1]) == 1060.0
    assert float(second.compressor_speed[0]) == 58.0 and float(second.time[1]) == 120.0
    inside = window(profile, 1000.0, 100.0)  # a start between two steps holds the earlier one
    assert float(inside.compressor_speed[0]) == 55.0 and float(inside.time[1]) == 20.0
    assert float(inside.compressor_speed[1]) == 65.0 and float(inside.time[-1]) == 900.0
    np.testing.assert_array_equal(window(profile, 1060.0, 0.0).time, window(profile, 1060.0).time)
    with pytest.raises(ValueError, match=r"t_start = 1060\.0 s must lie in"):
        window(profile, 1060.0, 1060.0)


def test_csv_round_trip_converts_celsius(tmp_path):
    path = tmp_path / "profile.csv"
    path.write_text(HEADER + "0,0.4,55,35,27\n100,0.5,60,30,25\n200,0.5,60,30,25\n")
    inputs = load_inputs_csv(path)
    assert float(inputs.T_ambient[0]) == pytest.approx(308.15)
    assert inputs.compressor_speed.attrs["units"] == "Hz"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (HEADER + "0,0.4,55,35,27\n100,0.4,55,nan,27\n", "T_ambient is NaN at time 100"),
        (HEADER + "0,0.4,55,35,27\n100,0.4,55,35,27\n50,0.4,55,35,27\n", "strictly increasing"),
        (HEADER + "5,0.4,55,35,27\n100,0.4,55,35,27\n", "start at 0"),
        (HEADER.replace("[Hz]", "[kg]") + "0,0.4,55,35,27\n9,0.4,55,35,27\n", "'kg'"),
        (HEADER.replace("[Hz]", "[rpm]") + "0,0.4,55,35,27\n9,0.4,55,35,27\n", "outside the"),
        (HEADER.replace("valve_opening", "lev") + "0,0.4,55,35,27\n9,0.4,55,35,27\n", "'lev'"),
        (HEADER.replace("time [s]", "t [s]") + "0,0.4,55,35,27\n9,0.4,55,35,27\n", "no 'time'"),
        (
            HEADER.replace("time [s]", "time [kg]") + "0,0.4,55,35,27\n9,0.4,55,35,27\n",
            "time_unit 'kg'",
        ),
        (HEADER + "0,0.4,55,35,27\n9,0.4,fast,35,27\n", "line 3: 'fast' is not a number"),
        (HEADER + "0,0.4,55,35,27\n9,1.4,55,35,27\n", r"outside the allowed range"),
        (HEADER + "0,0.4,55,35\n9,0.4,55,35,27\n", "every row"),
        ("time [s],valve_opening [1]\n0,0.4\n9,0.4\n", "missing"),
    ],
)
def test_bad_csv_is_a_clear_error(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        load_inputs_csv(path)


def test_csv_times_in_any_unit_of_time(tmp_path):
    path = tmp_path / "minutes.csv"
    path.write_text(HEADER.replace("time [s]", "time [min]") + "0,0.4,55,35,27\n2,0.4,55,35,27\n")
    assert load_inputs_csv(path)["time"].values.tolist() == [0.0, 120.0]


def test_dataset_validation_checks_units():
    inputs = constant_inputs(
        100.0, valve_opening=0.4, compressor_speed=55.0, T_ambient=308.15, T_indoor=300.15
    )
    inputs.T_indoor.attrs["units"] = "degC"
    from pymc_vcc.physics.inputs import validate_inputs

    with pytest.raises(ValueError, match="T_indoor must have units 'K'"):
        validate_inputs(inputs)


def test_optional_indoor_humidity():
    rated = {"valve_opening": 0.4, "compressor_speed": 55.0, "T_ambient": 308.15}
    humid = constant_inputs(100.0, **rated, T_indoor=300.15, RH_indoor=0.5)
    assert humid.RH_indoor.attrs["units"] == "1"
    np.testing.assert_array_equal(input_segments(humid)[1][:, 4], 0.5)
    with pytest.raises(ValueError, match=r"RH_indoor = 1.2 1 at time 0.0 s is outside"):
        constant_inputs(100.0, **rated, T_indoor=300.15, RH_indoor=1.2)
    with pytest.raises(ValueError, match="unknown input"):
        constant_inputs(100.0, **rated, T_indoor=300.15, RH_outdoor=0.5)


def _write(tmp_path, text):
    path = tmp_path / "profile.csv"
    path.write_text(text, encoding="utf-8")
    return path


def test_csv_with_bare_si_names_reads_as_si(tmp_path):
    path = _write(
        tmp_path,
        "time,valve_opening,compressor_speed,T_ambient,T_indoor,RH_indoor\n"
        "0,0.4,55,308.15,300.15,0.5\n60,0.45,60,308.15,300.15,0.5\n",
    )
    inputs = load_inputs_csv(path)
    np.testing.assert_allclose(inputs.compressor_speed.values, [55.0, 60.0])
    np.testing.assert_allclose(inputs.T_ambient.values, 308.15)
    np.testing.assert_allclose(inputs.RH_indoor.values, 0.5)


def test_csv_with_a_units_row_semicolons_and_decimal_commas(tmp_path):
    path = _write(
        tmp_path,
        "time;valve_opening;compressor_speed;T_ambient;T_indoor\n"
        "min;%;rpm;°C;degF\n"
        "0;40;3300;35,0;80,6\n2;45;3900;35,5;80,6\n4;45;3900;35,5;80,6\n",
    )
    inputs = load_inputs_csv(path)
    np.testing.assert_allclose(inputs.time.values, [0.0, 120.0, 240.0])
    np.testing.assert_allclose(inputs.valve_opening.values, [0.4, 0.45, 0.45])
    np.testing.assert_allclose(inputs.compressor_speed.values, [55.0, 65.0, 65.0])
    np.testing.assert_allclose(inputs.T_ambient.values, [308.15, 308.65, 308.65])
    np.testing.assert_allclose(inputs.T_indoor.values, 300.15)


def test_csv_read_like_a_logger_file_with_columns_and_units(tmp_path):
    path = _write(
        tmp_path,
        "Status,Seconds,EEV_pct,Comp (Hz),T_out_C,T_in_C\n"
        "RUN,0,40,55,35,27\nRUN,100,50,60,30,25\nRUN,200,50,60,30,25\n",
    )
    columns = {
        "EEV_pct": "valve_opening",
        "Comp": "compressor_speed",
        "T_out_C": "T_ambient",
        "T_in_C": "T_indoor",
    }
    units = {"EEV_pct": "%", "T_out_C": "C", "T_in_C": "C"}
    inputs = load_inputs_csv(path, units, columns=columns, time_column="Seconds")
    np.testing.assert_allclose(inputs.valve_opening.values, [0.4, 0.5, 0.5])
    np.testing.assert_allclose(inputs.T_indoor.values, [300.15, 298.15, 298.15])
    with pytest.raises(ValueError, match="unknown input"):
        load_inputs_csv(path, units, columns={**columns, "Status": "mode"}, time_column="Seconds")


def test_the_shipped_profiles_read_as_before():
    inputs = builtin_inputs()
    assert float(inputs.T_ambient[0]) == pytest.approx(308.15)
    assert float(inputs.valve_opening[0]) == pytest.approx(0.40)
    assert float(inputs.compressor_speed[0]) == pytest.approx(55.0)
