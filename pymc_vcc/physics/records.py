"""Numba records: NumPy structured arrays that carry a component's or a cycle's parameters.

A one-element structured array passes into Numba as cheaply as a float array (a NamedTuple of
floats costs ~20 times more per call, a structured scalar ``np.void`` over 100 times more), and
its record is read by field name, so no offset into a parameter vector is written down.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np


def make_record(dtype: np.dtype, values: Mapping[str, Any]) -> np.void:
    """A record of ``dtype`` with every field set from ``values`` (nested records as mappings
    or records). A missing or unknown field is an error naming it."""
    return record_array(dtype, values)[0]


def record_array(dtype: np.dtype, values: Mapping[str, Any]) -> np.ndarray:
    """:func:`make_record` as a one-element array: the form to pass from Python into Numba."""
    names = list(dtype.names or ())
    unknown = sorted(set(values) - set(names))
    missing = [name for name in names if name not in values]
    if unknown or missing:
        raise ValueError(f"record fields: unknown {unknown}, missing {missing}; expected {names}")
    record = np.zeros(1, dtype=dtype)
    fields: Mapping[str, tuple] = dtype.fields or {}
    for name in names:
        value = values[name]
        field = fields[name][0]
        if field.names is not None and isinstance(value, Mapping):
            value = make_record(field, value)
        record[name] = value
    return record
