"""Cells of the CSV files: a column's unit in its header, numbers with either decimal mark."""

from __future__ import annotations

import pytest

from pymc_vcc.physics.csv_cells import DECIMAL_COMMA, is_number, split_header_unit


@pytest.mark.parametrize(
    ("column", "split"),
    [
        ("TD [degC]", ("TD", "degC")),
        (" T_ambient (degC) ", ("T_ambient", "degC")),
        ("PD (bar(g))", ("PD", "bar(g)")),
        ("PD [bar(g)]", ("PD", "bar(g)")),
        ("valve_opening", ("valve_opening", None)),
        ("[s]", ("[s]", None)),
        ("TD []", ("TD []", None)),
    ],
)
def test_a_header_splits_into_name_and_unit(column, split):
    assert split_header_unit(column) == split


def test_numbers_with_either_decimal_mark():
    assert is_number("27.5", ".") and is_number("-27,5", ",")
    assert not is_number("27,5", ".") and not is_number("degC", ".")
    assert DECIMAL_COMMA.match("27,5") and not DECIMAL_COMMA.match("27.5")
