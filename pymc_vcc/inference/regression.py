"""Regression-adjusted ABC around a posterior (Beaumont, Zhang & Balding 2002; Fearnhead &
Prangle 2012).

SMC-ABC in 26–35 dimensions finds where the posterior lies, but with ~128 particles its spread
is shaped by resampling and by the ε it could reach rather than by the data. This stage takes
the posterior's place and spends its simulations on fresh, independent draws there:

1. **Box**: each parameter's range over the posterior draws, widened by ``widen`` of that range
   on each side and clipped to the prior's bounds.
2. **Draws**: ``n`` draws of the prior restricted to the box (the restriction drops only prior
   mass the posterior does not reach, so the posterior is unchanged), exact under a uniform
   prior and a mixture of diagonal Gaussians (dataset 2's: its second round's box held
   1e-22 of its mass), by rejection otherwise (uniform draws weighted by the mixture's density
   left one draw carrying all the weight in 35 dimensions).
3. **Simulations**: noise-free and checkpointed (:func:`~pymc_vcc.inference.reference_table.
   simulate_draws`), then each draw's output noise: the paper's ν or learnable sensor scales
   σ among the draw's parameters, or known sensor noise.
4. **Summaries** (semi-automatic ABC): each output's 10 s means over its observed spread and
   its roughness within them (which tells the output noise's scale, so that a second round
   draws it where the data put it, and its simulations are no noisier than the data); a
   ridge regression of each parameter on them (standardized), fitted on half the draws with
   its penalty chosen by leave-one-out error, predicts every parameter. The parameters are
   regressed as ``logit`` of their place between the prior's bounds. (Ridge explains more than
   partial least squares with up to 30 components: held-out R² of M0 0.92 against 0.87 on
   dataset 1's noise-free draws.)
5. **Rejection**: the ``accept`` fraction of draws whose summaries lie nearest the observed
   ones (Euclidean, each summary over its parameter's spread), Epanechnikov weights.
6. **Adjustment**: weighted least squares of the parameters on the summaries' offsets from the
   observed ones; each accepted draw becomes the fit at the data plus its residual over
   sqrt(1 − leverage) (the raw residuals of d + 1 coefficients fitted to a few hundred draws
   are too small by that factor), back through the logistic (inside the bounds). A parameter
   whose summary does not predict it (held-out R² below :data:`MIN_HELD_OUT_R2`) keeps its
   accepted draws: its slopes are noise, and their fit at the data, an extrapolation from the
   accepted cloud, shifted the inert FO_SPEED by 1.4 sds in logit space, which pressed its
   physical spread against a bound (0.68 of the prior's). The other summaries stay in the
   fit of each informed parameter: they also carry what the noise features add to its own.
7. **Rounds**: the next round draws in the box of this round's posterior. Summaries fitted
   over a box much wider than the posterior are linear where the outputs are not, and the
   first round's posterior can be wide and off (3 sd on the one-parameter sensor problem from
   a KS-SMC posterior); the second round's summaries are fitted where the posterior is.

A parameter the outputs do not inform has no predictive summary and is not adjusted: it keeps
the spread of the box draws, the prior's. The result is weighted; it is resampled (systematic) to
as many equally weighted draws as were accepted.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import xarray as xr
from sklearn.linear_model import RidgeCV
from sklearn.pipeline import Pipeline, make_pipeline
from sklearn.preprocessing import StandardScaler

from pymc_vcc.execution.options import RunOptions
from pymc_vcc.execution.outcomes import OK
from pymc_vcc.inference.distances import output_scales, window_means
from pymc_vcc.inference.noise import (
    SensorNoise,
    add_output_noise,
    is_noise_parameter,
    noise_parameter,
    sensor_parameter,
)
from pymc_vcc.inference.priors import MAX_BOX_TRIES, Prior
from pymc_vcc.inference.reference_table import simulate_draws
from pymc_vcc.inference.series import ObservedData, OutputData, prepare_observed
from pymc_vcc.inference.simulator import Simulator

SUMMARY_WINDOW = 10
"""Samples averaged into one summary feature (10 s on the 1 s grid)."""

RIDGE_PENALTIES = np.logspace(-4, 4, 17)
"""Ridge penalties tried for each parameter's summary (on standardized features)."""

WIDEN = 0.1
"""Default margin of the box on each side, in ranges of the posterior draws. The range of a few
hundred draws spans ~6 sd already; on dataset 1 a margin of 0.1 gave M0 and CF_VOL sd ratios
of 0.05–0.16 where 0.5 (a box ~11 sd wide, the summaries less local) gave 0.20–0.35."""

ACCEPT = 0.1
"""Default fraction of a round's draws kept, nearest in summaries to the data."""

ACCEPTED_PER_COEFFICIENT = 4
"""Accepted draws needed per coefficient of the adjustment (with barely more draws than
coefficients the fit passes through them and every adjusted draw lands on one point)."""

MAX_LEVERAGE = 0.9
"""Largest leverage a residual is corrected for (its inflation at most 1/sqrt(0.1) ≈ 3.2)."""

MIN_HELD_OUT_R2 = 0.05
"""Held-out R² below which a parameter's summary is noise and the parameter is not adjusted
(inert parameters score about 0, informed ones 0.1–0.9)."""

ROUNDS = 2
"""Default rounds, each around the posterior of the one before (module docstring, step 7)."""


def _check_fraction(name: str, value: float, low: float, high: float) -> float:
    if not low < float(value) < high:
        raise ValueError(f"{name} must lie in ({low}, {high}), got {value!r}")
    return float(value)


def posterior_box(
    posterior: xr.Dataset, prior: Prior, widen: float = WIDEN
) -> dict[str, tuple[float, float]]:
    """Each prior parameter's range over the posterior draws, widened by ``widen`` of that range
    on each side, inside the prior's bounds."""
    if not float(widen) >= 0.0:
        raise ValueError(f"widen must be >= 0, got {widen!r}")
    missing = [name for name in prior.names if name not in posterior.data_vars]
    if missing:
        raise ValueError(f"the posterior lacks the prior's parameter(s) {missing}")
    box = {}
    for name, (low, high) in prior.bounds.items():
        values = posterior[name].values
        least, most = float(values.min()), float(values.max())
        margin = widen * (most - least)
        box[name] = (max(low, least - margin), min(high, most + margin))
    return box


def check_draws(n: int, dimensions: int, accept: float) -> int:
    """The draws the ``accept`` fraction of ``n`` keeps, refused if fewer than
    :data:`ACCEPTED_PER_COEFFICIENT` per coefficient of the adjustment (``dimensions`` + 1)."""
    kept = round(accept * n)
    needed = ACCEPTED_PER_COEFFICIENT * (dimensions + 1)
    if kept < needed:
        raise ValueError(
            f"accept={accept} of {n} draws keeps {kept}; the adjustment of {dimensions} "
            f"parameters needs at least {needed}: give at least "
            f"{math.ceil(needed / accept)} draws a round or a larger accept"
        )
    return kept


def summary_features(
    values: np.ndarray, observed: np.ndarray, window: int = SUMMARY_WINDOW
) -> np.ndarray:
    """Each output's ``window``-sample means over its observed spread, then each output's
    roughness: its rms deviation from those means over its rms value (where output noise shows).

    ``values`` (N, n_outputs, n) on the observed grid, ``observed`` (n_outputs, n) → (N, F)."""
    values = np.asarray(values, dtype=float)
    means = window_means(values, window)
    within = values[..., : means.shape[-1] * window] - np.repeat(means, window, axis=-1)
    roughness = np.sqrt((within**2).mean(axis=-1) / (values**2).mean(axis=-1))
    scaled = means / output_scales(observed)
    return np.concatenate([scaled.reshape(scaled.shape[0], -1), roughness], axis=1)


def _to_logit(thetas: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    place = np.clip((thetas - lower) / (upper - lower), 1e-9, 1 - 1e-9)
    return np.log(place / (1 - place))


def _from_logit(z: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    return lower + (upper - lower) / (1 + np.exp(-z))


def _fit_summaries(x: np.ndarray, z: np.ndarray) -> Pipeline:
    """Ridge regressions of each parameter on the standardized features, each with the penalty
    its leave-one-out error prefers among :data:`RIDGE_PENALTIES`."""
    return make_pipeline(
        StandardScaler(), RidgeCV(alphas=RIDGE_PENALTIES, alpha_per_target=True)
    ).fit(x, z)


@dataclass(frozen=True)
class Adjustment:
    """The accepted draws, adjusted, and how they were found.

    Attributes:
        thetas: accepted draws before adjustment (n_accepted, d), physical units.
        adjusted: the same draws after the local-linear adjustment (n_accepted, d); those of a
            parameter with held-out R² below :data:`MIN_HELD_OUT_R2` as accepted.
        weights: Epanechnikov weights of the accepted draws (n_accepted,), summing to 1.
        penalties: per parameter, the ridge penalty of its summary.
        held_out_r2: per parameter, R² of its summary on the draws the fit did not see, from
            medians (1 − median squared error / median squared deviation): a few simulations
            100 sds off in their features took the mean-based R² of M0 to −0.43.
        bandwidth: largest accepted distance between summaries.
    """

    thetas: np.ndarray
    adjusted: np.ndarray
    weights: np.ndarray
    penalties: np.ndarray
    held_out_r2: np.ndarray
    bandwidth: float

    @property
    def effective_size(self) -> float:
        """Kish's effective sample size of the weights."""
        return float(1.0 / (self.weights**2).sum())


def _leverages(design: np.ndarray) -> np.ndarray:
    """The hat matrix's diagonal of a least-squares ``design`` (n, p), at most
    :data:`MAX_LEVERAGE`: a residual over sqrt(1 − h) has the noise's variance, where the raw
    residual's is (1 − h) of it (the fit bends towards each of its points)."""
    left, singular, _ = np.linalg.svd(design, full_matrices=False)
    rank = int((singular > singular[0] * 1e-10).sum()) if singular.size else 0
    return np.minimum((left[:, :rank] ** 2).sum(axis=1), MAX_LEVERAGE)


def regression_adjustment(
    thetas: np.ndarray,
    features: np.ndarray,
    observed_features: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    *,
    accept: float = ACCEPT,
) -> Adjustment:
    """Semi-automatic summaries, rejection and local-linear adjustment (module docstring, steps
    4–6) of draws ``thetas`` (N, d) inside ``lower``/``upper`` with ``features`` (N, F) of their
    simulations and ``observed_features`` (F,) of the data."""
    thetas = np.asarray(thetas, dtype=float)
    features = np.asarray(features, dtype=float)
    n, d = thetas.shape
    _check_fraction("accept", accept, 0.0, 1.0)
    if features.shape[0] != n or observed_features.shape != features.shape[1:]:
        raise ValueError(
            f"features {features.shape} and observed features {observed_features.shape} do not "
            f"match {n} draws"
        )
    n_accept = check_draws(n, d, accept)
    z = _to_logit(thetas, lower, upper)
    fit = np.arange(n) < n // 2
    model = _fit_summaries(features[fit], z[fit])
    summaries = model.predict(features).reshape(n, d)
    observed_summary = model.predict(observed_features[np.newaxis]).reshape(d)
    held_out = z[~fit]
    held_out_r2 = 1 - np.median((summaries[~fit] - held_out) ** 2, axis=0) / (
        np.median((held_out - np.median(held_out, axis=0)) ** 2, axis=0) + 1e-300
    )
    offsets = summaries - observed_summary
    distance = np.sqrt(((offsets / (z.std(axis=0) + 1e-300)) ** 2).sum(axis=1))
    nearest = np.argsort(distance, kind="stable")[:n_accept]
    bandwidth = float(distance[nearest[-1]]) * (1 + 1e-9) + 1e-300
    weights = 1 - (distance[nearest] / bandwidth) ** 2
    weights /= weights.sum()
    design = np.column_stack([np.ones(n_accept), offsets[nearest]])
    root = np.sqrt(weights)[:, np.newaxis]
    informed = held_out_r2 >= MIN_HELD_OUT_R2
    kept = z[nearest][:, informed]
    coefficients, *_ = np.linalg.lstsq(design * root, kept * root, rcond=None)
    residuals = kept - design @ coefficients
    adjusted = z[nearest]
    adjusted[:, informed] = (
        coefficients[0] + residuals / np.sqrt(1 - _leverages(design * root))[:, np.newaxis]
    )
    return Adjustment(
        thetas=thetas[nearest],
        adjusted=_from_logit(adjusted, lower, upper),
        weights=weights,
        penalties=np.broadcast_to(model[-1].alpha_, d).copy(),
        held_out_r2=held_out_r2,
        bandwidth=bandwidth,
    )


def _add_noise(
    values: np.ndarray,
    names: tuple[str, ...],
    draws: np.ndarray,
    outputs: tuple[str, ...],
    sensor_noise: SensorNoise | None,
    observed: OutputData,
    seeds: list[np.random.SeedSequence],
) -> np.ndarray:
    """Each finished simulation with its draw's output noise: the paper's ν and sensor noise
    (learnable σ among ``names``, else the fixed scales), in place."""
    column = {name: j for j, name in enumerate(names)}
    nu = [column.get(noise_parameter(output)) for output in outputs]
    sigma = [column.get(sensor_parameter(output)) for output in outputs]
    noise = None
    if sensor_noise is not None:
        noise = sensor_noise.resolve(prepare_observed(observed, list(outputs)))
    for index, seed in enumerate(seeds):
        if np.isnan(values[index]).any():
            continue
        rng = np.random.default_rng(seed)
        row = draws[index]
        if any(j is not None for j in nu):
            scales = np.array([0.0 if j is None else row[j] for j in nu])
            values[index] = add_output_noise(values[index], scales, rng)
        if noise is not None:
            scales = np.array(
                [
                    fixed if j is None else row[j]
                    for j, fixed in zip(sigma, noise.scales, strict=True)
                ]
            )
            values[index] = noise.sample(values[index], rng, scales)
    return values


@dataclass(frozen=True)
class _Round:
    """One round's posterior draws (n_accepted, d) resampled by weight, its adjustment and box,
    its failed simulations and the data as the simulations' outputs."""

    draws: np.ndarray
    adjustment: Adjustment
    box: dict[str, tuple[float, float]]
    failed: int
    data: ObservedData


def _regression_round(
    simulator: Simulator,
    prior: Prior,
    posterior: xr.Dataset,
    observed: OutputData,
    n: int,
    widen: float,
    accept: float,
    sensor_noise: SensorNoise | None,
    run: RunOptions,
    seed: np.random.SeedSequence,
) -> _Round:
    """One round (module docstring, steps 1–6), its simulations as ``run`` says, from
    ``seed``."""
    box_seed, noise_seed, simulation_seed, resample_seed = seed.spawn(4)
    box = posterior_box(posterior, prior, widen)
    draws = prior.sample_in_box(box, n, np.random.default_rng(box_seed))
    if draws is None:
        warnings.warn(
            f"the prior puts less than 1/{MAX_BOX_TRIES} of its mass in the posterior's box; "
            "this round draws from the whole prior",
            RuntimeWarning,
            stacklevel=3,
        )
        box = prior.bounds
        draws = prior.sample(n, np.random.default_rng(box_seed))
    model = tuple(name for name in prior.names if not is_noise_parameter(name))
    columns = [prior.names.index(name) for name in model]
    table = simulate_draws(
        simulator,
        model,
        draws[:, columns],
        observed,
        run=replace(run, seed=simulation_seed),
    )
    (phase,) = table.values
    finished = table.status[phase] == OK
    data = prepare_observed(observed, list(table.outputs))
    values = _add_noise(
        table.values[phase].copy(),
        prior.names,
        draws,
        table.outputs,
        sensor_noise,
        observed,
        noise_seed.spawn(n),
    )
    adjustment = regression_adjustment(
        draws[finished],
        summary_features(values[finished], data.values),
        summary_features(data.values[np.newaxis], data.values)[0],
        prior.lower,
        prior.upper,
        accept=accept,
    )
    rng = np.random.default_rng(resample_seed)
    size = len(adjustment.weights)
    positions = (rng.uniform() + np.arange(size)) / size
    picked = np.minimum(np.searchsorted(np.cumsum(adjustment.weights), positions), size - 1)
    return _Round(adjustment.adjusted[picked], adjustment, box, int((~finished).sum()), data)


def regression_abc(
    simulator: Simulator,
    prior: Prior,
    posterior: xr.Dataset,
    observed: OutputData,
    *,
    n: int,
    rounds: int = ROUNDS,
    widen: float = WIDEN,
    accept: float = ACCEPT,
    sensor_noise: SensorNoise | None = None,
    run: RunOptions | None = None,
) -> xr.DataTree:
    """The regression-adjusted posterior of ``observed`` around ``posterior`` (module docstring).

    Args:
        simulator: the model, ``simulator(theta, rng)`` on the observed grid, deterministic.
        prior: the prior of the calibration (model parameters and any noise scales).
        posterior: a posterior group holding every prior parameter (e.g. SMC-ABC's).
        observed: the data, a Dataset of outputs or an array (outputs, time).
        n: new simulations per round, drawn from the prior inside the posterior's box.
        rounds: rounds, each around the posterior of the one before.
        widen: the box's margin on each side, in ranges of the posterior draws.
        accept: fraction of the draws kept, nearest in summaries to the data.
        sensor_noise: sensor noise of the data (learnable scales ``sigma_<output>`` in the
            prior replace its fixed ones); None: only the prior's ν, if any.
        run: where and how the simulations run; its ``checkpoint`` is a folder persisting
            each finished chunk of simulations (a subfolder a round), its ``seed`` seeds the
            draws, the noise and the resampling.

    Returns:
        A DataTree: ``posterior`` (1 chain, the last round's accepted draws adjusted and
        resampled by weight), ``sample_stats`` (``n_simulations`` and ``n_failed`` of all
        rounds; the last round's ``n_accepted``, ``effective_size``, ``bandwidth``, and
        ``held_out_r2`` and ``penalty`` per parameter; ``box_low`` and ``box_high`` per round and
        parameter) and ``observed_data``.
    """
    started = time.perf_counter()
    for name, value in (("n", n), ("rounds", rounds)):
        if isinstance(value, bool) or int(value) != value or value < 1:
            raise ValueError(f"{name} must be a positive integer, got {value!r}")
    _check_fraction("accept", accept, 0.0, 1.0)
    check_draws(int(n), len(prior.names), accept)
    run = run or RunOptions()
    root = run.seed_sequence()
    boxes, failed = [], 0
    with run.open_executor() as running:
        for index, round_seed in enumerate(root.spawn(int(rounds))):
            last = _regression_round(
                simulator,
                prior,
                posterior,
                observed,
                int(n),
                widen,
                accept,
                sensor_noise,
                replace(
                    run,
                    executor=running,
                    checkpoint=None
                    if run.checkpoint is None
                    else Path(run.checkpoint) / f"round_{index}",
                ),
                round_seed,
            )
            posterior = xr.Dataset(
                {
                    name: (("chain", "draw"), last.draws[np.newaxis, :, j])
                    for j, name in enumerate(prior.names)
                }
            )
            boxes.append(last.box)
            failed += last.failed
    return xr.DataTree.from_dict(
        {
            "posterior": posterior,
            "sample_stats": xr.Dataset(
                {
                    "n_simulations": ((), int(n) * int(rounds)),
                    "n_failed": ((), failed),
                    "n_accepted": ((), len(last.draws)),
                    "effective_size": ((), last.adjustment.effective_size),
                    "bandwidth": ((), last.adjustment.bandwidth),
                    "held_out_r2": (("parameter",), last.adjustment.held_out_r2),
                    "penalty": (("parameter",), last.adjustment.penalties),
                    "box_low": (
                        ("round", "parameter"),
                        [[b[0] for b in box.values()] for box in boxes],
                    ),
                    "box_high": (
                        ("round", "parameter"),
                        [[b[1] for b in box.values()] for box in boxes],
                    ),
                },
                coords={"parameter": list(prior.names), "round": np.arange(int(rounds))},
                attrs={
                    "sampler": "regression_abc",
                    "widen": float(widen),
                    "accept": float(accept),
                    "wall_seconds": time.perf_counter() - started,
                },
            ),
            "observed_data": last.data.dataset,
        }
    )
