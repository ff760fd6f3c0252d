"""How the CSV files the package reads (input profiles, measured logs) write their cells: the
markers of a missing value, decimal commas, and a column's unit in its header."""

from __future__ import annotations

import re

MISSING_CELLS = (
    "",
    "nan",
    "NaN",
    "NAN",
    "na",
    "NA",
    "n/a",
    "N/A",
    "null",
    "NULL",
    "none",
    "None",
    "-",
)
"""Cells that mean "no value"."""

DECIMAL_COMMA = re.compile(r"^[+-]?\d+,\d+$")
"""A number written with a decimal comma (``27,5``)."""


def is_number(text: str, decimal: str) -> bool:
    """Whether ``text`` reads as a number with the decimal mark ``decimal`` (``"."`` or
    ``","``)."""
    try:
        float(text.replace(decimal, ".") if decimal != "." else text)
    except ValueError:
        return False
    return True


def split_header_unit(column: str) -> tuple[str, str | None]:
    """``"TD [degC]"`` or ``"PD (bar(g))"`` -> (``"TD"``, unit); a bare name -> (name, None)."""
    column = column.strip()
    closing = {"]": "[", ")": "("}.get(column[-1:]) if column else None
    if closing is None:
        return column, None
    depth = 0
    for position in range(len(column) - 1, -1, -1):
        char = column[position]
        depth += char == column[-1]
        depth -= char == closing
        if depth == 0:
            name, unit = column[:position].strip(), column[position + 1 : -1].strip()
            return (name, unit) if name and unit else (column, None)
    return column, None
