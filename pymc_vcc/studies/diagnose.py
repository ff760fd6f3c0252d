"""Fault diagnosis: which fault, how severe, how sure, from a unit's later log.

A later record is calibrated (:func:`~pymc_vcc.studies.unit_log.calibrate_record`, the same
error budget) under a spike-and-slab prior (:func:`~pymc_vcc.studies.unit_log.later_prior`):
the unit as commissioned, and with a small probability each fault's parameters anywhere in
their ranges (the cycle's fault parameters, ``unit.faults``: a liquid-line restriction,
non-condensable gas, leaking compressor valves, added near 0). Each fault of
:data:`~pymc_vcc.studies.faults.FAULTS` then has an *intensity* relative to commissioning per
posterior draw (:func:`~pymc_vcc.studies.faults.fault_intensities`), spread by the model's form
error (:func:`~pymc_vcc.studies.faults.with_model_form`). Its posterior probability of lying
beyond the fault's threshold, the form error integrated out
(:func:`~pymc_vcc.studies.faults.beyond_probability`), names it (:data:`NAMED`; or, on request,
as likely when no other fault rivals it: :data:`LIKELY`); two faults
that together are likely but neither alone are reported as not distinguishable, with the
sensor that would tell them apart (:func:`separating_sensor`).

The faults are the standard set of the fault-detection literature (Yuill and Braun's
evaluation of FDD protocols; ASHRAE RP-1043): undercharge, overcharge, condenser fouling or low
outdoor airflow, low indoor airflow, liquid-line restriction, compressor valve leakage,
non-condensable gas.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import xarray as xr
from matplotlib.figure import Figure

from pymc_vcc.execution.executors import Executor
from pymc_vcc.inference.error_model import SensorAccuracy, plateau_windows, summarise
from pymc_vcc.physics.cycles.split_cooling import SplitCooling
from pymc_vcc.physics.integration.solver import Solver
from pymc_vcc.physics.simulate import VCCSimulator, operating_point
from pymc_vcc.physics.unit import Unit, load_unit
from pymc_vcc.studies.faults import (
    FAULT_PROBABILITY,
    FAULTS,
    MODEL_FORM,
    Fault,
    beyond_probability,
    check_fault_probability,
    check_model_form,
    fault_intensities,
    moved_parameters,
    paired_commissioning,
    with_model_form,
)
from pymc_vcc.studies.record_budget import CHARGE, held_inputs, plateau_edges
from pymc_vcc.studies.unit_log import (
    MODEL_CHARGE,
    RECORD_BUDGETS,
    SETTLE,
    calibrate_record,
    predictive_checks,
)

NAMED = 0.9
"""The naming probability: a fault is named when P(intensity beyond its threshold) is at
least this (``pymc-vcc diagnose --named``)."""
POSSIBLE = 0.5
"""Below the naming probability and at least this, a fault is reported as possible."""
LIKELY: float | None = None
"""The probability that names a fault as likely when none reaches the naming probability and
no other fault rivals it (each under :data:`RIVAL`), ``pymc-vcc diagnose --likely``; None:
faults are named only at the naming probability."""
RIVAL = 0.2
"""A fault at this probability or more rivals another: neither is named as likely."""
LIKELY_PREFIX = "likely: "
"""How a verdict names a fault as likely (:func:`verdict`)."""
ROUNDS = 2
"""Calibrations of a later record in turn (``pymc-vcc diagnose --rounds``): the second with
half of the model's error drawn at the first's posterior, the faulted unit, and half, as the
first's, mostly at the unit as commissioned. Drawn at the commissioned unit alone, a large
fault's own model error was read as a second fault (a 30 % undercharge with a liquid-line
restriction); drawn at the posterior alone, a healthy unit's record read a fault."""
RATING_DRAWS = 96
"""Posterior draws what the faults cost at the rating point is read on (:func:`rating_change`):
two operating points of about 10 ms each per draw."""
RATED = ("capacity", "COP")
"""What :func:`rating_change` compares: the cycle's capacity (W) and COP at the rating point."""
RATING_FORM = 0.012
"""Sd of the model's error in what the faults cost at the rating point (a fraction of the
rating, the same for each of :data:`RATED`) on a unit that is not the model: its finer coils,
drifted held parameters and sensors move the cost the model reads by a point or two. Measured
on the fault benchmark's units 8500-8700 (66 cases, the model's reading alone covering 85 % of
the true capacity changes and 71 % of the COP's) as the split-conformal 95 % quantile of the
spread each case needed: 0.011 for the capacity, 0.012 for the COP."""
RATING_COPIES = 16  # form-error draws per posterior draw (:func:`with_rating_form`)


def check_named(named: float, likely: float | None = None) -> None:
    """Refuse a naming probability outside [:data:`POSSIBLE`, 1), or a likely one outside
    [:data:`POSSIBLE`, ``named``], in one line."""
    if not POSSIBLE <= named < 1.0:
        raise ValueError(f"naming probability must lie in [{POSSIBLE}, 1), got {named}")
    if likely is not None and not POSSIBLE <= likely <= named:
        raise ValueError(
            f"likely probability must lie in [{POSSIBLE}, {named:g}] (the naming probability), "
            f"got {likely}"
        )


@dataclass
class Diagnosis:
    """What a later record says of the unit's faults.

    Attributes:
        tree: the posterior DataTree of the later record (the parameters, fault parameters
            included).
        intensities: fault name -> its posterior draws of intensity, the model's form error
            included (:func:`~pymc_vcc.studies.faults.with_model_form`).
        probabilities: fault name -> P(intensity beyond its threshold).
        verdict: ``no fault``, ``<fault>``, ``several: ...`` or ``<fault> / <fault>: not
            distinguishable with these sensors``.
        confusions: pairs of faults the data cannot separate, each with what would (a sensor
            not logged, or more operating steps when the logged sensors are the best).
        commissioned: the commissioning posterior's mean of each parameter.
        unreproduced: the outputs the model could not reproduce at commissioning (its
            predictive check failed there: :func:`commissioning_misfits`); the intensities
            are read against a commissioning that misses them.
        model_intensities: fault name -> the intensity draws as the model reads them, before
            its form error.
        model_form: the form error's relative sd in :attr:`intensities`.
        named: the probability that named a fault in :attr:`verdict`.
        likely: the probability that names a fault no other rivals as likely (None: off).
        rating: what the faults cost at the rating point: ``"capacity"`` and ``"COP"`` ->
            draws of their relative changes with the faults undone, the model's error there
            included (:func:`with_rating_form`).
        model_rating: the same as the model reads it, one per posterior draw
            (:func:`rating_change`).
        rating_failed: the draws whose rating-point runs failed (left out of :attr:`rating`).
    """

    tree: xr.DataTree
    intensities: dict[str, np.ndarray]
    probabilities: dict[str, float]
    verdict: str
    confusions: list[tuple[str, str, str]] = field(default_factory=list)
    commissioned: dict[str, float] = field(default_factory=dict)
    unreproduced: list[str] = field(default_factory=list)
    model_intensities: dict[str, np.ndarray] = field(default_factory=dict)
    model_form: float = 0.0
    named: float = NAMED
    likely: float | None = None
    rating: dict[str, np.ndarray] = field(default_factory=dict)
    model_rating: dict[str, np.ndarray] = field(default_factory=dict)
    rating_failed: int = 0

    def summary(self) -> dict:
        """The JSON summary: per fault its intensity (mean, 95 % interval) and probability, and
        what the faults cost at the rating point (mean, 95 % interval)."""
        faults = {}
        for fault in FAULTS:
            draws = self.intensities[fault.name]
            low, high = np.quantile(draws, [0.025, 0.975])
            faults[fault.name] = {
                "intensity_mean": float(draws.mean()),
                "intensity_low": float(low),
                "intensity_high": float(high),
                "probability": self.probabilities[fault.name],
                "threshold": fault.threshold,
                "relative": fault.relative,
            }
        charge = self.tree["posterior"][CHARGE].values.ravel()
        return {
            "verdict": self.verdict,
            "faults": faults,
            "confusions": [list(c) for c in self.confusions],
            "charge_change_kg": float(charge.mean() - self.commissioned[CHARGE]),
            "commissioning_unreproduced": self.unreproduced,
            "model_form": self.model_form,
            "named_at": self.named,
            "likely_at": self.likely,
            "rating_change": {
                name: _interval(changes) for name, changes in self.rating.items() if changes.size
            },
            "rating_draws_failed": self.rating_failed,
        }

    def plot(self) -> Figure:
        """Every fault's intensity in units of its threshold, its probability in its label and
        the verdict above (:func:`~pymc_vcc.plots.plot_fault_intensities`)."""
        from pymc_vcc.plots import plot_fault_intensities

        rows = {
            f"{f.name.replace(' or ', ' or\n')}\nP = {self.probabilities[f.name]:.2f}": (
                self.intensities[f.name] / f.threshold
            )
            for f in FAULTS
        }
        return plot_fault_intensities(rows, f"verdict: {self.verdict}")

    def format_table(self) -> str:
        """The one-page report: the verdict, the charge change and what the faults cost at the
        rating point, then every fault's intensity and probability."""
        charge = self.tree["posterior"][CHARGE].values.ravel() - self.commissioned[CHARGE]
        low, high = np.quantile(charge, [0.025, 0.975])
        lines = [
            f"verdict: {self.verdict} ({self._naming_rule()})",
            f"charge change since commissioning: {charge.mean():+.3f} kg "
            f"(95 % interval {low:+.3f} to {high:+.3f} kg)",
            self._rating_line(),
            "",
            f"{'fault':<42} {'intensity (95 % interval)':>32}  {'threshold':>10}  P(fault)",
        ]
        for fault in FAULTS:
            unit, factor = fault.display
            draws = self.intensities[fault.name] * factor
            q_low, q_high = np.quantile(draws, [0.025, 0.975])
            interval = f"{draws.mean():+.1f} ({q_low:+.1f} to {q_high:+.1f}) {unit}"
            lines.append(
                f"{fault.name:<42} {interval:>32}  {fault.threshold * factor:>7.0f} {unit:<3}"
                f"{self.probabilities[fault.name]:8.2f}"
            )
        if self.model_form > 0:
            lines.append(
                f"(intervals and probabilities include the model's form error: "
                f"±{100 * self.model_form:.0f} % of each intensity, 1 sd)"
            )
        for first, second, advice in self.confusions:
            lines.append(
                f"\n{first} and {second} are not distinguishable with these sensors; {advice}"
            )
        if self.unreproduced:
            lines.append(f"\n{_misfit_caution(self.unreproduced)}")
        return "\n".join(lines)

    def _naming_rule(self) -> str:
        """The report's words for when a fault is named."""
        rule = f"a fault is named at P(fault) >= {self.named:g}"
        if self.likely is None:
            return rule
        return f"{rule}, or as likely at >= {self.likely:g} when no other reaches {RIVAL:g}"

    def _rating_line(self) -> str:
        """The report's line on what the faults cost at the rating point."""
        read = {name: changes for name, changes in self.rating.items() if changes.size}
        if not read:
            return "what the faults cost at the rating point: not read (every run failed)"
        parts = []
        for name, changes in read.items():
            at = _interval(100 * changes)
            parts.append(f"{name} {at['mean']:+.1f} % ({at['low']:+.1f} to {at['high']:+.1f})")
        failed = f"; {self.rating_failed} draw(s) failed" if self.rating_failed else ""
        return (
            f"what the faults cost at the rating point: {', '.join(parts)}{failed} (the "
            f"model's error there included, ±{100 * RATING_FORM:.1f} points, 1 sd)"
        )


def _interval(draws: np.ndarray) -> dict[str, float]:
    """Mean and 95 % interval of ``draws``."""
    low, high = np.quantile(draws, [0.025, 0.975])
    return {"mean": float(draws.mean()), "low": float(low), "high": float(high)}


def commissioning_misfits(commissioning: xr.DataTree) -> list[str]:
    """The outputs whose predictive check failed at commissioning (as
    :func:`~pymc_vcc.studies.unit_log.calibrate_record` stores it; none for a posterior
    written without one)."""
    if "sample_stats" not in commissioning or "ppc_misfit" not in commissioning["sample_stats"]:
        return []
    return [name for name, check in predictive_checks(commissioning).items() if check["misfit"]]


def _misfit_caution(outputs: Sequence[str]) -> str:
    return (
        f"caution: at commissioning the model could not reproduce {', '.join(outputs)}; "
        "every intensity is read against that commissioning"
    )


def verdict(
    probabilities: Mapping[str, float], named: float = NAMED, likely: float | None = LIKELY
) -> tuple[str, list[tuple[str, str]]]:
    """The verdict from each fault's probability, and the pairs it could not separate: two
    faults neither of which reaches ``named`` but whose probabilities together do.

    Args:
        probabilities: fault name -> P(intensity beyond its threshold).
        named: the probability that names a fault (:data:`NAMED`; lower names more faults
            near their thresholds for more false alarms and misdiagnoses).
        likely: the probability that names the likeliest fault as likely when none reaches
            ``named`` and every other is under :data:`RIVAL` (:data:`LIKELY`; None: never).
    """
    check_named(named, likely)
    sure = [name for name, p in probabilities.items() if p >= named]
    if len(sure) > 1:
        return "several: " + ", ".join(sure), []
    if len(sure) == 1:
        return sure[0], []
    if likely is not None and probabilities:
        likeliest = max(probabilities, key=probabilities.__getitem__)
        rivals = [p for name, p in probabilities.items() if name != likeliest]
        if probabilities[likeliest] >= likely and max(rivals, default=0.0) < RIVAL:
            return LIKELY_PREFIX + likeliest, []
    pairs = [
        (a, b)
        for a, b in itertools.combinations(probabilities, 2)
        if probabilities[a] >= 1 - named
        and probabilities[b] >= 1 - named
        and probabilities[a] + probabilities[b] >= named
    ]
    if pairs:
        a, b = max(pairs, key=lambda pair: probabilities[pair[0]] + probabilities[pair[1]])
        return f"{a} / {b}: not distinguishable with these sensors", [(a, b)]
    possible = [name for name, p in probabilities.items() if p >= POSSIBLE]
    if possible:
        return "no fault named; possible: " + ", ".join(possible), []
    return "no fault", []


def separating_sensor(
    model: VCCSimulator,
    point: Mapping[str, float],
    faults: tuple[Fault, Fault],
    logged: Sequence[str],
    accuracy: SensorAccuracy,
) -> str:
    """The output whose plateau readings differ most, in units of its sensor's accuracy,
    between the two faults each at its threshold from ``point``, once the second fault's size
    is matched to the first on the ``logged`` outputs: the best of the cycle's outputs not
    logged if it differs by one accuracy or more, else the best of all.

    Args:
        model: the calibration's simulator (its unit, inputs, window and solver are used).
        point: parameter values to start from (the posterior mean), id -> value.
        faults: the two faults.
        logged: the outputs the record has.
        accuracy: the sensors' accuracy (the unit each output's difference is counted in).
    """
    outputs = list(model.unit.cycle_model.outputs.output_ids)
    everything = VCCSimulator(
        model.unit,
        model.inputs,
        outputs=outputs,
        t_window=model.t_window,
        solver=model.solver,
        settle=model.settle,
    )
    runs = [everything(dict(point))]
    for fault in faults:
        step = fault.direction * fault.threshold
        moved = {
            pid: point[pid] * (1 + step) if fault.relative else step for pid in fault.parameters
        }
        runs.append(everything({**point, **moved}))
    if any(run.attrs["status"] != "ok" for run in runs):
        return "(none found: the model failed near the posterior mean)"
    times = runs[0]["time"].values
    windows = plateau_windows(plateau_edges(model.inputs) - model.t_window[0], times)
    base, *moved_runs = (
        summarise(np.stack([run[o].values for o in outputs]), windows).reshape(len(outputs), -1)
        for run in runs
    )
    scale = []
    for j, name in enumerate(outputs):
        bound, relative = accuracy.bias_bound(runs[0][name].attrs["units"])
        scale.append(bound * float(np.abs(base[j]).mean()) if relative else bound)
    first, second = ((r - base) / np.array(scale)[:, None] for r in moved_runs)
    seen = [outputs.index(o) for o in logged if o in outputs]
    a, b = first[seen].ravel(), second[seen].ravel()
    match = float(a @ b / (b @ b)) if b @ b > 0 else 0.0
    gap = np.abs(first - match * second).max(axis=1)
    unlogged = [j for j, name in enumerate(outputs) if name not in logged]
    best_unlogged = max(unlogged, key=lambda j: gap[j], default=None)
    if best_unlogged is not None and gap[best_unlogged] >= 1.0:
        return outputs[best_unlogged]
    return outputs[int(np.argmax(gap))]


def rating_change(
    later: Mapping[str, np.ndarray],
    commissioning: xr.Dataset,
    unit: Unit,
    seed: int,
    solver: str | Solver = "cvode",
    draws: int = RATING_DRAWS,
) -> tuple[dict[str, np.ndarray], int]:
    """What the faults cost at the rating point: per later posterior draw (``draws`` of them,
    evenly spread), the relative change of the cycle's capacity and COP (:data:`RATED`) at the
    unit's rating inputs between the unit as the draw has it and the same unit with every
    fault undone (the fault parameters at 0 and what the faults move, the charge and the
    coils' air sides, at a commissioning draw paired with it as
    :func:`~pymc_vcc.studies.faults.fault_intensities` pairs them). What no fault moves (the
    compressor's and the valve's factors) stays the draw's: their drift is no fault's, and a
    commissioning draw elsewhere on the ridge its data left would read a cost that is not there.

    Args:
        later: variable -> the later posterior's draws (the model's charge in ``M0_model``).
        commissioning: the commissioning posterior (its ``posterior`` group).
        unit: the unit.
        seed: seeds the pairing, as :func:`~pymc_vcc.studies.faults.fault_intensities`'s.
        solver: ODE solver.
        draws: the most later draws simulated.

    Returns:
        ``{"capacity": changes, "COP": changes}`` (fractions; draws whose runs failed left
        out) and the number of draws left out.
    """
    n_later = len(later[CHARGE])
    paired = paired_commissioning(n_later, commissioning, seed)
    moved = set(moved_parameters(unit)) & set(paired)  # a posterior holds them all (later_prior)

    def rated(k: int, undone: bool) -> np.ndarray:
        theta = {
            name: float(values[k])
            for name, values in later.items()
            if name in unit.parameters.ids or (name in unit.faults.ids and not undone)
        }
        theta[CHARGE] = float(later.get(MODEL_CHARGE, later[CHARGE])[k])
        if undone:
            theta |= {name: float(paired[name][k]) for name in moved}
            theta[CHARGE] = float(paired.get(MODEL_CHARGE, paired[CHARGE])[k])
        point = operating_point(unit, theta, solver=solver)
        if point["status"] != "ok":
            return np.full(len(RATED), np.nan)
        return np.array([float(point[name]) for name in RATED])

    chosen = np.unique(np.linspace(0, n_later - 1, min(draws, n_later)).round().astype(int))
    ratios = np.array([rated(k, undone=False) / rated(k, undone=True) - 1.0 for k in chosen])
    kept = np.isfinite(ratios).all(axis=1)
    return {name: ratios[kept, j] for j, name in enumerate(RATED)}, int((~kept).sum())


def with_rating_form(
    rating: Mapping[str, np.ndarray], seed: int, spread: float = RATING_FORM
) -> dict[str, np.ndarray]:
    """What the faults cost at the rating point (:func:`rating_change`'s draws) spread by the
    model's error there (:data:`RATING_FORM`): each draw :data:`RATING_COPIES` times, each copy
    plus N(0, s²), s = ``spread``."""
    rng = np.random.default_rng([seed, 2])
    return {
        name: np.repeat(changes, RATING_COPIES)
        + rng.normal(0.0, spread, changes.size * RATING_COPIES)
        for name, changes in rating.items()
    }


def diagnose(
    observed: xr.Dataset,
    inputs: xr.Dataset,
    commissioning: xr.DataTree,
    executor: Executor,
    *,
    unit: Unit | None = None,
    drift: float = 0.03,
    budget: str = "small",
    seed: int = 0,
    solver: str | Solver = "cvode",
    coils: str = "finer",
    rounds: int = ROUNDS,
    method: str = "likelihood",
    accuracy: SensorAccuracy | None = None,
    fault_probability: float = FAULT_PROBABILITY,
    model_form: float = MODEL_FORM,
    named: float = NAMED,
    likely: float | None = LIKELY,
) -> Diagnosis:
    """Diagnose a later record of a unit against its commissioning posterior.

    Args:
        observed: the later record's outputs (SI, ``units`` attrs) on a regular grid from 0 s.
        inputs: its logged inputs.
        commissioning: the commissioning posterior (``pymc-vcc calibrate``'s
            ``posterior.nc``).
        executor: runs the simulations.
        unit: the unit description (default: the built-in split unit).
        drift: sd of each parameter no fault moves, since commissioning, a fraction of its
            range.
        budget: :data:`~pymc_vcc.studies.unit_log.RECORD_BUDGETS` name.
        seed: seeds every random draw.
        solver: ODE solver.
        rounds: calibrations in turn (:data:`ROUNDS`).
        coils, method: as for :func:`~pymc_vcc.studies.unit_log.calibrate_record`.
        accuracy: the sensors' accuracy.
        fault_probability: each fault's prior probability
            (:func:`~pymc_vcc.studies.unit_log.later_prior`).
        model_form: the relative sd of the model's reading of an intensity
            (:data:`~pymc_vcc.studies.faults.MODEL_FORM`; 0: the model's reading alone).
        named, likely: the probabilities that name a fault, and a fault no other rivals as
            likely (:func:`verdict`).
    """
    check_fault_probability(fault_probability)
    check_model_form(model_form)
    check_named(named, likely)
    unit = load_unit() if unit is None else unit
    if budget not in RECORD_BUDGETS:
        raise ValueError(f"budget {budget!r}: a diagnosis takes {list(RECORD_BUDGETS)}")
    if unit.cycle != SplitCooling.name:  # the standard faults name the cooling mode's coils
        raise ValueError(
            f"the diagnosis knows the faults of a unit cooling ({SplitCooling.name!r}); this "
            f"unit's cycle is {unit.cycle!r}"
        )
    accuracy = SensorAccuracy() if accuracy is None else accuracy
    unreproduced = commissioning_misfits(commissioning)
    if unreproduced:
        warnings.warn(_misfit_caution(unreproduced), stacklevel=2)
    posterior = commissioning["posterior"]
    commissioned = {
        str(n): float(posterior[n].mean()) for n in posterior.data_vars if n in unit.parameters.ids
    }
    draws, error_draws = RECORD_BUDGETS[budget]
    tree = calibrate_record(
        observed,
        inputs,
        executor,
        unit=unit,
        commissioning=commissioning,
        drift=drift,
        fault_probability=fault_probability,
        draws=draws,
        error_draws=error_draws,
        seed=seed,
        solver=solver,
        coils=coils,
        rounds=rounds,
        method=method,
        accuracy=accuracy,
    )
    samples = {str(n): tree["posterior"][n].values.ravel() for n in tree["posterior"].data_vars}
    read = fault_intensities(samples, posterior, unit, seed)
    intensities = with_model_form(read, seed, model_form)
    probabilities = {
        f.name: beyond_probability(read[f.name], f.threshold, model_form) for f in FAULTS
    }
    text, pairs = verdict(probabilities, named, likely)
    model_rating, rating_failed = rating_change(samples, posterior, unit, seed, solver)
    by_name = {f.name: f for f in FAULTS}
    point = {name: float(values.mean()) for name, values in samples.items()}
    point[CHARGE] = point.get(MODEL_CHARGE, point[CHARGE])
    inferred = {*unit.parameters.ids, *unit.faults.ids}
    point = {k: v for k, v in point.items() if k in inferred}
    model = VCCSimulator(
        unit,
        held_inputs(inputs),
        outputs=[str(n) for n in observed.data_vars],
        t_window=(0.0, float(observed["time"].values[-1])),
        solver=solver,
        settle=SETTLE,
    )
    logged = list(model.output_names)
    confusions = []
    for a, b in pairs:
        sensor = separating_sensor(model, point, (by_name[a], by_name[b]), logged, accuracy)
        advice = (
            f"they differ most on the logged {sensor}: a log with more operating steps would "
            "tell them apart"
            if sensor in logged
            else f"a {sensor} sensor would tell them apart"
        )
        confusions.append((a, b, advice))
    return Diagnosis(
        tree,
        intensities,
        probabilities,
        text,
        confusions,
        commissioned,
        unreproduced,
        model_intensities=read,
        model_form=model_form,
        named=named,
        likely=likely,
        rating=with_rating_form(model_rating, seed),
        model_rating=model_rating,
        rating_failed=rating_failed,
    )


def diagnose_study(
    settings,
    log: str,
    commissioning: str,
    *,
    column_map: str | None = None,
    unit: Unit | None = None,
    drift: float = 0.03,
    coils: str = "finer",
    rounds: int = ROUNDS,
    method: str = "likelihood",
    fault_probability: float = FAULT_PROBABILITY,
    model_form: float = MODEL_FORM,
    named: float = NAMED,
    likely: float | None = LIKELY,
) -> Diagnosis:
    """``pymc-vcc diagnose LOG --prior COMMISSIONING``: load and check the log and the
    commissioning posterior before any simulation, diagnose, and write the posterior, the
    report, the summary and the intensities' figure into ``settings.out``.

    Args:
        settings: where and how it runs (budget ``smoke``, ``small`` or ``paper``).
        log: the later CSV log.
        commissioning: the folder (or ``posterior.nc``) of the healthy unit's calibration.
        column_map: the log's column map (default: ``LOG.columns.toml`` beside it).
        unit: the unit description (default: the built-in split unit).
        drift, coils, rounds, method, fault_probability, model_form, named, likely: as for
            :func:`diagnose`.
    """
    from pymc_vcc.io.measurements import load_log
    from pymc_vcc.physics.simulate import OUTPUT_INTERVAL
    from pymc_vcc.plots import save_figure
    from pymc_vcc.studies.common import write_json, write_netcdf, write_text
    from pymc_vcc.studies.unit_log import (
        POSTERIOR_FILE,
        check_drift,
        load_commissioning,
        record_budget_name,
    )

    check_drift(drift)
    check_fault_probability(fault_probability)
    check_model_form(model_form)
    check_named(named, likely)
    budget = record_budget_name(settings)
    unit = unit or load_unit()
    measured = load_log(log, column_map, dt=OUTPUT_INTERVAL)
    healthy = load_commissioning(commissioning)
    with settings.claim_output("diagnose"), settings.open_executor() as executor:
        result = diagnose(
            measured.observed,
            measured.inputs,
            healthy,
            executor,
            unit=unit,
            drift=drift,
            budget=budget,
            seed=settings.seed,
            solver=settings.solver or "cvode",
            coils=coils,
            rounds=rounds,
            method=method,
            fault_probability=fault_probability,
            model_form=model_form,
            named=named,
            likely=likely,
        )
        if settings.out is not None:
            write_netcdf(result.tree, settings.out / POSTERIOR_FILE)
            write_json(settings.out / "summary.json", result.summary())
            write_text(settings.out / "report.txt", result.format_table() + "\n")
            save_figure(result.plot(), settings.out / "faults")
    return result


__all__ = [
    "FAULTS",
    "LIKELY",
    "LIKELY_PREFIX",
    "NAMED",
    "POSSIBLE",
    "RIVAL",
    "ROUNDS",
    "Diagnosis",
    "Fault",
    "check_named",
    "commissioning_misfits",
    "diagnose",
    "diagnose_study",
    "separating_sensor",
    "verdict",
]
