"""Measured data: CSV logs of a real unit as simulator inputs and observed outputs (SI).

A log holds a time column (seconds or ISO-8601 datetimes), the four inputs and some or all of the
nine outputs, in engineering units, sampled irregularly, with gaps. :func:`load_measurements`
maps file columns to ids, converts to SI (K, Pa absolute, kg/s, valve fraction, speed in Hz),
and resamples onto a regular grid of spacing ``dt`` (s, the unit's output interval):

* every variable is interpolated linearly between its own valid (finite) samples, but never
  across a *gap*: two consecutive valid samples more than ``max_gap`` seconds apart;
* the simulator needs every input at every instant, so a gap in any input (or in the rows
  themselves) **cuts** the record into segments; one segment is kept (the longest, or the one
  asked for) and its time restarts at 0 s;
* a gap in an output only **masks** that stretch: grid times where any loaded output has no
  data are left out of the observed Dataset (its ``time`` is then the simulation grid with
  holes; the KS distance compares value distributions, so it needs no regular times);
* inputs are held piecewise constant (as :mod:`pymc_vcc.physics.inputs` profiles are) over blocks of
  ``input_hold`` seconds, each block at the mean of its resampled values. The solver restarts
  at every step of an input, so a short hold costs run time (built-in unit, 1060 s: ~0.3 s with
  the 10 s default, ~2.5 s with a 1 s hold).

Everything dropped is listed in the :class:`MeasurementReport` returned beside the data.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from importlib import resources
from pathlib import Path

import numpy as np
import xarray as xr

from pymc_vcc.io.plausibility import check_plausible
from pymc_vcc.physics.cycles import OUTPUT_IDS, OUTPUT_INFO
from pymc_vcc.physics.inputs import INPUT_IDS, make_inputs

EXAMPLE_LOG = "example_log.csv"
"""File name of the example field log inside ``pymc_vcc/data``."""

ATMOSPHERIC_PRESSURE = 101325.0
"""Default ambient pressure added to gauge pressures, Pa."""

_LINEAR: dict[str, dict[str, tuple[float, float]]] = {
    # quantity -> unit -> (scale, offset) with SI = value * scale + offset
    "temperature": {
        "K": (1.0, 0.0),
        "degC": (1.0, 273.15),
        "°C": (1.0, 273.15),
        "C": (1.0, 273.15),
        "degF": (5.0 / 9.0, 273.15 - 32.0 * 5.0 / 9.0),
        "°F": (5.0 / 9.0, 273.15 - 32.0 * 5.0 / 9.0),
    },
    "pressure": {
        "Pa": (1.0, 0.0),
        "kPa": (1e3, 0.0),
        "MPa": (1e6, 0.0),
        "bar": (1e5, 0.0),
        "psi": (6894.757293168, 0.0),
    },
    "mass_flow": {
        "kg/s": (1.0, 0.0),
        "g/s": (1e-3, 0.0),
        "kg/min": (1.0 / 60.0, 0.0),
        "kg/h": (1.0 / 3600.0, 0.0),
        "lb/h": (0.45359237 / 3600.0, 0.0),
    },
    "fraction": {"1": (1.0, 0.0), "fraction": (1.0, 0.0), "%": (0.01, 0.0)},
    "speed": {
        "Hz": (1.0, 0.0),
        "rps": (1.0, 0.0),
        "1/s": (1.0, 0.0),
        "rpm": (1.0 / 60.0, 0.0),
        "1/min": (1.0 / 60.0, 0.0),
    },
}
_GAUGE_SUFFIXES = ("(g)", "g")
_ABSOLUTE_SUFFIXES = ("(a)", "a")

_QUANTITY: dict[str, str] = {
    "valve_opening": "fraction",
    "compressor_speed": "speed",
    "T_ambient": "temperature",
    "T_indoor": "temperature",
    "TD": "temperature",
    "PD": "pressure",
    "TS": "temperature",
    "PS": "pressure",
    "TC": "temperature",
    "PC": "pressure",
    "TE": "temperature",
    "PE": "pressure",
    "MDOT": "mass_flow",
}
"""The physical quantity of every input and output id."""

_TIME_UNITS = {"s": 1.0, "ms": 1e-3, "min": 60.0, "h": 3600.0}
_MISSING = {"", "nan", "na", "n/a", "null", "none", "-"}


def _allowed_units(quantity: str) -> list[str]:
    units = list(_LINEAR[quantity])
    if quantity == "pressure":
        units += [u + "g" for u in ("bar", "kPa", "MPa", "psi")] + ["bar(g)", "bara", "bar(a)"]
    return units


def unit_converter(
    unit: str, quantity: str, atmospheric_pressure: float = ATMOSPHERIC_PRESSURE
) -> Callable[[np.ndarray], np.ndarray]:
    """A function converting values in ``unit`` to SI for ``quantity``.

    Quantities: ``temperature`` (K, degC, degF), ``pressure`` (Pa, kPa, MPa, bar, psi, absolute;
    a ``g`` or ``(g)`` suffix marks gauge, e.g. ``barg``: ``atmospheric_pressure`` Pa is added;
    ``a``/``(a)`` marks absolute), ``mass_flow`` (kg/s, g/s, kg/min, kg/h, lb/h), ``fraction``
    (1, %), ``speed`` (Hz, rps, rpm). Raises ``ValueError`` naming the allowed units.
    """
    table = _LINEAR[quantity]
    text = unit.strip()
    gauge = False
    if quantity == "pressure" and text not in table:
        for suffixes, is_gauge in ((_GAUGE_SUFFIXES, True), (_ABSOLUTE_SUFFIXES, False)):
            stem = next((text[: -len(s)] for s in suffixes if text.endswith(s)), None)
            if stem is not None and stem.strip() in table:
                text, gauge = stem.strip(), is_gauge
                break
    if text not in table:
        raise ValueError(
            f"unknown {quantity} unit {unit!r}; allowed are {_allowed_units(quantity)}"
        )
    scale, offset = table[text]
    if gauge:
        offset += atmospheric_pressure

    def convert(values: np.ndarray) -> np.ndarray:
        return np.asarray(values, dtype=float) * scale + offset

    return convert


@dataclass(frozen=True)
class Gap:
    """A stretch without data: ``variable`` (an id, or ``"rows"`` for the whole log) has no
    valid sample between ``start`` and ``end`` (s since the first row of the file)."""

    variable: str
    start: float
    end: float

    @property
    def duration(self) -> float:
        """Length of the gap, s."""
        return self.end - self.start


@dataclass(frozen=True)
class MeasurementReport:
    """What :func:`load_measurements` read, kept and dropped.

    Attributes:
        source: the file read.
        n_rows: data rows in the file.
        time_origin: the first row's timestamp as written in the file.
        median_interval: median spacing of the rows, s.
        missing_values: file column -> number of empty or NaN cells.
        gaps: every gap longer than ``max_gap``, in s since the first row.
        segments: the (start, end) stretches where every input has data, s since the first row.
        kept: the segment kept; its start is time 0 of the returned Datasets.
        dropped_seconds: length of the log outside ``kept``, s.
        outputs: the output ids loaded.
        masked_points: output id -> grid points of ``kept`` where it has no data.
        n_grid: grid points of ``kept``; n_observed: those with every output (the observed time).
    """

    source: str
    n_rows: int
    time_origin: str
    median_interval: float
    missing_values: dict[str, int]
    gaps: tuple[Gap, ...]
    segments: tuple[tuple[float, float], ...]
    kept: tuple[float, float]
    dropped_seconds: float
    outputs: tuple[str, ...]
    masked_points: dict[str, int] = field(default_factory=dict)
    n_grid: int = 0
    n_observed: int = 0

    def __str__(self) -> str:
        lines = [
            f"{self.source}: {self.n_rows} rows from {self.time_origin}, "
            f"median interval {self.median_interval:.2f} s",
            f"outputs loaded: {', '.join(self.outputs)}",
        ]
        missing = {name: n for name, n in self.missing_values.items() if n}
        if missing:
            lines.append(f"empty cells: {missing}")
        for gap in self.gaps:
            lines.append(
                f"gap in {gap.variable}: {gap.start:.1f} s to {gap.end:.1f} s "
                f"({gap.duration:.1f} s)"
            )
        lines.append(
            f"kept {self.kept[0]:.1f} s to {self.kept[1]:.1f} s of {len(self.segments)} "
            f"segment(s); dropped {self.dropped_seconds:.1f} s"
        )
        masked = {name: n for name, n in self.masked_points.items() if n}
        lines.append(
            f"observed at {self.n_observed} of {self.n_grid} grid points"
            + (f" (masked: {masked})" if masked else "")
        )
        return "\n".join(lines)


@dataclass(frozen=True)
class Measurements:
    """Measured data ready for calibration.

    Attributes:
        inputs: input profile (SI) for :func:`~pymc_vcc.physics.simulate.simulate` and
            :class:`~pymc_vcc.physics.simulate.VCCSimulator`, from 0 s to the end of the kept
            segment.
        observed: the loaded outputs (SI, ``units`` attrs) at the grid times where all have data.
        report: what was read, kept and dropped.
    """

    inputs: xr.Dataset
    observed: xr.Dataset
    report: MeasurementReport


def _read_table(path: Path) -> tuple[list[str], list[list[str]]]:
    with path.open(newline="", encoding="utf-8-sig") as handle:
        sample = handle.read(4096)
        handle.seek(0)
        try:
            dialect = csv.Sniffer().sniff(sample, delimiters=",;\t")
        except csv.Error:
            dialect = csv.excel
        rows = [row for row in csv.reader(handle, dialect) if any(cell.strip() for cell in row)]
    if len(rows) < 3:
        raise ValueError(f"{path}: expected a header row and at least two data rows")
    header = [cell.strip() for cell in rows[0]]
    if len(set(header)) != len(header):
        duplicates = sorted({name for name in header if header.count(name) > 1})
        raise ValueError(f"{path}: duplicate column name(s) {duplicates}")
    for number, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise ValueError(
                f"{path}: line {number} has {len(row)} fields; the header has {len(header)}"
            )
    return header, rows[1:]


def _column_values(path: Path, name: str, cells: list[str]) -> np.ndarray:
    values = np.empty(len(cells))
    for k, cell in enumerate(cells):
        text = cell.strip()
        if text.lower() in _MISSING:
            values[k] = np.nan
            continue
        try:
            values[k] = float(text)
        except ValueError:
            raise ValueError(
                f"{path}: column {name!r}, line {k + 2}: {text!r} is not a number"
            ) from None
    return values


def _parse_times(path: Path, name: str, cells: list[str], time_unit: str) -> np.ndarray:
    """Seconds since the first row (numbers in ``time_unit``, or ISO-8601 datetimes)."""
    first = cells[0].strip()
    try:
        float(first)
        numeric = True
    except ValueError:
        numeric = False
    if numeric:
        if time_unit not in _TIME_UNITS:
            raise ValueError(f"unknown time_unit {time_unit!r}; allowed are {list(_TIME_UNITS)}")
        seconds = _column_values(path, name, cells) * _TIME_UNITS[time_unit]
    else:
        seconds = np.empty(len(cells))
        for k, cell in enumerate(cells):
            try:
                stamp = datetime.fromisoformat(cell.strip())
            except ValueError:
                raise ValueError(
                    f"{path}: time column {name!r}, line {k + 2}: {cell!r} is neither a number "
                    "nor an ISO-8601 datetime (e.g. 2024-07-01T14:03:07)"
                ) from None
            if stamp.tzinfo is None:
                stamp = stamp.replace(tzinfo=UTC)
            seconds[k] = stamp.timestamp()
    if not np.all(np.isfinite(seconds)):
        line = int(np.argmin(np.isfinite(seconds))) + 2
        raise ValueError(f"{path}: time column {name!r} is empty or NaN on line {line}")
    steps = np.diff(seconds)
    if not np.all(steps > 0):
        k = int(np.argmin(steps > 0)) + 1
        raise ValueError(
            f"{path}: time must be strictly increasing; line {k + 2} ({cells[k].strip()!r}) "
            f"does not come after line {k + 1} ({cells[k - 1].strip()!r})"
        )
    return seconds - seconds[0]


def _gaps(variable: str, times: np.ndarray, max_gap: float) -> list[Gap]:
    steps = np.diff(times)
    return [
        Gap(variable, float(times[k]), float(times[k + 1])) for k in np.flatnonzero(steps > max_gap)
    ]


def _segments(start: float, end: float, gaps: list[Gap]) -> list[tuple[float, float]]:
    """The stretches of [start, end] between the (possibly overlapping) gaps."""
    pieces = []
    cursor = start
    for gap in sorted(gaps, key=lambda g: g.start):
        if gap.start > cursor:
            pieces.append((cursor, gap.start))
        cursor = max(cursor, gap.end)
    if end > cursor:
        pieces.append((cursor, end))
    return pieces


def _resample(
    times: np.ndarray, values: np.ndarray, grid: np.ndarray, max_gap: float
) -> np.ndarray:
    """Linear interpolation of the valid samples on ``grid``; NaN outside them or in gaps."""
    valid = np.isfinite(values)
    t, v = times[valid], values[valid]
    result = np.full(grid.size, np.nan)
    if t.size == 0:
        return result
    inside = (grid >= t[0]) & (grid <= t[-1])
    result[inside] = np.interp(grid[inside], t, v)
    right = np.clip(np.searchsorted(t, grid, side="right"), 1, max(t.size - 1, 1))
    left = right - 1
    in_gap = (t[right] - t[left] > max_gap) & (grid > t[left]) & (grid < t[right])
    result[in_gap] = np.nan
    return result


def _held_inputs(resampled: dict[str, np.ndarray], dt: float, hold: float) -> xr.Dataset:
    n_grid = next(iter(resampled.values())).size
    per_block = max(1, round(hold / dt))
    starts = np.arange(0, n_grid - 1, per_block)
    values = {
        name: np.append(
            np.add.reduceat(series[:-1], starts) / np.diff(np.append(starts, n_grid - 1)),
            series[-1],
        )
        for name, series in resampled.items()
    }
    time = np.append(starts * dt, (n_grid - 1) * dt)
    return make_inputs(time, **values)


def load_measurements(
    path: str | Path,
    columns: Mapping[str, str],
    units: Mapping[str, str] | None = None,
    *,
    time_column: str = "time",
    time_unit: str = "s",
    dt: float = 1.0,
    max_gap: float = 30.0,
    input_hold: float = 10.0,
    segment: int | None = None,
    atmospheric_pressure: float = ATMOSPHERIC_PRESSURE,
) -> Measurements:
    """Load a measured CSV log as simulator inputs and observed outputs in SI units.

    Args:
        path: CSV file (``,``, ``;`` or tab separated) with a header row.
        columns: file column -> id, one for each of the four inputs (:data:`INPUT_IDS`) and at
            least one output (:data:`~pymc_vcc.physics.cycles.OUTPUT_IDS`); other file columns are
            ignored.
        units: file column -> unit (see :func:`unit_converter`); a column missing here may carry
            its unit in its header, ``"name [unit]"``.
        time_column: the file column of the timestamps: numbers in ``time_unit`` (s, ms, min, h)
            or ISO-8601 datetimes (time zone: UTC unless written).
        dt: spacing of the simulation grid, s (the unit's ``solver.output_interval``).
        max_gap: longest stretch without samples that interpolation may bridge, s.
        input_hold: inputs are held constant over blocks of this length, s (a multiple of dt).
        segment: which gap-free input segment to keep (0 = first; default: the longest).
        atmospheric_pressure: added to gauge pressures, Pa.

    Returns:
        :class:`Measurements` with ``inputs``, ``observed`` and ``report``.

    Raises:
        FileNotFoundError: no such file.
        ValueError: missing columns or inputs, unknown ids or units, non-numeric cells,
            non-monotonic time, an output without data, inputs outside their allowed range,
            no segment of at least two grid steps.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"measurement file {path} does not exist")
    for name, value in (("dt", dt), ("max_gap", max_gap), ("input_hold", input_hold)):
        if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive number of seconds, got {value!r}")
    if max_gap < dt:
        raise ValueError(f"max_gap = {max_gap} s must be at least dt = {dt} s")
    header, rows = _read_table(path)
    bare = {_strip_unit(name): name for name in header}

    def find(column: str) -> str:
        if column in header:
            return column
        if column in bare:
            return bare[column]
        raise ValueError(f"{path}: column {column!r} not found; the file has columns {header}")

    ids = list(columns.values())
    known = set(INPUT_IDS) | set(OUTPUT_IDS)
    unknown = [name for name in ids if name not in known]
    if unknown:
        raise ValueError(
            f"columns map to unknown id(s) {unknown}; allowed are {list(INPUT_IDS)} (inputs) "
            f"and {list(OUTPUT_IDS)} (outputs)"
        )
    repeated = sorted({name for name in ids if ids.count(name) > 1})
    if repeated:
        raise ValueError(f"columns map several file columns to {repeated}")
    missing_inputs = [name for name in INPUT_IDS if name not in ids]
    if missing_inputs:
        raise ValueError(f"columns must map a file column to every input; missing {missing_inputs}")
    outputs = tuple(name for name in OUTPUT_IDS if name in ids)
    if not outputs:
        raise ValueError(f"columns must map at least one output of {list(OUTPUT_IDS)}")

    time_name = find(time_column)
    time_index = header.index(time_name)
    times = _parse_times(path, time_name, [row[time_index] for row in rows], time_unit)
    units = dict(units or {})
    raw: dict[str, np.ndarray] = {}
    missing_values: dict[str, int] = {}
    for column, variable in columns.items():
        file_column = find(column)
        unit = units.get(column, units.get(file_column, _header_unit(file_column)))
        if unit is None:
            raise ValueError(
                f"{path}: no unit for column {column!r} ({variable}); give units={{{column!r}: "
                f"...}} from {_allowed_units(_QUANTITY[variable])}"
            )
        try:
            convert = unit_converter(unit, _QUANTITY[variable], atmospheric_pressure)
        except ValueError as error:
            raise ValueError(f"{path}: column {column!r} ({variable}): {error}") from None
        index = header.index(file_column)
        values = _column_values(path, file_column, [row[index] for row in rows])
        missing_values[column] = int(np.isnan(values).sum())
        if missing_values[column] == values.size:
            raise ValueError(f"{path}: column {column!r} ({variable}) has no values (all empty)")
        raw[variable] = convert(values)
        check_plausible(variable, column, raw[variable], unit)

    row_gaps = _gaps("rows", times, max_gap)
    outages = {(gap.start, gap.end) for gap in row_gaps}

    def variable_gaps(names: tuple[str, ...]) -> list[Gap]:
        """Gaps of single variables, except those of the whole log (reported once as rows)."""
        found = [g for n in names for g in _gaps(n, times[np.isfinite(raw[n])], max_gap)]
        return [gap for gap in found if (gap.start, gap.end) not in outages]

    input_gaps = variable_gaps(INPUT_IDS)
    output_gaps = variable_gaps(outputs)
    start = max(float(times[np.isfinite(raw[name])][0]) for name in INPUT_IDS)
    end = min(float(times[np.isfinite(raw[name])][-1]) for name in INPUT_IDS)
    pieces = [(a, b) for a, b in _segments(start, end, row_gaps + input_gaps) if b - a >= 2 * dt]
    if not pieces:
        raise ValueError(
            f"{path}: no stretch of at least {2 * dt} s has every input; gaps: "
            f"{[(g.variable, g.start, g.end) for g in row_gaps + input_gaps]}"
        )
    if segment is None:
        chosen = max(range(len(pieces)), key=lambda k: pieces[k][1] - pieces[k][0])
    elif not 0 <= segment < len(pieces):
        raise ValueError(
            f"segment = {segment}, but the log has {len(pieces)} gap-free segment(s) {pieces}"
        )
    else:
        chosen = segment
    kept = pieces[chosen]
    grid = np.arange(0.0, kept[1] - kept[0] + 1e-9, dt)
    absolute = kept[0] + grid

    resampled_inputs = {name: _resample(times, raw[name], absolute, max_gap) for name in INPUT_IDS}
    try:
        inputs = _held_inputs(resampled_inputs, dt, input_hold)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None

    observed_values = {name: _resample(times, raw[name], absolute, max_gap) for name in outputs}
    for name, series in observed_values.items():
        if not np.isfinite(series).any():
            raise ValueError(
                f"{path}: output {name} has no data in the kept segment {kept[0]:.1f} s to "
                f"{kept[1]:.1f} s"
            )
    complete = np.logical_and.reduce([np.isfinite(s) for s in observed_values.values()])
    observed = xr.Dataset(
        {
            name: (
                "time",
                series[complete],
                {"units": OUTPUT_INFO[name][1], "long_name": OUTPUT_INFO[name][0]},
            )
            for name, series in observed_values.items()
        },
        coords={"time": ("time", grid[complete], {"units": "s"})},
        attrs={"source": str(path), "t_offset": kept[0]},
    )
    inputs.attrs.update({"source": str(path), "t_offset": kept[0]})
    report = MeasurementReport(
        source=str(path),
        n_rows=len(rows),
        time_origin=rows[0][time_index].strip(),
        median_interval=float(np.median(np.diff(times))),
        missing_values=missing_values,
        gaps=tuple(sorted(row_gaps + input_gaps + output_gaps, key=lambda g: g.start)),
        segments=tuple(pieces),
        kept=kept,
        dropped_seconds=float(times[-1] - (kept[1] - kept[0])),
        outputs=outputs,
        masked_points={name: int((~np.isfinite(s)).sum()) for name, s in observed_values.items()},
        n_grid=int(grid.size),
        n_observed=int(complete.sum()),
    )
    return Measurements(inputs=inputs, observed=observed, report=report)


def _strip_unit(column: str) -> str:
    return column.split("[", 1)[0].strip() if column.endswith("]") else column


def _header_unit(column: str) -> str | None:
    if column.endswith("]") and "[" in column:
        return column[:-1].split("[", 1)[1].strip()
    return None


EXAMPLE_COLUMNS: dict[str, str] = {
    "EEV_position_pct": "valve_opening",
    "Compressor_rpm": "compressor_speed",
    "T_outdoor_C": "T_ambient",
    "T_return_air_C": "T_indoor",
    "T_discharge_C": "TD",
    "P_discharge_barg": "PD",
    "T_suction_C": "TS",
    "P_suction_barg": "PS",
    "T_liquid_C": "TC",
    "T_evap_out_C": "TE",
    "Mass_flow_g_s": "MDOT",
}
"""Column mapping of the example log (file column -> id)."""

EXAMPLE_UNITS: dict[str, str] = {
    "EEV_position_pct": "%",
    "Compressor_rpm": "rpm",
    "T_outdoor_C": "degC",
    "T_return_air_C": "degC",
    "T_discharge_C": "degC",
    "P_discharge_barg": "barg",
    "T_suction_C": "degC",
    "P_suction_barg": "barg",
    "T_liquid_C": "degC",
    "T_evap_out_C": "degC",
    "Mass_flow_g_s": "g/s",
}
"""Units of the example log's columns."""


def example_log_path() -> Path:
    """Path of the example field log shipped in ``pymc_vcc/data/example_log.csv``: the built-in
    unit at nominal parameters on the built-in profile from 300 s to 1800 s, sampled every
    1.5-3.5 s with sensor noise, an 80 s logger outage and a 45 s suction-temperature drop-out
    (made by ``scripts/make_example_log.py``). Load it with ``load_measurements(path,
    EXAMPLE_COLUMNS, EXAMPLE_UNITS, time_column="Timestamp")``."""
    return Path(str(resources.files("pymc_vcc").joinpath("data", EXAMPLE_LOG)))
