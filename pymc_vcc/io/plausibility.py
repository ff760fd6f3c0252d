"""Measured outputs that cannot be right for their declared unit: refused before any work.

A refrigerant pressure of 27 Pa or a discharge temperature of 68 K is not a measurement but a
wrong unit declaration (27 bar declared as Pa, 68 °C declared as K). :func:`check_plausible`
compares the median of a column, converted to SI, with the range a vapor-compression cycle can
reach, and names the unit under which the file's numbers would be plausible.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pymc_vcc.physics.cycles import MEASURABLE_OUTPUT_INFO

PLAUSIBLE_SI: dict[str, tuple[float, float]] = {
    "Pa": (3e4, 7e6),  # refrigerant pressure: 0.3 to 70 bar absolute
    "K": (200.0, 450.0),  # refrigerant temperature: -73 to 177 °C
    "kg/s": (1e-4, 2.0),  # compressor mass flow: 0.1 g/s to 2 kg/s
    "W": (10.0, 1e6),  # compressor electrical power: 10 W to 1 MW
}
"""Range of the median of a measured output, by SI unit, that a vapor-compression cycle can
reach (wide: it catches unit mistakes, which are off by factors of 10 to 10^5, not faults)."""

COMMON_UNITS: dict[str, dict[str, tuple[float, float]]] = {
    # SI unit -> unit -> (scale, offset), SI = value * scale + offset; most likely first
    "Pa": {"bar": (1e5, 0.0), "kPa": (1e3, 0.0), "MPa": (1e6, 0.0), "psi": (6894.757, 0.0)}
    | {"Pa": (1.0, 0.0)},
    "K": {"degC": (1.0, 273.15), "degF": (5 / 9, 273.15 - 160 / 9), "K": (1.0, 0.0)},
    "kg/s": {"g/s": (1e-3, 0.0), "kg/h": (1 / 3600, 0.0), "kg/min": (1 / 60, 0.0)}
    | {"lb/h": (0.45359237 / 3600, 0.0), "kg/s": (1.0, 0.0)},
    "W": {"kW": (1e3, 0.0), "W": (1.0, 0.0)},
}
"""Units a logger commonly writes, per SI unit, to name the likely one."""

_SPELLINGS = {"°C": "degC", "C": "degC", "°F": "degF"}


def _known_unit(declared: str, units: Mapping[str, tuple[float, float]]) -> str | None:
    text = _SPELLINGS.get(declared.strip(), declared.strip())
    for suffix in ("(g)", "(a)", "g", "a", ""):  # gauge or absolute: same magnitude
        stem = text[: len(text) - len(suffix)].strip() if text.endswith(suffix) else None
        if stem in units:
            return stem
    return None


def check_plausible(output: str, column: str, values_si: np.ndarray, declared_unit: str) -> None:
    """Refuse a measured ``output`` whose median (SI) is implausible for a cycle.

    Args:
        output: the output id (inputs, unknown ids and outputs in a unit without a range in
            :data:`PLAUSIBLE_SI` are not checked).
        column: the file column, for the message.
        values_si: the column's values converted to SI (NaN for missing ones).
        declared_unit: the unit the column was declared in.

    Raises:
        ValueError: naming the column, its median and the likely unit.
    """
    if output not in MEASURABLE_OUTPUT_INFO:
        return
    si_unit = MEASURABLE_OUTPUT_INFO[output][1]
    if si_unit not in PLAUSIBLE_SI:
        return
    low, high = PLAUSIBLE_SI[si_unit]
    finite = np.asarray(values_si, dtype=float)
    finite = finite[np.isfinite(finite)]
    if finite.size == 0:
        return
    median = float(np.median(finite))
    if low <= median <= high:
        return
    units = COMMON_UNITS[si_unit]
    declared = _known_unit(declared_unit, units)
    hint = ""
    if declared is not None:
        scale, offset = units[declared]
        number = (median - offset) / scale  # the median as written in the file
        likely = [
            u for u, (s, o) in units.items() if u != declared and low <= number * s + o <= high
        ]
        if likely:
            hint = f"; the numbers look like {likely[0]}, not {declared_unit}"
    long_name = MEASURABLE_OUTPUT_INFO[output][0].lower()
    raise ValueError(
        f"column {column!r} ({output}, {long_name}): median {median:.4g} "
        f"{si_unit} is implausible (expected {low:g} to {high:g} {si_unit}){hint}; check its "
        "declared unit"
    )
