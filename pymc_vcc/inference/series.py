"""Output time series as (outputs × time) arrays: conversion from xarray and validation.

A simulator or a measurement gives its outputs either as an :class:`xarray.Dataset` with one
1-D variable per output (over time), or as an array of shape (outputs, time). Inference works on
the array form; this module converts, selects outputs by name and checks observed data before
any simulation runs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import xarray as xr

OutputData = xr.Dataset | np.ndarray
"""What a simulator returns and what observed data may be: a Dataset or an (outputs, time) array."""


class InvalidOutputError(ValueError):
    """A simulation result that cannot be compared with the observed data."""


def default_output_names(n_outputs: int) -> tuple[str, ...]:
    """Names given to the rows of an unnamed (outputs, time) array: ``y0``, ``y1``, ..."""
    return tuple(f"y{j}" for j in range(n_outputs))


@dataclass(frozen=True)
class ObservedData:
    """Validated observed outputs.

    Attributes:
        all_names: names of every output the data holds (array rows, or Dataset variables).
        names: the outputs used for inference, a subset of ``all_names`` in the order given.
        values: float array (len(names), n_time) of the outputs used.
        dataset: the observed outputs as an xarray Dataset (for the ``observed_data`` group).
    """

    all_names: tuple[str, ...]
    names: tuple[str, ...]
    values: np.ndarray
    dataset: xr.Dataset

    @cached_property
    def row_indices(self) -> tuple[int, ...]:
        """Positions of ``names`` among ``all_names`` (the rows taken from simulated arrays)."""
        return tuple(self.all_names.index(name) for name in self.names)


def _check_names(requested: Sequence[str], available: Sequence[str], what: str) -> None:
    if isinstance(requested, str):
        raise TypeError(f"{what} must be a sequence of output names, got the string {requested!r}")
    unknown = [name for name in requested if name not in available]
    if unknown:
        raise ValueError(f"unknown {what} {unknown}; available outputs: {list(available)}")
    if len(set(requested)) != len(requested):
        raise ValueError(f"{what} {list(requested)} name an output more than once")
    if not requested:
        raise ValueError(f"{what} is empty; name at least one of {list(available)}")


def prepare_observed(
    observed: OutputData,
    outputs: Sequence[str] | None = None,
    output_names: Sequence[str] | None = None,
) -> ObservedData:
    """Validate observed data and select the outputs used for inference.

    Args:
        observed: a Dataset with one 1-D variable per output (all the same length), or an array
            (outputs, time); a 1-D array is one output.
        outputs: names of the outputs to use (default: all of them).
        output_names: names of the rows of an array (default ``y0, y1, ...``); ignored for a
            Dataset. A simulator's ``output_names`` attribute is the usual source.

    Raises:
        ValueError: empty data, NaN or infinite values, wrong dimensions, unknown output names.
    """
    if isinstance(observed, xr.Dataset):
        all_names = tuple(str(name) for name in observed.data_vars)
        if not all_names:
            raise ValueError("observed Dataset has no variables; expected one per output")
        selected = tuple(outputs) if outputs is not None else all_names
        _check_names(selected, all_names, "outputs")
        lengths = {}
        for name in selected:
            variable = observed[name]
            if variable.ndim != 1:
                raise ValueError(
                    f"observed output {name!r} has dims {variable.dims}; expected one (time) dim"
                )
            lengths[name] = variable.size
        if len(set(lengths.values())) != 1:
            raise ValueError(f"observed outputs differ in length {lengths}; expected one grid")
        values = np.stack([np.asarray(observed[name].values, dtype=float) for name in selected])
        dataset = observed[list(selected)]
    else:
        array = np.asarray(observed, dtype=float)
        if array.ndim == 1:
            array = array[np.newaxis, :]
        if array.ndim != 2:
            raise ValueError(
                f"observed array has shape {array.shape}; expected (outputs, time) or (time,)"
            )
        if output_names is None:
            all_names = default_output_names(array.shape[0])
        else:
            all_names = tuple(output_names)
            if len(all_names) != array.shape[0]:
                raise ValueError(
                    f"observed array has {array.shape[0]} rows but the simulator names "
                    f"{len(all_names)} outputs {list(all_names)}; expected shape "
                    f"({len(all_names)}, n_time)"
                )
        selected = tuple(outputs) if outputs is not None else all_names
        _check_names(selected, all_names, "outputs")
        values = array[[all_names.index(name) for name in selected]]
        dataset = xr.Dataset(
            {name: ("time", row) for name, row in zip(selected, values, strict=True)}
        )
    if values.shape[1] == 0:
        raise ValueError("observed data have no time points")
    bad = ~np.isfinite(values)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise ValueError(
            f"observed output {selected[row]!r} has {int(bad[row].sum())} non-finite value(s), "
            f"the first at time index {int(col)} ({values[row, col]}); observed data must be finite"
        )
    return ObservedData(all_names=all_names, names=selected, values=values, dataset=dataset)


def extract_outputs(result: OutputData, observed: ObservedData) -> np.ndarray:
    """The outputs of one simulation as a float array (len(observed.names), n_time).

    A Dataset gives its variables by name; an array gives its rows in ``observed.all_names``
    order. Raises :class:`InvalidOutputError` naming what is missing or misshapen.
    """
    if isinstance(result, xr.Dataset):
        missing = [name for name in observed.names if name not in result.data_vars]
        if missing:
            raise InvalidOutputError(f"simulation result lacks output(s) {missing}")
        rows = [np.asarray(result[name].values, dtype=float) for name in observed.names]
        shapes = {row.shape for row in rows}
        if len(shapes) != 1 or len(rows[0].shape) != 1:
            raise InvalidOutputError(
                f"simulated outputs must be 1-D over one time grid; got shapes "
                f"{[row.shape for row in rows]}"
            )
        return np.stack(rows)
    array = np.asarray(result, dtype=float)
    if array.ndim == 1 and len(observed.all_names) == 1:
        array = array[np.newaxis, :]
    if array.ndim != 2 or array.shape[0] != len(observed.all_names):
        raise InvalidOutputError(
            f"simulated array has shape {array.shape}; expected ({len(observed.all_names)}, "
            "n_time), one row per observed output"
        )
    return array[list(observed.row_indices)]
