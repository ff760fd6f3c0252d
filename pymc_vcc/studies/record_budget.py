"""The error budget of a unit's record: its plateaus, and the model's error against a unit
that is not the model (:mod:`pymc_vcc.inference.error_model` for the budget's parts).

The model's error is drawn: a unit whose coils lie between the model's and the continuum,
whose held parameters are off within what is known of them, whose logged inputs are off and
whose sensors lag. Finer coils read as the model at a higher charge (:class:`CoilOffset`); the
error is drawn against them at the charge that reads the same.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import xarray as xr
from scipy.special import expit, logit

from pymc_vcc.execution.executors import Executor
from pymc_vcc.execution.outcomes import finished
from pymc_vcc.inference.error_model import (
    ErrorBudget,
    SensorAccuracy,
    approximation_error,
    bias_covariance,
    error_moments,
    lagged,
    model_errors,
    noise_variance,
    plateau_windows,
    summarise,
)
from pymc_vcc.inference.priors import Prior
from pymc_vcc.physics.inputs import input_segments
from pymc_vcc.physics.simulate import VCCSimulator
from pymc_vcc.physics.unit import Unit

CHARGE = "M0"

FINE_VOLUMES = 20  # volumes per coil of the finer unit that stands for model-form error
CONTINUUM = 2.0
"""Where a real unit's coils lie, in steps of the model → :data:`FINE_VOLUMES` difference: the
coils converge to first order (the 10 → 20 difference is twice the 20 → 40 one for every output
at 1.2 and 1.9 kg), so the continuum is 2 steps away. A unit is drawn uniformly between the
model's own discretisation (0) and the continuum."""
COILS: tuple[str, ...] = ("finer", "model")
"""Whose coils made a record: ``finer``, a physical unit's (every real unit: between the
model's and the continuum); ``model``, the model's own (synthetic data, the paper's case)."""
RUNS_PER_DRAW = {"finer": 3, "model": 2}  # simulations of one model-error draw (ErrorPair)


def check_coils(coils: str) -> None:
    """Refuse a ``coils`` not in :data:`COILS`, in one line."""
    if coils not in COILS:
        raise ValueError(f"coils {coils!r}: allowed are {list(COILS)}")


FIXED_SPREAD = 0.2  # a parameter held fixed is known to ±20 % of nominal unless the unit says
ERROR_DRAWS = 96  # draws of the model-error statistics

COIL_OFFSET_CHARGES = 6  # charges at which the coils' charge offset is measured
COIL_OFFSET_STEP = 0.01  # kg between the model's charges searched for each offset


@dataclass(frozen=True)
class CoilOffset:
    """How much more charge the model needs than a unit with :data:`FINE_VOLUMES` coils to
    read the same: the model at ``charge + offset(charge)`` reproduces the finer unit at
    ``charge`` (kg; measured at nominal parameters on the record's inputs).

    A finer coil resolves where the refrigerant turns from two-phase to vapour, and holds a
    little less of it at the same pressures: most of the model's discretisation error on a
    record is this equivalent charge (on the built-in unit 0.03-0.05 kg at 20 volumes, 0.05
    at 30, 0.06 at 40: first order, like the outputs), not a misfit of the outputs' shapes.
    """

    charges: np.ndarray
    offsets: np.ndarray

    def __call__(self, charge: np.ndarray | float) -> np.ndarray:
        """The offset at ``charge`` (kg), held constant beyond the measured charges."""
        return np.interp(charge, self.charges, self.offsets)

    def unit_charge(self, model_charge: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The unit's charge of each model charge draw, kg: the unit's coils drawn, like the
        model-error draws, uniformly between the model's (offset 0) and the continuum
        (:data:`CONTINUUM` × the offset)."""
        fineness = rng.uniform(0.0, CONTINUUM, np.shape(model_charge))
        return model_charge - fineness * self(model_charge)


def coil_offset(
    model: VCCSimulator,
    fine_unit: Unit,
    scale: np.ndarray,
    windows: Sequence[np.ndarray],
    executor: Executor,
    charge_range: tuple[float, float],
) -> tuple[CoilOffset, int]:
    """Measure :class:`CoilOffset` over ``charge_range`` (kg), and count its simulations: the
    finer unit at :data:`COIL_OFFSET_CHARGES` charges, the model on a grid every
    :data:`COIL_OFFSET_STEP` kg, each offset where the summaries' misfit (in units of
    ``scale``) is least."""
    low, high = charge_range
    margin = 0.1 * (high - low)
    grid = np.arange(low - margin, high + margin + COIL_OFFSET_STEP / 2, COIL_OFFSET_STEP)
    charges = np.linspace(low, high, COIL_OFFSET_CHARGES + 2)[1:-1]
    fine, nominal = _unit_runs(model, fine_unit), _unit_runs(model, model.unit)
    tasks = [(fine, float(c)) for c in charges] + [(nominal, float(c)) for c in grid]
    runs = executor.map(_run_at_charge, tasks)
    summaries = [summarise(_series(run), windows) if finished(run) else None for run in runs]
    targets, candidates = summaries[: charges.size], summaries[charges.size :]
    usable = np.array([s is not None for s in candidates])
    model_grid = grid[usable]
    model_summaries = np.array([s for s in candidates if s is not None])
    measured, offsets = [], []
    for charge, target in zip(charges, targets, strict=True):
        if target is None or model_grid.size < 3:
            continue
        misfit = (((model_summaries - target) / scale) ** 2).sum(axis=1)
        best = int(np.argmin(misfit))
        if best in (0, model_grid.size - 1):
            continue
        measured.append(charge)
        offsets.append(
            _least(model_grid[best - 1 : best + 2], misfit[best - 1 : best + 2]) - charge
        )
    if not measured:
        raise RuntimeError(
            "the model reproduced the finer unit at none of the charges tried: no coil "
            "offset can be measured on this record"
        )
    return CoilOffset(np.array(measured), np.array(offsets)), len(tasks)


def _least(x: np.ndarray, y: np.ndarray) -> float:
    """Where the parabola through three points (``x`` increasing, ``y[1]`` the least) is
    least: the grid's spacing may be uneven where a run failed."""
    (x0, x1, x2), (y0, y1, y2) = x, y
    a, b = (x1 - x0) * (y1 - y2), (x1 - x2) * (y1 - y0)
    denominator = a - b
    if denominator == 0.0:
        return float(x1)
    return float(x1 - 0.5 * ((x1 - x0) * a - (x1 - x2) * b) / denominator)


def _unit_runs(model: VCCSimulator, unit: Unit, inputs: xr.Dataset | None = None) -> VCCSimulator:
    """``model``'s runs (outputs, window, solver, settling) of ``unit``, every parameter
    settable, on ``inputs`` (default: the model's)."""
    return VCCSimulator(
        unit,
        model.inputs if inputs is None else inputs,
        outputs=model.output_names,
        t_window=model.t_window,
        solver=model.solver,
        settle=model.settle,
    )


def _run_at_charge(task: tuple[VCCSimulator, float]) -> xr.Dataset:
    simulator, charge = task
    return simulator({CHARGE: charge})


def _series(run: xr.Dataset) -> np.ndarray:
    return np.stack([run[name].values for name in run.data_vars])


@dataclass(frozen=True)
class ErrorPair:
    """Picklable: the unit's and the model's series for one draw of what is not inferred (the
    unit is the model's coils moved ``fineness`` steps toward :data:`FINE_VOLUMES`, its
    charge ``fineness`` × :class:`CoilOffset` below the model's; 3 runs, 2 at fineness 0).
    The model runs at the draw's ``model_theta`` where it has one (:func:`compensate`), else at
    the unit's ``theta``; with ``biases`` (a share of each sensor's accuracy bound, in
    [-1, 1]) the unit's sensors read off by them."""

    model: VCCSimulator
    fine_unit: Unit
    times: np.ndarray
    accuracy: SensorAccuracy
    offset: CoilOffset | None = None

    def __call__(self, draw: dict) -> tuple[np.ndarray, np.ndarray] | None:
        model_theta = draw.get("model_theta", draw["theta"])
        if model_theta is None:  # its commissioning runs failed: no compensation known
            return None
        logged = self.accuracy.shift_inputs(self.model.inputs, draw["input_errors"])
        true_parameters = {**draw["fixed"], **draw["theta"]}
        runs = [
            _unit_runs(self.model, self.model.unit, logged)(true_parameters),
            self.model(model_theta),
        ]
        if draw["fineness"] > 0.0:
            fine_parameters = dict(true_parameters)
            if self.offset is not None:
                fine_parameters[CHARGE] -= float(self.offset(true_parameters[CHARGE]))
            runs.append(_unit_runs(self.model, self.fine_unit, logged)(fine_parameters))
        if not all(finished(run) for run in runs):
            return None
        coarse, model, *fine = (
            np.stack([run[name].sel(time=self.times).values for name in self.model.output_names])
            for run in runs
        )
        unit = coarse + draw["fineness"] * (fine[0] - coarse) if fine else coarse
        dt = float(np.median(np.diff(self.times)))
        unit = lagged(unit, draw["lags"], dt)
        for j, share in enumerate(draw.get("biases", ())):  # of each sensor's accuracy bound
            units = runs[0][self.model.output_names[j]].attrs["units"]
            bound, relative = self.accuracy.bias_bound(units)
            unit[j] = unit[j] * (1.0 + share * bound) if relative else unit[j] + share * bound
        return unit, model


STEP_THRESHOLDS = {
    "valve_opening": ("relative", 0.02),
    "compressor_speed": ("relative", 0.02),
    "T_ambient": ("absolute", 1.0),
    "T_indoor": ("absolute", 1.0),
}
"""An input that moves this far from its value at a plateau's start begins a new plateau (K or
a fraction of the value); smaller changes (a logged input's noise, slow drift) do not."""


def plateau_edges(inputs: xr.Dataset) -> np.ndarray:
    """Times at which the operating point steps, with the record's start and end, s."""
    edges, _ = input_segments(inputs)
    names = [name for name in STEP_THRESHOLDS if name in inputs.data_vars]
    values = {
        name: np.asarray(inputs[name].sel(time=edges[:-1], method="nearest").values)
        for name in names
    }
    starts = [0]
    for k in range(1, len(edges) - 1):
        anchor = starts[-1]
        for name in names:
            kind, bound = STEP_THRESHOLDS[name]
            change = values[name][k] - values[name][anchor]
            if kind == "relative":
                change /= max(abs(values[name][anchor]), 1e-12)
            if abs(change) > bound:
                starts.append(k)
                break
    return np.append(edges[starts], edges[-1])


def held_inputs(inputs: xr.Dataset) -> xr.Dataset:
    """The logged inputs held at their mean over each operating step (:func:`plateau_edges`).

    A logger reads its inputs with noise at every row; run as logged, the solver would restart
    at every row (2 s a simulation of a 1 s log instead of 0.04 s). What is lost is part of
    the inputs' logging error, which the error budget spreads."""
    edges = plateau_edges(inputs)
    time = np.asarray(inputs["time"].values, dtype=float)
    steps = [
        inputs.isel(time=np.flatnonzero((time >= start) & (time < end))).mean(
            "time", keep_attrs=True
        )
        for start, end in itertools.pairwise(edges)
    ]
    held = xr.concat([*steps, steps[-1]], dim="time", combine_attrs="override")
    held = held.assign_coords(time=edges)
    held["time"].attrs = dict(inputs["time"].attrs)
    return held


def fixed_spread(
    unit: Unit, inferred: Sequence[str], spread: float
) -> dict[str, tuple[float, float]]:
    """The range of each parameter the calibration holds at nominal: ± its tolerance (or
    ``spread`` when the unit states none) × nominal, inside the unit's bounds."""
    return {
        spec.id: spec.known_range(spread) for spec in unit.parameters if spec.id not in inferred
    }


@dataclass(frozen=True)
class SensorBudget:
    """The record's plateau summaries and the sensors' part of their error (see
    :mod:`pymc_vcc.inference.error_model`)."""

    outputs: tuple[str, ...]
    windows: list[np.ndarray]
    observed: np.ndarray
    parts: dict[str, np.ndarray]

    @classmethod
    def of(
        cls, model: VCCSimulator, observed: xr.Dataset, accuracy: SensorAccuracy
    ) -> SensorBudget:
        """The sensors' budget of ``observed`` (outputs of ``model``, on its time grid)."""
        outputs = tuple(str(name) for name in observed.data_vars)
        times = observed["time"].values
        windows = plateau_windows(plateau_edges(model.inputs) - model.t_window[0], times)
        values = np.stack([observed[name].values for name in outputs])
        summaries = summarise(values, windows)
        units = [observed[name].attrs["units"] for name in outputs]
        parts = {
            "noise": np.diag(noise_variance(values, windows)),
            "bias": bias_covariance(summaries, units, len(windows), accuracy),
        }
        return cls(outputs, windows, summaries, parts)

    @property
    def scale(self) -> np.ndarray:
        """Standard deviation of each summary from the sensors alone (SI)."""
        return np.sqrt(np.diag(sum(self.parts.values())))

    def budget(self) -> ErrorBudget:
        """The error budget of a record the model itself made: the sensors' errors alone."""
        zero = np.zeros_like(self.observed)
        return ErrorBudget(self.outputs, self.windows, self.observed, zero, dict(self.parts))


def error_budget(
    model: VCCSimulator,
    observed: xr.Dataset,
    prior: Prior,
    executor: Executor,
    rng: np.random.Generator,
    *,
    accuracy: SensorAccuracy | None = None,
    n_draws: int = ERROR_DRAWS,
    fine_volumes: int = FINE_VOLUMES,
    spread: float = FIXED_SPREAD,
    thetas: np.ndarray | None = None,
    offset: CoilOffset | None = None,
    coils: str = "finer",
    commissioning: Commissioning | None = None,
) -> ErrorBudget:
    """The error budget of ``observed`` (outputs of ``model``, on its time grid) for a
    calibration of ``prior``'s parameters (see the module docstring); the inferred parameters
    of the model-error draws are ``thetas`` (rows in ``prior.names`` order, e.g. an earlier
    posterior's draws) or ``n_draws`` draws of the prior. With ``offset``, the model's error
    is drawn against finer coils at the charge that reads the same (:class:`CoilOffset`);
    ``coils`` says whose coils made the record (:data:`COILS`: with ``model`` the unit of
    every draw has the model's coils). For a later record of a commissioned unit,
    ``commissioning`` gives each draw's model the parameters the commissioning calibration
    would have found for its unit (:func:`compensate`: :attr:`Commissioning.runs` more
    simulations, and the draws' own on the commissioning record)."""
    check_coils(coils)
    continuum = CONTINUUM if coils == "finer" else 0.0
    accuracy = SensorAccuracy() if accuracy is None else accuracy
    sensors = SensorBudget.of(model, observed, accuracy)
    fixed = fixed_spread(model.unit, prior.names, spread)
    thetas = prior.sample(n_draws, rng) if thetas is None else thetas
    draws = [
        {
            "theta": dict(zip(prior.names, map(float, row), strict=True)),
            "fixed": {pid: float(rng.uniform(lo, hi)) for pid, (lo, hi) in fixed.items()},
            "input_errors": {
                name: float(rng.uniform(-bound, bound))
                for name, (_, bound) in accuracy.inputs.items()
            },
            "lags": rng.uniform(0.0, accuracy.lag, len(sensors.outputs)),
            "fineness": float(rng.uniform(0.0, continuum)),
        }
        for row in thetas
    ]
    sensor_parts = sensors.parts
    if commissioning is not None:  # the sensors' biases, shared by both records, in the draws
        names = commissioning.model.parameter_names
        for draw in draws:
            row = commissioning.draws[rng.integers(len(commissioning.draws))]
            draw["theta_c"] = dict(zip(names, map(float, row), strict=True))
            draw["biases"] = rng.uniform(-1.0, 1.0, len(sensors.outputs))
        compensate(draws, commissioning, executor, accuracy, fine_volumes)
        sensor_parts = {"noise": sensors.parts["noise"]}
    pair = ErrorPair(
        model,
        model.unit.with_changes(discretisation={"n_volumes": fine_volumes}),
        observed["time"].values,
        accuracy,
        offset,
    )
    mean, model_cov, n_ok = approximation_error(pair, draws, sensors.windows, executor)
    return ErrorBudget(
        outputs=sensors.outputs,
        windows=sensors.windows,
        observed=sensors.observed,
        mean=mean,
        parts={**sensor_parts, "model": model_cov},
        n_draws=n_ok,
        n_failed=n_draws - n_ok,
    )


COMPENSATION_STEP = 0.02  # finite-difference step of the commissioning Jacobian, of each range
COMPENSATION_SPREAD = 0.5  # prior sd of a compensation, a fraction of each range (a ridge)
LOGIT_EDGE = 1e-9  # fraction of a range kept between a compensated parameter and its bound


@dataclass(frozen=True)
class Commissioning:
    """A commissioned unit's record and posterior, for a later record's model error
    (:func:`compensate`).

    Attributes:
        model: the model on the commissioning record (its held inputs, window, outputs), its
            parameters the commissioning calibration's (the model's charge first).
        observed: the commissioning record's outputs.
        draws: the commissioning posterior's draws, rows in ``model.parameter_names`` order.
        offset: the coils' offset measured on the commissioning record (None: model coils).
    """

    model: VCCSimulator
    observed: xr.Dataset
    draws: np.ndarray
    offset: CoilOffset | None = None

    @property
    def runs(self) -> int:
        """Simulations of :func:`compensate` besides its draws' (the Jacobian's)."""
        return len(self.model.parameter_names) + 1


def _run(task: tuple[VCCSimulator, dict[str, float]]) -> xr.Dataset:
    simulator, theta = task
    return simulator(theta)


def _jacobian(
    model: VCCSimulator, centre: np.ndarray, windows: Sequence[np.ndarray], executor: Executor
) -> np.ndarray:
    """∂ summaries / ∂ parameters of ``model`` at ``centre`` (forward differences of
    :data:`COMPENSATION_STEP` × each range, backward at the upper bound)."""
    names = model.parameter_names
    specs = [model.unit.parameter_spec(name) for name in names]
    steps = np.array([COMPENSATION_STEP * (spec.high - spec.low) for spec in specs])
    steps = np.where(centre + steps > [spec.high for spec in specs], -steps, steps)
    points = [centre] + [centre + step * np.eye(len(names))[k] for k, step in enumerate(steps)]
    runs = executor.map(
        _run, [(model, dict(zip(names, map(float, p), strict=True))) for p in points]
    )
    if not all(finished(run) for run in runs):
        raise RuntimeError("the model failed at the commissioning posterior's mean")
    summaries = np.array([summarise(_series(run), windows) for run in runs])
    return ((summaries[1:] - summaries[0]) / steps[:, None]).T


def compensate(
    draws: list[dict],
    commissioning: Commissioning,
    executor: Executor,
    accuracy: SensorAccuracy,
    fine_volumes: int = FINE_VOLUMES,
) -> None:
    """Give each model-error draw of a later record its ``model_theta``: the model's parameters
    moved as the commissioning calibration moved them to absorb that draw's unit.

    A calibration absorbs part of a unit's difference from the model into its parameters; a
    later record of the same unit meets the model at those absorbed values, and what they
    absorbed at commissioning does not hold at another charge. Each draw's unit (its held
    parameters, coils, logged inputs, sensors' lags and biases) is simulated on the
    commissioning record at a commissioning posterior draw (``draw["theta_c"]``), its
    summaries' error against the model there taken as the commissioning calibration would,
    linearised in the parameters' logit space (the bounds', as the priors'): the parameters'
    logits move by (Jᵀ W J + P)⁻¹ Jᵀ W (e − ē), J the model's Jacobian in those logits at the
    posterior mean, W the commissioning budget's precision, P a ridge of
    :data:`COMPENSATION_SPREAD` of each range there. The draw's model then runs at its later
    parameters so moved. In the parameters themselves, the move of a draw far below the mean
    (a condenser HTC of 29 against 62) took it to its bound, where the coil's conductance
    collapses: errors of the discharge pressure of −250 to −480 kPa in 7 of 64 draws, the
    budget's sd 101 kPa, and a 25 % conductance loss read as 10 %; in the logits a move
    shrinks toward a bound. A draw whose commissioning runs failed gets None (it fails)."""
    model = commissioning.model
    names = model.parameter_names
    sensors = SensorBudget.of(model, commissioning.observed, accuracy)
    centre = commissioning.draws.mean(axis=0)
    jacobian = _jacobian(model, centre, sensors.windows, executor)
    pair = ErrorPair(
        model,
        model.unit.with_changes(discretisation={"n_volumes": fine_volumes}),
        commissioning.observed["time"].values,
        accuracy,
        commissioning.offset,
    )
    errors = model_errors(
        pair, [{**draw, "theta": draw["theta_c"]} for draw in draws], sensors.windows, executor
    )
    mean, covariance, _ = error_moments(errors)
    precision = np.linalg.inv(covariance + sensors.parts["noise"])
    bounds = {name: _bounds(model.unit, name) for name in names}
    lows, highs = np.array(list(bounds.values())).T
    ranges = highs - lows
    fraction = _fraction(centre, lows, highs)
    slope = ranges * fraction * (1.0 - fraction)  # ∂ parameter / ∂ its logit at the centre
    jacobian = jacobian * slope
    ridge = np.diag((slope / (COMPENSATION_SPREAD * ranges)) ** 2)
    gain = np.linalg.solve(jacobian.T @ precision @ jacobian + ridge, jacobian.T @ precision)
    for draw, error in zip(draws, errors, strict=True):
        if error is None:
            draw["model_theta"] = None
            continue
        shift = dict(zip(names, gain @ (error - mean), strict=True))
        draw["model_theta"] = {
            name: _moved(value, shift[name], *bounds[name]) if name in shift else value
            for name, value in draw["theta"].items()
        }


def _fraction(
    value: np.ndarray | float, low: np.ndarray | float, high: np.ndarray | float
) -> np.ndarray:
    """Where ``value`` lies between ``low`` and ``high`` (0-1), kept off the ends."""
    return np.clip((value - low) / (high - low), LOGIT_EDGE, 1.0 - LOGIT_EDGE)


def _moved(value: float, logit_shift: float, low: float, high: float) -> float:
    """``value`` with its logit in (``low``, ``high``) moved by ``logit_shift``."""
    return float(low + (high - low) * expit(logit(_fraction(value, low, high)) + logit_shift))


def _bounds(unit: Unit, name: str) -> tuple[float, float]:
    spec = unit.parameter_spec(name)
    return spec.low, spec.high
