"""Measured CSV logs: units, resampling, gaps, errors, and the example log's round trip."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pymc_vcc.io.measurements import (
    column_map_beside,
    example_log_path,
    load_column_map,
    load_measurements,
)
from pymc_vcc.physics.simulate import VCCSimulator, simulate

LOG_START = 300.0
"""Truth time of the example log's first row (scripts/make_example_log.py)."""
NOISE_SI = {"TD": 0.3, "PD": 5e3, "TS": 0.2, "PS": 3e3, "TC": 0.2, "TE": 0.2, "MDOT": 2e-4}
"""Sensor noise sd of the example log, SI."""

EXAMPLE = load_column_map(column_map_beside(example_log_path()))


@pytest.fixture(scope="module")
def example():
    return load_measurements(
        example_log_path(), EXAMPLE.columns, EXAMPLE.units, time_column="Timestamp"
    )


@pytest.fixture(scope="module")
def truth():
    return simulate(t_end=1200.0)


def test_example_log_is_small_and_shipped():
    assert example_log_path().is_file()
    assert example_log_path().stat().st_size < 200_000


def test_example_log_recovers_the_simulated_outputs_within_the_noise(example, truth):
    observed = example.observed
    assert set(observed.data_vars) == set(NOISE_SI)
    reference = truth.interp(time=observed["time"].values + LOG_START)
    for name, sd in NOISE_SI.items():
        assert observed[name].attrs["units"] == truth[name].attrs["units"]
        residual = observed[name].values - reference[name].values
        assert abs(residual.mean()) < 0.3 * sd, name
        assert residual.std() < 1.2 * sd, name


def test_example_log_recovers_the_inputs_without_smearing_a_step(example, truth):
    inputs = example.inputs
    time = inputs["time"].values
    assert time[0] == 0.0
    assert np.diff(time[:-1]).max() == 10.0
    from pymc_vcc.physics.inputs import builtin_inputs, input_segments

    edges, held = input_segments(builtin_inputs())
    true_steps = edges[1:][(edges[1:] > LOG_START) & (edges[1:] < LOG_START + time[-1])]
    middle = 0.5 * (time[:-1] + time[1:]) + LOG_START
    index = np.searchsorted(edges, middle, side="right") - 1
    for column, name in enumerate(("valve_opening", "compressor_speed")):
        # commanded inputs: every block holds one value of the truth, steps within a sample
        error = np.abs(inputs[name].values[:-1] - held[index, column])
        assert error.max() < 1e-9, name
        stepped = true_steps[np.diff(held[:, column])[np.searchsorted(edges, true_steps) - 1] != 0]
        for step in stepped:
            assert np.min(np.abs(time + LOG_START - step)) <= 3.5, (name, step)
    # measured temperatures are interpolated linearly: a block starting within a sample spacing
    # (3.5 s) of a step of the truth sees the ramp between the samples either side of it
    first = np.searchsorted(edges, time[:-1] + LOG_START - 3.5, side="right") - 1
    last = np.searchsorted(edges, time[1:] + LOG_START - 1e-6, side="right") - 1
    settled = first == last
    for column, name in ((2, "T_ambient"), (3, "T_indoor")):
        error = np.abs(inputs[name].values[:-1] - held[index, column])
        assert error[settled].max() < 0.15, name


def test_example_log_reports_the_outage_and_the_sensor_dropout(example):
    report = example.report
    assert report.n_rows == 571
    assert report.outputs == ("TD", "PD", "TS", "PS", "TC", "TE", "MDOT")
    assert report.missing_values["T_suction_C"] > 0
    rows = [gap for gap in report.gaps if gap.variable == "rows"]
    assert len(rows) == 1 and 80.0 < rows[0].duration < 90.0
    (dropout,) = [gap for gap in report.gaps if gap.variable == "TS"]
    assert 45.0 < dropout.duration < 55.0
    assert len(report.segments) == 2
    assert report.kept == report.segments[0]
    assert report.dropped_seconds == pytest.approx(1500.0 - report.kept[1], abs=5.0)
    # the drop-out masks TS (and so the observed time) but does not cut the record
    assert report.masked_points["TS"] == pytest.approx(dropout.duration, abs=2)
    assert report.n_observed == example.observed.sizes["time"] == report.n_grid - 48
    assert "gap in rows" in str(report)
    held = example.observed["time"].values
    assert not ((held > dropout.start + 1) & (held < dropout.end - 1)).any()


def test_choosing_the_second_segment_restarts_time_at_zero():
    measured = load_measurements(
        example_log_path(), EXAMPLE.columns, EXAMPLE.units, time_column="Timestamp", segment=1
    )
    assert measured.report.kept == measured.report.segments[1]
    assert measured.inputs.attrs["t_offset"] == measured.report.kept[0]
    assert measured.observed["time"].values[0] == 0.0
    with pytest.raises(ValueError, match="2 gap-free segment"):
        load_measurements(
            example_log_path(), EXAMPLE.columns, EXAMPLE.units, time_column="Timestamp", segment=2
        )


def test_the_simulator_runs_on_measured_inputs_and_matches_after_start_up(example):
    outputs = ["PD", "PS", "MDOT"]
    end = float(example.inputs["time"].values[-1])
    simulator = VCCSimulator(inputs=example.inputs, outputs=outputs, t_window=(300.0, end))
    result = simulator({})
    assert result.attrs["status"] == "ok"
    observed = example.observed.sel(time=slice(300.0, None))
    simulated = result.sel(time=observed["time"].values)
    for name in outputs:
        relative = np.abs(simulated[name].values / observed[name].values - 1.0)
        assert np.median(relative) < 0.015, name


# ----------------------------------------------------------------- small hand-made logs

HEADER = "t [s],valve [%],speed [rpm],Tamb [degC],Tin [degC],PD [bar],TD [degC]"
COLUMNS = {
    "valve": "valve_opening",
    "speed": "compressor_speed",
    "Tamb": "T_ambient",
    "Tin": "T_indoor",
    "PD": "PD",
    "TD": "TD",
}


def _write(path: Path, rows: list[str], header: str = HEADER) -> Path:
    path.write_text("\n".join([header, *rows]) + "\n")
    return path


def _rows(times, pd="27.0", td="70.0", valve="40") -> list[str]:
    return [f"{t},{valve},3000,35.0,27.0,{pd},{td}" for t in times]


def test_header_units_seconds_and_interpolation(tmp_path):
    rows = [f"{t},40,3000,35.0,27.0,{27.0 + 0.1 * t},70.0" for t in (0.0, 2.5, 5.0, 7.5, 10.0)]
    measured = load_measurements(
        _write(tmp_path / "log.csv", rows), COLUMNS, time_column="t", input_hold=5.0
    )
    np.testing.assert_allclose(measured.observed["time"], np.arange(11.0))
    np.testing.assert_allclose(measured.observed["PD"], (27.0 + 0.1 * np.arange(11.0)) * 1e5)
    assert measured.observed["PD"].attrs["units"] == "Pa"
    np.testing.assert_allclose(measured.inputs["time"], [0.0, 5.0, 10.0])
    np.testing.assert_allclose(measured.inputs["compressor_speed"], 50.0)
    np.testing.assert_allclose(measured.inputs["valve_opening"], 0.4)
    np.testing.assert_allclose(measured.inputs["T_ambient"], 308.15)


def test_time_in_minutes_and_semicolons(tmp_path):
    path = tmp_path / "log.csv"
    path.write_text(
        HEADER.replace(",", ";") + "\n" + "\n".join(r.replace(",", ";") for r in _rows([0, 1, 2]))
    )
    measured = load_measurements(path, COLUMNS, time_column="t", time_unit="min", max_gap=90.0)
    assert measured.observed["time"].values[-1] == 120.0


def test_output_gap_masks_and_input_gap_cuts(tmp_path):
    times = np.arange(0.0, 200.0, 2.0)
    rows = [
        f"{t},{'' if 100 < t < 150 else 40},3000,35,27,{'' if 20 < t < 70 else 27},70"
        for t in times
    ]
    measured = load_measurements(
        _write(tmp_path / "log.csv", rows), COLUMNS, time_column="t", max_gap=10.0
    )
    report = measured.report
    assert [(g.variable, g.start, g.end) for g in report.gaps] == [
        ("PD", 20.0, 70.0),
        ("valve_opening", 100.0, 150.0),
    ]
    assert report.segments == ((0.0, 100.0), (150.0, 198.0))
    assert report.kept == (0.0, 100.0)
    assert report.masked_points == {"PD": 49, "TD": 0}
    observed_time = measured.observed["time"].values
    assert observed_time.size == 101 - 49
    assert not ((observed_time > 20) & (observed_time < 70)).any()


def test_short_gaps_are_bridged(tmp_path):
    rows = _rows([0, 5, 25, 30])
    measured = load_measurements(_write(tmp_path / "log.csv", rows), COLUMNS, time_column="t")
    assert measured.report.gaps == ()
    assert measured.observed.sizes["time"] == 31


def test_iso_timestamps_with_zone(tmp_path):
    stamps = ["2024-07-15T13:05:00+02:00", "2024-07-15T13:05:03.5+02:00", "2024-07-15T11:05:07Z"]
    rows = [f"{s},40,3000,35,27,27,70" for s in stamps]
    measured = load_measurements(_write(tmp_path / "log.csv", rows), COLUMNS, time_column="t")
    assert measured.observed["time"].values[-1] == 7.0
    assert measured.report.time_origin == stamps[0]


@pytest.mark.parametrize(
    ("rows", "columns", "units", "match"),
    [
        (_rows([0, 1, 2]), {**COLUMNS, "PE": "PE"}, {}, r"column 'PE' not found"),
        (_rows([0, 1, 2]), {**COLUMNS, "PD": "XX"}, {}, r"unknown id\(s\) \['XX'\]"),
        (_rows([0, 1, 2]), {k: v for k, v in COLUMNS.items() if k != "Tin"}, {}, "T_indoor"),
        (
            _rows([0, 1, 2]),
            {
                "valve": "valve_opening",
                "speed": "compressor_speed",
                "Tamb": "T_ambient",
                "Tin": "T_indoor",
            },
            {},
            "at least one output",
        ),
        (_rows([0, 1, 2]), COLUMNS, {"PD": "kg/s"}, r"'PD' \(PD\): unknown pressure unit 'kg/s'"),
        (_rows([0, 2, 1]), COLUMNS, {}, "strictly increasing; line 4"),
        (_rows([0, 1, 1]), COLUMNS, {}, "strictly increasing"),
        (_rows([0, 1, 2], td=""), COLUMNS, {}, r"column 'TD' \(TD\) has no values"),
        (_rows([0, 1, 2], pd="high"), COLUMNS, {}, r"column 'PD \[bar\]', line 2: 'high'"),
        (_rows([0, 1, 2], valve="0"), COLUMNS, {}, "valve_opening = 0.0 1 .* outside"),
        (["yesterday,40,3000,35,27,27,70", *_rows([1, 2])], COLUMNS, {}, "neither a number"),
        (_rows([0]), COLUMNS, {}, "at least two data rows"),
    ],
)
def test_bad_files_give_clear_errors(tmp_path, rows, columns, units, match):
    path = _write(tmp_path / "bad.csv", rows)
    with pytest.raises(ValueError, match=match):
        load_measurements(path, columns, units, time_column="t")


def test_columns_without_any_unit_are_refused(tmp_path):
    path = _write(tmp_path / "log.csv", _rows([0, 1, 2]), header=HEADER.replace(" [bar]", ""))
    with pytest.raises(ValueError, match=r"no unit for column 'PD'.*barg"):
        load_measurements(path, COLUMNS, time_column="t")
    measured = load_measurements(path, COLUMNS, {"PD": "barg"}, time_column="t")
    assert measured.observed["PD"].values[0] == pytest.approx(27e5 + 101325.0)


def test_missing_file_and_bad_settings(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_measurements(tmp_path / "none.csv", COLUMNS)
    path = _write(tmp_path / "log.csv", _rows([0, 1, 2]))
    with pytest.raises(ValueError, match="dt must be a positive"):
        load_measurements(path, COLUMNS, time_column="t", dt=0.0)
    with pytest.raises(ValueError, match=r"max_gap = 0\.5 s must be at least dt"):
        load_measurements(path, COLUMNS, time_column="t", max_gap=0.5)
    with pytest.raises(ValueError, match="unknown time_unit 'm'; allowed are units of time"):
        load_measurements(path, COLUMNS, time_column="t", time_unit="m")


@pytest.mark.parametrize(
    ("header", "values", "message"),
    [
        ("PD [Pa]", {"pd": "27.0"}, r"column 'PD' \(PD.*median 27 Pa .*look like bar, not Pa"),
        ("TD [K]", {"td": "68.0"}, r"column 'TD' \(TD.*median 68 K .*look like degC, not K"),
    ],
)
def test_outputs_implausible_for_their_declared_unit_are_refused(tmp_path, header, values, message):
    wrong = HEADER.replace(header.replace("[Pa]", "[bar]").replace("[K]", "[degC]"), header)
    path = _write(tmp_path / "log.csv", _rows(np.arange(0.0, 40.0, 2.0), **values), wrong)
    with pytest.raises(ValueError, match=message):
        load_measurements(path, COLUMNS, time_column="t")


# ------------------------------------------------- formats written by real loggers (pandas, pint)

SI_ROW = {"PD": 27e5, "TD": 343.15, "T_ambient": 308.15, "compressor_speed": 50.0}
"""What every row of the logs below means, SI."""


def _assert_si(measured, times):
    np.testing.assert_allclose(measured.observed["time"].values[[0, -1]], times)
    np.testing.assert_allclose(measured.observed["PD"], SI_ROW["PD"], rtol=1e-4)
    np.testing.assert_allclose(measured.observed["TD"], SI_ROW["TD"])
    np.testing.assert_allclose(measured.inputs["T_ambient"], SI_ROW["T_ambient"])
    np.testing.assert_allclose(measured.inputs["compressor_speed"], SI_ROW["compressor_speed"])


def test_us_dates_fahrenheit_and_pounds_per_minute_in_parentheses(tmp_path):
    header = "t,valve (%),speed (rpm),Tamb (F),Tin (F),PD (psi),TD (F),MDOT (lb/min)"
    stamps = ["07/01/2024 01:59:58 PM", "07/01/2024 02:00:00 PM", "07/01/2024 02:00:03 PM"]
    rows = [f"{s},40,3000,95,80.6,391.6085,158,2.6455" for s in stamps]
    path = _write(tmp_path / "us.csv", rows, header=header)
    measured = load_measurements(path, {**COLUMNS, "MDOT": "MDOT"}, time_column="t")
    _assert_si(measured, [0.0, 5.0])
    np.testing.assert_allclose(measured.observed["PD"], 391.6085 * 6894.757293168)
    np.testing.assert_allclose(measured.observed["MDOT"], 2.6455 * 0.45359237 / 60.0)
    assert measured.report.units["TD"] == "F"


def test_european_dates_decimal_commas_and_a_units_row(tmp_path):
    lines = [
        "Zeit;valve;speed;Tamb;Tin;PD;TD",
        ";%;rpm;°C;°C;bar;°C",
        "01.07.2024 14:00:00;40;3000;35,0;27,0;27,0;70,0",
        "01.07.2024 14:00:02;40;3000;35,0;27,0;27,0;70,0",
        "01.07.2024 14:00:04;40;3000;35,0;27,0;27,0;70,0",
    ]
    path = tmp_path / "eu.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    measured = load_measurements(path, COLUMNS, time_column="Zeit")
    _assert_si(measured, [0.0, 4.0])
    assert measured.report.n_rows == 3
    assert measured.report.units["Tamb"] == "°C"


def test_time_format_and_decimal_options(tmp_path):
    header = "t;valve [%];speed [rpm];Tamb [C];Tin [C];PD [kPa];TD [K]"
    stamps = ["2/7/2024 14.00.00", "2/7/2024 14.00.06"]  # day/month, dots in the time
    rows = [f"{s};40;3000;35;27;2700;343,15" for s in stamps]
    path = _write(tmp_path / "log.csv", rows, header=header)
    measured = load_measurements(
        path, COLUMNS, time_column="t", time_format="%d/%m/%Y %H.%M.%S", decimal=","
    )
    _assert_si(measured, [0.0, 6.0])
    with pytest.raises(ValueError, match=r"line 2: '2/7/2024 14.00.00' .* format '%m'"):
        load_measurements(path, COLUMNS, time_column="t", time_format="%m")
    with pytest.raises(ValueError, match="decimal must be"):
        load_measurements(path, COLUMNS, time_column="t", decimal=";")


def test_a_decimal_comma_in_a_comma_separated_file_says_what_to_do(tmp_path):
    path = _write(tmp_path / "log.csv", _rows([0, 1, 2], td='"70,5"'))
    with pytest.raises(ValueError, match=r"'70,5' is not a number \(set decimal=','"):
        load_measurements(path, COLUMNS, time_column="t")


def test_a_step_of_a_commanded_input_starts_a_new_hold_block(tmp_path):
    times = np.arange(0.0, 41.0, 2.0)
    rows = [f"{t},{40 if t < 13 else 60},3000,35,27,27,70" for t in times]
    measured = load_measurements(
        _write(tmp_path / "log.csv", rows), COLUMNS, time_column="t", input_hold=10.0
    )
    inputs = measured.inputs
    np.testing.assert_allclose(inputs["time"], [0.0, 13.0, 23.0, 33.0, 40.0])
    np.testing.assert_allclose(inputs["valve_opening"], [0.4, 0.6, 0.6, 0.6, 0.6])


def test_indoor_humidity_input_and_compressor_power_output(tmp_path):
    header = HEADER + ",RH [%],Power [kW]"
    rows = [f"{row},{45 + t},{1.2 + 0.01 * t}" for t, row in enumerate(_rows(range(11)))]
    measured = load_measurements(
        _write(tmp_path / "log.csv", rows, header),
        {**COLUMNS, "RH": "RH_indoor", "Power": "W_comp"},
        time_column="t",
        input_hold=5.0,
    )
    np.testing.assert_allclose(measured.inputs["RH_indoor"], [0.47, 0.52, 0.55])
    power = measured.observed["W_comp"]
    np.testing.assert_allclose(power, 1200.0 + 10.0 * np.arange(11.0))
    assert power.attrs == {"units": "W", "long_name": "Compressor electrical power"}
    assert measured.report.outputs == ("TD", "PD", "W_comp")
    assert measured.report.units["Power"] == "kW"


@pytest.mark.parametrize(
    ("unit", "values", "match"),
    [
        ("1", "45", r"RH_indoor = 45.0 1 .* outside the allowed range \[0.0, 1.0\]"),
        ("W", "1.2", r"median 1.2 W is implausible.*look like kW"),
    ],
)
def test_humidity_and_power_in_the_wrong_unit_are_refused(tmp_path, unit, values, match):
    header = HEADER + f",X [{unit}]"
    rows = [f"{row},{values}" for row in _rows(range(5))]
    target = "RH_indoor" if unit == "1" else "W_comp"
    with pytest.raises(ValueError, match=match):
        load_measurements(
            _write(tmp_path / "log.csv", rows, header),
            {**COLUMNS, "X": target},
            time_column="t",
        )
