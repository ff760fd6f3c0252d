"""Units to SI: any pint unit of the right dimension, gauge pressures, clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from pymc_vcc.physics.quantities import time_unit_seconds, unit_converter


@pytest.mark.parametrize(
    ("unit", "quantity", "value", "si"),
    [
        ("degC", "temperature", 25.0, 298.15),
        ("°C", "temperature", 0.0, 273.15),
        ("degF", "temperature", 212.0, 373.15),
        ("K", "temperature", 300.0, 300.0),
        ("bar", "pressure", 10.0, 1e6),
        ("barg", "pressure", 10.0, 1e6 + 101325.0),
        ("bar(g)", "pressure", 0.0, 101325.0),
        ("bara", "pressure", 1.0, 1e5),
        ("kPa", "pressure", 500.0, 5e5),
        ("psig", "pressure", 0.0, 101325.0),
        ("MPa", "pressure", 2.5, 2.5e6),
        ("g/s", "mass_flow", 20.0, 0.02),
        ("kg/h", "mass_flow", 72.0, 0.02),
        ("%", "fraction", 40.0, 0.4),
        ("1", "fraction", 0.4, 0.4),
        ("rpm", "speed", 3000.0, 50.0),
        ("Hz", "speed", 50.0, 50.0),
        # any pint unit of the right dimension
        ("F", "temperature", 32.0, 273.15),
        ("C", "temperature", 0.0, 273.15),
        ("lb/min", "mass_flow", 60.0, 0.45359237),
        ("atm", "pressure", 1.0, 101325.0),
        ("kPag", "pressure", 0.0, 101325.0),
        ("1/min", "speed", 60.0, 1.0),
        ("percent", "fraction", 50.0, 0.5),
    ],
)
def test_unit_conversion(unit, quantity, value, si):
    assert unit_converter(unit, quantity)(np.array([value]))[0] == pytest.approx(si)


def test_gauge_pressure_uses_the_given_atmosphere():
    assert unit_converter("barg", "pressure", 95000.0)(np.array([1.0]))[0] == 195000.0


def test_unknown_unit_names_the_allowed_ones():
    with pytest.raises(ValueError, match=r"unknown pressure unit 'kg'.*barg"):
        unit_converter("kg", "pressure")
    with pytest.raises(ValueError, match=r"unknown temperature unit 'Kelvins'.*degF"):
        unit_converter("Kelvins", "temperature")


@pytest.mark.parametrize(
    ("unit", "seconds"), [("s", 1.0), ("ms", 1e-3), ("min", 60.0), ("h", 3600.0)]
)
def test_time_units_in_seconds(unit, seconds):
    assert time_unit_seconds(unit) == pytest.approx(seconds)


def test_a_unit_that_is_not_of_time_is_refused():
    with pytest.raises(ValueError, match="unknown time_unit 'kg'; allowed are units of time"):
        time_unit_seconds("kg")
