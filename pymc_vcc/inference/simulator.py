"""The simulator contract samplers rely on, checked once per run.

A simulator is any picklable callable ``simulator(theta, rng) -> outputs`` (:class:`Simulator`):
parameters by name (SI units), a random generator, outputs as a Dataset or an (outputs, time)
array. It may also name its parameters (:class:`NamesParameters`) and outputs
(:class:`NamesOutputs`) and give its parameter box (:class:`BoundedSimulator`), as
:class:`~pymc_vcc.physics.simulate.VCCSimulator` does.
:func:`check_simulator` reads all of it once, into a :class:`SimulatorInfo`;
:func:`run_simulation` runs it once, every failure captured in the outcome.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
import xarray as xr

from pymc_vcc.execution.outcomes import OK, SimulationOutcome, SimulationTimeout, time_limit
from pymc_vcc.inference.series import InvalidOutputError, ObservedData, OutputData, extract_outputs
from pymc_vcc.physics.failures import FailureKind

Bounds = dict[str, tuple[float, float]]


@runtime_checkable
class Simulator(Protocol):
    """``simulator(theta, rng) -> outputs``; picklable (a module-level function, a
    ``functools.partial`` of one, or an instance of a module-level class) to run in other
    processes.

    Parameters
    ----------
    theta
        Parameter values by name, in the parameters' units (SI).
    rng
        A generator for a stochastic simulator (the cycle is deterministic and ignores it).
    """

    def __call__(
        self, theta: Mapping[str, float], rng: np.random.Generator | None, /
    ) -> OutputData: ...


@runtime_checkable
class NamesParameters(Protocol):
    """A simulator that names the parameters it takes, so samplers can check priors."""

    parameter_names: Sequence[str]


@runtime_checkable
class NamesOutputs(Protocol):
    """A simulator that names its outputs, so samplers can check observed data."""

    output_names: Sequence[str]


@runtime_checkable
class BoundedSimulator(Protocol):
    """A simulator that knows its parameters' physical bounds (name -> (low, high))."""

    bounds: Mapping[str, tuple[float, float]]


@runtime_checkable
class RestrictsPriors(Protocol):
    """A simulator valid only inside ``parameter_bounds`` (name -> (low, high)): samplers refuse
    priors that reach outside them; None allows any prior (extrapolation)."""

    parameter_bounds: Mapping[str, tuple[float, float]] | None


@dataclass(frozen=True)
class SimulatorInfo:
    """What a simulator tells about itself; ``None`` where it does not say."""

    parameter_names: tuple[str, ...] | None
    output_names: tuple[str, ...] | None
    bounds: Bounds | None
    support: Bounds | None


def check_simulator(simulator: Any) -> SimulatorInfo:
    """Check that ``simulator`` keeps the contract and read its description, once.

    Raises ``TypeError`` naming what is wrong: not callable, or names that are not sequences
    of strings.

    Parameters
    ----------
    simulator
        The callable to check (a :class:`Simulator`).
    """
    if not isinstance(simulator, Simulator):
        raise TypeError(
            f"the simulator must be callable as simulator(theta, rng), got "
            f"{type(simulator).__name__}"
        )
    parameter_names = output_names = None
    if isinstance(simulator, NamesParameters):
        parameter_names = _names(simulator, "parameter_names", simulator.parameter_names)
    if isinstance(simulator, NamesOutputs):
        output_names = _names(simulator, "output_names", simulator.output_names)
    bounds: Bounds | None = None
    if isinstance(simulator, BoundedSimulator):
        bounds = {name: (float(lo), float(hi)) for name, (lo, hi) in simulator.bounds.items()}
    support: Bounds | None = None
    if isinstance(simulator, RestrictsPriors) and simulator.parameter_bounds is not None:
        support = {
            name: (float(lo), float(hi)) for name, (lo, hi) in simulator.parameter_bounds.items()
        }
    return SimulatorInfo(parameter_names, output_names, bounds, support)


def _names(simulator: object, attribute: str, value: object) -> tuple[str, ...]:
    if isinstance(value, str) or not isinstance(value, Sequence):
        raise TypeError(
            f"{type(simulator).__name__}.{attribute} must be a sequence of names, got {value!r}"
        )
    names = tuple(value)
    if not all(isinstance(name, str) for name in names):
        raise TypeError(f"{type(simulator).__name__}.{attribute} must hold strings: {names}")
    return names


def run_simulation(
    simulator: Simulator,
    theta: Mapping[str, float],
    rng: np.random.Generator,
    observed: ObservedData,
    *,
    time_limit_s: float | None = None,
) -> SimulationOutcome:
    """Run ``simulator(theta, rng)`` and return its outputs in ``observed``'s layout, or why not
    (a :class:`~pymc_vcc.physics.failures.FailureKind` and a reason): nothing it does is fatal.
    A Dataset flagged ``attrs["status"] != "ok"`` fails with its ``attrs["failure_kind"]``
    (``reported`` when it names none of the kinds).

    Args:
        simulator: the model, ``simulator(theta, rng) -> Dataset | array``.
        theta: parameter values by name.
        rng: the run's own random generator.
        observed: validated observed data; selects and orders the outputs.
        time_limit_s: wall-time limit of the run, s (None: no limit).
    """
    start = time.perf_counter()
    try:
        with time_limit(time_limit_s):
            result = simulator(theta, rng)
    except SimulationTimeout:
        return SimulationOutcome.failed(
            FailureKind.TIME_LIMIT,
            f"exceeded the time limit of {time_limit_s} s",
            time.perf_counter() - start,
        )
    except Exception as exc:
        return SimulationOutcome.failed(
            FailureKind.EXCEPTION, f"{type(exc).__name__}: {exc}", time.perf_counter() - start
        )
    elapsed = time.perf_counter() - start
    if time_limit_s is not None and elapsed > time_limit_s:
        return SimulationOutcome.failed(
            FailureKind.TIME_LIMIT,
            f"took {elapsed:.3g} s, over the limit of {time_limit_s} s",
            elapsed,
        )
    if isinstance(result, xr.Dataset):
        status = result.attrs.get("status", OK)
        if status != OK:
            reason = result.attrs.get("failure_reason") or f"status {status!r}"
            return SimulationOutcome.failed(_reported_kind(result), str(reason), elapsed)
    try:
        values = extract_outputs(result, observed)
    except (InvalidOutputError, TypeError, ValueError) as exc:
        return SimulationOutcome.failed(FailureKind.INVALID_OUTPUT, str(exc), elapsed)
    finite = np.isfinite(values)
    if not finite.all():
        row = int(np.flatnonzero(~finite.all(axis=1))[0])
        count = int((~finite[row]).sum())
        reason = f"output {observed.names[row]!r} has {count} non-finite value(s)"
        return SimulationOutcome.failed(FailureKind.NON_FINITE, reason, elapsed)
    return SimulationOutcome(values, OK, "", elapsed)


def _reported_kind(result: xr.Dataset) -> FailureKind:
    """The kind a failed result names in ``attrs["failure_kind"]``; ``reported`` if none."""
    try:
        return FailureKind(result.attrs.get("failure_kind", ""))
    except ValueError:
        return FailureKind.REPORTED
