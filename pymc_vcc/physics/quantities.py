"""Physical quantities and their units: the quantity each SI unit measures, and conversion to SI
of any unit pint knows (temperature, pressure with gauge suffixes, mass flow, fraction, speed,
power, time)."""

from __future__ import annotations

from collections.abc import Callable
from functools import cache

import numpy as np
import pint

from pymc_vcc.physics.components.moist_air import ATMOSPHERIC_PRESSURE

QUANTITY_OF_UNIT: dict[str, str] = {
    "K": "temperature",
    "Pa": "pressure",
    "kg/s": "mass_flow",
    "1": "fraction",
    "Hz": "speed",
    "W": "power",
}
"""The physical quantity (as :func:`unit_converter` names it) of each SI unit an input or output
is declared in."""

UNIT_EXAMPLES: dict[str, str] = {
    "temperature": "K, degC, °C, C, degF, °F, F",
    "pressure": "Pa, kPa, MPa, bar, psi, atm; gauge: barg, bar(g), kPag, psig",
    "mass_flow": "kg/s, g/s, kg/h, lb/min, lb/h",
    "fraction": "1, %",
    "speed": "Hz, rps, rpm, 1/min",
    "power": "W, kW",
}
"""Quantity -> examples of the units :func:`unit_converter` accepts for it (for messages)."""

_SI_UNIT = {
    quantity: "dimensionless" if unit == "1" else unit
    for unit, quantity in QUANTITY_OF_UNIT.items()
}
_ALIASES = {
    "temperature": {"C": "degC", "F": "degF"},
    "fraction": {"fraction": "dimensionless", "-": "dimensionless"},
}
_GAUGE_SUFFIXES = ("(g)", "g")
_ABSOLUTE_SUFFIXES = ("(a)", "a")
_UNPARSABLE = (pint.errors.PintError, ValueError, TypeError, AttributeError, SyntaxError)


@cache
def _registry() -> pint.UnitRegistry:
    """pint's registry with a revolution counted as 1, so that rpm / 60 = Hz = rev/s."""
    registry = pint.UnitRegistry(on_redefinition="ignore")
    registry.define("turn = 1 = revolution = cycle = rev")
    return registry


def _parse_unit(text: str, quantity: str) -> pint.Unit | None:
    """The pint unit ``text`` names if it measures ``quantity``, else None."""
    registry = _registry()
    text = _ALIASES.get(quantity, {}).get(text, text)
    try:
        unit = registry.Unit(text)
    except _UNPARSABLE:
        return None
    target = registry.Unit(_SI_UNIT[quantity])
    return unit if unit.dimensionality == target.dimensionality else None


def unit_converter(
    unit: str, quantity: str, atmospheric_pressure: float = ATMOSPHERIC_PRESSURE
) -> Callable[[np.ndarray], np.ndarray]:
    """A function converting values in ``unit`` to SI for ``quantity`` (with pint).

    Quantities and their SI units: ``temperature`` (K), ``pressure`` (Pa, absolute; a ``g`` or
    ``(g)`` suffix marks gauge, e.g. ``barg``: ``atmospheric_pressure`` Pa is added; ``a`` or
    ``(a)`` marks absolute), ``mass_flow`` (kg/s), ``fraction`` (1; ``%`` allowed), ``speed``
    (Hz = rev/s; ``rpm`` allowed), ``power`` (W). Any unit pint knows of the right dimension is
    accepted; ``C`` and ``F`` mean °C and °F. Raises ``ValueError`` naming examples of allowed
    units.
    """
    text = unit.strip()
    parsed = _parse_unit(text, quantity)
    gauge = False
    if parsed is None and quantity == "pressure":
        for suffixes, is_gauge in ((_GAUGE_SUFFIXES, True), (_ABSOLUTE_SUFFIXES, False)):
            stem = next((text[: -len(s)] for s in suffixes if text.endswith(s)), None)
            if stem and (parsed := _parse_unit(stem.strip(), "pressure")) is not None:
                gauge = is_gauge
                break
    if parsed is None:
        raise ValueError(
            f"unknown {quantity} unit {unit!r}; allowed are units of {quantity} such as "
            f"{UNIT_EXAMPLES[quantity]}"
        )
    registry = _registry()
    target = registry.Unit(_SI_UNIT[quantity])
    offset = atmospheric_pressure if gauge else 0.0

    def convert(values: np.ndarray) -> np.ndarray:
        magnitudes = np.asarray(values, dtype=float)
        return registry.Quantity(magnitudes, parsed).to(target).magnitude + offset

    return convert


def time_unit_seconds(time_unit: str) -> float:
    """Seconds in one ``time_unit`` (any pint unit of time: s, ms, min, h, ...); raises
    ``ValueError`` for anything else."""
    registry = _registry()
    try:
        unit = registry.Unit(time_unit)
    except _UNPARSABLE:
        unit = None
    if unit is None or unit.dimensionality != registry.Unit("s").dimensionality:
        raise ValueError(
            f"unknown time_unit {time_unit!r}; allowed are units of time such as s, ms, min, h"
        )
    return float(registry.Quantity(1.0, unit).to("s").magnitude)
