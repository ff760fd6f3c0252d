"""Input profiles of a cycle: valve opening, compressor speed, ambient and indoor temperature.

Each cycle model declares the inputs it reads
(:attr:`~pymc_vcc.physics.cycles.base.CycleModel.inputs`); this module knows them through
:data:`~pymc_vcc.physics.cycles.INPUTS`, every input some cycle reads. An input profile is an
``xarray.Dataset`` over ``time`` (s, starting at 0, strictly increasing) with one variable per
input, SI units in their ``units`` attrs. Values are held constant from one time to the next
(zero-order hold, as the step profiles of the paper's Fig. 4); the last time is the end of the
profile. CSV files (:func:`load_inputs_csv`) carry a time column and one column per input, in
any unit of the right kind (``degC``, ``%``, ``rpm``, ...), given in the header
(``T_ambient [degC]``), in a row of units under it, or SI for a bare name.
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Mapping
from importlib import resources
from pathlib import Path

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

from pymc_vcc.physics.csv_cells import DECIMAL_COMMA, MISSING_CELLS, is_number, split_header_unit
from pymc_vcc.physics.cycles import INPUTS
from pymc_vcc.physics.cycles.base import InputLayout
from pymc_vcc.physics.quantities import QUANTITY_OF_UNIT, time_unit_seconds, unit_converter

BUILTIN_PROFILE = "fig4_steps.csv"
"""File name of the built-in 2120 s step profile inside ``pymc_vcc/data``."""
CALIBRATION_SECONDS = 1060.0
"""The paper's calibration window, s: the first half of the built-in profile (the second half
is held out for prediction)."""

WINTER_PROFILE = "winter_day_steps.csv"
"""A winter day for the heat pump in ``pymc_vcc/data``: 2400 s of steps, outdoor -7 to 8 °C,
indoor 20 to 22 °C, the compressor faster when it is colder."""


INPUT_IDS: tuple[str, ...] = INPUTS.required_ids
"""Ids of the inputs every cycle requires, in order: ``valve_opening`` (fraction),
``compressor_speed`` (Hz), ``T_ambient`` and ``T_indoor`` (K)."""

_CELSIUS_OFFSET = 273.15


def make_inputs(time: ArrayLike, **values: ArrayLike) -> xr.Dataset:
    """Build and validate an input Dataset from arrays in SI units (one value per time).

    Parameters
    ----------
    time
        Times, s: starting at 0, strictly increasing; the last one is the end of the profile.
    **values
        One array (or scalar) per input id, SI: ``valve_opening`` (fraction),
        ``compressor_speed`` (Hz), ``T_ambient`` and ``T_indoor`` (K), optionally
        ``RH_indoor`` (fraction). Each value is held until the next time.
    """
    time = np.asarray(time, dtype=float)
    data_vars = {}
    for spec in INPUTS:
        if spec.id not in values:
            if spec.id in INPUTS.defaults:
                continue
            raise ValueError(f"input {spec.id!r} is missing; required inputs are {INPUT_IDS}")
        array = np.broadcast_to(np.asarray(values[spec.id], dtype=float), time.shape)
        data_vars[spec.id] = ("time", array.copy(), {"units": spec.unit, "long_name": spec.name})
    unknown = sorted(set(values) - set(INPUTS.ids))
    if unknown:
        raise ValueError(f"unknown input(s) {unknown}; allowed inputs are {INPUTS.ids}")
    dataset = xr.Dataset(data_vars, coords={"time": ("time", time, {"units": "s"})})
    validate_inputs(dataset)
    return dataset


def validate_inputs(inputs: xr.Dataset, layout: InputLayout = INPUTS) -> None:
    """Raise ``ValueError`` naming the problem if ``inputs`` is not a valid input profile of the
    inputs ``layout`` (a cycle model's ``inputs``; default: of any cycle)."""
    if not isinstance(inputs, xr.Dataset):
        raise ValueError(f"inputs must be an xarray.Dataset, got {type(inputs).__name__}")
    if "time" not in inputs.coords:
        raise ValueError("inputs need a 'time' coordinate in s")
    time = np.asarray(inputs["time"].values, dtype=float)
    if time.ndim != 1 or time.size < 2:
        raise ValueError("inputs need at least two times (the last one is the end time)")
    if not np.all(np.isfinite(time)):
        raise ValueError("inputs: time contains NaN or infinite values")
    if time[0] != 0.0:
        raise ValueError(f"inputs: time must start at 0 s, got {time[0]}")
    if not np.all(np.diff(time) > 0):
        bad = int(np.argmin(np.diff(time) > 0)) + 1
        raise ValueError(
            f"inputs: time must be strictly increasing; time[{bad}] = {time[bad]} s "
            f"follows {time[bad - 1]} s"
        )
    time_units = inputs["time"].attrs.get("units", "s")
    if time_units != "s":
        raise ValueError(f"inputs: time units must be 's', got {time_units!r}")
    missing = [pid for pid in layout.required_ids if pid not in inputs.data_vars]
    if missing:
        raise ValueError(
            f"inputs: missing variable(s) {missing}; required are {layout.required_ids}"
        )
    unknown = sorted(str(name) for name in set(inputs.data_vars) - set(layout.ids))
    if unknown:
        raise ValueError(f"inputs: unknown variable(s) {unknown}; allowed are {layout.ids}")
    for spec in layout:
        if spec.id not in inputs.data_vars:
            continue
        variable = inputs[spec.id]
        if variable.dims != ("time",):
            raise ValueError(f"inputs: {spec.id} must have dims ('time',), got {variable.dims}")
        units = variable.attrs.get("units")
        if units != spec.unit:
            raise ValueError(f"inputs: {spec.id} must have units {spec.unit!r}, got {units!r}")
        values = np.asarray(variable.values, dtype=float)
        if np.isnan(values).any():
            first = float(time[np.isnan(values)][0])
            raise ValueError(f"inputs: {spec.id} is NaN at time {first} s")
        outside = (values < spec.low) | (values > spec.high)
        if outside.any():
            index = int(np.argmax(outside))
            raise ValueError(
                f"inputs: {spec.id} = {values[index]} {spec.unit} at time {time[index]} s "
                f"is outside the allowed range [{spec.low}, {spec.high}]"
            )


_CELSIUS = ("degC", "°C", "C", "℃", "celsius")


def _converter(unit: str, input_id: str, source: str) -> Callable[[np.ndarray], np.ndarray]:
    """Values in ``unit`` to the SI unit of ``input_id``: SI, °C and % directly, anything else
    (``rpm``, ``degF``, ...) with pint, as the measured-log reader converts."""
    spec = INPUTS[input_id]
    if unit == spec.unit:
        return lambda values: values
    if spec.unit == "K" and unit in _CELSIUS:
        return lambda values: values + _CELSIUS_OFFSET
    if spec.unit == "1" and unit == "%":
        return lambda values: values / 100.0
    try:
        return unit_converter(unit, QUANTITY_OF_UNIT[spec.unit])
    except ValueError as error:
        raise ValueError(f"{source}: column {input_id}: {error}") from None


def load_inputs_csv(
    path: str | Path,
    units: Mapping[str, str] | None = None,
    *,
    columns: Mapping[str, str] | None = None,
    time_column: str = "time",
    time_unit: str = "s",
    decimal: str | None = None,
) -> xr.Dataset:
    """Load an input profile from a CSV file, converting its units to SI.

    The file reads as a measured log does (:func:`pymc_vcc.io.measurements.load_measurements`):
    separated by ``,``, ``;`` or tabs, a header row, optionally a row of units under it. Each
    column is named by an input id (``valve_opening``, ``compressor_speed``, ``T_ambient``,
    ``T_indoor``, optionally ``RH_indoor``), or by any name that ``columns`` maps to one. A
    column's unit comes from ``units``, else from its header (``T_ambient [degC]`` or
    ``T_ambient (degC)``), else from the units row; a bare name means SI (fraction, Hz, K). Any
    unit of the right kind converts: ``degC``, ``°C``, ``C``, ``degF``, ``%``, ``rpm``, ...
    Values are held from one row to the next; the last row is the end time.

    Parameters
    ----------
    path
        The CSV file.
    units
        File column -> unit, for columns whose header and units row do not give one.
    columns
        File column -> input id; other file columns are then ignored. Without it every
        column but the time must be named by an input id.
    time_column
        The column of the times: numbers from 0, strictly increasing, in ``time_unit`` (or
        the unit its header or the units row gives: any unit of time, ``s``, ``ms``, ``min``,
        ``h``, ...).
    time_unit
        Unit of the times when the file does not give one.
    decimal
        The decimal mark, ``"."`` or ``","`` (default: ``","`` if the file is not
        comma-separated and its numbers are written ``27,5``).

    Returns
    -------
    xarray.Dataset
        The input profile over ``time`` (s), SI units in ``units`` attrs.

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        Naming the file and what is wrong: a missing or unknown column, a unit of the wrong
        kind, a cell that is not a number, times that do not start at 0 or do not increase, a
        value outside the input's allowed range.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"input profile {path} does not exist")
    return _inputs_from_csv_text(
        path.read_text(encoding="utf-8-sig"),
        str(path),
        units=units,
        columns=columns,
        time_column=time_column,
        time_unit=time_unit,
        decimal=decimal,
    )


def _inputs_from_csv_text(
    text: str,
    source: str,
    *,
    units: Mapping[str, str] | None = None,
    columns: Mapping[str, str] | None = None,
    time_column: str = "time",
    time_unit: str = "s",
    decimal: str | None = None,
) -> xr.Dataset:
    lines = [line for line in text.splitlines() if line.strip()]
    if len(lines) < 3:
        raise ValueError(f"{source}: expected a header and at least two rows")
    try:
        delimiter = csv.Sniffer().sniff(lines[0], delimiters=",;\t").delimiter
    except csv.Error:
        delimiter = ","
    rows = [[cell.strip() for cell in row] for row in csv.reader(lines, delimiter=delimiter)]
    header = rows[0]
    if len(set(header)) != len(header):
        raise ValueError(f"{source}: duplicate column names in {header}")
    for number, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise ValueError(
                f"{source}: every row needs {len(header)} values; line {number} has {len(row)}"
            )
    names = [split_header_unit(column)[0] for column in header]
    if decimal not in (None, ".", ","):
        raise ValueError(f"decimal must be '.' or ',' (or None to infer it), got {decimal!r}")
    first_line = 2
    units_row: dict[str, str] = {}
    if all(
        cell and cell not in MISSING_CELLS and not is_number(cell, decimal or ".")
        for cell in rows[1]
    ):
        units_row = dict(zip(header, rows[1], strict=True))
        rows = [header, *rows[2:]]
        first_line = 3
        if len(rows) < 3:
            raise ValueError(f"{source}: expected at least two rows under the units row")
    if decimal is None:
        cells = [cell for row in rows[1:] for cell in row]
        decimal = "," if delimiter != "," and any(DECIMAL_COMMA.match(c) for c in cells) else "."

    given = dict(units or {})
    mapping = dict(columns or {})
    unknown_ids = sorted(set(mapping.values()) - set(INPUTS.ids))
    if unknown_ids:
        raise ValueError(f"columns map to unknown input(s) {unknown_ids}; allowed are {INPUTS.ids}")

    def find(column: str) -> int | None:
        if column in header:
            return header.index(column)
        return names.index(column) if column in names else None

    time_index = find(time_column)
    if time_index is None:
        raise ValueError(
            f"{source}: no {time_column!r} column (the times, s); the file has columns {header}"
        )
    selected: dict[str, int] = {}
    if mapping:
        for column, input_id in mapping.items():
            index = find(column)
            if index is None:
                raise ValueError(f"{source}: column {column!r} not found; the file has {header}")
            selected[input_id] = index
    else:
        for index, name in enumerate(names):
            if index == time_index:
                continue
            if name not in INPUTS.ids:
                raise ValueError(
                    f"{source}: unknown input column {name!r}; allowed are {INPUTS.ids} "
                    "(or map file columns to them with columns=)"
                )
            selected[name] = index

    def unit_of(index: int) -> str | None:
        column = header[index]
        return (
            given.get(column)
            or given.get(names[index])
            or split_header_unit(column)[1]
            or units_row.get(column)
        )

    def numbers(index: int) -> np.ndarray:
        values = np.empty(len(rows) - 1)
        for row_number, row in enumerate(rows[1:]):
            cell = row[index]
            if cell in MISSING_CELLS:
                values[row_number] = np.nan
                continue
            try:
                values[row_number] = float(cell.replace(decimal, ".") if decimal != "." else cell)
            except ValueError:
                raise ValueError(
                    f"{source}: column {header[index]!r}, line {first_line + row_number}: "
                    f"{cell!r} is not a number"
                ) from None
        return values

    try:
        seconds = time_unit_seconds(unit_of(time_index) or time_unit)
    except ValueError as error:
        raise ValueError(f"{source}: {error}") from None
    values = {}
    for input_id, index in selected.items():
        convert = _converter(unit_of(index) or INPUTS[input_id].unit, input_id, source)
        values[input_id] = convert(numbers(index))
    try:
        return make_inputs(numbers(time_index) * seconds, **values)
    except ValueError as error:
        raise ValueError(f"{source}: {error}") from None


def builtin_inputs(name: str = BUILTIN_PROFILE) -> xr.Dataset:
    """A shipped profile: by default the 2120 s step profile (the paper's Fig. 4 kind: every
    input stepped); :data:`WINTER_PROFILE` is the heat pump's winter day.

    Parameters
    ----------
    name
        File name of the profile inside ``pymc_vcc/data``.
    """
    shipped = (BUILTIN_PROFILE, WINTER_PROFILE)
    if name not in shipped:
        raise ValueError(f"unknown shipped profile {name!r}; shipped are {list(shipped)}")
    text = resources.files("pymc_vcc").joinpath("data", name).read_text()
    return _inputs_from_csv_text(text, name)


def constant_inputs(duration: float, **values: float) -> xr.Dataset:
    """A profile holding the inputs constant for ``duration`` seconds (SI units).

    Parameters
    ----------
    duration
        Length of the profile, s.
    **values
        One value per input, SI: the split unit's ``valve_opening`` (fraction of full opening,
        0.02 to 1), ``compressor_speed`` (Hz, 10 to 150), ``T_ambient`` and ``T_indoor`` (K),
        optionally ``RH_indoor`` (fraction, default 0: dry air).
    """
    return make_inputs(np.array([0.0, float(duration)]), **values)


def input_segments(
    inputs: xr.Dataset, layout: InputLayout = INPUTS
) -> tuple[np.ndarray, np.ndarray]:
    """Break points and held values: ``(edges, values)`` with ``values[k]`` (ordered as
    ``layout``, a cycle model's ``inputs``, absent optional inputs at their default) held on
    ``[edges[k], edges[k + 1])``; rows that repeat the previous values are merged, so the solver
    restarts only where an input really steps."""
    time = np.asarray(inputs["time"].values, dtype=float)
    table = np.column_stack(
        [
            np.asarray(inputs[pid].values, dtype=float)
            if pid in inputs.data_vars
            else np.full(time.size, layout.defaults[pid])
            for pid in layout.ids
        ]
    )
    keep = [0] + [k for k in range(1, time.size - 1) if np.any(table[k] != table[k - 1])]
    edges = np.append(time[keep], time[-1])
    return edges, table[keep]


def with_settling(inputs: xr.Dataset, seconds: float) -> xr.Dataset:
    """The profile preceded by ``seconds`` s at its first inputs (times shifted by ``seconds``):
    a unit that has run at those inputs before the record starts."""
    if not (np.isfinite(seconds) and seconds >= 0.0):
        raise ValueError(f"settling time must be a non-negative number of seconds, got {seconds}")
    if seconds == 0.0:
        return inputs
    first = inputs.isel(time=[0]).assign_coords(time=[0.0])
    shifted = inputs.assign_coords(time=inputs["time"].values + float(seconds))
    settled = xr.concat([first, shifted], dim="time")
    settled["time"].attrs["units"] = "s"
    return settled


def window(inputs: xr.Dataset, t_end: float, t_start: float = 0.0) -> xr.Dataset:
    """The profile from ``t_start`` to ``t_end`` seconds (both inside it), its time counted from
    ``t_start``: the inputs held at ``t_start`` begin it, those held at ``t_end`` end it."""
    time = np.asarray(inputs["time"].values, dtype=float)
    if not 0.0 < t_end <= time[-1]:
        raise ValueError(f"t_end = {t_end} s must lie in (0, {time[-1]}] s")
    if not 0.0 <= t_start < t_end:
        raise ValueError(f"t_start = {t_start} s must lie in [0, t_end = {t_end}) s")
    held = np.flatnonzero(time <= t_start)[-1]
    inside = np.flatnonzero((time > t_start) & (time < t_end))
    last = np.flatnonzero(time < t_end)[-1]
    cut = xr.concat(
        [
            inputs.isel(time=[held]).assign_coords(time=[t_start]),
            inputs.isel(time=inside),
            inputs.isel(time=[last]).assign_coords(time=[t_end]),
        ],
        dim="time",
    )
    cut = cut.assign_coords(time=cut["time"].values - t_start)
    cut["time"].attrs["units"] = "s"
    return cut
