"""Probes of the physics over the Table III box: laws, ranges, oscillation, observability.

What a refrigeration engineer checks before trusting a model that samplers will drive across
its whole parameter box (``scripts/probe_physics.py`` runs them at full size; the tests run a
dozen draws):

* :func:`box_probe`: uniform draws at constant rated inputs; per draw, the compressor's first
  and second law at every output time, air flows and fan powers inside the ranges the box
  implies, no sustained oscillation of PC, charge held, and success (and the cycle's energy
  balance at the end, reported);
* :func:`charge_observability`: how far each 0.1 kg step of M0 moves the outputs, in sensor
  noise standard deviations;
* :func:`parameter_effects`: the same for each Table III parameter moved to either bound;
* :func:`fault_effects`: what each fault of the cycle does to the rating point's operating
  point, in engineering quantities (flow, superheat, pressures, power, capacity).

Sensor noise is stated the way instruments are specified: 0.3 K on temperatures, 0.5 % of
reading on pressures, 1 % of reading on mass flow and electrical power (:func:`noise_sd`, from
the table in :mod:`pymc_vcc.physics.sensors`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import xarray as xr

from pymc_vcc.physics.cycles import QUANTITY_INFO
from pymc_vcc.physics.inputs import constant_inputs
from pymc_vcc.physics.integration.solver import Solver
from pymc_vcc.physics.sensors import KIND_OF_UNITS, RELATIVE_KINDS, TYPICAL_NOISE
from pymc_vcc.physics.simulate import operating_point, simulate
from pymc_vcc.physics.unit import Unit, load_unit

OSCILLATION_WINDOW = 300.0
"""Seconds at the end of a constant-input run over which PC must be still."""

OSCILLATION_LIMIT = 1e-3
"""Largest peak-to-peak change of PC over :data:`OSCILLATION_WINDOW`, relative to PC."""

MASS_LIMIT = 1e-4
"""Largest relative deviation of the total refrigerant mass from M0 over a run."""

PROBE_WALL_TIME = 600.0
"""Wall-clock limit (s) of the observability runs: they measure physics, not speed, and may
share a busy machine (the box probe keeps the unit's own limit, which samplers face)."""


def noise_sd(output: str, value: np.ndarray | float) -> np.ndarray:
    """Sensor noise standard deviation of ``output`` at ``value`` (SI)."""
    kind = KIND_OF_UNITS[QUANTITY_INFO[output][1]]
    reading = np.asarray(value, dtype=float)
    if kind in RELATIVE_KINDS:
        return TYPICAL_NOISE[kind] * np.abs(reading)
    return np.full_like(reading, TYPICAL_NOISE[kind])


def separation(first: xr.Dataset, second: xr.Dataset) -> dict[str, float]:
    """Per output of the runs, the time-averaged |difference| of two runs in noise standard
    deviations."""
    return {
        name: float(
            np.mean(
                np.abs(second[name].values - first[name].values)
                / noise_sd(name, first[name].values)
            )
        )
        for name in map(str, first.data_vars)
    }


def rated_inputs(unit: Unit, duration: float) -> xr.Dataset:
    """The unit's rating point held for ``duration`` s."""
    return constant_inputs(duration, **unit.rating)


@dataclass(frozen=True)
class DrawReport:
    """What :func:`box_probe` found for one parameter draw."""

    theta: dict[str, float]
    status: str
    failure_reason: str
    first_law: bool  # electrical power >= power to the refrigerant at every output time
    second_law: bool  # power to the refrigerant >= isentropic power at every output time
    air_in_range: bool  # diagnostics inside the ranges the box implies (the cycle's box_ranges)
    oscillation: float  # peak-to-peak PC over the last window / PC
    mass_error: float  # max |M - M0| / M0
    energy_balance: float  # (Q_cond - Q_evap - W_ref) / Q_cond at the end

    @property
    def holds(self) -> bool:
        """Every check passed (a failed run holds nothing)."""
        return (
            self.status == "ok"
            and self.first_law
            and self.second_law
            and self.air_in_range
            and self.oscillation < OSCILLATION_LIMIT
            and self.mass_error < MASS_LIMIT
        )


def check_draw(
    unit: Unit,
    theta: Mapping[str, float],
    duration: float = 1200.0,
    solver: str | Solver | None = None,
) -> DrawReport:
    """Run ``theta`` (calibration and fault parameters by id) at constant rated inputs for
    ``duration`` s with ``solver`` (default: :func:`~pymc_vcc.physics.simulate.simulate`'s)
    and check it (see module)."""
    run = simulate(unit, theta, rated_inputs(unit, duration), diagnostics=True, solver=solver)
    if run.attrs["status"] != "ok":
        nan = float("nan")
        return DrawReport(
            dict(theta), "failed", run.attrs["failure_reason"], False, False, False, nan, nan, nan
        )
    tolerance = 1e-9 * run["W_comp"].values
    first_law = bool(np.all(run["W_ref"].values <= run["W_comp"].values + tolerance))
    second_law = bool(np.all(run["W_ref"].values >= run["W_is"].values - tolerance))
    air = all(
        np.all((low * (1 - 1e-9) <= run[name].values) & (run[name].values <= high * (1 + 1e-9)))
        for name, (low, high) in unit.cycle_model.box_ranges(unit).items()
    )
    recent = run["PC"].sel(time=slice(duration - OSCILLATION_WINDOW, None)).values
    end = run.isel(time=-1)
    q_cond = float(end["Q_cond"])
    return DrawReport(
        theta=dict(theta),
        status="ok",
        failure_reason="",
        first_law=first_law,
        second_law=second_law,
        air_in_range=bool(air),
        oscillation=float(np.ptp(recent) / np.mean(recent)),
        mass_error=float(run.attrs["mass_error"]),
        energy_balance=(q_cond - float(end["Q_evap"]) - float(end["W_ref"])) / q_cond,
    )


def box_probe(
    n_draws: int, seed: int = 0, unit: Unit | None = None, duration: float = 1200.0
) -> list[DrawReport]:
    """:func:`check_draw` for ``n_draws`` uniform draws from the unit's Table III box."""
    unit = load_unit() if unit is None else unit
    draws = unit.parameters.sample_uniform(n_draws, np.random.default_rng(seed))
    return [check_draw(unit, theta, duration) for theta in draws]


def charge_observability(
    charges: Sequence[float],
    unit: Unit | None = None,
    inputs: xr.Dataset | None = None,
    fixed: Mapping[str, float] | None = None,
) -> list[tuple[float, float, str, float]]:
    """For each step between consecutive ``charges`` (kg): (M0 low, M0 high, the output that
    moves most, its time-averaged change in noise standard deviations).

    ``inputs`` defaults to the rating point held for 2000 s, compared over its last 500 s
    (steady state); pass ``builtin_inputs()`` to compare over the whole step profile.
    """
    unit = load_unit() if unit is None else unit
    steady = inputs is None
    inputs = rated_inputs(unit, 2000.0) if steady else inputs
    runs = []
    for charge in charges:
        theta = {**(fixed or {}), "M0": float(charge)}
        run = simulate(unit, theta, inputs, max_wall_time=PROBE_WALL_TIME)
        if run.attrs["status"] != "ok":
            raise RuntimeError(f"M0 = {charge} kg failed: {run.attrs['failure_reason']}")
        runs.append(run.sel(time=slice(1500.0, None)) if steady else run)
    rows = []
    for (low, first), (high, second) in zip(
        zip(charges, runs, strict=True), zip(charges[1:], runs[1:], strict=True), strict=False
    ):
        moved = separation(first, second)
        best = max(moved, key=moved.__getitem__)
        rows.append((float(low), float(high), best, moved[best]))
    return rows


def parameter_effects(
    unit: Unit | None = None, inputs: xr.Dataset | None = None
) -> dict[str, tuple[tuple[str, float], tuple[str, float]]]:
    """For each Table III parameter: (output, separation in noise sd) of the most moved output
    when the parameter goes from nominal to its lower, then its upper bound (rated inputs held
    2000 s, last 500 s compared, unless ``inputs`` is given)."""
    unit = load_unit() if unit is None else unit
    steady = inputs is None
    inputs = rated_inputs(unit, 2000.0) if steady else inputs

    def run(theta: Mapping[str, float]) -> xr.Dataset:
        result = simulate(unit, theta, inputs, max_wall_time=PROBE_WALL_TIME)
        return result.sel(time=slice(1500.0, None)) if steady else result

    nominal = run({})
    effects = {}
    for spec in unit.parameters:
        pair = []
        for bound in (spec.low, spec.high):
            moved = run({spec.id: bound})
            if moved.attrs["status"] != "ok":
                pair.append(("failed", float("nan")))
                continue
            distance = separation(nominal, moved)
            best = max(distance, key=distance.__getitem__)
            pair.append((best, distance[best]))
        effects[spec.id] = (pair[0], pair[1])
    return effects


FAULT_QUANTITIES = (
    "MDOT",
    "superheat",
    "subcooling",
    "PE",
    "PD",
    "PC",
    "TD",
    "TS",
    "W_comp",
    "capacity",
    "COP",
)
"""What :func:`fault_effects` compares: the flow, the superheat at the suction and the
(apparent) subcooling, K, the pressures, the discharge and suction temperatures, the
compressor's power, the capacity and the COP."""


def fault_effects(
    unit: Unit | None = None,
    fractions: Sequence[float] = (0.5, 1.0),
    solver: str | Solver | None = "cvode",
) -> dict[str, dict[str, float]]:
    """The operating point at the unit's rating
    (:func:`~pymc_vcc.physics.simulate.operating_point`) with each fault of the unit's cycle
    at each of ``fractions`` of its upper bound, the others at 0: ``"nominal"`` -> the
    fault-free values of :data:`FAULT_QUANTITIES`, ``"<id>=<value>"`` -> their values with the
    fault (SI)."""
    unit = load_unit() if unit is None else unit

    def point(theta: Mapping[str, float]) -> dict[str, float]:
        result = operating_point(unit, theta, solver=solver)
        if result["status"] != "ok":
            raise RuntimeError(f"{dict(theta)} failed: {result['failure_reason']}")
        return {name: float(result[name]) for name in FAULT_QUANTITIES}

    effects = {"nominal": point({})}
    for spec in unit.faults:
        for fraction in fractions:
            value = fraction * spec.high
            effects[f"{spec.id}={value:g}"] = point({spec.id: value})
    return effects


__all__ = [
    "FAULT_QUANTITIES",
    "DrawReport",
    "box_probe",
    "charge_observability",
    "check_draw",
    "fault_effects",
    "noise_sd",
    "parameter_effects",
    "separation",
]
