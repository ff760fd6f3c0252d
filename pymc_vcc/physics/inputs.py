"""Input profiles of the cycle: valve opening, compressor speed, ambient and indoor temperature.

An input profile is an ``xarray.Dataset`` over ``time`` (s, starting at 0, strictly increasing)
with the four variables of :data:`INPUTS`, SI units in their ``units`` attrs. Values are held
constant from one time to the next (zero-order hold, as the step profiles of the paper's Fig. 4);
the last time is the end of the profile. CSV files carry a ``time [s]`` column and one
``name [unit]`` column per input; temperatures may be given in ``degC``.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

BUILTIN_PROFILE = "fig4_steps.csv"
"""File name of the built-in 2120 s step profile inside ``pymc_vcc/data``."""

WINTER_PROFILE = "winter_day_steps.csv"
"""A winter day for the heat pump in ``pymc_vcc/data``: 2400 s of steps, outdoor -7 to 8 °C,
indoor 20 to 22 °C, the compressor faster when it is colder."""


@dataclass(frozen=True)
class InputSpec:
    """One input: id, long name, SI unit and the physically allowed range [low, high]."""

    id: str
    name: str
    unit: str
    low: float
    high: float


INPUTS: tuple[InputSpec, ...] = (
    InputSpec("valve_opening", "Expansion valve opening", "1", 0.02, 1.0),
    InputSpec("compressor_speed", "Compressor speed", "Hz", 10.0, 150.0),
    InputSpec("T_ambient", "Outdoor (ambient) air temperature", "K", 253.15, 323.15),
    InputSpec("T_indoor", "Indoor air temperature", "K", 283.15, 313.15),
)
"""The four inputs in the order the cycle reads them."""

INPUT_IDS: tuple[str, ...] = tuple(spec.id for spec in INPUTS)

OPTIONAL_INPUTS: tuple[tuple[InputSpec, float], ...] = (
    (InputSpec("RH_indoor", "Indoor relative humidity", "1", 0.0, 1.0), 0.0),
)
"""Inputs a profile may carry, with the value used when it does not (RH 0: dry indoor air, as
in the paper; with RH > 0 the indoor coil dehumidifies where it is below the dew point)."""

CYCLE_INPUT_IDS: tuple[str, ...] = INPUT_IDS + tuple(spec.id for spec, _ in OPTIONAL_INPUTS)
"""Every input the cycle reads, in order: the four required, then the optional ones."""

_ALL_INPUTS = INPUTS + tuple(spec for spec, _ in OPTIONAL_INPUTS)
_DEFAULTS = {spec.id: default for spec, default in OPTIONAL_INPUTS}

_CELSIUS_OFFSET = 273.15


def make_inputs(time: ArrayLike, **values: ArrayLike) -> xr.Dataset:
    """Build and validate an input Dataset from arrays in SI units (one value per time)."""
    time = np.asarray(time, dtype=float)
    data_vars = {}
    for spec in _ALL_INPUTS:
        if spec.id not in values:
            if spec.id in _DEFAULTS:
                continue
            raise ValueError(f"input {spec.id!r} is missing; required inputs are {INPUT_IDS}")
        array = np.broadcast_to(np.asarray(values[spec.id], dtype=float), time.shape)
        data_vars[spec.id] = ("time", array.copy(), {"units": spec.unit, "long_name": spec.name})
    unknown = sorted(set(values) - set(CYCLE_INPUT_IDS))
    if unknown:
        raise ValueError(f"unknown input(s) {unknown}; allowed inputs are {CYCLE_INPUT_IDS}")
    dataset = xr.Dataset(data_vars, coords={"time": ("time", time, {"units": "s"})})
    validate_inputs(dataset)
    return dataset


def validate_inputs(inputs: xr.Dataset) -> None:
    """Raise ``ValueError`` naming the problem if ``inputs`` is not a valid input profile."""
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
    missing = [pid for pid in INPUT_IDS if pid not in inputs.data_vars]
    if missing:
        raise ValueError(f"inputs: missing variable(s) {missing}; required are {INPUT_IDS}")
    unknown = sorted(str(name) for name in set(inputs.data_vars) - set(CYCLE_INPUT_IDS))
    if unknown:
        raise ValueError(f"inputs: unknown variable(s) {unknown}; allowed are {CYCLE_INPUT_IDS}")
    for spec in _ALL_INPUTS:
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


def _parse_header(column: str) -> tuple[str, str]:
    column = column.strip()
    if not (column.endswith("]") and "[" in column):
        raise ValueError(f"CSV column {column!r}: expected a header of the form 'name [unit]'")
    name, unit = column[:-1].split("[", 1)
    return name.strip(), unit.strip()


def load_inputs_csv(path: str | Path) -> xr.Dataset:
    """Load an input profile from CSV (``time [s]`` plus one ``name [unit]`` column per input)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"input profile {path} does not exist")
    return _inputs_from_csv_text(path.read_text(), str(path))


def _inputs_from_csv_text(text: str, source: str) -> xr.Dataset:
    lines = [line for line in text.splitlines() if line.strip()]
    if len(lines) < 3:
        raise ValueError(f"{source}: expected a header and at least two rows")
    header = [_parse_header(column) for column in lines[0].split(",")]
    names = [name for name, _ in header]
    if names[0] != "time":
        raise ValueError(f"{source}: the first column must be 'time [s]', got {names[0]!r}")
    if len(set(names)) != len(names):
        raise ValueError(f"{source}: duplicate column names in {names}")
    rows = [line.split(",") for line in lines[1:]]
    for number, row in enumerate(rows, start=2):
        if len(row) != len(header):
            raise ValueError(
                f"{source}: every row needs {len(header)} values; line {number} has {len(row)}"
            )
    try:
        table = np.array([[float(cell) for cell in row] for row in rows], dtype=float)
    except ValueError as error:
        raise ValueError(f"{source}: non-numeric value ({error})") from None
    if header[0][1] != "s":
        raise ValueError(f"{source}: time must be in 's', got {header[0][1]!r}")
    specs = {spec.id: spec for spec in INPUTS}
    values = {}
    for column, (name, unit) in enumerate(header[1:], start=1):
        if name not in specs:
            raise ValueError(f"{source}: unknown input column {name!r}; allowed are {INPUT_IDS}")
        data = table[:, column]
        if specs[name].unit == "K" and unit == "degC":
            data = data + _CELSIUS_OFFSET
        elif unit != specs[name].unit:
            allowed = [specs[name].unit] + (["degC"] if specs[name].unit == "K" else [])
            raise ValueError(f"{source}: {name} has unit {unit!r}; allowed are {allowed}")
        values[name] = data
    return make_inputs(table[:, 0], **values)


def builtin_inputs(name: str = BUILTIN_PROFILE) -> xr.Dataset:
    """A shipped profile: by default the 2120 s step profile (the paper's Fig. 4 kind: every
    input stepped); :data:`WINTER_PROFILE` is the heat pump's winter day."""
    shipped = (BUILTIN_PROFILE, WINTER_PROFILE)
    if name not in shipped:
        raise ValueError(f"unknown shipped profile {name!r}; shipped are {list(shipped)}")
    text = resources.files("pymc_vcc").joinpath("data", name).read_text()
    return _inputs_from_csv_text(text, name)


def constant_inputs(
    duration: float,
    *,
    valve_opening: float,
    compressor_speed: float,
    T_ambient: float,
    T_indoor: float,
    **optional: float,
) -> xr.Dataset:
    """A profile holding the inputs constant for ``duration`` seconds (SI units); ``optional``
    may set the optional inputs (``RH_indoor``)."""
    return make_inputs(
        np.array([0.0, float(duration)]),
        valve_opening=valve_opening,
        compressor_speed=compressor_speed,
        T_ambient=T_ambient,
        T_indoor=T_indoor,
        **optional,
    )


def input_segments(inputs: xr.Dataset) -> tuple[np.ndarray, np.ndarray]:
    """Break points and held values: ``(edges, values)`` with ``values[k]`` (ordered as
    :data:`CYCLE_INPUT_IDS`, absent optional inputs at their default) held on
    ``[edges[k], edges[k + 1])``; rows that repeat the previous values are merged, so the solver
    restarts only where an input really steps."""
    time = np.asarray(inputs["time"].values, dtype=float)
    table = np.column_stack(
        [
            np.asarray(inputs[pid].values, dtype=float)
            if pid in inputs.data_vars
            else np.full(time.size, _DEFAULTS[pid])
            for pid in CYCLE_INPUT_IDS
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


def window(inputs: xr.Dataset, t_end: float) -> xr.Dataset:
    """The profile cut at ``t_end`` seconds (which must lie inside it)."""
    time = np.asarray(inputs["time"].values, dtype=float)
    if not 0.0 < t_end <= time[-1]:
        raise ValueError(f"t_end = {t_end} s must lie in (0, {time[-1]}] s")
    before = time < t_end
    cut = inputs.isel(time=np.flatnonzero(before))
    last = inputs.isel(time=[int(np.flatnonzero(before)[-1])]).assign_coords(time=[t_end])
    cut = xr.concat([cut, last], dim="time")
    cut["time"].attrs["units"] = "s"
    return cut
