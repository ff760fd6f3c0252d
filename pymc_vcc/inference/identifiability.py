"""Local identifiability: which parameter combinations a test profile's data can tell apart.

At a point θ, the outputs' sensitivities to each parameter, whitened by the sensor noise, give
the Fisher information ``F = Sᵀ S`` of noisy data (``S`` by central differences, one parallel
batch of 2·d simulations). In units of each parameter's prior sd, and with the prior taken as a
Gaussian of that sd, ``(F + I)⁻¹`` is the covariance a calibration on such data would reach
near θ: its diagonal's square roots are the expected posterior sd / prior sd, and its principal
axes the directions the data inform, from well (a ratio near 0) to not at all (near 1).

It needs no measured data: the same function answers, before a test, whether a profile can
identify the charge, and, after a calibration that will not contract or cover, whether the
parameters it was given can be told apart at all. Noise scales are held at their values at θ
(relative scales move with the outputs, which the Gauss–Newton information ignores); Student-t
errors carry (ν + 1)/(ν + 3) of the Gaussian information.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
import xarray as xr

from pymc_vcc.execution.executors import WorkerCrash
from pymc_vcc.execution.options import RunOptions
from pymc_vcc.inference.likelihood import innovations
from pymc_vcc.inference.noise import SensorNoise
from pymc_vcc.inference.series import ObservedData, prepare_observed
from pymc_vcc.inference.simulator import Simulator, check_simulator, run_simulation

NOT_IDENTIFIED = 0.5
"""A direction whose expected posterior sd exceeds this fraction of its prior sd is reported as
not identified: the data would not even halve it."""


@dataclass(frozen=True)
class Direction:
    """A principal axis of the expected posterior, in prior-sd units.

    Attributes:
        sd_ratio: expected posterior sd along it over the prior sd (1: the data say nothing).
        loadings: parameter -> weight of the unit axis (signs tell which trade off).
    """

    sd_ratio: float
    loadings: dict[str, float]

    def summary(self, smallest: float = 0.01) -> dict:
        """The ratio and the loadings at least ``smallest`` in size, for JSON."""
        shown = {name: w for name, w in self.loadings.items() if abs(w) >= smallest}
        return {"sd_ratio": self.sd_ratio, "loadings": shown}

    def describe(self, smallest: float = 0.1) -> str:
        """``"0.98: +0.71 CF_POW −0.70 CF_PREF"``: the ratio and the loadings above
        ``smallest`` in size, largest first."""
        terms = sorted(self.loadings.items(), key=lambda item: -abs(item[1]))
        shown = [f"{weight:+.2f} {name}" for name, weight in terms if abs(weight) >= smallest]
        return f"{self.sd_ratio:.3g}: " + " ".join(shown)


@dataclass(frozen=True)
class Identifiability:
    """The local information of noisy data about the parameters at one point.

    Attributes:
        parameters: the parameters, in the order of :attr:`information`'s rows.
        at: the point, SI units.
        prior_sd: each parameter's prior sd, SI units (the unit of its information).
        information: Fisher information in prior-sd units, (d, d); NaN rows and columns for a
            parameter whose simulations failed.
        simulations: simulations run (the point's included).
        failed: parameters whose perturbed simulations failed, with the reason.
    """

    parameters: tuple[str, ...]
    at: dict[str, float]
    prior_sd: dict[str, float]
    information: np.ndarray
    simulations: int
    failed: dict[str, str]

    @property
    def _usable(self) -> np.ndarray:
        return np.array([name not in self.failed for name in self.parameters])

    def _posterior_covariance(self) -> np.ndarray:
        """(F + I)⁻¹ over the usable parameters, in prior-sd units."""
        usable = self._usable
        information = self.information[np.ix_(usable, usable)]
        return np.linalg.inv(information + np.eye(usable.sum()))

    @property
    def sd_ratio(self) -> dict[str, float]:
        """Expected posterior sd / prior sd of each parameter, the others unknown too (NaN for
        a failed one)."""
        ratios = dict.fromkeys(self.parameters, float("nan"))
        usable = [name for name in self.parameters if name not in self.failed]
        for name, variance in zip(usable, np.diag(self._posterior_covariance()), strict=True):
            ratios[name] = float(np.sqrt(variance))
        return ratios

    @property
    def conditional_sd_ratio(self) -> dict[str, float]:
        """Expected posterior sd / prior sd of each parameter were all others known."""
        diagonal = np.diag(self.information)
        return {
            name: float(1.0 / np.sqrt(value + 1.0))
            for name, value in zip(self.parameters, diagonal, strict=True)
        }

    def directions(self) -> list[Direction]:
        """The expected posterior's principal axes, the least informed first."""
        usable = [name for name in self.parameters if name not in self.failed]
        variances, vectors = np.linalg.eigh(self._posterior_covariance())
        order = np.argsort(variances)[::-1]
        return [
            Direction(
                float(np.sqrt(variances[k])),
                {
                    name: float(weight)
                    for name, weight in zip(usable, _sign_fixed(vectors[:, k]), strict=True)
                },
            )
            for k in order
        ]

    def not_identified(self, threshold: float = NOT_IDENTIFIED) -> list[Direction]:
        """The directions whose expected sd ratio exceeds ``threshold``."""
        return [d for d in self.directions() if d.sd_ratio > threshold]

    def confounding(self, fitted: Sequence[str]) -> pd.DataFrame:
        """How far a calibration of ``fitted`` is misled by each parameter it holds fixed when
        that one is off: the shift of each fitted parameter's estimate (its SI units; columns)
        when the held parameter's true value is 1 prior sd above the value held (rows), by the
        data's least squares near the point, ``F_ff⁻¹ F_fh``. A large entry names a held
        parameter the fitted one cannot be told from: know it better, or fit it too."""
        unknown = [name for name in fitted if name not in self.parameters]
        if unknown:
            raise ValueError(f"fitted parameter(s) {unknown} were not examined: {self.parameters}")
        broken = [name for name in self.parameters if name in self.failed]
        if broken:
            raise ValueError(f"the perturbed simulations of {broken} failed: no confounding")
        index = {name: k for k, name in enumerate(self.parameters)}
        held = [name for name in self.parameters if name not in fitted]
        f = [index[name] for name in fitted]
        h = [index[name] for name in held]
        shift = np.linalg.solve(self.information[np.ix_(f, f)], self.information[np.ix_(f, h)])
        scale = np.array([self.prior_sd[name] for name in fitted])
        return pd.DataFrame((shift * scale[:, None]).T, index=held, columns=list(fitted))

    def to_dataframe(self) -> pd.DataFrame:
        """One row per parameter: the point, its prior sd, the expected sd ratios."""
        return pd.DataFrame(
            {
                "at": self.at,
                "prior_sd": self.prior_sd,
                "sd_ratio": self.sd_ratio,
                "conditional_sd_ratio": self.conditional_sd_ratio,
            }
        ).loc[list(self.parameters)]

    def __str__(self) -> str:
        lines = [self.to_dataframe().to_string(float_format=lambda x: f"{x:.4g}")]
        weak = self.not_identified()
        lines.append(
            f"{len(weak)} of {len(self.parameters) - len(self.failed)} directions not identified "
            f"(expected sd above {NOT_IDENTIFIED} of the prior's):"
        )
        lines += ["  " + direction.describe() for direction in weak]
        lines += [f"  failed: {name} ({reason})" for name, reason in self.failed.items()]
        return "\n".join(lines)


def _sign_fixed(vector: np.ndarray) -> np.ndarray:
    """``vector`` with its largest entry positive (an axis has no sign)."""
    return vector if vector[np.argmax(np.abs(vector))] >= 0 else -vector


@dataclass(frozen=True)
class _Perturbed:
    """Worker side: the outputs at one point, or why there are none."""

    simulator: Simulator
    template: ObservedData
    time_limit: float | None

    def __call__(self, theta: dict[str, float]) -> tuple[np.ndarray | None, str]:
        outcome = run_simulation(
            self.simulator,
            theta,
            np.random.default_rng(0),
            self.template,
            time_limit_s=self.time_limit,
        )
        return outcome.values, outcome.reason


def identifiability(
    simulator: Simulator,
    sensor_noise: SensorNoise,
    *,
    at: Mapping[str, float] | None = None,
    parameters: Sequence[str] | None = None,
    prior_sd: Mapping[str, float] | None = None,
    step: float = 0.1,
    run: RunOptions | None = None,
) -> Identifiability:
    """What noisy data from ``simulator``'s runs would tell about ``parameters`` near ``at``.

    Args:
        simulator: ``simulator(theta, rng) -> outputs`` (a
            :class:`~pymc_vcc.physics.simulate.VCCSimulator`: its window, inputs and outputs
            are those of the data). Its error must be small beside the output changes of
            ``step`` prior sd, or it passes for information: for the cycle model, a solver
            ``scaled(DIFFERENCING_TOLERANCE_SCALE)`` (see
            :mod:`pymc_vcc.physics.integration.solver`), as the studies use.
        sensor_noise: the sensors' noise (its ``learnable`` flag is ignored).
        at: the point, SI units; parameters not given take the simulator's defaults
            (nominal), and the perturbed ones must be given unless the simulator has bounds
            (then the box's centre).
        parameters: the parameters examined (default: the simulator's ``parameter_names``).
        prior_sd: each parameter's prior sd, SI units (default: a uniform prior over the
            simulator's bounds, width / √12).
        step: central-difference half-step, in prior sds (one-sided at a bound).
        run: where the 2·d perturbed simulations run, and their time limit (no checkpoint;
            the simulations are seeded with 0, so no ``seed`` either).

    Returns:
        The :class:`Identifiability` at the point; print it for the table and the directions
        the data do not identify.
    """
    run = run or RunOptions()
    run.refuse_checkpoint("identifiability")
    info = check_simulator(simulator)
    names = tuple(parameters if parameters is not None else (info.parameter_names or ()))
    if not names:
        raise ValueError("identifiability needs parameters: pass parameters=[...]")
    if info.parameter_names is not None and (unknown := set(names) - set(info.parameter_names)):
        raise ValueError(
            f"parameters {sorted(unknown)} are not the simulator's; allowed: "
            f"{list(info.parameter_names)}"
        )
    if not step > 0:
        raise ValueError(f"step must be positive (prior sds), got {step}")
    bounds = info.bounds or {}
    point = dict(at or {})
    sds = dict(prior_sd or {})
    for name in names:
        low, high = bounds.get(name, (-np.inf, np.inf))
        if name not in sds:
            if not np.isfinite(high - low):
                raise ValueError(f"prior_sd[{name!r}] is needed: the simulator gives no bounds")
            sds[name] = (high - low) / np.sqrt(12.0)
        if not sds[name] > 0:
            raise ValueError(f"prior_sd[{name!r}] must be positive, got {sds[name]}")
        if name not in point:
            if not np.isfinite(high - low):
                raise ValueError(f"at[{name!r}] is needed: the simulator gives no bounds")
            point[name] = 0.5 * (low + high)
        if not low <= point[name] <= high:
            raise ValueError(
                f"at[{name!r}] = {point[name]} lies outside the simulator's bounds [{low}, {high}]"
            )

    base = simulator(point, np.random.default_rng(0))
    if isinstance(base, xr.Dataset) and base.attrs.get("status", "ok") != "ok":
        raise RuntimeError(
            f"the simulation at the point failed: {base.attrs.get('failure_reason')}"
        )
    template = prepare_observed(base, output_names=info.output_names)
    noise = sensor_noise.resolve(template)
    sigma = noise.std(template.values)
    if not (sigma > 0).all():
        zero = template.names[int(np.argmax(~(sigma > 0).all(axis=1)))]
        raise ValueError(
            f"the sensor noise of output {zero!r} is zero at the point (a relative scale of a "
            "zero reading); give it an absolute scale or leave the output out"
        )

    moves = []
    for name in names:
        low, high = bounds.get(name, (-np.inf, np.inf))
        h = step * sds[name]
        moves.append((min(point[name] + h, high), max(point[name] - h, low)))
    thetas = [
        {**point, name: value} for name, pair in zip(names, moves, strict=True) for value in pair
    ]
    with run.open_executor() as opened:
        results = opened.map(
            _Perturbed(simulator, template, run.time_limit), thetas, time_limit=run.time_limit
        )

    columns, failed = [], {}
    for j, name in enumerate(names):
        (up, up_reason), (down, down_reason) = (
            (None, str(r)) if isinstance(r, WorkerCrash) else r for r in results[2 * j : 2 * j + 2]
        )
        if up is None or down is None:
            failed[name] = up_reason if up is None else down_reason
            columns.append(np.full(template.values.size, np.nan))
            continue
        span = (moves[j][0] - moves[j][1]) / sds[name]  # prior sds
        change = innovations((np.asarray(up) - np.asarray(down)) / sigma, noise.correlation)
        columns.append(change.ravel() / span)
    sensitivities = np.column_stack(columns)
    factor = 1.0 if noise.dof is None else (noise.dof + 1.0) / (noise.dof + 3.0)
    return Identifiability(
        parameters=names,
        at={name: float(point[name]) for name in names},
        prior_sd={name: float(sds[name]) for name in names},
        information=factor * sensitivities.T @ sensitivities,
        simulations=1 + len(thetas),
        failed=failed,
    )


__all__ = ["NOT_IDENTIFIED", "Direction", "Identifiability", "identifiability"]
