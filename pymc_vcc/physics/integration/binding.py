"""Numba kernels bound to their argument types once, not typed again on every call.

A Numba dispatcher types each argument on every call to pick the machine code; for the cycle
kernels' six arguments (the refrigerant tables are a NamedTuple of 13 fields, the constants a
record array) that costs 3 µs of a 20 µs right-hand side, paid thousands of times per
simulation. The arguments' types do not change within a simulation, so :func:`bind` picks the
machine code once and returns it; calling it only converts the arguments (0.7 µs).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numba
import numpy as np

_TYPES: dict[tuple, Any] = {}
"""Numba type by :func:`_type_key`: ``numba.typeof`` of a record array takes ~1 ms."""


def _type_key(value: Any) -> tuple:
    """What Numba's type of ``value`` depends on (arrays: dtype, shape rank, layout flags)."""
    if isinstance(value, np.ndarray):
        flags = value.flags
        return (
            np.ndarray,
            value.dtype,
            value.ndim,
            flags.c_contiguous,
            flags.f_contiguous,
            flags.writeable,
            flags.aligned,
        )
    if isinstance(value, tuple):
        return (type(value), *map(_type_key, value))
    return (type(value),)


def numba_type(value: Any) -> Any:
    """``numba.typeof(value)``, remembered by what it depends on."""
    key = _type_key(value)
    if key not in _TYPES:
        _TYPES[key] = numba.typeof(value)
    return _TYPES[key]


def bind(kernel: Any, *args: Any) -> Callable[..., Any]:
    """The machine code of ``kernel`` (a Numba dispatcher) for the types of ``args``, loaded or
    compiled if need be. Call it only with arguments of those same types: it does not check."""
    return kernel.compile(tuple(numba_type(value) for value in args))
