"""Printed tables show the precision their numbers have (an sd of 0.0001 kg is not 0.000)."""

import pytest

from pymc_vcc.studies.leak import LeakResult
from pymc_vcc.studies.precision import decimals, significant
from pymc_vcc.studies.validation import ValidationResult


@pytest.mark.parametrize(
    ("sd", "places"),
    [(0.013, 3), (0.097, 3), (0.0001, 5), (0.00011, 5), (7e-7, 8), (0.5, 2), (12.0, 0)],
)
def test_an_uncertainty_keeps_two_significant_figures(sd, places):
    assert decimals(sd) == places
    assert decimals(0.0) == 3  # no spread: the column's usual places


def test_significant_is_fixed_notation():
    assert significant(0.00007) == "0.000070"
    assert significant(0.0141) == "0.014"
    assert significant(0.0349, width=9) == "    0.035"


def _leak(rows):
    return LeakResult(
        table=rows,
        trees=[],
        sampler="likelihood",
        n_simulations=0,
        wall_seconds=0.0,
        alarm_threshold_kg=1.8,
    )


def test_table_ii_prints_the_mean_as_precise_as_its_sd():
    lines = (
        _leak(
            [
                {"reference_kg": 1.5, "mean_kg": 1.50018, "sd_kg": 0.00011, "p_leak": 1.0},
                {"reference_kg": 2.0, "mean_kg": 1.99712, "sd_kg": 0.0131, "p_leak": 0.0},
            ]
        )
        .format_table()
        .splitlines()
    )
    assert lines[2].split()[:2] == ["1.50018", "0.00011"]
    assert lines[3].split()[:2] == ["1.997", "0.013"]
    assert "0.000 " not in lines[2]


def test_the_validation_table_keeps_small_errors_and_sds():
    row = {
        "method": "likelihood",
        "datasets": 50,
        "mean_abs_error_kg": 0.00007,
        "median_sd_kg": 0.00010,
        "coverage": 0.94,
        "simulations_per_dataset": 908,
        "median_wall_seconds": 96.0,
    }
    table = ValidationResult(reference_kg=1.5, rows=[row], runs=[], wall_seconds=0.0)
    assert table.format_table().splitlines()[-1].split()[2:4] == ["0.000070", "0.00010"]
