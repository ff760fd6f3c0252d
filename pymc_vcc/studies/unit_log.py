"""Calibration of a real unit's record: the charge among the parameters that drift.

The charge ``M0`` is inferred jointly with the parameters a real unit changes or that were never
known exactly (:data:`NUISANCE`: the compressor and valve factors, the air-side conductances
and the fan flows), marginalising them, under the error budget of
:mod:`pymc_vcc.studies.record_budget` (sensor noise estimated from the record, sensor biases
within their accuracy, and the model's error against a finer unit whose other parameters are
spread around nominal, whose logged inputs are off and whose sensors lag). Their prior is the
unit's box at commissioning; a later record's is the unit as commissioned, with drift, or with
any of the standard faults (:func:`later_prior`: whatever else has changed takes its share of
the data rather than push the charge).

The model's coarse coils read as a different charge
(:class:`~pymc_vcc.studies.record_budget.CoilOffset`): each calibration measures that offset
first, draws the model's error against finer coils at the charge that reads the same, and
reports the unit's charge (``M0``) beside the model's (``M0_model``).

The model starts from its steady state at the record's first inputs (:data:`SETTLE` s of
settling), so a record taken from a running unit needs no start-up transient.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pymc as pm
import xarray as xr
from scipy.special import expit, logit

from pymc_vcc.execution.executors import Executor
from pymc_vcc.execution.options import RunOptions
from pymc_vcc.execution.outcomes import finished
from pymc_vcc.inference.error_model import (
    ErrorBudget,
    SensorAccuracy,
    predictive_check,
    summarise,
)
from pymc_vcc.inference.priors import GMMPrior, Prior, UniformPrior
from pymc_vcc.inference.pymc.laplace import fit_reference, laplace_draws
from pymc_vcc.inference.pymc.likelihood import add_likelihood
from pymc_vcc.inference.pymc.reference import GaussianReference
from pymc_vcc.inference.pymc.smc import PosteriorQualityWarning, sample_smc_abc
from pymc_vcc.inference.rejection import abc_rejection
from pymc_vcc.physics.integration.solver import Solver
from pymc_vcc.physics.simulate import OUTPUT_INTERVAL, VCCSimulator
from pymc_vcc.physics.unit import Unit, load_unit
from pymc_vcc.studies.faults import (
    ERROR_FAULT_PROBABILITY,
    FAULT_PROBABILITY,
    FAULTS,
    HEALTHY_FAULT_FRACTION,
    REFERENCE_FAULT_PROBABILITY,
    beyond_probability,
    check_fault_probability,
    fault_intensities,
    moved_parameters,
)
from pymc_vcc.studies.record_budget import (
    CHARGE,
    ERROR_DRAWS,
    FINE_VOLUMES,
    RUNS_PER_DRAW,
    CoilOffset,
    Commissioning,
    SensorBudget,
    check_coils,
    coil_offset,
    error_budget,
    held_inputs,
)

NUISANCE: tuple[str, ...] = (
    "CF_VOL",
    "CF_POW",
    "CF_PREF",
    "CF_SHELL",
    "CF_LEV",
    "HTC_CA",
    "HTC_EA",
    "FO_FLOW",
    "FI_FLOW",
)
"""Parameters inferred with the charge and marginalised: what a real unit changes (fouling,
airflow, valve and compressor wear) or what was never known exactly."""

SETTLE = 600.0  # s at the record's first inputs before it starts
MODEL_CHARGE = f"{CHARGE}_model"  # the sampled (model's) charge, beside the unit's
SCOUTING_SHARE = 0.5  # particles and model-error draws of a round before the last
MIN_PARTICLES = 16  # fewest SMC particles of a round
MIN_ERROR_DRAWS = 12  # fewest model-error draws of a round (the covariance needs 10)
RECORD_BUDGETS: dict[str, tuple[int, int]] = {
    "smoke": (24, 12),
    "small": (96, ERROR_DRAWS),
    "paper": (512, 256),
}
"""Budget name -> (SMC particles, model-error draws) of a record's calibration."""

METHODS: tuple[str, ...] = ("likelihood", "rejection")
"""How a record's posterior is sampled under its error budget: ``likelihood``, SMC on the
budget's likelihood (recommended); ``rejection``, the paper's ABC rejection with the budget's
Mahalanobis distance (:meth:`~pymc_vcc.inference.error_model.ErrorBudget.distance`)."""
REJECTION_PILOT = 10  # pilot draws of a rejection calibration per SMC particle of the budget
REJECTION_MAIN = 30  # main-phase draws per SMC particle (about 5 % accepted)
REJECTION_QUANTILE = 0.05

PREDICTIVE_DRAWS = 24  # posterior draws simulated for the predictive check
EXACT_SHARE = 0.3
"""Share of the simulations of a record the model itself made (``coils`` ``model``) kept for
its exact stage: the fits under the sensors' errors alone."""
EXACT_STEP = 1e-3  # forward-difference step of the exact stage's fits, of each box
EXACT_DRAWS = 1000  # posterior draws of the exact stage's Laplace approximation
EXACT_STARTS = (0.1, 0.9)
"""Quantiles of the charge under the model's error whose particles start fits of the exact
stage besides the mean: from the mean alone, model (13) found a mode 0.10 kg off."""
SIMULATIONS_PER_PARTICLE = 52  # a calibration's default simulation cap per SMC particle
PPC_KEYS = ("z_mean", "p_value", "misfit")  # the check per output, ppc_<key> in sample_stats
COMMISSIONING_ATTEMPTS = 3
"""Calibrations of a commissioning record at most, each from a new seed while the predictive
check fails (:func:`calibrate_record`'s ``attempts``): at the ``small`` budget the SMC sometimes
settles where the model misses a sensor (a benchmark unit read 1.65 kg for 1.41, its check
failing on TS and TE; from the next seed 1.40 kg, every sensor reproduced)."""


def record_budget_name(settings) -> str:
    """The name of ``settings``' budget for a record's calibration (a budget given as a
    :class:`~pymc_vcc.studies.common.Budget` counts as ``small``), refused in one line unless
    one of :data:`RECORD_BUDGETS`."""
    budget = settings.budget if isinstance(settings.budget, str) else "small"
    if budget not in RECORD_BUDGETS:
        raise ValueError(f"budget {budget!r}: a record's calibration takes {list(RECORD_BUDGETS)}")
    return budget


def check_method(method: str) -> None:
    """Refuse a sampler not in :data:`METHODS`, in one line."""
    if method not in METHODS:
        raise ValueError(f"method {method!r}: allowed are {list(METHODS)}")


def check_rounds(rounds: int) -> None:
    """Refuse fewer than one calibration round, in one line."""
    if rounds < 1:
        raise ValueError(f"rounds must be at least 1, got {rounds}")


def check_drift(drift: float) -> None:
    """Refuse a drift outside [0, 1] (a fraction of each parameter's range), in one line."""
    if not 0.0 <= drift <= 1.0:
        raise ValueError(f"drift must lie in [0, 1] (a fraction of each range), got {drift}")


def box_prior(unit: Unit, parameters: Sequence[str]) -> UniformPrior:
    """Uniform on the unit's bounds of ``parameters`` (calibration or fault parameters)."""
    specs = map(unit.parameter_spec, parameters)
    return UniformPrior({spec.id: (spec.low, spec.high) for spec in specs})


def calibrate_record(
    observed: xr.Dataset,
    inputs: xr.Dataset,
    executor: Executor,
    *,
    attempts: int = 1,
    seed: int = 0,
    **options: Any,
) -> xr.DataTree:
    """The posterior of a unit's record (:func:`calibrate_once`), calibrated again from seed
    ``seed + k`` while its predictive check fails, ``attempts`` times at most: the attempt
    whose check fails on the fewest outputs (then with the largest smallest p-value) is kept;
    ``check_attempts`` in its ``sample_stats`` says how many ran, ``n_simulations`` counts
    them all, and only the kept attempt's warnings are shown.

    Args:
        observed, inputs, executor, seed, options: as for :func:`calibrate_once`.
        attempts: calibrations at most (1: one, whatever its check says;
            :data:`COMMISSIONING_ATTEMPTS` for a commissioning).
    """
    if attempts < 1:
        raise ValueError(f"attempts must be at least 1, got {attempts}")
    tried: list[tuple[xr.DataTree, list[warnings.WarningMessage]]] = []
    for k in range(attempts):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            tree = calibrate_once(observed, inputs, executor, seed=seed + k, **options)
        tried.append((tree, caught))
        if _check_rank(tree)[0] == 0:  # every sensor reproduced
            break
    kept, caught = min(tried, key=lambda attempt: _check_rank(attempt[0]))
    for message in caught:
        warnings.warn(message.message, message.category, stacklevel=2)
    stats = kept["sample_stats"].to_dataset()
    stats["check_attempts"] = len(tried)
    stats["n_simulations"] = sum(int(tree["sample_stats"]["n_simulations"]) for tree, _ in tried)
    kept["sample_stats"] = xr.DataTree(stats)
    return kept


def _check_rank(tree: xr.DataTree) -> tuple[float, float]:
    """Orders calibrations by their predictive check: fewest misfits, then the largest
    smallest p-value."""
    checks = predictive_checks(tree).values()
    return sum(c["misfit"] for c in checks), -min(c["p_value"] for c in checks)


def calibrate_once(
    observed: xr.Dataset,
    inputs: xr.Dataset,
    executor: Executor,
    *,
    unit: Unit | None = None,
    prior: Prior | None = None,
    commissioning: xr.DataTree | None = None,
    drift: float = 0.03,
    fault_probability: float = FAULT_PROBABILITY,
    parameters: Sequence[str] = (CHARGE, *NUISANCE),
    accuracy: SensorAccuracy | None = None,
    draws: int = RECORD_BUDGETS["small"][0],
    error_draws: int = ERROR_DRAWS,
    max_simulations: int | None = None,
    seed: int = 0,
    solver: str | Solver = "cvode",
    progressbar: bool = False,
    rounds: int = 1,
    coils: str = "finer",
    method: str = "likelihood",
) -> xr.DataTree:
    """The posterior of ``parameters`` given a record of a real unit.

    Args:
        observed: the recorded outputs (SI, ``units`` attrs) on a regular grid from 0 s.
        inputs: the logged inputs over the record.
        executor: runs the simulations.
        unit: the unit description (default: the built-in split unit).
        prior: prior of ``parameters`` (default: uniform on the unit's bounds).
        commissioning: for a later record of a commissioned unit, instead of ``prior``: the
            commissioning posterior, whose :func:`later_prior` (with ``drift`` and
            ``fault_probability``) is the prior. The model's error is then first drawn where
            each fault has :data:`~pymc_vcc.studies.faults.ERROR_FAULT_PROBABILITY` (mostly
            the unit as commissioned: drawn where each fault was as likely as not, the
            faulted draws set the budget's correlations and a healthy unit's record read a
            liquid-line restriction). With the commissioning record in the tree
            (``observed_data``, ``constant_data``, as this function writes it), each error
            draw's model runs where the commissioning calibration would have left it for
            that draw's unit, the sensors' biases shared by both records
            (:func:`~pymc_vcc.studies.record_budget.compensate`; twice the error draws'
            simulations): a unit's differences from the model, absorbed into its parameters
            at commissioning, stop being absorbed at another charge, and read as a smaller
            leak without it (some units' 20 % loss read as 10-12 %). The SMC
            tempers from the prior with each fault as likely as not
            (:data:`~pymc_vcc.studies.faults.REFERENCE_FAULT_PROBABILITY`,
            :meth:`~pymc_vcc.inference.pymc.reference.GaussianReference.of_mixture`), so
            that its first particles reach every fault's range: from the prior itself, mostly
            the healthy unit, a 20 % loss near the box's low end (0.98 kg) was missed for a
            liquid-line restriction, on the model's own data too.
        drift, fault_probability: see :func:`later_prior`.
        parameters: the inferred parameters (default: the charge and :data:`NUISANCE`).
        accuracy: the sensors' and logged inputs' accuracy.
        draws: SMC particles.
        error_draws: draws of the model-error statistics.
        max_simulations: the calibration's simulations, at most about (default:
            :data:`SIMULATIONS_PER_PARTICLE` × ``draws``, 4992 at the small budget): the SMC
            gets what the coils' offset, the model-error draws and the predictive check leave,
            and makes fewer mutation steps where it would run over (``max_simulations`` of
            :func:`~pymc_vcc.inference.pymc.smc.sample_smc_abc`).
        seed: seeds every random draw.
        solver: ODE solver, a method name or a
            :class:`~pymc_vcc.physics.integration.solver.Solver`.
        rounds: calibrations in turn, each after the first with the model error drawn half at
            the previous posterior's draws (local), half where the first round drew it (a first
            record: over the whole prior; a later record: mostly the unit as commissioned);
            the rounds before the last scout with :data:`SCOUTING_SHARE` of the particles and
            draws, their posterior's quality not reported
            (:class:`~pymc_vcc.inference.pymc.smc.PosteriorQualityWarning`: the small
            budget's 48 scouting particles hold an ESS of 24 by design).
        progressbar: show PyMC's progress bar.
        coils: whose coils made the record
            (:data:`~pymc_vcc.studies.record_budget.COILS`): ``finer`` for a physical unit
            (the default: every real unit), ``model`` for data the model itself generated
            (then no coil offset, and the model-error draws keep the model's coils; and for
            a first record sampled by ``likelihood``, the posterior under the model's error
            is only the start of an exact stage under the sensors' errors alone, with
            :data:`EXACT_SHARE` of the simulations: :func:`_sample_exact`).
        method: the sampler under the error budget (:data:`METHODS`); ``draws`` sets the
            rejection's budget too (:data:`REJECTION_PILOT`, :data:`REJECTION_MAIN` per
            particle).

    Returns:
        The ArviZ DataTree, the record in it (its outputs in ``observed_data``, its logged
        inputs in ``constant_data``). When the charge is inferred from a unit's record (``coils``
        ``finer``), ``posterior`` holds the unit's charge in ``M0`` and the model's
        equivalent charge in ``M0_model`` (they differ by the coils' offset,
        :class:`~pymc_vcc.studies.record_budget.CoilOffset`, measured first:
        ``coil_offset_kg`` in ``sample_stats``). ``sample_stats`` also holds the predictive
        check per output (``ppc_z_mean``, ``ppc_p_value``, ``ppc_misfit``), the last error
        budget's size (``error_draws``, ``error_failed``, ``error_rounds``), the exact stage's
        simulations (``exact_simulations``, 0 without one) and every simulation's count
        (``n_simulations``).
    """
    unit = load_unit() if unit is None else unit
    error_prior, reference = None, None
    if commissioning is not None:
        if prior is not None:
            raise ValueError("a later record takes a prior or a commissioning posterior, not both")
        prior = later_prior(commissioning, unit, drift, seed, fault_probability)
        error_prior = later_prior(commissioning, unit, drift, seed, ERROR_FAULT_PROBABILITY)
        reference = GaussianReference.of_mixture(
            later_prior(commissioning, unit, drift, seed, REFERENCE_FAULT_PROBABILITY)
        )
    prior = box_prior(unit, parameters) if prior is None else prior
    check_rounds(rounds)
    check_coils(coils)
    check_method(method)
    if max_simulations is None:
        max_simulations = SIMULATIONS_PER_PARTICLE * draws
    exact = coils == "model" and commissioning is None and method == "likelihood"
    exact_reserve = round(EXACT_SHARE * max_simulations) if exact else 0
    rng = np.random.default_rng(seed)
    t_end = float(observed["time"].values[-1])
    model = VCCSimulator(
        unit,
        held_inputs(inputs),
        outputs=[str(name) for name in observed.data_vars],
        t_window=(0.0, t_end),
        parameters=prior.names,
        solver=solver,
        settle=SETTLE,
    )
    accuracy = SensorAccuracy() if accuracy is None else accuracy
    thetas, simulations, offset, commissioned = None, 0, None, None
    if error_prior is not None:
        thetas = error_prior.sample(error_draws, rng)
    error_thetas = thetas
    if error_thetas is None and rounds > 1:  # a first record's later rounds: half over the box
        error_thetas = prior.sample(error_draws, rng)
    if commissioning is not None:
        commissioned = _commissioning_record(commissioning, model)
    if CHARGE in prior.names and coils == "finer":
        sensors = SensorBudget.of(model, observed, accuracy)
        spec = unit.parameters[CHARGE]
        offset, simulations = coil_offset(
            model,
            unit.with_changes(discretisation={"n_volumes": FINE_VOLUMES}),
            sensors.scale,
            sensors.windows,
            executor,
            (spec.low, spec.high),
        )
    for round_left in reversed(range(rounds)):
        share = SCOUTING_SHARE if round_left else 1.0
        n_error = max(MIN_ERROR_DRAWS, round(share * error_draws))
        budget = error_budget(
            model,
            observed,
            prior,
            executor,
            rng,
            accuracy=accuracy,
            n_draws=n_error,
            thetas=_error_thetas(error_thetas, thetas, n_error, rng),
            offset=offset,
            coils=coils,
            commissioning=commissioned,
        )
        simulations += _error_runs(n_error, coils, commissioned)
        particles = max(MIN_PARTICLES, round(share * draws))
        to_come = PREDICTIVE_DRAWS + exact_reserve
        to_come += round_left * _error_runs(error_draws, coils, commissioned)
        affordable = share * (max_simulations - simulations - to_come)
        with warnings.catch_warnings():
            if round_left:  # a scout's posterior only places the next round's model error
                warnings.simplefilter("ignore", PosteriorQualityWarning)
            tree, n_sampled = _sample(
                method,
                model,
                observed,
                budget,
                prior,
                particles,
                max(1, int(affordable)),
                executor,
                seed,
                progressbar,
                reference,
            )
        simulations += n_sampled
        thetas = np.column_stack([tree["posterior"][n].values.ravel() for n in prior.names])
    checked, n_exact = budget, 0
    if exact:
        checked = SensorBudget.of(model, observed, accuracy).budget()
        affordable = max_simulations - simulations - PREDICTIVE_DRAWS
        tree, n_exact = _sample_exact(
            model, observed, checked, prior, tree, affordable, executor, seed
        )
        simulations += n_exact
    check, n_check = _predictive_check(tree, model, checked, executor, rng)
    stats = tree["sample_stats"].to_dataset()
    coords = {"output": list(checked.outputs)}
    for key in PPC_KEYS:
        stats[f"ppc_{key}"] = xr.DataArray(
            [check[name][key] for name in checked.outputs], dims="output", coords=coords
        )
    if offset is not None:
        _to_unit_charge(tree, offset, rng)
        stats["coil_offset_kg"] = xr.DataArray(
            offset.offsets, dims="offset_charge", coords={"offset_charge": offset.charges}
        )
    stats["error_draws"] = budget.n_draws
    stats["error_failed"] = budget.n_failed
    stats["error_rounds"] = rounds
    stats["exact_simulations"] = n_exact
    stats["n_simulations"] = simulations + n_check
    tree["sample_stats"] = xr.DataTree(stats)
    tree["constant_data"] = xr.DataTree(inputs)
    misfit = [name for name in checked.outputs if check[name]["misfit"]]
    if misfit:
        warnings.warn(
            "the model cannot reproduce "
            + ", ".join(
                f"{name} (mean standardised residual {check[name]['z_mean']:+.1f})"
                for name in misfit
            )
            + ": the posterior rests on a model that misses these sensors",
            stacklevel=2,
        )
    return tree


def _error_thetas(
    first: np.ndarray | None, previous: np.ndarray | None, n_draws: int, rng: np.random.Generator
) -> np.ndarray | None:
    """Where a round's model error is drawn: ``n_draws`` of the ``previous`` round's posterior
    draws, half of them instead of the ``first`` round's draws when both are given (a second
    round: its error both where the first round drew it and where the first round's posterior
    put it)."""
    if previous is None:
        return None
    if first is None or first is previous:
        return previous[rng.choice(len(previous), n_draws)]
    half = n_draws // 2
    return np.vstack(
        [first[rng.choice(len(first), half)], previous[rng.choice(len(previous), n_draws - half)]]
    )


def _error_runs(n_draws: int, coils: str, commissioned: Commissioning | None) -> int:
    """Simulations of an error budget of ``n_draws`` draws: each draw's pair, and with a
    commissioning record each draw's unit on it too and the commissioning Jacobian."""
    runs = RUNS_PER_DRAW[coils] * n_draws
    return runs if commissioned is None else 2 * runs + commissioned.runs


def _commissioning_record(commissioning: xr.DataTree, model: VCCSimulator) -> Commissioning | None:
    """The commissioning record behind a commissioning posterior, for the later record's
    model error (:func:`~pymc_vcc.studies.record_budget.compensate`); None for a posterior
    written without its record (before the record travelled with it) or of other outputs."""
    observed = None
    if {"observed_data", "constant_data"} <= set(commissioning):
        observed = commissioning["observed_data"].to_dataset()
    if observed is None or list(observed.data_vars) != list(model.output_names):
        warnings.warn(
            "the commissioning posterior holds no record of the later record's outputs (it was "
            "written before a calibration kept its record, or logged other sensors): the model "
            "error is drawn without what the commissioning absorbed, and a large leak reads "
            "short; calibrate the commissioning log again to keep it",
            stacklevel=3,
        )
        return None
    posterior = commissioning["posterior"]
    names = [
        name
        for name in model.parameter_names
        if name in posterior.data_vars and name not in model.unit.faults.ids
    ]
    columns = [
        posterior.get(MODEL_CHARGE, posterior[CHARGE]) if n == CHARGE else posterior[n]
        for n in names
    ]
    stats = commissioning["sample_stats"]
    offset = None
    if "coil_offset_kg" in stats:
        table = stats["coil_offset_kg"]
        offset = CoilOffset(np.asarray(table["offset_charge"].values), np.asarray(table.values))
    record = VCCSimulator(
        model.unit,
        held_inputs(commissioning["constant_data"].to_dataset()),
        outputs=list(model.output_names),
        t_window=(0.0, float(observed["time"].values[-1])),
        parameters=names,
        solver=model.solver,
        settle=SETTLE,
    )
    draws = np.column_stack([np.asarray(c.values).ravel() for c in columns])
    return Commissioning(record, observed, draws, offset)


def _sample(
    method: str,
    model: VCCSimulator,
    observed: xr.Dataset,
    budget: ErrorBudget,
    prior: Prior,
    particles: int,
    max_simulations: int,
    executor: Executor,
    seed: int,
    progressbar: bool,
    reference: GaussianReference | None,
) -> tuple[xr.DataTree, int]:
    """The posterior under ``budget`` by ``method``, and its simulations (SMC's soft cap
    ``max_simulations``, its tempering from ``reference`` if given; the rejection's budget is
    set by ``particles``)."""
    if method == "rejection":
        tree = abc_rejection(
            model,
            prior,
            observed,
            n_pilot=REJECTION_PILOT * particles,
            quantile=REJECTION_QUANTILE,
            n_main=REJECTION_MAIN * particles,
            n_desired=REJECTION_MAIN * particles,
            distance=budget.distance,
            run=RunOptions(executor=executor, seed=seed, progress=progressbar),
        )
        return tree, int(tree["sample_stats"]["n_simulations"])
    with pm.Model():
        add_likelihood("outputs", model, observed, error_budget=budget, prior=prior)
        tree = sample_smc_abc(
            particles,
            executor=executor,
            random_seed=seed,
            progressbar=progressbar,
            max_simulations=max_simulations,
            reference=reference,
        )
    stats = tree["sample_stats"]
    return tree, int(stats["simulations"].sum() + stats["resumed_simulations"].sum())


def _sample_exact(
    model: VCCSimulator,
    observed: xr.Dataset,
    budget: ErrorBudget,
    prior: Prior,
    start: xr.DataTree,
    max_simulations: int,
    executor: Executor,
    seed: int,
) -> tuple[xr.DataTree, int]:
    """``start`` with its posterior replaced by that of a record the model itself made, under
    ``budget`` (the sensors' errors alone), and the simulations that took: least-squares fits
    from the ``start`` posterior (the calibration under the model's error: its mean and the
    particles at :data:`EXACT_STARTS`) and the Laplace approximation at the modes found
    (:func:`~pymc_vcc.inference.pymc.laplace.fit_reference`, forward differences of
    :data:`EXACT_STEP` of each box, :func:`~pymc_vcc.inference.pymc.laplace.laplace_draws`).
    SMC under so sharp a likelihood, from the prior or from that approximation, left 96
    particles on wrong modes or too narrow (4 of the first 6 model records missed)."""
    run = RunOptions(executor=executor, seed=seed)
    posterior = start["posterior"]
    draws = np.column_stack([posterior[name].values.ravel() for name in prior.names])
    charge = draws[:, prior.names.index(CHARGE) if CHARGE in prior.names else 0]
    picks = [np.argmin(np.abs(charge - np.quantile(charge, q))) for q in EXACT_STARTS]
    points = [dict(zip(prior.names, map(float, draws[k]), strict=True)) for k in picks]
    with pm.Model() as pymc_model:
        add_likelihood("outputs", model, observed, error_budget=budget, prior=prior)
        for name, value in zip(prior.names, draws.mean(axis=0), strict=True):
            pymc_model.set_initval(pymc_model[name], float(value))
        reference = fit_reference(
            points=points,
            max_simulations=max_simulations // (1 + len(points)),
            step=EXACT_STEP,
            inflation=1.0,
            axis_rounds=0,
            run=run,
        )
        exact = laplace_draws(reference, EXACT_DRAWS, np.random.default_rng(seed))
    dims = ("chain", "draw")
    coords = {"chain": [0], "draw": np.arange(EXACT_DRAWS)}
    tree = start.copy()
    tree["posterior"] = xr.DataTree(
        xr.Dataset({name: (dims, values[np.newaxis]) for name, values in exact.items()}, coords)
    )
    return tree, reference.simulations


def _to_unit_charge(tree: xr.DataTree, offset: CoilOffset, rng: np.random.Generator) -> None:
    """Rename the sampled charge ``M0_model`` and put the unit's charge in ``M0``."""
    posterior = tree["posterior"].to_dataset()
    model_charge = posterior[CHARGE]
    unit_charge = offset.unit_charge(model_charge.values, rng)
    posterior[MODEL_CHARGE] = model_charge
    posterior[CHARGE] = model_charge.copy(data=unit_charge)
    tree["posterior"] = xr.DataTree(posterior)


def _predictive_check(
    tree: xr.DataTree,
    model: VCCSimulator,
    budget: ErrorBudget,
    executor: Executor,
    rng: np.random.Generator,
) -> tuple[dict[str, dict[str, float]], int]:
    posterior = tree["posterior"]
    names = list(model.parameter_names)
    samples = np.column_stack([posterior[name].values.ravel() for name in names])
    picks = rng.choice(len(samples), min(PREDICTIVE_DRAWS, len(samples)), replace=False)
    thetas = [dict(zip(names, map(float, samples[k]), strict=True)) for k in picks]
    runs = executor.map(model, thetas)
    summaries = [
        summarise(np.stack([run[name].values for name in budget.outputs]), budget.windows)
        for run in runs
        if finished(run)
    ]
    return predictive_check(budget, np.asarray(summaries)), len(thetas)


def predictive_checks(tree: xr.DataTree) -> dict[str, dict[str, float]]:
    """The predictive check per output that :func:`calibrate_record` stored in
    ``sample_stats``: output -> ``z_mean``, ``p_value``, ``misfit`` (1.0 or 0.0)."""
    stats = tree["sample_stats"]
    return {
        str(name): {key: float(stats[f"ppc_{key}"].sel(output=name)) for key in PPC_KEYS}
        for name in stats["output"].values
    }


def charge_summary(tree: xr.DataTree, interval: float = 0.95) -> dict[str, float]:
    """Posterior mean, sd and central interval of the charge, kg."""
    draws = tree["posterior"][CHARGE].values.ravel()
    low, high = np.quantile(draws, [(1 - interval) / 2, (1 + interval) / 2])
    return {
        "mean_kg": float(draws.mean()),
        "sd_kg": float(draws.std()),
        "low_kg": float(low),
        "high_kg": float(high),
    }


POSTERIOR_FILE = "posterior.nc"
PRIOR_FILE = "prior.nc"


@dataclass
class RecordResult:
    """What a record's calibration found.

    Attributes:
        tree: the posterior DataTree (with the predictive check in ``sample_stats``).
        charge: the charge's posterior mean, sd and 95 % interval, kg.
        checks: per output, the predictive check (``z_mean``, ``p_value``, ``misfit``).
        n_simulations: every simulation the result rests on.
        wall_seconds: wall time, s.
        alarm: P(charge <= alarm fraction × commissioned charge) on a later record
            (:func:`leak_alarm`).
        commissioning_kg: the commissioning posterior's mean charge, kg.
    """

    tree: xr.DataTree
    charge: dict[str, float]
    checks: dict[str, dict[str, float]]
    n_simulations: int
    wall_seconds: float
    alarm: float | None = None
    commissioning_kg: float | None = None

    def summary(self) -> dict:
        """The JSON summary."""
        return {
            "charge": self.charge,
            "checks": self.checks,
            "misfit_outputs": [name for name, c in self.checks.items() if c["misfit"]],
            "alarm": self.alarm,
            "commissioning_kg": self.commissioning_kg,
            "n_simulations": self.n_simulations,
            "wall_seconds": round(self.wall_seconds, 1),
        }

    def format_table(self) -> str:
        """The charge and the predictive check, as engineers read them."""
        c = self.charge
        lines = [
            f"charge M0 = {c['mean_kg']:.3f} ± {c['sd_kg']:.3f} kg "
            f"(95 % interval {c['low_kg']:.3f} to {c['high_kg']:.3f} kg)"
        ]
        if self.alarm is not None:
            lines.append(
                f"leak alarm: P(M0 below the alarm threshold) = {self.alarm:.2f} "
                f"(commissioned at {self.commissioning_kg:.3f} kg)"
            )
        lines.append("\noutput  z_mean  p_value  model reproduces it")
        for name, check in self.checks.items():
            verdict = "NO" if check["misfit"] else "yes"
            lines.append(f"{name:<7} {check['z_mean']:+6.2f}  {check['p_value']:7.3g}  {verdict}")
        return "\n".join(lines)


def later_prior(
    commissioning: xr.DataTree,
    unit: Unit,
    drift: float,
    seed: int,
    probability: float = FAULT_PROBABILITY,
) -> GMMPrior:
    """The prior of a later record of a commissioned unit (a spike and slabs): the unit as
    commissioned (each parameter moved by ``drift`` × its range, the charge the model's own,
    the fault parameters near 0) as the spike, and each fault's parameters
    (:data:`~pymc_vcc.studies.faults.FAULTS`), with ``probability``, anywhere in their ranges
    the fault can move them to (a coil's conductance only below commissioning), at most two
    faults at once.

    The spike is one Gaussian with a full covariance (in the bounds' logit space): the
    commissioning data pin combinations of parameters (the condenser's conductance, not its
    HTC and airflow apart), which a diagonal spike, as wide as each parameter alone, would let
    a later record move freely. A healthy unit is the likelier state before the data are seen,
    so that a change is found only when the data ask for it, and whatever else has changed
    can take its share of the data rather than push the charge.

    Args:
        commissioning: the commissioning posterior (it must hold the charge and every
            calibration parameter a fault moves, as ``pymc-vcc calibrate`` writes it).
        unit: the unit (its cycle must have the fault parameters).
        drift: sd of each parameter's move since commissioning, a fraction of its range.
        seed: seeds the mixture's fit.
        probability: each fault's prior probability
            (:data:`~pymc_vcc.studies.faults.FAULT_PROBABILITY`).
    """
    check_fault_probability(probability)
    needed = {pid for fault in FAULTS for pid in fault.parameters}
    lacking = sorted(needed - set(unit.parameters.ids) - set(unit.faults.ids))
    if lacking:
        raise ValueError(f"the unit's cycle lacks the fault parameter(s) {lacking}")
    posterior = commissioning["posterior"]
    names = [str(n) for n in posterior.data_vars if n in unit.parameters.ids]
    absent = [pid for pid in (CHARGE, *moved_parameters(unit)) if pid not in names]
    if absent:
        raise ValueError(
            f"the commissioning posterior lacks {absent}; calibrate the healthy unit with "
            "`pymc-vcc calibrate` (the charge and its nuisance parameters)"
        )
    samples = {n: posterior[n].values.ravel() for n in names}
    samples[CHARGE] = posterior.get(MODEL_CHARGE, posterior[CHARGE]).values.ravel()
    n_draws = len(samples[CHARGE])
    rng = np.random.default_rng(seed)
    for name in unit.faults.ids:
        spec = unit.parameter_spec(name)
        healthy = expit(logit(HEALTHY_FAULT_FRACTION) + rng.standard_normal(n_draws))
        samples[name] = spec.low + (spec.high - spec.low) * healthy
    drifts = {name: (drift if name in names else 0.0) for name in samples}
    spike = GMMPrior.fit(
        samples,
        box_prior(unit, list(samples)),
        max_components=1,
        seed=seed,
        drift=drifts,
        covariance="full",
    )
    groups = list(dict.fromkeys(fault.parameters for fault in FAULTS))
    # a group only a lowering fault moves (a coil's conductance) spreads below commissioning
    raising = {fault.parameters for fault in FAULTS if fault.direction > 0}
    lowering = [group for group in groups if group not in raising]
    return spike.with_slabs(groups, probability, downward=lowering)


ALARM_FRACTION = 0.9  # the leak alarm: P(charge <= 0.9 × commissioned)
ALARM_PROBABILITY = 0.5  # the alarm sounds above this posterior probability


def leak_alarm(
    later: xr.DataTree, commissioning: xr.DataTree, unit: Unit, fraction: float, seed: int
) -> float:
    """The leak alarm's probability: that the charge of a later record's posterior is below
    ``fraction`` of the commissioned one, each draw paired with a commissioning draw (the
    undercharge's intensity beyond 1 − ``fraction``,
    :func:`~pymc_vcc.studies.faults.fault_intensities`; the model's form error integrated
    out, :func:`~pymc_vcc.studies.faults.beyond_probability`)."""
    draws = {str(n): later["posterior"][n].values.ravel() for n in later["posterior"].data_vars}
    undercharge = next(fault for fault in FAULTS if fault.name == "undercharge")
    read = fault_intensities(draws, commissioning["posterior"], unit, seed, [undercharge])
    return beyond_probability(read[undercharge.name], 1.0 - fraction)


def load_commissioning(path: str | Path) -> xr.DataTree:
    """The posterior a calibration wrote (its folder, or its ``posterior.nc``)."""
    path = Path(path)
    path = path / POSTERIOR_FILE if path.is_dir() else path
    if not path.is_file():
        raise FileNotFoundError(f"no commissioning posterior at {path}")
    return xr.open_datatree(path, engine="h5netcdf")


def record_study(
    settings,
    log: str,
    *,
    column_map: str | None = None,
    unit: Unit | None = None,
    commissioning: str | None = None,
    drift: float = 0.03,
    alarm_fraction: float = ALARM_FRACTION,
    rounds: int = 1,
    coils: str = "finer",
    method: str = "likelihood",
    attempts: int = 1,
) -> RecordResult:
    """Calibrate a unit's log (``pymc-vcc calibrate``), or identify its charge against a
    commissioning result (``pymc-vcc leak LOG --prior``): load and check the log before any
    simulation, calibrate, and write the posterior, its mixture prior for later records, the
    predictive check and a figure into ``settings.out``.

    Args:
        settings: where and how it runs (:class:`~pymc_vcc.studies.StudySettings`; budget
            ``smoke``, ``small`` or ``paper``, see :data:`RECORD_BUDGETS`).
        log: the CSV log.
        column_map: its column map (TOML; default: ``LOG.columns.toml`` beside it).
        unit: the unit description (default: the built-in split unit).
        commissioning: a folder (or ``posterior.nc``) written by a calibration of the healthy
            unit; then the leak check against it (prior :func:`later_prior`, alarm
            :func:`leak_alarm`).
        drift: sd of each parameter's change since commissioning, a fraction of its range.
        alarm_fraction: the alarm's threshold, a fraction of the commissioned charge.
        rounds, coils, method, attempts: as for :func:`calibrate_record`.
    """
    from pymc_vcc.io.measurements import load_log
    from pymc_vcc.plots import plot_charge_posteriors, save_figure
    from pymc_vcc.studies.common import write_json, write_netcdf, write_text

    started = time.perf_counter()
    if not 0.0 < alarm_fraction < 1.0:
        raise ValueError(f"alarm fraction must lie in (0, 1), got {alarm_fraction}")
    check_drift(drift)
    budget = record_budget_name(settings)
    unit = unit or load_unit()
    measured = load_log(log, column_map, dt=OUTPUT_INTERVAL)
    commissioned, before = None, None
    if commissioning is not None:
        before = load_commissioning(commissioning)
        commissioned = float(before["posterior"][CHARGE].mean())
    draws, error_draws = RECORD_BUDGETS[budget]
    with settings.claim_output("calibrate" if commissioning is None else "leak"):
        with settings.open_executor() as executor:
            tree = calibrate_record(
                measured.observed,
                measured.inputs,
                executor,
                unit=unit,
                commissioning=before,
                drift=drift,
                draws=draws,
                error_draws=error_draws,
                seed=settings.seed,
                solver=settings.solver or "cvode",
                rounds=rounds,
                coils=coils,
                method=method,
                attempts=attempts,
            )
        stats = tree["sample_stats"]
        checks = predictive_checks(tree)
        alarm = None
        if before is not None:
            alarm = leak_alarm(tree, before, unit, alarm_fraction, settings.seed)
        result = RecordResult(
            tree=tree,
            charge=charge_summary(tree),
            checks=checks,
            n_simulations=int(stats["n_simulations"]),
            wall_seconds=time.perf_counter() - started,
            alarm=alarm,
            commissioning_kg=commissioned,
        )
        if settings.out is not None:
            out = settings.out
            write_netcdf(tree, out / POSTERIOR_FILE)
            names = [n for n in tree["posterior"].data_vars if n in unit.parameters.ids]
            samples = {n: tree["posterior"][n].values.ravel() for n in names}
            GMMPrior.fit(samples, box_prior(unit, names), seed=settings.seed).save(out / PRIOR_FILE)
            write_json(out / "summary.json", result.summary())
            write_text(out / "report.txt", result.format_table() + "\n")
            figure = plot_charge_posteriors([tree], [commissioned or result.charge["mean_kg"]])
            save_figure(figure, out / "charge")
    return result
