"""Simulation driver: any cycle model, a stiff solver (scipy's Radau or SUNDIALS CVODE), restarted
at every input step.

The driver knows no topology: the unit names its cycle model (:mod:`pymc_vcc.physics.cycles`),
which supplies the state layout, tolerances, initial state, right-hand side, Jacobian and
outputs. :func:`simulate` never raises for a run that goes wrong: it returns the output Dataset
flagged ``status = "failed"`` with a ``failure_kind`` (:class:`FailureKind`) and a
``failure_reason`` (the detail), outputs NaN from the failure on. Bad *arguments* (unknown
parameter ids, invalid inputs) do raise, before anything runs.
"""

from __future__ import annotations

import contextlib
import functools
import time
from collections.abc import Mapping, Sequence

import numpy as np
import xarray as xr
from threadpoolctl import ThreadpoolController

from pymc_vcc.physics.failures import Failure, FailureKind
from pymc_vcc.physics.inputs import (
    builtin_inputs,
    input_segments,
    validate_inputs,
    window,
    with_settling,
)
from pymc_vcc.physics.integration.callbacks import BoundCycle
from pymc_vcc.physics.integration.segments import Counters, make_solver
from pymc_vcc.physics.integration.solver import Solver, get_solver
from pymc_vcc.physics.integration.warmup import ensure_compiled
from pymc_vcc.physics.unit import Unit, load_unit

OUTPUT_INTERVAL = 1.0
"""Default spacing of the output grid, s."""

MAX_WALL_TIME = 20.0
"""Default wall-clock limit of one simulation, s: a run taking longer is flagged failed."""


@functools.lru_cache(maxsize=8)
def _fluid(name: str):
    from pymc_vcc.physics.refrigerant import load_refrigerant

    return load_refrigerant(name)


@functools.lru_cache(maxsize=1)
def _builtin_unit() -> Unit:
    return load_unit()


_THREADPOOLS = ThreadpoolController()
"""BLAS runs single-threaded inside a Radau simulation: its small LU factorisations only lose by
threading (five times slower at 126 states on a busy 2-core machine), and samplers run one
simulation per core anyway. CVODE does not call BLAS, and is not wrapped: setting OpenBLAS's
threads back after each run woke its threads in a forked worker, where they spun (a CVODE run
took 2.3 times its wall time in CPU)."""


def simulate(
    unit: Unit | None = None,
    params: Mapping[str, float] | None = None,
    inputs: xr.Dataset | None = None,
    *,
    t_end: float | None = None,
    output_interval: float = OUTPUT_INTERVAL,
    controller: bool | None = None,
    diagnostics: bool = False,
    max_wall_time: float = MAX_WALL_TIME,
    solver: str | Solver | None = None,
    states: bool = False,
) -> xr.Dataset:
    """Simulate the cycle and return the nine outputs on a regular time grid.

    Parameters
    ----------
    unit
        Unit description (default: the built-in 3.5 kW R410A split).
    params
        Parameter values by id (the unit's table, Table III for the split unit, and its cycle's
        fault parameters, ``unit.faults``); missing ids take their nominal value (faults: 0).
    inputs
        Input profile (default: the built-in 2120 s step profile), see
        :mod:`pymc_vcc.physics.inputs`.
    t_end
        Simulate ``[0, t_end]`` s only (default: the whole profile).
    output_interval
        Output grid spacing, s (default :data:`OUTPUT_INTERVAL`).
    controller
        Switch the virtual PI charge controller on/off (default: the unit's setting).
    diagnostics
        Also return heats, powers, total mass and controller source (the diagnostics of the
        cycle model's ``outputs``).
    max_wall_time
        Wall-clock limit in s (default :data:`MAX_WALL_TIME`).
    solver
        A :class:`~pymc_vcc.physics.integration.solver.Solver`, or ``"radau"`` (scipy, the
        reference; the default) or ``"cvode"`` (SUNDIALS, faster) at that method's default
        tolerances.
    states
        Also return the solver's state on the grid: ``states`` over (``time``, ``state``), the
        state variables named by the cycle's layout (coordinate ``state``: ``p_cond``,
        ``h_cond[0]``, ...) with their SI units (coordinate ``state_units``).

    Returns
    -------
    xarray.Dataset
        Variables ``TD, PD, TS, PS, TC, PC, TE, PE, MDOT`` over ``time`` with ``units`` attrs;
        attrs ``status`` ("ok" | "failed"), ``failure_reason``, ``solver``, ``n_rhs``,
        ``n_jac``, ``n_steps``, ``wall_time`` (s), ``mass_error`` (max ``|M - M0| / M0``
        on the grid), ``source_integral`` (∫|ṁ_src| dt, kg).
    """
    simulation = Simulation(
        unit,
        inputs,
        t_end=t_end,
        output_interval=output_interval,
        controller=controller,
        diagnostics=diagnostics,
        max_wall_time=max_wall_time,
        solver=solver,
    )
    return simulation.run(params, states=states)


class Simulation:
    """A unit over an input profile on an output grid with a solver, ready to run for any
    parameters (the arguments of :func:`simulate`, which runs one). What a sampler's draws
    share is prepared once: the checked inputs, their segments, the grid, the state layout,
    the kernels bound to their argument types and the solver's memory; a run computes the
    constants, the initial state, the integration and the outputs."""

    def __init__(
        self,
        unit: Unit | None = None,
        inputs: xr.Dataset | None = None,
        *,
        t_end: float | None = None,
        output_interval: float = OUTPUT_INTERVAL,
        controller: bool | None = None,
        diagnostics: bool = False,
        max_wall_time: float = MAX_WALL_TIME,
        solver: str | Solver | None = None,
    ) -> None:
        unit = _builtin_unit() if unit is None else unit
        ensure_compiled(unit)  # before any wall clock starts: compiling is not simulating
        model = unit.cycle_model
        inputs = builtin_inputs() if inputs is None else inputs
        validate_inputs(inputs, model.inputs)
        if t_end is not None:
            inputs = window(inputs, float(t_end))
        dt = float(output_interval)
        if not dt > 0:
            raise ValueError(f"output_interval must be positive, got {dt}")
        self.unit, self.model, self.controller = unit, model, controller
        self.diagnostics = diagnostics
        self.limit = float(max_wall_time)
        self.solver = get_solver(solver)
        self.edges, self.held = input_segments(inputs, model.inputs)
        self.times = np.arange(0.0, self.edges[-1] + 1e-9 * self.edges[-1], dt)
        self.times.flags.writeable = False  # every run's Datasets share it
        segment_of = np.searchsorted(self.edges, self.times, side="right") - 1
        self.controls = self.held[np.clip(segment_of, 0, len(self.held) - 1)]
        self.tables = _fluid(unit.refrigerant).tables
        self.layout = model.layout(unit.discretisation.n_volumes)
        self.stepper = make_solver(self.solver, self.layout.tolerances(self.solver), self.limit)
        # the kernels read the constants through this array: each run writes its own into it
        theta, faults = unit.parameter_vectors(None)
        self.c = model.constants(unit, theta, controller, faults)
        y = np.zeros(self.layout.size)
        self.cycle = BoundCycle(model, y, self.held[0], self.c, self.tables)
        info = model.outputs.info
        names = model.outputs.ids if diagnostics else model.outputs.output_ids
        self.template = xr.Dataset(  # each run's outputs are a copy with its own data
            {
                name: ("time", self.times, {"units": info[name][1], "long_name": info[name][0]})
                for name in names
            },
            coords={"time": ("time", self.times, {"units": "s"})},
        )

    def run(self, params: Mapping[str, float] | None = None, *, states: bool = False) -> xr.Dataset:
        """Simulate with ``params`` (id -> value; missing ids nominal, faults 0) and return the
        outputs as :func:`simulate` does (``states``: the solver's state on the grid too)."""
        unit, model, times, tables = self.unit, self.model, self.times, self.tables
        theta, faults = unit.parameter_vectors(params)
        started = time.perf_counter()
        self.c[:] = model.constants(unit, theta, self.controller, faults)
        c = self.c
        stepper = self.stepper
        stepper.counters = Counters()
        on_grid = np.full((times.size, self.layout.size), np.nan)
        failure: Failure | None = None
        try:
            y = model.initial_state(c, unit.discretisation.n_volumes, self.held[0], tables)
        except Exception as error:  # any numerical trouble is a failed run, never an exception
            y = None
            failure = Failure(FailureKind.INITIAL_STATE, f"initial state: {error}")
        if y is not None:
            blas = (
                _THREADPOOLS.limit(limits=1, user_api="blas")
                if stepper.calls_blas
                else contextlib.nullcontext()
            )
            with blas:
                failure = stepper.integrate_segments(
                    self.cycle, y, self.edges, self.held, times, on_grid, started + self.limit
                )

        names = list(self.template.data_vars)
        done = np.isfinite(on_grid.sum(axis=1))  # a state of ~1e7 at most: no overflow
        reached = slice(None) if done.all() else done  # a finished run's rows: views, no copies
        evaluated = np.full((times.size, model.n_eval), np.nan)
        mass_error = source_integral = float("nan")
        if done.any():
            evaluated[reached] = model.outputs_along(
                on_grid[reached], self.controls[reached], c, tables, self.diagnostics
            )
            charge = model.charge(c)
            at = model.outputs.offsets
            mass_error = float(np.max(np.abs(evaluated[done, at.M] - charge)) / charge)
            source = np.abs(evaluated[done, at.mdot_src])
            source_integral = float(np.trapezoid(source, times[done]))
        values = evaluated[:, : len(names)]
        if failure is None and not np.isfinite(values).all():
            failure = Failure(FailureKind.NON_FINITE, "non-finite outputs")
        data = {name: values[:, k] for k, name in enumerate(names)}
        dataset = self.template.copy(deep=False, data=data)
        dataset.attrs = {
            "status": "failed" if failure else "ok",
            "failure_kind": failure.kind.value if failure else "",
            "failure_reason": failure.detail if failure else "",
            "n_rhs": stepper.counters.n_rhs,
            "n_jac": stepper.counters.n_jac,
            "n_steps": stepper.counters.n_steps,
            "solver": str(self.solver),
            "n_states": self.layout.size,
            "wall_time": time.perf_counter() - started,
            "mass_error": mass_error,
            "source_integral": source_integral,
            "unit": unit.name,
            "cycle": model.name,
        }
        if states:
            dataset["states"] = (("time", "state"), on_grid, {"long_name": "solver state"})
            dataset = dataset.assign_coords(
                state=("state", list(self.layout.labels)),
                state_units=("state", list(self.layout.units)),
            )
        return dataset


class VCCSimulator:
    """A picklable simulator for the samplers: ``simulator(theta, rng) -> xarray.Dataset``.

    Parameters not in ``theta`` take their nominal values; the simulation is deterministic
    (``rng`` is accepted for the interface). Failed runs are returned flagged in attrs, never
    raised. ``outputs`` selects output ids (the cycle's outputs, and its optional ones such as
    ``W_comp``); ``t_window = (t_start, t_end)`` simulates up to ``t_end`` and returns the
    outputs from ``t_start`` on. ``parameters`` names the ids a sampler calibrates (default: all
    26; the cycle's fault parameters, ``unit.faults``, may be named too); the others stay at
    nominal (faults: 0), or at ``fixed`` values. Samplers refuse priors reaching
    outside the unit's parameter bounds (``parameter_bounds``) unless
    ``allow_outside_unit_bounds=True`` (extrapolation). ``solver`` picks the ODE solver and
    its tolerances.

    Parameters
    ----------
    unit
        Unit description (default: the built-in 3.5 kW R410A split).
    inputs
        Input profile (default: the built-in 2120 s step profile).
    outputs
        Output ids returned (default: the cycle's nine; ``W_comp``, the compressor's
        electrical power in W, may be added).
    t_window
        (t_start, t_end), s: simulate up to ``t_end``, return the outputs from ``t_start`` on
        (default: the whole profile).
    controller
        Switch the virtual PI charge controller on/off (default: the unit's setting).
    max_wall_time
        Wall-clock limit of one simulation, s (default :data:`MAX_WALL_TIME`).
    parameters
        Ids a sampler calibrates (default: all of the unit's table; fault ids may be added).
    fixed
        Values of parameters not calibrated, by id, in their units (default: nominal), fault
        parameters too.
    allow_outside_unit_bounds
        Let priors reach outside the unit's parameter bounds.
    solver
        A :class:`~pymc_vcc.physics.integration.solver.Solver`, or ``"radau"`` (the default) or
        ``"cvode"`` at that method's default tolerances.
    settle
        Seconds run at the profile's first inputs before it starts (not returned; times
        start at 0 s), so that a record of a running unit starts from its steady state
        rather than a start-up transient (default 0).
    """

    def __init__(
        self,
        unit: Unit | None = None,
        inputs: xr.Dataset | None = None,
        outputs: Sequence[str] | None = None,
        t_window: tuple[float, float] | None = None,
        *,
        controller: bool | None = None,
        max_wall_time: float = MAX_WALL_TIME,
        parameters: Sequence[str] | None = None,
        fixed: Mapping[str, float] | None = None,
        allow_outside_unit_bounds: bool = False,
        solver: str | Solver | None = None,
        settle: float = 0.0,
    ) -> None:
        self.unit = load_unit() if unit is None else unit
        self.inputs = builtin_inputs() if inputs is None else inputs
        model = self.unit.cycle_model
        validate_inputs(self.inputs, model.inputs)
        output_ids = model.output_ids
        selected = tuple(output_ids if outputs is None else outputs)
        allowed = output_ids + model.outputs.optional_ids
        unknown = [name for name in selected if name not in allowed]
        if unknown or not selected:
            raise ValueError(f"unknown output id(s) {unknown}; allowed are {list(allowed)}")
        self.output_names: tuple[str, ...] = selected
        table_ids = self.unit.parameters.ids
        all_ids = table_ids + self.unit.faults.ids
        self.parameter_names: tuple[str, ...] = (
            table_ids if parameters is None else tuple(parameters)
        )
        self.fixed: dict[str, float] = dict(fixed or {})
        for what, names in (("parameters", self.parameter_names), ("fixed", self.fixed)):
            unknown = [name for name in names if name not in all_ids]
            if unknown:
                raise ValueError(f"unknown {what} id(s) {unknown}; allowed are {list(all_ids)}")
        self.unit.parameter_vectors(self.fixed, check_bounds=True)
        end = float(self.inputs["time"].values[-1])
        if t_window is None:
            t_window = (0.0, end)
        t_start, t_stop = map(float, t_window)
        if not 0.0 <= t_start < t_stop <= end:
            raise ValueError(f"t_window {t_window} must satisfy 0 <= start < end <= {end} s")
        self.t_window = (t_start, t_stop)
        # cut once here: cutting the profile at every run took 10 ms of a 100 ms simulation
        self._run_inputs = self.inputs if t_stop == end else window(self.inputs, t_stop)
        self.settle = float(settle)
        self._run_inputs = with_settling(self._run_inputs, self.settle)
        self.controller = controller
        self.max_wall_time = max_wall_time
        self.solver = get_solver(solver)
        self.allow_outside_unit_bounds = allow_outside_unit_bounds
        ensure_compiled(self.unit)
        self._simulation: Simulation | None = None  # prepared at the first run

    def __getstate__(self) -> dict:
        return self.__dict__ | {"_simulation": None}  # the solver's memory stays in its process

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        ensure_compiled(self.unit)  # in a worker: before any run's time limit starts

    @property
    def checkpoint_identity(self) -> str:
        """What a checkpoint records of this simulator, so that a resume with another unit,
        solver, window or fixed values is refused rather than mixed in."""
        fixed = ", ".join(f"{name}={value:g}" for name, value in sorted(self.fixed.items()))
        settling = f", settled {self.settle:g} s" if self.settle else ""
        return (
            f"unit {self.unit.name!r}, solver {self.solver}, window {self.t_window} s, "
            f"controller {self.controller}, fixed {{{fixed}}}{settling}"
        )

    @property
    def parameter_bounds(self) -> dict[str, tuple[float, float]] | None:
        """The unit's bounds of the calibrated parameters (None with extrapolation allowed)."""
        if self.allow_outside_unit_bounds:
            return None
        specs = map(self.unit.parameter_spec, self.parameter_names)
        return {spec.id: (spec.low, spec.high) for spec in specs}

    def __call__(
        self, theta: Mapping[str, float], rng: np.random.Generator | None = None
    ) -> xr.Dataset:
        """Simulate with parameters ``theta`` (id -> value) and return the selected outputs."""
        if self._simulation is None:
            self._simulation = Simulation(
                self.unit,
                self._run_inputs,
                controller=self.controller,
                max_wall_time=self.max_wall_time,
                solver=self.solver,
                diagnostics=any(
                    name in self.unit.cycle_model.outputs.optional_ids for name in self.output_names
                ),
            )
        result = self._simulation.run({**self.fixed, **theta})
        if len(self.output_names) < len(result.data_vars):
            result = result[list(self.output_names)]
        start = self.t_window[0] + self.settle
        if start <= 0.0:  # the whole run (selecting it anyway took 0.25 ms)
            return result
        result = result.sel(time=slice(start, None))
        if self.settle:
            result = result.assign_coords(time=result["time"].values - self.settle)
            result["time"].attrs["units"] = "s"
        return result

    @property
    def bounds(self) -> dict[str, tuple[float, float]]:
        """Bounds (low, high) of every parameter of the unit's table and of the fault
        parameters it calibrates, SI units."""
        faults = [pid for pid in self.parameter_names if pid in self.unit.faults.ids]
        specs = [*self.unit.parameters, *map(self.unit.faults.__getitem__, faults)]
        return {spec.id: (spec.low, spec.high) for spec in specs}

    def __repr__(self) -> str:
        return (
            f"VCCSimulator(unit={self.unit.name!r}, outputs={list(self.output_names)}, "
            f"t_window={self.t_window})"
        )


def operating_point(
    unit: Unit | None = None,
    params: Mapping[str, float] | None = None,
    *,
    duration: float = 1500.0,
    controller: bool | None = None,
    solver: str | Solver | None = None,
    **conditions: float,
) -> dict[str, float | str]:
    """The (near) steady state reached after ``duration`` s at constant inputs.

    ``conditions`` override the unit's rating point (the split unit's ``valve_opening``,
    ``compressor_speed``, ``T_ambient``, ``T_indoor``, SI; optional ``RH_indoor``, default dry).
    Returns the outputs and the diagnostics at the end, the cycle model's summary (the split
    unit's: ``superheat`` (K, at the suction), ``subcooling`` (K, condenser outlet),
    ``capacity`` (W, the cycle's useful heat: evaporator heat cooling, condenser heat heating),
    ``COP`` (capacity over compressor and fan power), ``energy_balance_error`` ((Q_cond - Q_evap
    - W_ref) / Q_cond)), ``drift`` (largest relative change of an output over the last 100 s)
    and the run's ``status``/``failure_reason``.

    Parameters
    ----------
    unit
        Unit description (default: the built-in 3.5 kW R410A split).
    params
        Parameter values by id (calibration and fault parameters, as for :func:`simulate`);
        missing ids take their nominal value.
    duration
        Simulated time at constant inputs, s.
    controller
        Switch the virtual PI charge controller on/off (default: the unit's setting).
    solver
        A :class:`~pymc_vcc.physics.integration.solver.Solver` or a method name (default:
        ``"radau"``), as for :func:`simulate`.
    **conditions
        Inputs that differ from the unit's ``[rating]`` point, SI (K, Hz, fractions).
    """
    from pymc_vcc.physics.inputs import constant_inputs

    unit = _builtin_unit() if unit is None else unit
    model = unit.cycle_model
    unknown = sorted(set(conditions) - set(model.inputs.ids))
    if unknown:
        raise ValueError(f"unknown condition(s) {unknown}; allowed are {list(model.inputs.ids)}")
    result = simulate(
        unit,
        params,
        constant_inputs(duration, **(unit.rating | conditions)),
        diagnostics=True,
        controller=controller,
        output_interval=10.0,
        solver=solver,
    )
    final = {str(name): float(result[name].values[-1]) for name in result.data_vars}
    recent = result.sel(time=slice(duration - 100.0, None))
    drift = max(
        float(np.ptp(recent[name].values) / abs(recent[name].values[-1]))
        for name in model.output_ids
    )
    summary: dict[str, float | str] = dict(final)
    return (
        summary
        | model.summary(final, _fluid(unit.refrigerant).tables)
        | {
            "drift": drift,
            "status": result.attrs["status"],
            "failure_reason": result.attrs["failure_reason"],
        }
    )
