"""Regression-adjusted ABC around a posterior (Beaumont, Zhang & Balding 2002; Fearnhead &
Prangle 2012).

SMC-ABC in 26–35 dimensions finds where the posterior lies, but with ~128 particles its spread
is shaped by resampling and by the ε it could reach rather than by the data. This stage takes
the posterior's place and spends its simulations on fresh, independent draws there:

1. **Box**: each parameter's range over the posterior draws, widened by ``widen`` of that range
   on each side and clipped to the prior's bounds.
2. **Draws**: ``n`` draws of the prior restricted to the box (the restriction drops only prior
   mass the posterior does not reach, so the posterior is unchanged).
3. **Simulations**: noise-free and checkpointed (:func:`~pymc_vcc.inference.reference_table.
   simulate_draws`), then each draw's output noise: the paper's ν or learnable sensor scales
   σ among the draw's parameters, or known sensor noise.
4. **Summaries** (semi-automatic ABC): each output's 10 s means over its observed spread; a
   partial-least-squares regression of the parameters on them, fitted on half the draws with
   its number of components chosen by k-fold cross-validation, predicts every parameter. The
   parameters are regressed as ``logit`` of their place between the prior's bounds.
5. **Rejection**: the ``accept`` fraction of draws whose summaries lie nearest the observed
   ones (Euclidean, each summary over its parameter's spread), Epanechnikov weights.
6. **Adjustment**: weighted least squares of the parameters on the summaries' offsets from the
   observed ones; each accepted draw is moved by −B·(s − s_obs), back through the logistic
   (inside the bounds).

A parameter the outputs do not inform has no predictive summary and no slope: it keeps the
spread of the box draws, the prior's. The result is weighted; it is resampled (systematic) to
as many equally weighted draws as were accepted.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import xarray as xr
from sklearn.cross_decomposition import PLSRegression
from sklearn.model_selection import KFold

from pymc_vcc.execution.executors import Executor, ExecutorKind
from pymc_vcc.execution.outcomes import OK
from pymc_vcc.inference.distances import output_scales, window_means
from pymc_vcc.inference.noise import (
    SensorNoise,
    add_output_noise,
    is_noise_parameter,
    noise_parameter,
    sensor_parameter,
)
from pymc_vcc.inference.priors import Prior
from pymc_vcc.inference.reference_table import simulate_draws
from pymc_vcc.inference.series import OutputData, prepare_observed
from pymc_vcc.inference.simulator import Simulator

SUMMARY_WINDOW = 10
"""Samples averaged into one summary feature (10 s on the 1 s grid)."""

MAX_COMPONENTS = 30
"""Most partial-least-squares components tried."""

CV_FOLDS = 5
"""Folds of the cross-validation choosing the number of components."""

MAX_BOX_TRIES = 2000
"""Prior draws tried per wanted draw inside the box before giving up."""


def _check_fraction(name: str, value: float, low: float, high: float) -> float:
    if not low < float(value) < high:
        raise ValueError(f"{name} must lie in ({low}, {high}), got {value!r}")
    return float(value)


def posterior_box(
    posterior: xr.Dataset, prior: Prior, widen: float = 0.5
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


def draw_in_box(
    prior: Prior, box: Mapping[str, tuple[float, float]], n: int, rng: np.random.Generator
) -> np.ndarray:
    """``n`` draws (n, d) of ``prior`` restricted to ``box`` (name -> (low, high)), by rejection."""
    low = np.array([box[name][0] for name in prior.names])
    high = np.array([box[name][1] for name in prior.names])
    kept: list[np.ndarray] = []
    found, tried, batch = 0, 0, max(int(n), 64)
    while found < n:
        if tried > MAX_BOX_TRIES * n:
            raise RuntimeError(
                f"only {found} of {tried} prior draws fell inside the box; the prior puts too "
                "little mass there (is the posterior from another prior?)"
            )
        draws = prior.sample(batch, rng)
        inside = draws[((draws >= low) & (draws <= high)).all(axis=1)]
        kept.append(inside)
        found += len(inside)
        tried += batch
    return np.concatenate(kept)[:n]


def summary_features(
    values: np.ndarray, observed: np.ndarray, window: int = SUMMARY_WINDOW
) -> np.ndarray:
    """Each output's ``window``-sample means over its observed spread, flattened.

    ``values`` (N, n_outputs, n) on the observed grid, ``observed`` (n_outputs, n) → (N, F)."""
    scaled = window_means(np.asarray(values, dtype=float), window) / output_scales(observed)
    return scaled.reshape(scaled.shape[0], -1)


def _to_logit(thetas: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    place = np.clip((thetas - lower) / (upper - lower), 1e-9, 1 - 1e-9)
    return np.log(place / (1 - place))


def _from_logit(z: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    return lower + (upper - lower) / (1 + np.exp(-z))


@dataclass(frozen=True)
class _Pls:
    """A partial-least-squares regression of standardized parameters on standardized
    features; its first ``c`` components predict as a fit with ``c`` components would (NIPALS
    finds them one after another)."""

    model: PLSRegression
    x_mean: np.ndarray
    x_scale: np.ndarray
    z_mean: np.ndarray
    z_scale: np.ndarray

    @classmethod
    def fit(cls, x: np.ndarray, z: np.ndarray, components: int) -> _Pls:
        x_mean, x_scale = x.mean(axis=0), x.std(axis=0)
        z_mean, z_scale = z.mean(axis=0), z.std(axis=0)
        x_scale[x_scale == 0] = 1.0  # a feature or parameter that never varies
        z_scale[z_scale == 0] = 1.0
        model = PLSRegression(components, scale=False).fit(
            (x - x_mean) / x_scale, (z - z_mean) / z_scale
        )
        return cls(model, x_mean, x_scale, z_mean, z_scale)

    def predict(self, x: np.ndarray, components: int | None = None) -> np.ndarray:
        used = components or self.model.n_components
        scores = ((x - self.x_mean) / self.x_scale) @ self.model.x_rotations_[:, :used]
        return scores @ self.model.y_loadings_[:, :used].T * self.z_scale + self.z_mean


def _choose_components(x: np.ndarray, z: np.ndarray, most: int, seed: int) -> int:
    """The number of PLS components with the least cross-validated squared error, each
    parameter over its variance."""
    errors = np.zeros(most)
    spread = z.var(axis=0) + 1e-300
    for train, test in KFold(CV_FOLDS, shuffle=True, random_state=seed).split(x):
        fitted = _Pls.fit(x[train], z[train], most)
        for c in range(1, most + 1):
            gap = fitted.predict(x[test], c) - z[test]
            errors[c - 1] += ((gap**2) / spread).sum()
    return int(np.argmin(errors)) + 1


@dataclass(frozen=True)
class Adjustment:
    """The accepted draws, adjusted, and how they were found.

    Attributes:
        thetas: accepted draws before adjustment (n_accepted, d), physical units.
        adjusted: the same draws after the local-linear adjustment (n_accepted, d).
        weights: Epanechnikov weights of the accepted draws (n_accepted,), summing to 1.
        components: PLS components of the summaries.
        held_out_r2: per parameter, R² of its summary on the draws the fit did not see.
        bandwidth: largest accepted distance between summaries.
    """

    thetas: np.ndarray
    adjusted: np.ndarray
    weights: np.ndarray
    components: int
    held_out_r2: np.ndarray
    bandwidth: float

    @property
    def effective_size(self) -> float:
        """Kish's effective sample size of the weights."""
        return float(1.0 / (self.weights**2).sum())


def regression_adjustment(
    thetas: np.ndarray,
    features: np.ndarray,
    observed_features: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    *,
    accept: float = 0.1,
    seed: int = 0,
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
    n_accept = round(accept * n)
    if n_accept < d + 2:
        raise ValueError(
            f"accept={accept} of {n} draws keeps {n_accept}; the adjustment of {d} parameters "
            f"needs at least {d + 2}: give more draws or a larger accept"
        )
    z = _to_logit(thetas, lower, upper)
    fit = np.arange(n) < n // 2
    most = max(1, min(MAX_COMPONENTS, features.shape[1], int(fit.sum()) // 2 - 1))
    components = _choose_components(features[fit], z[fit], most, seed)
    model = _Pls.fit(features[fit], z[fit], components)
    summaries = model.predict(features)
    observed_summary = model.predict(observed_features[np.newaxis])[0]
    held_out = z[~fit]
    held_out_r2 = 1 - ((summaries[~fit] - held_out) ** 2).mean(axis=0) / (
        held_out.var(axis=0) + 1e-300
    )
    offsets = summaries - observed_summary
    distance = np.sqrt(((offsets / (z.std(axis=0) + 1e-300)) ** 2).sum(axis=1))
    nearest = np.argsort(distance, kind="stable")[:n_accept]
    bandwidth = float(distance[nearest[-1]]) * (1 + 1e-9) + 1e-300
    weights = 1 - (distance[nearest] / bandwidth) ** 2
    weights /= weights.sum()
    design = np.column_stack([np.ones(n_accept), offsets[nearest]])
    root = np.sqrt(weights)[:, np.newaxis]
    coefficients, *_ = np.linalg.lstsq(design * root, z[nearest] * root, rcond=None)
    adjusted = z[nearest] - offsets[nearest] @ coefficients[1:]
    return Adjustment(
        thetas=thetas[nearest],
        adjusted=_from_logit(adjusted, lower, upper),
        weights=weights,
        components=components,
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


def regression_abc(
    simulator: Simulator,
    prior: Prior,
    posterior: xr.Dataset,
    observed: OutputData,
    *,
    n: int,
    widen: float = 0.5,
    accept: float = 0.1,
    sensor_noise: SensorNoise | None = None,
    executor: Executor | ExecutorKind = "processes",
    n_workers: int | None = None,
    checkpoint: str | Path | None = None,
    seed: int | np.random.SeedSequence | None = None,
    time_limit: float | None = None,
    progress: bool | None = None,
) -> xr.DataTree:
    """The regression-adjusted posterior of ``observed`` around ``posterior`` (module docstring).

    Args:
        simulator: the model, ``simulator(theta, rng)`` on the observed grid, deterministic.
        prior: the prior of the calibration (model parameters and any noise scales).
        posterior: a posterior group holding every prior parameter (e.g. SMC-ABC's).
        observed: the data, a Dataset of outputs or an array (outputs, time).
        n: new simulations, drawn from the prior inside the posterior's box.
        widen: the box's margin on each side, in ranges of the posterior draws.
        accept: fraction of the draws kept, nearest in summaries to the data.
        sensor_noise: sensor noise of the data (learnable scales ``sigma_<output>`` in the
            prior replace its fixed ones); None: only the prior's ν, if any.
        executor, n_workers, time_limit, progress: where and how the simulations run.
        checkpoint: folder persisting each finished chunk of simulations.
        seed: integer or SeedSequence of the draws, the noise and the cross-validation.

    Returns:
        A DataTree: ``posterior`` (1 chain, the accepted draws adjusted and resampled by weight),
        ``sample_stats`` (``n_simulations``, ``n_failed``, ``n_accepted``, ``effective_size``,
        ``components``, ``bandwidth``, ``held_out_r2`` per parameter) and ``observed_data``.
    """
    started = time.perf_counter()
    if isinstance(n, bool) or int(n) != n or n < 1:
        raise ValueError(f"n must be a positive integer, got {n!r}")
    _check_fraction("accept", accept, 0.0, 1.0)
    root = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    box_seed, noise_seed, simulation_seed, cv_seed, resample_seed = root.spawn(5)
    box = posterior_box(posterior, prior, widen)
    draws = draw_in_box(prior, box, int(n), np.random.default_rng(box_seed))
    model = tuple(name for name in prior.names if not is_noise_parameter(name))
    columns = [prior.names.index(name) for name in model]
    table = simulate_draws(
        simulator,
        model,
        draws[:, columns],
        observed,
        executor=executor,
        n_workers=n_workers,
        checkpoint=checkpoint,
        seed=simulation_seed,
        time_limit=time_limit,
        progress=progress,
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
        noise_seed.spawn(int(n)),
    )
    features = summary_features(values[finished], data.values)
    adjustment = regression_adjustment(
        draws[finished],
        features,
        summary_features(data.values[np.newaxis], data.values)[0],
        prior.lower,
        prior.upper,
        accept=accept,
        seed=int(cv_seed.generate_state(1)[0]),
    )
    rng = np.random.default_rng(resample_seed)
    size = len(adjustment.weights)
    positions = (rng.uniform() + np.arange(size)) / size
    picked = np.minimum(np.searchsorted(np.cumsum(adjustment.weights), positions), size - 1)
    posterior_draws = adjustment.adjusted[picked]
    tree = xr.DataTree.from_dict(
        {
            "posterior": xr.Dataset(
                {
                    name: (("chain", "draw"), posterior_draws[np.newaxis, :, j])
                    for j, name in enumerate(prior.names)
                }
            ),
            "sample_stats": xr.Dataset(
                {
                    "n_simulations": ((), int(n)),
                    "n_failed": ((), int((~finished).sum())),
                    "n_accepted": ((), size),
                    "effective_size": ((), adjustment.effective_size),
                    "components": ((), adjustment.components),
                    "bandwidth": ((), adjustment.bandwidth),
                    "held_out_r2": (("parameter",), adjustment.held_out_r2),
                },
                coords={"parameter": list(prior.names)},
                attrs={
                    "sampler": "regression_abc",
                    "widen": float(widen),
                    "accept": float(accept),
                    "box": str(box),
                    "wall_seconds": time.perf_counter() - started,
                },
            ),
            "observed_data": data.dataset,
        }
    )
    return tree
