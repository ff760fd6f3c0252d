"""An error budget for a real unit: plateau summaries with sensor and model errors accounted for.

A real unit is never the model: its sensors lag and are biased, its logged inputs are off, its
physics is finer than ten volumes, and the parameters the calibration holds fixed are not at
their nominal values. Fitted point by point under white noise, such data pin the parameters
wherever the misfit is least, with sub-gram intervals that miss (the real-units benchmark).

Here the data are summarised by the mean of each output over the late part of each held input
step (*plateaus*, :func:`plateau_windows`): insensitive to sensor lags and to the exact timing
of transients, and few enough (outputs × steps) for a full covariance. Their error is Gaussian
with covariance the sum of

* **sensor noise**: estimated from the record itself (scale and lag-1 autocorrelation from the
  first differences within each plateau), divided by the plateau's effective sample count;
* **sensor bias**: a constant per sensor, uniform within its accuracy class
  (:class:`SensorAccuracy`), shared by all plateaus of the sensor;
* **model error** (Bayesian approximation error, Kaipio and Somersalo): the mean and covariance
  of *unit − model* summaries over draws of everything the calibration does not infer — a finer
  discretisation, the fixed parameters spread around nominal, the inputs' logging errors, the
  sensors' lags — at parameters drawn from the prior (:func:`approximation_error`; the
  caller simulates the pairs). The mean is
  subtracted from the data (it corrects the model's systematic offset from a finer one).

:class:`ErrorBudget` holds the result and gives the log-likelihood of simulated summaries and
the posterior predictive check per output (:func:`predictive_check`).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike
from scipy import stats
from scipy.signal import lfilter
from sklearn.covariance import ShrunkCovariance
from sklearn.model_selection import GridSearchCV

from pymc_vcc.execution.executors import Executor, WorkerCrash

PLATEAU_SKIP = 60.0
"""Seconds after an input step before its plateau starts (sensor lags and fast transients)."""

MIN_PLATEAU_POINTS = 10
"""Fewest samples a plateau must hold to be summarised."""

SHRINKAGES = np.logspace(-3, 0, 16)
"""The shrinkages of the model-error correlations toward the identity tried by cross-validation."""

_KIND_OF_UNITS = {"K": "temperature", "Pa": "pressure", "kg/s": "mass_flow", "W": "power"}


@dataclass(frozen=True)
class SensorAccuracy:
    """What is known of the sensors and the logged inputs, in engineering terms.

    Attributes:
        temperature: bound of a temperature sensor's constant error, K.
        pressure: bound of a pressure sensor's constant error, fraction of the reading.
        mass_flow: bound of a flow meter's constant error, fraction of the reading.
        power: bound of a power meter's constant error, fraction of the reading.
        lag: longest first-order time constant of a sensor, s.
        inputs: input id -> (``"absolute"`` or ``"relative"``, bound of its logging error:
            K or a fraction of the reading).
    """

    temperature: float = 0.5
    pressure: float = 0.01
    mass_flow: float = 0.02
    power: float = 0.02
    lag: float = 30.0
    inputs: Mapping[str, tuple[str, float]] = field(
        default_factory=lambda: {
            "T_ambient": ("absolute", 0.5),
            "T_indoor": ("absolute", 0.5),
            "compressor_speed": ("relative", 0.01),
            "valve_opening": ("relative", 0.02),
        }
    )

    def bias_bound(self, units: str) -> tuple[float, bool]:
        """(bound, relative) of the constant error of a sensor reading in ``units``."""
        kind = _KIND_OF_UNITS.get(units)
        if kind is None:
            raise ValueError(
                f"no sensor accuracy for outputs in {units!r}; known: {_KIND_OF_UNITS}"
            )
        return float(getattr(self, kind)), kind != "temperature"

    def shift_inputs(self, inputs: xr.Dataset, errors: Mapping[str, ArrayLike]) -> xr.Dataset:
        """``inputs`` with each named input off by its error (K, or a fraction of the reading
        for relative inputs); an error is a number or one per profile row."""
        shifted = inputs.copy()
        for name, error in errors.items():
            kind, _ = self.inputs[name]
            values = np.asarray(inputs[name].values, dtype=float)
            moved = values + error if kind == "absolute" else values * (1.0 + np.asarray(error))
            shifted[name] = inputs[name].copy(data=moved)
        return shifted


def plateau_windows(
    edges: np.ndarray, times: np.ndarray, skip: float = PLATEAU_SKIP
) -> list[np.ndarray]:
    """Indices into ``times`` of the late part of each held input step (``skip`` s after the
    step to its end) that holds at least :data:`MIN_PLATEAU_POINTS` samples; ``edges`` are
    the step times, the record's start and end included."""
    windows = []
    for start, end in itertools.pairwise(edges):
        last = end == edges[-1]
        inside = (times >= start + skip) & ((times < end) | (last & (times <= end)))
        if inside.sum() >= MIN_PLATEAU_POINTS:
            windows.append(np.flatnonzero(inside))
    if not windows:
        raise ValueError(
            f"no input step of the record lasts {skip + MIN_PLATEAU_POINTS:g} s or more; plateau "
            "summaries need steps held at least that long"
        )
    return windows


def summarise(values: np.ndarray, windows: Sequence[np.ndarray]) -> np.ndarray:
    """Plateau means of (outputs, time) ``values``: output-major, (outputs × plateaus,)."""
    values = np.asarray(values, dtype=float)
    return np.stack([values[:, w].mean(axis=1) for w in windows], axis=1).ravel()


def noise_variance(values: np.ndarray, windows: Sequence[np.ndarray]) -> np.ndarray:
    """Variance of each plateau mean from the record's own noise: per output, a robust scale
    and lag-1 autocorrelation φ of AR(1) errors from the first differences inside plateaus,
    then σ² (1 + φ) / ((1 − φ) n) per plateau of n samples."""
    values = np.asarray(values, dtype=float)
    variances = []
    for row in values:
        steps = [np.diff(row[w]) for w in windows]
        d = np.concatenate(steps)
        scale2 = (1.4826 * np.median(np.abs(d - np.median(d)))) ** 2
        pairs = np.concatenate([np.column_stack([s[:-1], s[1:]]) for s in steps if s.size > 1])
        rho = np.corrcoef(pairs.T)[0, 1] if np.ptp(pairs) > 0 else -0.5
        phi = float(np.clip(1.0 + 2.0 * rho, 0.0, 0.99))
        sigma2 = scale2 / (2.0 * (1.0 - phi))
        variances.append([sigma2 * (1 + phi) / ((1 - phi) * w.size) for w in windows])
    return np.asarray(variances).ravel()


def bias_covariance(
    levels: np.ndarray, units: Sequence[str], n_plateaus: int, accuracy: SensorAccuracy
) -> np.ndarray:
    """Covariance of plateau means from constant sensor errors uniform within their bounds;
    ``levels`` are the plateau means (relative errors scale with the reading)."""
    n = len(units) * n_plateaus
    cov = np.zeros((n, n))
    for j, unit in enumerate(units):
        bound, relative = accuracy.bias_bound(unit)
        block = slice(j * n_plateaus, (j + 1) * n_plateaus)
        scale = levels[block] if relative else np.ones(n_plateaus)
        cov[block, block] = bound**2 / 3.0 * np.outer(scale, scale)
    return cov


@dataclass(eq=False)
class ErrorBudget:
    """The Gaussian error model of plateau summaries: data = model + mean + error.

    Attributes:
        outputs: the outputs, in summary order (output-major).
        windows: the plateaus' indices into the observed times.
        observed: the observed summaries.
        mean: systematic unit − model offset of each summary (subtracted from the data).
        parts: the covariance's parts by name (``noise``, ``bias``, ``model``).
        n_draws: approximation-error draws that succeeded.
        n_failed: approximation-error draws that failed.
    """

    outputs: tuple[str, ...]
    windows: list[np.ndarray]
    observed: np.ndarray
    mean: np.ndarray
    parts: dict[str, np.ndarray]
    n_draws: int = 0
    n_failed: int = 0

    def __post_init__(self) -> None:
        self.covariance = sum(self.parts.values())
        self._cholesky = np.linalg.cholesky(self.covariance)
        self._log_det = 2.0 * np.log(np.diag(self._cholesky)).sum()

    @property
    def n_plateaus(self) -> int:
        """Plateaus per output."""
        return len(self.windows)

    def whitened(self, simulated: np.ndarray) -> np.ndarray:
        """The residual of the observed summaries from a simulated (outputs, time) series,
        whitened by the budget's covariance: independent standard normals under it."""
        residual = self.observed - self.mean - summarise(simulated, self.windows)
        return np.linalg.solve(self._cholesky, residual)

    def log_likelihood(self, simulated: np.ndarray) -> float:
        """log p(observed summaries | simulated (outputs, time) series); −inf if not finite."""
        if not np.isfinite(simulated).all():
            return -np.inf
        z = self.whitened(simulated)
        return float(-0.5 * (z @ z + self._log_det + z.size * np.log(2 * np.pi)))

    def distance(self, sims: np.ndarray, obs: np.ndarray) -> np.ndarray:
        """A batch distance for the ABC samplers, (N, outputs, time) and (outputs, time) →
        (N,): the Mahalanobis norm of the plateau summaries' residual under this budget
        (inf for a simulation that is not finite).

        So an ABC sampler infers under the same observation model as the likelihood: with
        the Gaussian kernel at ε = 1 (``add_simulator(..., distance=budget.distance,
        epsilon=1.0)``) the ABC posterior is the exact posterior under the budget's errors
        (Wilkinson 2013: ABC's kernel as the model's error); rejection keeps the draws nearest
        the data in the same metric."""
        sims = np.asarray(sims, dtype=float)
        observed = summarise(obs, self.windows) - self.mean
        simulated = np.stack([summarise(sim, self.windows) for sim in sims])
        z = np.linalg.solve(self._cholesky, (observed - simulated).T)
        norms = np.sqrt((z**2).sum(axis=0))
        return np.where(np.isfinite(simulated).all(axis=1), norms, np.inf)

    def sd_by_output(self) -> dict[str, dict[str, float]]:
        """Root-mean-square standard deviation of each part, per output (its SI units)."""
        table = {}
        for j, name in enumerate(self.outputs):
            block = slice(j * self.n_plateaus, (j + 1) * self.n_plateaus)
            table[name] = {
                part: float(np.sqrt(np.mean(np.diag(cov)[block])))
                for part, cov in self.parts.items()
            }
        return table


def model_errors[T](
    pair: Callable[[T], tuple[np.ndarray, np.ndarray] | None],
    draws: Sequence[T],
    windows: Sequence[np.ndarray],
    executor: Executor,
) -> list[np.ndarray | None]:
    """The unit − model summaries of each draw, None where a simulation failed.

    ``pair(draw)`` returns the (outputs, time) series of the unit and of the model for one
    draw, or None when either simulation failed; it runs on the executor's workers (a draw
    whose run killed its worker is None too).
    """
    runs = executor.map(pair, list(draws))
    return [
        None
        if run is None or isinstance(run, WorkerCrash)
        else summarise(run[0], windows) - summarise(run[1], windows)
        for run in runs
    ]


def error_moments(errors: Sequence[np.ndarray | None]) -> tuple[np.ndarray, np.ndarray, int]:
    """Mean and covariance of the ``errors`` that are not None, and their count. The
    correlations are shrunk toward the identity by the amount that best predicts held-out
    draws (5-fold cross-validated likelihood over :data:`SHRINKAGES`): the errors come from a
    few causes and are strongly correlated, which Ledoit-Wolf's shrinkage, tuned for a
    different loss, blurs away."""
    found = [error for error in errors if error is not None]
    if len(found) < 10:
        raise RuntimeError(
            f"only {len(found)} of {len(errors)} model-error simulations succeeded; at least 10 "
            "are needed for the model-error covariance"
        )
    sample = np.asarray(found)
    scale = sample.std(axis=0) + 1e-12 * np.abs(sample).max(axis=0) + 1e-300
    search = GridSearchCV(ShrunkCovariance(), {"shrinkage": SHRINKAGES}, cv=5)
    shrunk = search.fit(sample / scale).best_estimator_.covariance_
    return sample.mean(axis=0), shrunk * np.outer(scale, scale), len(found)


def approximation_error[T](
    pair: Callable[[T], tuple[np.ndarray, np.ndarray] | None],
    draws: Sequence[T],
    windows: Sequence[np.ndarray],
    executor: Executor,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Mean and covariance of unit − model summaries over ``draws`` (:func:`model_errors`,
    :func:`error_moments`), and how many draws succeeded."""
    return error_moments(model_errors(pair, draws, windows, executor))


def lagged(values: np.ndarray, taus: np.ndarray, dt: float) -> np.ndarray:
    """First-order sensors of time constants ``taus`` (s, one per row; 0: none) reading the
    (outputs, time) ``values`` sampled every ``dt`` s, settled at the first values."""
    out = np.array(values, dtype=float)
    for j, tau in enumerate(taus):
        if tau > 0:
            a = np.exp(-dt / tau)
            out[j], _ = lfilter([1.0 - a], [1.0, -a], out[j], zi=[a * out[j, 0]])
    return out


def predictive_check(
    budget: ErrorBudget, predicted: np.ndarray, level: float = 0.001
) -> dict[str, dict[str, float]]:
    """Per output: the mean standardised residual of its plateaus, the χ² p-value of its block
    under the error model plus the predictive spread, and whether it fails at ``level``.

    ``predicted``: summaries of posterior predictive simulations (draws, outputs × plateaus).
    """
    predicted = np.asarray(predicted, dtype=float)
    residual = budget.observed - budget.mean - predicted.mean(axis=0)
    spread = np.cov(predicted.T) if predicted.shape[0] > 1 else 0.0
    covariance = budget.covariance + spread
    k = budget.n_plateaus
    report = {}
    for j, name in enumerate(budget.outputs):
        block = slice(j * k, (j + 1) * k)
        cov = covariance[block, block]
        r = residual[block]
        chi2 = float(r @ np.linalg.solve(cov, r))
        p_value = float(stats.chi2.sf(chi2, k))
        report[name] = {
            "z_mean": float(np.mean(r / np.sqrt(np.diag(cov)))),
            "p_value": p_value,
            "misfit": float(p_value < level),
        }
    return report
