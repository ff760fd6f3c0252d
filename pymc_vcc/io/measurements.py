"""Measured data: CSV logs of a real unit as simulator inputs and observed outputs (SI).

A log holds a time column (numbers in some time unit, or date-times in any common format),
the four inputs (and optionally the indoor relative humidity ``RH_indoor``) and some or all
of the nine outputs (and optionally the compressor's electrical power ``W_comp``), in
engineering units, sampled irregularly, with gaps. :func:`load_measurements` reads it with
pandas, maps file columns to ids, converts to SI with pint (K, Pa absolute, kg/s, W, valve
and humidity fractions, speed in rev/s = Hz), and resamples onto a regular grid of spacing
``dt`` (s, the unit's output interval):

* units come from ``units=``, from the header (``TD [degC]`` or ``TD (F)``) or from a row of
  units right under the header; ``C`` and ``F`` mean °C and °F, a ``g`` suffix marks a gauge
  pressure (``barg``, ``psig``, ``bar(g)``);
* numbers may use a decimal comma (``decimal=","``, found by itself in ``;``- or
  tab-separated files); date-times are parsed by pandas (ISO 8601, ``07/01/2024 02:00:00 PM``;
  day first when written with dots, ``01.07.2024 14:00:00``; ``time_format=`` otherwise);
* every variable is interpolated between its own valid (finite) samples, but never across a
  *gap*: two consecutive valid samples more than ``max_gap`` seconds apart;
* the simulator needs every input at every instant, so a gap in any input (or in the rows
  themselves) **cuts** the record into segments; one segment is kept (the longest, or the one
  asked for) and its time restarts at 0 s;
* a gap in an output only **masks** that stretch: grid times where any loaded output has no
  data are left out of the observed Dataset (its ``time`` is then the simulation grid with
  holes; the KS distance compares value distributions, so it needs no regular times);
* inputs are held piecewise constant (as :mod:`pymc_vcc.physics.inputs` profiles are) over blocks
  of ``input_hold`` seconds, each block at the mean of its resampled values. The commanded
  inputs (:data:`STEPPED_INPUTS`) are resampled by nearest sample, and each of their steps
  starts a new block, so a step is never smeared over a block. The solver restarts at every
  step of an input, so a short hold costs run time (built-in unit, 1060 s: ~0.3 s with the
  10 s default, ~2.5 s with a 1 s hold).

Everything dropped is listed in the :class:`MeasurementReport` returned beside the data.
"""

from __future__ import annotations

import csv
import itertools
import math
import re
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr

from pymc_vcc.io.plausibility import check_plausible
from pymc_vcc.physics.components.moist_air import ATMOSPHERIC_PRESSURE
from pymc_vcc.physics.csv_cells import DECIMAL_COMMA, MISSING_CELLS, is_number, split_header_unit
from pymc_vcc.physics.cycles import INPUTS, MEASURABLE_OUTPUT_INFO
from pymc_vcc.physics.inputs import INPUT_IDS, make_inputs
from pymc_vcc.physics.quantities import (
    QUANTITY_OF_UNIT,
    UNIT_EXAMPLES,
    time_unit_seconds,
    unit_converter,
)

EXAMPLE_LOG = "example_log.csv"
"""File name of the example field log inside ``pymc_vcc/data``."""

STEPPED_INPUTS: tuple[str, ...] = tuple(spec.id for spec in INPUTS if spec.stepped)
"""Inputs a controller sets in steps (the split unit's valve opening and compressor speed):
resampled by nearest sample, and held without averaging across a step (each step starts a new
hold block)."""

_DOTTED_DATE = re.compile(r"^\s*\d{1,2}\.\d{1,2}\.\d{2,4}")


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
        n_rows: data rows in the file (a units row not counted).
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
        units: file column -> the unit it was read in.
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
    units: dict[str, str] = field(default_factory=dict)

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


@dataclass(frozen=True)
class _Table:
    """A log as read: stripped header names, text cells, the units row (if any) and the file
    line number of the first data row."""

    header: list[str]
    cells: pd.DataFrame
    units_row: dict[str, str]
    first_line: int

    def column(self, name: str) -> pd.Series:
        return self.cells[self.header.index(name)]

    def line(self, row: int) -> int:
        """File line number (1-based) of data row ``row``."""
        return self.first_line + row


def _delimiter(path: Path) -> str:
    with path.open(newline="", encoding="utf-8-sig") as handle:
        sample = handle.read(4096)
    try:
        return csv.Sniffer().sniff(sample, delimiters=",;\t").delimiter
    except csv.Error:
        return ","


def _read_table(path: Path) -> tuple[_Table, str]:
    """The log's cells as text (pandas), and its delimiter."""
    delimiter = _delimiter(path)
    try:
        frame = pd.read_csv(
            path,
            sep=delimiter,
            header=None,
            dtype=str,
            keep_default_na=False,
            skip_blank_lines=True,
            encoding="utf-8-sig",
        )
    except pd.errors.ParserError as error:
        raise ValueError(f"{path}: {str(error).strip()}") from None
    except pd.errors.EmptyDataError:
        frame = pd.DataFrame()
    frame = frame.apply(lambda column: column.fillna("").str.strip())
    frame = frame[frame.ne("").any(axis=1)]
    if len(frame) < 3:
        raise ValueError(f"{path}: expected a header row and at least two data rows")
    header = list(frame.iloc[0])
    if len(set(header)) != len(header):
        duplicates = sorted({name for name in header if header.count(name) > 1})
        raise ValueError(f"{path}: duplicate column name(s) {duplicates}")
    cells = frame.iloc[1:].reset_index(drop=True)
    return _Table(header, cells, {}, 2), delimiter


def _split_units_row(table: _Table, value_columns: list[str], decimal: str) -> _Table:
    """Take a row of units right under the header out of the data, if there is one: every
    value column's first cell is text that is not a number (e.g. ``degC``, ``bar``)."""
    first = [table.column(name).iloc[0] for name in value_columns]
    if not all(
        cell and cell not in MISSING_CELLS and not is_number(cell, decimal) for cell in first
    ):
        return table
    units_row = {name: table.column(name).iloc[0] for name in table.header}
    cells = table.cells.iloc[1:].reset_index(drop=True)
    if len(cells) < 2:
        raise ValueError("expected at least two data rows under the units row")
    return _Table(table.header, cells, units_row, table.first_line + 1)


def _infer_decimal(table: _Table, value_columns: list[str], delimiter: str) -> str:
    """``","`` if the file is not comma-separated and its numbers are written ``27,5``."""
    if delimiter == ",":
        return "."
    sample = pd.concat([table.column(name).head(50) for name in value_columns])
    return "," if sample.str.match(DECIMAL_COMMA).any() else "."


def _column_values(path: Path, table: _Table, name: str, decimal: str) -> np.ndarray:
    """The numbers of file column ``name`` (NaN where empty); a non-number is an error."""
    text = table.column(name)
    missing = text.isin(MISSING_CELLS)
    normalised = text.str.replace(decimal, ".", regex=False) if decimal != "." else text
    values = pd.to_numeric(normalised.where(~missing), errors="coerce")
    bad = np.flatnonzero(values.isna() & ~missing)
    if bad.size:
        row = int(bad[0])
        raise ValueError(
            f"{path}: column {name!r}, line {table.line(row)}: {text.iloc[row]!r} is not a number"
            + (" (set decimal=',' for decimal commas)" if "," in text.iloc[row] else "")
        )
    return values.to_numpy(dtype=float)


def _parse_times(
    path: Path,
    table: _Table,
    name: str,
    time_unit: str,
    time_format: str | None,
    decimal: str,
) -> np.ndarray:
    """Seconds since the first row: numbers in ``time_unit``, or date-times parsed by pandas
    (``time_format`` if given, else ISO 8601 or the format pandas infers; day first when the
    date is written with dots). Zone-less date-times are taken as UTC."""
    cells = table.column(name)
    if is_number(cells.iloc[0], decimal):
        scale = time_unit_seconds(time_unit)
        seconds = _column_values(path, table, name, decimal) * scale
    else:
        stamps = _datetimes(cells, time_format)
        bad = np.flatnonzero(stamps.isna())
        if bad.size:
            row = int(bad[0])
            hint = "" if time_format else "; give time_format= (e.g. '%d/%m/%Y %H:%M:%S')"
            raise ValueError(
                f"{path}: time column {name!r}, line {table.line(row)}: {cells.iloc[row]!r} is "
                f"neither a number nor a date-time"
                + (f" in the format {time_format!r}" if time_format else hint)
            )
        nanoseconds = stamps.to_numpy(dtype="datetime64[ns]").astype(np.int64)
        seconds = (nanoseconds - nanoseconds[0]) / 1e9
    if not np.all(np.isfinite(seconds)):
        row = int(np.argmin(np.isfinite(seconds)))
        raise ValueError(f"{path}: time column {name!r} is empty or NaN on line {table.line(row)}")
    steps = np.diff(seconds)
    if not np.all(steps > 0):
        k = int(np.argmin(steps > 0)) + 1
        raise ValueError(
            f"{path}: time must be strictly increasing; line {table.line(k)} "
            f"({cells.iloc[k]!r}) does not come after line {table.line(k - 1)} "
            f"({cells.iloc[k - 1]!r})"
        )
    return seconds - seconds[0]


def _datetimes(cells: pd.Series, time_format: str | None) -> pd.Series:
    """Date-times (UTC) of ``cells``, NaT where they do not parse."""
    if time_format is not None:
        return pd.to_datetime(cells, format=time_format, utc=True, errors="coerce")
    iso = pd.to_datetime(cells, format="ISO8601", utc=True, errors="coerce")
    if not iso.isna().any():
        return iso
    dayfirst = bool(_DOTTED_DATE.match(cells.iloc[0]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "could not infer format": per element
        inferred = pd.to_datetime(cells, dayfirst=dayfirst, utc=True, errors="coerce")
    return inferred if inferred.isna().sum() < iso.isna().sum() else iso


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
    times: np.ndarray, values: np.ndarray, grid: np.ndarray, max_gap: float, *, stepped: bool
) -> np.ndarray:
    """The valid samples on ``grid`` (pandas): linear in time, or the nearest sample if
    ``stepped``; NaN outside the samples and inside gaps longer than ``max_gap``."""
    valid = np.isfinite(values)
    samples = pd.Series(values[valid], index=times[valid])
    if samples.empty:
        return np.full(grid.size, np.nan)
    if stepped:
        result = samples.reindex(grid, method="nearest").to_numpy(dtype=float, copy=True)
    else:
        union = samples.reindex(samples.index.union(grid))
        interpolated = union.interpolate(method="index", limit_area="inside")
        result = interpolated.reindex(grid).to_numpy(dtype=float, copy=True)
    t = samples.index.to_numpy()
    result[(grid < t[0]) | (grid > t[-1])] = np.nan
    right = np.clip(np.searchsorted(t, grid, side="right"), 1, max(t.size - 1, 1))
    left = right - 1
    in_gap = (t[right] - t[left] > max_gap) & (grid > t[left]) & (grid < t[right])
    result[in_gap] = np.nan
    return result


def _block_starts(resampled: dict[str, np.ndarray], per_block: int) -> np.ndarray:
    """Grid indices where hold blocks start: every ``per_block`` points from each step of a
    stepped input (and from 0); a last block shorter than half a block joins the one before."""
    n_grid = next(iter(resampled.values())).size
    steps = {0}
    for name in STEPPED_INPUTS:
        steps.update((np.flatnonzero(np.diff(resampled[name][:-1]) != 0) + 1).tolist())
    edges = [*sorted(steps), n_grid - 1]
    starts = []
    for first, end in itertools.pairwise(edges):
        piece = list(range(first, end, per_block))
        if len(piece) > 1 and end - piece[-1] < per_block / 2:
            piece.pop()
        starts += piece
    return np.asarray(starts)


def _held_inputs(resampled: dict[str, np.ndarray], dt: float, hold: float) -> xr.Dataset:
    n_grid = next(iter(resampled.values())).size
    starts = _block_starts(resampled, max(1, round(hold / dt)))
    lengths = np.diff(np.append(starts, n_grid - 1))
    values = {
        name: np.append(np.add.reduceat(series[:-1], starts) / lengths, series[-1])
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
    time_format: str | None = None,
    decimal: str | None = None,
    dt: float = 1.0,
    max_gap: float = 30.0,
    input_hold: float = 10.0,
    segment: int | None = None,
    atmospheric_pressure: float = ATMOSPHERIC_PRESSURE,
) -> Measurements:
    """Load a measured CSV log as simulator inputs and observed outputs in SI units.

    Args:
        path: CSV file (``,``, ``;`` or tab separated) with a header row, optionally followed by
            a row of units.
        columns: file column -> id, one for each of the four inputs (:data:`INPUT_IDS`), at
            most one for ``RH_indoor`` (fraction or %; default: dry air), and at least one output
            of :data:`~pymc_vcc.physics.cycles.MEASURABLE_OUTPUT_INFO` (the nine, and ``W_comp``
            in W or kW); other file columns are ignored. A file column may be named with or
            without its header unit.
        units: file column -> unit (see :func:`~pymc_vcc.physics.quantities.unit_converter`);
            a column missing here carries its unit in its header (``"name [unit]"`` or
            ``"name (unit)"``) or in the units row.
        time_column: the file column of the timestamps: numbers in ``time_unit`` or date-times.
        time_unit: unit of numeric timestamps (any unit of time: s, ms, min, h).
        time_format: ``strftime`` format of the date-times (e.g. ``"%d/%m/%Y %H:%M:%S"``);
            default: ISO 8601 or the format pandas infers from the first row (US month first
            with slashes, day first with dots). Zone-less times are taken as UTC.
        decimal: the decimal mark (``"."`` or ``","``); default: ``","`` if the file is not
            comma-separated and its numbers are written with a comma, else ``"."``.
        dt: spacing of the simulation grid, s (``simulate``'s default output interval).
        max_gap: longest stretch without samples that interpolation may bridge, s.
        input_hold: inputs are held constant over blocks of this length, s (a multiple of dt);
            a step of a commanded input (:data:`STEPPED_INPUTS`) starts a new block.
        segment: which gap-free input segment to keep (0 = first; default: the longest).
        atmospheric_pressure: added to gauge pressures, Pa.

    Returns:
        :class:`Measurements` with ``inputs``, ``observed`` and ``report``.

    Raises:
        FileNotFoundError: no such file.
        ValueError: missing columns or inputs, unknown ids or units, non-numeric cells,
            unparseable or non-monotonic time, an output without data, inputs outside their
            allowed range, no segment of at least two grid steps.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"measurement file {path} does not exist")
    for name, value in (("dt", dt), ("max_gap", max_gap), ("input_hold", input_hold)):
        if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive number of seconds, got {value!r}")
    if max_gap < dt:
        raise ValueError(f"max_gap = {max_gap} s must be at least dt = {dt} s")
    if decimal not in (None, ".", ","):
        raise ValueError(f"decimal must be '.' or ',' (or None to infer it), got {decimal!r}")
    ids = list(columns.values())
    known = set(INPUTS.ids) | set(MEASURABLE_OUTPUT_INFO)
    unknown = [name for name in ids if name not in known]
    if unknown:
        raise ValueError(
            f"columns map to unknown id(s) {unknown}; allowed are {list(INPUTS.ids)} "
            f"(inputs) and {list(MEASURABLE_OUTPUT_INFO)} (outputs)"
        )
    repeated = sorted({name for name in ids if ids.count(name) > 1})
    if repeated:
        raise ValueError(f"columns map several file columns to {repeated}")
    missing_inputs = [name for name in INPUT_IDS if name not in ids]
    if missing_inputs:
        raise ValueError(f"columns must map a file column to every input; missing {missing_inputs}")
    inputs_read = tuple(name for name in INPUTS.ids if name in ids)
    outputs = tuple(name for name in MEASURABLE_OUTPUT_INFO if name in ids)
    if not outputs:
        raise ValueError(f"columns must map at least one output of {list(MEASURABLE_OUTPUT_INFO)}")

    table, delimiter = _read_table(path)
    bare = {split_header_unit(name)[0]: name for name in table.header}

    def find(column: str) -> str:
        if column in table.header:
            return column
        if column in bare:
            return bare[column]
        raise ValueError(
            f"{path}: column {column!r} not found; the file has columns {table.header}"
        )

    file_columns = {column: find(column) for column in columns}
    time_name = find(time_column)
    value_columns = list(file_columns.values())
    try:
        table = _split_units_row(table, value_columns, decimal or ".")
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None
    decimal = decimal or _infer_decimal(table, value_columns, delimiter)
    times = _parse_times(path, table, time_name, time_unit, time_format, decimal)

    given_units = dict(units or {})
    raw: dict[str, np.ndarray] = {}
    missing_values: dict[str, int] = {}
    read_units: dict[str, str] = {}
    for column, variable in columns.items():
        file_column = file_columns[column]
        unit = (
            given_units.get(column)
            or given_units.get(file_column)
            or split_header_unit(file_column)[1]
            or table.units_row.get(file_column)
        )
        quantity = QUANTITY_OF_UNIT[
            INPUTS[variable].unit if variable in INPUTS.ids else MEASURABLE_OUTPUT_INFO[variable][1]
        ]
        if unit is None:
            raise ValueError(
                f"{path}: no unit for column {column!r} ({variable}); give units={{{column!r}: "
                f"...}} with a unit of {quantity} such as {UNIT_EXAMPLES[quantity]}"
            )
        try:
            convert = unit_converter(unit, quantity, atmospheric_pressure)
        except ValueError as error:
            raise ValueError(f"{path}: column {column!r} ({variable}): {error}") from None
        values = _column_values(path, table, file_column, decimal)
        missing_values[column] = int(np.isnan(values).sum())
        if missing_values[column] == values.size:
            raise ValueError(f"{path}: column {column!r} ({variable}) has no values (all empty)")
        raw[variable] = convert(values)
        check_plausible(variable, column, raw[variable], unit)
        read_units[column] = unit

    row_gaps = _gaps("rows", times, max_gap)
    outages = {(gap.start, gap.end) for gap in row_gaps}

    def variable_gaps(names: tuple[str, ...]) -> list[Gap]:
        """Gaps of single variables, except those of the whole log (reported once as rows)."""
        found = [g for n in names for g in _gaps(n, times[np.isfinite(raw[n])], max_gap)]
        return [gap for gap in found if (gap.start, gap.end) not in outages]

    input_gaps = variable_gaps(inputs_read)
    output_gaps = variable_gaps(outputs)
    start = max(float(times[np.isfinite(raw[name])][0]) for name in inputs_read)
    end = min(float(times[np.isfinite(raw[name])][-1]) for name in inputs_read)
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

    resampled_inputs = {
        name: _resample(times, raw[name], absolute, max_gap, stepped=name in STEPPED_INPUTS)
        for name in inputs_read
    }
    try:
        inputs = _held_inputs(resampled_inputs, dt, input_hold)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None

    observed_values = {
        name: _resample(times, raw[name], absolute, max_gap, stepped=False) for name in outputs
    }
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
                {
                    "units": MEASURABLE_OUTPUT_INFO[name][1],
                    "long_name": MEASURABLE_OUTPUT_INFO[name][0],
                },
            )
            for name, series in observed_values.items()
        },
        coords={"time": ("time", grid[complete], {"units": "s"})},
        attrs={"source": str(path), "t_offset": kept[0]},
    )
    inputs.attrs.update({"source": str(path), "t_offset": kept[0]})
    report = MeasurementReport(
        source=str(path),
        n_rows=len(table.cells),
        time_origin=table.column(time_name).iloc[0],
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
        units=read_units,
    )
    return Measurements(inputs=inputs, observed=observed, report=report)


COLUMN_MAP_SUFFIX = ".columns.toml"
"""A log's column map sits beside it: ``LOG.csv`` -> ``LOG.columns.toml``."""


@dataclass(frozen=True)
class ColumnMap:
    """How to read a log: file column -> id, file column -> unit, and the time column.

    Written as TOML: ``time_column = "..."`` (optionally ``time_unit``, ``time_format``), a
    ``[columns]`` table (file column = id) and an optional ``[units]`` table (file column =
    unit).

    Attributes:
        columns: file column -> input or output id (as ``load_measurements``'s ``columns``).
        units: file column -> unit, for columns whose header and units row give none.
        time_column: the file column of the timestamps.
        time_unit: unit of numeric timestamps (s, ms, min, h).
        time_format: ``strftime`` format of date-times (default: inferred).
    """

    columns: dict[str, str]
    units: dict[str, str] = field(default_factory=dict)
    time_column: str = "time"
    time_unit: str = "s"
    time_format: str | None = None


def load_column_map(path: str | Path) -> ColumnMap:
    """Read a column map (TOML, see :class:`ColumnMap`); errors name the file and the key.

    Args:
        path: the TOML file.
    """
    import tomllib

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"column map {path} does not exist")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as error:
        raise ValueError(f"column map {path} is not valid TOML: {error}") from None
    allowed = {"columns", "units", "time_column", "time_unit", "time_format"}
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise ValueError(
            f"column map {path}: unknown key(s) {unknown}; allowed are {sorted(allowed)}"
        )
    columns = data.get("columns")
    if not isinstance(columns, dict) or not columns:
        raise ValueError(f"column map {path} needs a [columns] table: file column = id")
    for table in ("columns", "units"):
        bad = [k for k, v in data.get(table, {}).items() if not isinstance(v, str)]
        if bad:
            raise ValueError(f"column map {path}: [{table}] values must be strings, not for {bad}")
    return ColumnMap(
        columns=dict(columns),
        units=dict(data.get("units", {})),
        time_column=str(data.get("time_column", "time")),
        time_unit=str(data.get("time_unit", "s")),
        time_format=data.get("time_format"),
    )


def column_map_beside(log: str | Path) -> Path:
    """Where the column map of ``log`` is looked for: ``LOG.columns.toml`` beside it."""
    log = Path(log)
    return log.with_name(log.stem + COLUMN_MAP_SUFFIX)


def load_log(
    path: str | Path, column_map: str | Path | ColumnMap | None = None, **options
) -> Measurements:
    """:func:`load_measurements` with a column map (default: the one beside the log);
    ``options`` as for :func:`load_measurements`.

    Args:
        path: the CSV log.
        column_map: a :class:`ColumnMap` or its TOML file (default: ``LOG.columns.toml``
            beside the log).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"log {path} does not exist")
    if column_map is None:
        beside = column_map_beside(path)
        if not beside.is_file():
            raise FileNotFoundError(
                f"no column map for {path}: write {beside} ([columns] file column = id) or pass one"
            )
        column_map = beside
    if not isinstance(column_map, ColumnMap):
        column_map = load_column_map(column_map)
    return load_measurements(
        path,
        column_map.columns,
        column_map.units,
        time_column=column_map.time_column,
        time_unit=column_map.time_unit,
        time_format=column_map.time_format,
        **options,
    )


def example_log_path() -> Path:
    """Path of the example field log shipped in ``pymc_vcc/data/example_log.csv``: the built-in
    unit at nominal parameters on the built-in profile from 300 s to 1800 s, sampled every
    1.5-3.5 s with sensor noise, an 80 s logger outage and a 45 s suction-temperature drop-out
    (made by ``scripts/make_example_log.py``). Its column map ships beside it, so
    ``load_log(example_log_path())`` reads it."""
    return Path(str(resources.files("pymc_vcc").joinpath("data", EXAMPLE_LOG)))
