"""Cheap simulators with exact posteriors, and simulators that fail, stall or log their calls.

Users and the test suite share these problems to check samplers against known answers. Each
simulator is a picklable callable ``simulator(theta, rng)`` with ``parameter_names``,
``output_names`` and ``bounds`` (the uniform prior box the exact posteriors assume).

Rejection ABC with a threshold ε does not sample the exact posterior p(θ | y) but the ABC target
p(θ) P(d(y_sim, y) ≤ ε | θ). When the distance is a function of a sufficient statistic, that
acceptance probability has a closed form, so each problem gives both the exact posterior and the
exact ABC target for the realised ε (``abc_target``, bounds included): a sampler must match the
target within Monte Carlo error, and the target's distance from the exact posterior is known.
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import ClassVar

import numpy as np
import xarray as xr
from scipy import stats

from pymc_vcc.inference.series import OutputData
from pymc_vcc.inference.simulator import Simulator


def _grid_moments(axes: list[np.ndarray], log_weight: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of a density given on a tensor grid (trapezoid rule)."""
    weight = np.exp(log_weight - log_weight.max())
    cell = np.ones_like(weight)
    for axis, nodes in enumerate(axes):
        spacing = np.gradient(nodes)
        spacing[[0, -1]] /= 2  # trapezoid end weights
        shape = [1] * len(axes)
        shape[axis] = nodes.size
        cell = cell * spacing.reshape(shape)
    mass = weight * cell
    mass /= mass.sum()
    points = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))
    flat = mass.ravel()
    mean = flat @ points
    centred = points - mean
    return mean, (centred * flat[:, None]).T @ centred


def _window(low: float, high: float, centre: float, half_width: float) -> np.ndarray:
    return np.linspace(max(low, centre - half_width), min(high, centre + half_width), 4001)


def _as_rows(observed: OutputData) -> np.ndarray:
    if isinstance(observed, xr.Dataset):
        return np.stack([np.asarray(v.values, dtype=float) for v in observed.data_vars.values()])
    array = np.asarray(observed, dtype=float)
    return array[np.newaxis, :] if array.ndim == 1 else array


@dataclass(frozen=True)
class GaussianLocation:
    """Gaussian location: y_t = mu + sigma·e_t, t = 1..n_time, e_t ~ N(0, 1), one output ``y``.

    With a uniform prior on [low, high] the exact posterior of mu is N(ȳ, sigma²/n_time)
    truncated to the bounds; ȳ is sufficient, and :meth:`distance` measures it in posterior sd.
    """

    n_time: int = 100
    sigma: float = 1.0
    low: float = -3.0
    high: float = 3.0

    parameter_names: ClassVar[tuple[str, ...]] = ("mu",)
    output_names: ClassVar[tuple[str, ...]] = ("y",)

    @property
    def bounds(self) -> dict[str, tuple[float, float]]:
        """The uniform prior box the exact posterior assumes."""
        return {"mu": (self.low, self.high)}

    @property
    def standard_error(self) -> float:
        """sigma / sqrt(n_time): sd of ȳ given mu, the untruncated posterior sd."""
        return self.sigma / np.sqrt(self.n_time)

    def __call__(self, theta: Mapping[str, float], rng: np.random.Generator) -> np.ndarray:
        return theta["mu"] + self.sigma * rng.standard_normal((1, self.n_time))

    def posterior(self, observed: OutputData) -> stats.rv_continuous:
        """Exact posterior of mu (a frozen scipy truncated normal)."""
        mean = float(_as_rows(observed)[0].mean())
        scale = self.standard_error
        return stats.truncnorm(
            (self.low - mean) / scale, (self.high - mean) / scale, loc=mean, scale=scale
        )

    def distance(self, sims: np.ndarray, obs: np.ndarray) -> np.ndarray:
        """|ȳ_sim − ȳ_obs| in units of sigma/sqrt(n_time) (batch form, (N, 1, m) → (N,))."""
        return np.abs(sims[:, 0, :].mean(axis=1) - obs[0].mean()) / self.standard_error

    def abc_target(self, observed: OutputData, epsilon: float) -> tuple[float, float]:
        """Mean and sd of the ABC target of :meth:`distance` ≤ ε (uniform prior on the bounds).

        P(accept | mu) = Φ((ȳ − mu)/se + ε) − Φ((ȳ − mu)/se − ε), se = sigma/sqrt(n_time).
        """
        mean = float(_as_rows(observed)[0].mean())
        scale = self.standard_error
        grid = _window(self.low, self.high, mean, (12 + 2 * epsilon) * scale)
        z = (mean - grid) / scale
        accept = stats.norm.cdf(z + epsilon) - stats.norm.cdf(z - epsilon)
        moments = _grid_moments([grid], np.log(np.maximum(accept, 1e-300)))
        return float(moments[0][0]), float(np.sqrt(moments[1][0, 0]))


@dataclass(frozen=True)
class LinearGaussian:
    """A drifting line in noise: y_t = a + b·t + sigma·e_t on t = linspace(0, 1, n_time).

    With a flat prior the exact posterior of (a, b) is N(β̂, sigma²(XᵀX)⁻¹), β̂ the least-squares
    fit, with strongly correlated a and b; :meth:`posterior_moments` ignores the prior bounds
    (exact when the posterior lies many sds inside them). :meth:`distance` is the Mahalanobis
    distance between least-squares fits, a function of the sufficient statistic.
    """

    n_time: int = 20
    sigma: float = 0.5
    low: float = -1.5
    high: float = 1.5

    parameter_names: ClassVar[tuple[str, ...]] = ("a", "b")
    output_names: ClassVar[tuple[str, ...]] = ("y",)

    @property
    def bounds(self) -> dict[str, tuple[float, float]]:
        """The uniform prior box."""
        return {"a": (self.low, self.high), "b": (self.low, self.high)}

    @cached_property
    def design(self) -> np.ndarray:
        """Design matrix X (n_time, 2): a column of ones and t."""
        x = np.linspace(0.0, 1.0, self.n_time)
        return np.column_stack([np.ones_like(x), x])

    def __call__(self, theta: Mapping[str, float], rng: np.random.Generator) -> np.ndarray:
        line = self.design @ np.array([theta["a"], theta["b"]])
        return (line + self.sigma * rng.standard_normal(self.n_time))[np.newaxis, :]

    def _fit(self, series: np.ndarray) -> np.ndarray:
        design = self.design
        return np.linalg.solve(design.T @ design, design.T @ series.T).T

    def posterior_moments(self, observed: OutputData) -> tuple[np.ndarray, np.ndarray]:
        """Exact posterior mean (2,) and covariance (2, 2) of (a, b) under a flat prior."""
        design = self.design
        covariance = self.sigma**2 * np.linalg.inv(design.T @ design)
        return self._fit(_as_rows(observed)[0]), covariance

    def distance(self, sims: np.ndarray, obs: np.ndarray) -> np.ndarray:
        """Mahalanobis distance between least-squares fits, in posterior sds ((N,1,m) → (N,))."""
        design = self.design
        whitening = np.linalg.cholesky(design.T @ design) / self.sigma
        difference = self._fit(sims[:, 0, :]) - self._fit(obs[0])
        return np.linalg.norm(difference @ whitening, axis=1)

    def abc_target(self, observed: OutputData, epsilon: float) -> tuple[np.ndarray, np.ndarray]:
        """Mean (2,) and covariance (2, 2) of the ABC target of :meth:`distance` ≤ ε.

        In whitened units the simulated fit is N(w(a, b), I), so P(accept | a, b) is the
        non-central chi-square CDF at ε² with 2 degrees of freedom and non-centrality
        |w(a, b) − w_obs|²; the uniform prior's bounds are included.
        """
        mean, covariance = self.posterior_moments(observed)
        sd = np.sqrt(np.diag(covariance))
        axes = [
            np.linspace(
                max(self.low, centre - (10 + 2 * epsilon) * s),
                min(self.high, centre + (10 + 2 * epsilon) * s),
                401,
            )
            for centre, s in zip(mean, sd, strict=True)
        ]
        a, b = np.meshgrid(*axes, indexing="ij")
        offset = np.stack([a - mean[0], b - mean[1]], axis=-1)
        noncentrality = np.einsum("...i,ij,...j->...", offset, np.linalg.inv(covariance), offset)
        accept = stats.ncx2.cdf(epsilon**2, 2, noncentrality)
        return _grid_moments(axes, np.log(np.maximum(accept, 1e-300)))


@dataclass(frozen=True)
class ShiftedProfile:
    """A known profile seen with an unknown offset: y_t = mu + sigma·e + c_t, e ~ N(0, 1) once.

    c_t is ``n_time`` equally spaced values on [−span/2, span/2] (a ramp). The offset
    x = mu + sigma·e is sufficient and the KS statistic between two such series depends only on
    the offset difference δ, monotonically: KS = min(n, floor(|δ|/h) + 1)/n with h the grid
    step. So KS-distance ABC with threshold ε accepts exactly |δ| < :meth:`ks_window` (ε), and
    its exact ABC posterior is N(x_obs, sigma²) convolved with that uniform window.
    """

    n_time: int = 501
    sigma: float = 0.05
    span: float = 1.0
    low: float = -1.0
    high: float = 1.0

    parameter_names: ClassVar[tuple[str, ...]] = ("mu",)
    output_names: ClassVar[tuple[str, ...]] = ("y",)

    @property
    def bounds(self) -> dict[str, tuple[float, float]]:
        """The uniform prior box."""
        return {"mu": (self.low, self.high)}

    @property
    def profile(self) -> np.ndarray:
        """The known profile c_t (n_time,)."""
        return np.linspace(-self.span / 2, self.span / 2, self.n_time)

    def __call__(self, theta: Mapping[str, float], rng: np.random.Generator) -> np.ndarray:
        offset = theta["mu"] + self.sigma * rng.standard_normal()
        return (offset + self.profile)[np.newaxis, :]

    def posterior(self, observed: OutputData) -> stats.rv_continuous:
        """Exact posterior of mu: N(x_obs, sigma²) truncated to the bounds."""
        offset = float(_as_rows(observed)[0].mean())
        return stats.truncnorm(
            (self.low - offset) / self.sigma,
            (self.high - offset) / self.sigma,
            loc=offset,
            scale=self.sigma,
        )

    def ks_window(self, epsilon: float) -> float:
        """Half-width of the offset differences |δ| that KS ≤ ε accepts (same units as mu)."""
        step = self.span / (self.n_time - 1)
        return step * np.floor(epsilon * self.n_time + 1e-9)

    def abc_target(self, observed: OutputData, epsilon: float) -> tuple[float, float]:
        """Mean and sd of the ABC target of KS ≤ ε: offsets within the window, bounds included."""
        offset = float(_as_rows(observed)[0].mean())
        window = self.ks_window(epsilon)
        grid = _window(self.low, self.high, offset, window + 12 * self.sigma)
        accept = stats.norm.cdf((offset + window - grid) / self.sigma) - stats.norm.cdf(
            (offset - window - grid) / self.sigma
        )
        moments = _grid_moments([grid], np.log(np.maximum(accept, 1e-300)))
        return float(moments[0][0]), float(np.sqrt(moments[1][0, 0]))


@dataclass(frozen=True)
class Flaky:
    """Wraps a simulator so that a fraction ``rate`` of runs fail, decided by the run's rng.

    Failure modes, chosen evenly among ``modes`` by the same uniform draw: ``"raise"`` raises
    RuntimeError, ``"nan"`` and ``"inf"`` return outputs with a non-finite value, ``"status"``
    returns a Dataset flagged ``attrs["status"] = "failed"`` of kind ``"solver"`` as the VCC
    simulator does, and
    ``"stall"`` sleeps ``stall_seconds`` before answering (for time limits).
    """

    base: Simulator
    rate: float
    modes: tuple[str, ...] = ("raise", "nan", "inf", "status")
    stall_seconds: float = 30.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.rate <= 1.0:
            raise ValueError(f"rate must be in [0, 1], got {self.rate}")
        unknown = set(self.modes) - {"raise", "nan", "inf", "status", "stall"}
        if unknown or not self.modes:
            raise ValueError(
                f"unknown failure modes {sorted(unknown)}; use raise/nan/inf/status/stall"
            )

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(self.base.parameter_names)

    @property
    def output_names(self) -> tuple[str, ...]:
        return tuple(self.base.output_names)

    def __call__(self, theta: Mapping[str, float], rng: np.random.Generator) -> OutputData:
        draw = rng.random()
        outputs = self.base(theta, rng)
        if draw >= self.rate:
            return outputs
        mode = self.modes[min(int(draw / self.rate * len(self.modes)), len(self.modes) - 1)]
        if mode == "raise":
            raise RuntimeError("synthetic failure")
        if mode == "stall":
            return Slow(lambda theta, rng: outputs, self.stall_seconds, busy=False)(theta, rng)
        if mode == "status":
            dataset = as_dataset(outputs, self.output_names)
            dataset.attrs.update(
                status="failed", failure_kind="solver", failure_reason="synthetic solver failure"
            )
            return dataset
        broken = np.array(outputs, dtype=float)
        broken[..., 0] = np.nan if mode == "nan" else np.inf
        return broken


def as_dataset(outputs: np.ndarray, names: tuple[str, ...]) -> xr.Dataset:
    """An (outputs, time) array as a Dataset with one variable per output over ``time``."""
    rows = np.asarray(outputs, dtype=float)
    dataset = xr.Dataset({name: ("time", row) for name, row in zip(names, rows, strict=True)})
    dataset.attrs["status"] = "ok"
    return dataset


@dataclass(frozen=True)
class AsDataset:
    """Wraps a simulator so that it returns an xarray Dataset (with ``status = "ok"``)."""

    base: Simulator

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(self.base.parameter_names)

    @property
    def output_names(self) -> tuple[str, ...]:
        return tuple(self.base.output_names)

    def __call__(self, theta: Mapping[str, float], rng: np.random.Generator) -> xr.Dataset:
        return as_dataset(self.base(theta, rng), self.output_names)


@dataclass(frozen=True)
class Slow:
    """Wraps a simulator so that each run first takes ``seconds``.

    ``busy=True`` spends that much CPU time of the calling thread (a fixed amount of work,
    whatever the machine's load); ``busy=False`` sleeps in 10 ms slices (a stalled solver).
    """

    base: Simulator
    seconds: float
    busy: bool = True

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(self.base.parameter_names)

    @property
    def output_names(self) -> tuple[str, ...]:
        return tuple(self.base.output_names)

    def __call__(self, theta: Mapping[str, float], rng: np.random.Generator) -> OutputData:
        if self.busy:
            end = time.thread_time() + self.seconds
            while time.thread_time() < end:
                pass
        else:
            end = time.perf_counter() + self.seconds
            while (left := end - time.perf_counter()) > 0:
                time.sleep(min(left, 0.01))
        return self.base(theta, rng)


@dataclass(frozen=True)
class Recording:
    """Wraps a simulator and appends one line per finished run to ``path``: the θ values.

    Lets tests count how often each parameter draw was simulated (e.g. across a kill and a
    resume); lines are written with O_APPEND, so concurrent processes do not interleave them.
    """

    base: Simulator
    path: str

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(self.base.parameter_names)

    @property
    def output_names(self) -> tuple[str, ...]:
        return tuple(self.base.output_names)

    def __call__(self, theta: Mapping[str, float], rng: np.random.Generator) -> OutputData:
        outputs = self.base(theta, rng)
        line = " ".join(repr(float(theta[name])) for name in sorted(theta)) + "\n"
        descriptor = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            os.write(descriptor, line.encode())
        finally:
            os.close(descriptor)
        return outputs


@dataclass(frozen=True)
class SensorProblem:
    """A cheap deterministic one-parameter "cycle" with VCC-like outputs and units.

    Outputs on a 1 s grid (an array; :meth:`dataset` gives them with units), linear in the
    charge M0 (kg) around a periodic load: a discharge
    temperature ``TD`` (K), a discharge pressure ``PD`` (Pa) and a mass flow ``MDOT`` (kg/s), so
    that :class:`~pymc_vcc.inference.noise.SensorNoise` applies as on the VCC model (absolute
    noise on temperatures, relative on the others). With absolute noise only (``TD``, or
    every output given ``kinds`` of temperature), the posterior under a Gaussian (or AR(1))
    likelihood is Gaussian with the moments of :meth:`exact_posterior` (bounds far away).

    Attributes:
        n_time: samples on the 1 s grid.
        period: period of the load wave, s.
    """

    n_time: int = 120
    period: float = 60.0

    parameter_names: ClassVar[tuple[str, ...]] = ("M0",)
    output_names: ClassVar[tuple[str, ...]] = ("TD", "PD", "MDOT")
    units: ClassVar[tuple[str, ...]] = ("K", "Pa", "kg/s")
    bounds: ClassVar[dict[str, tuple[float, float]]] = {"M0": (0.9, 2.2)}

    def _design(self) -> tuple[np.ndarray, np.ndarray]:
        """Intercepts and slopes (3, n_time): outputs = intercept + slope · (M0 − 1.5)."""
        wave = np.sin(2 * np.pi * np.arange(self.n_time) / self.period)
        intercept = np.stack(
            [340.0 + 2.0 * wave, 2.7e6 * (1 + 0.01 * wave), 0.021 * (1 + 0.02 * wave)]
        )
        slope = np.stack(
            [
                np.full(self.n_time, 4.0),
                np.full(self.n_time, 2.7e6 * 0.02),
                0.021 * 0.01 * (1 + wave),
            ]
        )
        return intercept, slope

    def outputs(self, charge: float) -> np.ndarray:
        """Noise-free outputs (3, n_time) at charge M0, SI units."""
        intercept, slope = self._design()
        return intercept + slope * (float(charge) - 1.5)

    def __call__(self, theta: Mapping[str, float], rng: np.random.Generator) -> np.ndarray:
        return self.outputs(theta["M0"])

    def dataset(self, charge: float) -> xr.Dataset:
        """Noise-free outputs at charge M0 as a Dataset whose variables carry their units."""
        dataset = as_dataset(self.outputs(charge), self.output_names)
        for name, units in zip(self.output_names, self.units, strict=True):
            dataset[name].attrs["units"] = units
        return dataset

    def exact_posterior(
        self,
        observed: xr.Dataset,
        scales: Mapping[str, float],
        correlation: float = 0.0,
    ) -> tuple[float, float]:
        """Posterior mean and sd of M0 (flat prior) under absolute Gaussian AR(1) noise.

        Args:
            observed: observed outputs, the variables named in ``scales``.
            scales: output -> absolute noise sd, in the output's units.
            correlation: lag-1 autocorrelation of the errors.
        """
        rows = [self.output_names.index(name) for name in scales]
        intercept, slope = (part[rows] for part in self._design())
        observed = np.stack([observed[name].values for name in scales])
        sd = np.array(list(scales.values()), dtype=float)[:, None]
        residual, design = (observed - intercept) / sd, slope / sd

        def whiten(rows: np.ndarray) -> np.ndarray:
            out = rows.copy()
            out[:, 1:] = (rows[:, 1:] - correlation * rows[:, :-1]) / np.sqrt(1 - correlation**2)
            return out

        residual, design = whiten(residual), whiten(design)
        precision = float((design**2).sum())
        return 1.5 + float((design * residual).sum()) / precision, precision**-0.5
