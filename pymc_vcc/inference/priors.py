"""Priors over named, bounded parameters: a uniform box and a bounded Gaussian mixture.

Both describe parameters by ordered names with physical bounds [low, high] and offer
``sample(n, rng)`` (an (n, d) array in name order), ``logpdf(x)`` and a netCDF round trip.

:class:`GMMPrior` is the paper's device for passing a posterior on as the next prior: a Gaussian
mixture fitted with scikit-learn, its number of components chosen by BIC. It lives in the
unbounded logit space of the bounds, u = log(p / (1 − p)) with p = (x − low) / (high − low), so
every draw respects the physical bounds; its ``logpdf`` is the density in the physical space,
log q(u(x)) − Σ log((high − low) p (1 − p)).
"""

from __future__ import annotations

import itertools
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import xarray as xr
from scipy.optimize import least_squares
from scipy.special import expit, log_ndtr, logit, logsumexp
from scipy.stats import truncnorm

Bounds = Mapping[str, tuple[float, float]]

_EDGE = 1e-9  # fraction of the range kept between a sample and its bound in logit space
_SAMPLES_PER_FREE_PARAMETER = 10  # samples a mixture needs per free parameter it fits
_COVARIANCE_FLOOR = 1e-3  # added to covariance diagonals, in units of the logit variance
_MOMENT_DRAWS = 20000  # draws checking a fitted mixture's marginal moments
SLAB_SD = 1.7
"""sd of the logit of a parameter spread over its range in :meth:`GMMPrior.with_slabs`: its
density in the range stays within 15 % of the uniform's from 2 % to 98 % of it (a logistic's sd,
the exact uniform, is π/√3 ≈ 1.81, but no normal of that sd is flatter)."""


def _with_marginal_moments(
    prior: GMMPrior, samples: np.ndarray, rng: np.random.Generator
) -> GMMPrior:
    """``prior`` mapped per parameter by an affine map of its logit, u → a + b (u − c), so that
    its marginal means and sds in physical units equal the samples' (within Monte Carlo error).

    An affine map of one logit coordinate changes only that marginal, and keeps a Gaussian
    mixture a Gaussian mixture.
    """
    width = prior.upper - prior.lower
    draws = logit(
        np.clip((prior.sample(_MOMENT_DRAWS, rng) - prior.lower) / width, _EDGE, 1 - _EDGE)
    )
    centre = draws.mean(axis=0)
    shift, stretch = centre.copy(), np.ones(prior.ndim)
    for i in range(prior.ndim):
        mean, sd = samples[:, i].mean(), samples[:, i].std(ddof=1)
        if sd <= 0:
            continue

        def gaps(x: np.ndarray, i: int = i, mean: float = mean, sd: float = sd) -> np.ndarray:
            values = prior.lower[i] + width[i] * expit(
                x[0] + np.exp(x[1]) * (draws[:, i] - centre[i])
            )
            return np.array([values.mean() - mean, values.std() - sd]) / sd

        solution = least_squares(gaps, [centre[i], 0.0]).x
        shift[i], stretch[i] = solution[0], np.exp(solution[1])
    means = shift + stretch * (prior.means - centre)
    covariances = prior.covariances * np.outer(stretch, stretch)
    return GMMPrior(prior.bounds, prior.weights, means, covariances)


def _moment_gap(prior: Prior, samples: np.ndarray, rng: np.random.Generator) -> float:
    """Largest gap of a marginal mean or sd between ``prior`` and ``samples``, in sample sds."""
    draws = prior.sample(_MOMENT_DRAWS, rng)
    sd = samples.std(axis=0, ddof=1)
    varying = sd > 0
    if not varying.any():
        return 0.0
    mean_gap = np.abs(draws.mean(axis=0) - samples.mean(axis=0))[varying] / sd[varying]
    sd_gap = np.abs(draws.std(axis=0) - sd)[varying] / sd[varying]
    return float(max(mean_gap.max(), sd_gap.max()))


def validate_bounds(bounds: Bounds) -> dict[str, tuple[float, float]]:
    """Check parameter bounds: a non-empty mapping name -> (low, high), finite, low < high."""
    if not isinstance(bounds, Mapping) or not bounds:
        raise ValueError(f"bounds must be a non-empty mapping name -> (low, high), got {bounds!r}")
    checked = {}
    for name, pair in bounds.items():
        if not isinstance(name, str) or not name:
            raise ValueError(f"parameter names must be non-empty strings, got {name!r}")
        try:
            low, high = (float(value) for value in pair)
        except (TypeError, ValueError):
            raise ValueError(
                f"bounds of {name!r} must be a pair (low, high), got {pair!r}"
            ) from None
        if not (np.isfinite(low) and np.isfinite(high)):
            raise ValueError(f"bounds of {name!r} must be finite, got ({low}, {high})")
        if low >= high:
            raise ValueError(f"bounds of {name!r} need low < high, got low={low} >= high={high}")
        checked[name] = (low, high)
    return checked


def check_prior_support(allowed: Bounds | None, bounds: Bounds) -> None:
    """Refuse prior bounds that reach outside a simulator's support (``parameter_bounds``, read
    by :func:`pymc_vcc.inference.simulator.check_simulator`); None allows any bounds.

    Raises:
        ValueError: naming the parameter, the prior's bounds and the allowed range.
    """
    if allowed is None:
        return
    for name, (low, high) in bounds.items():
        if name not in allowed:
            continue
        allowed_low, allowed_high = allowed[name]
        if low < allowed_low or high > allowed_high:
            raise ValueError(
                f"prior bounds of {name!r} ({low:g}, {high:g}) reach outside the simulator's "
                f"parameter bounds [{allowed_low:g}, {allowed_high:g}]; narrow the prior, or "
                "build the simulator with allow_outside_unit_bounds=True to extrapolate"
            )


MAX_BOX_TRIES = 2000
"""Prior draws tried per wanted draw inside a box before giving up."""


def _box_edges(
    names: tuple[str, ...], box: Mapping[str, tuple[float, float]]
) -> tuple[np.ndarray, np.ndarray]:
    return np.array([box[name][0] for name in names]), np.array([box[name][1] for name in names])


class Prior(ABC):
    """A distribution over named parameters inside physical bounds.

    Attributes:
        names: parameter names, the column order of samples.
        lower, upper: bounds per parameter, arrays (d,).
    """

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    kind: str

    def _set_bounds(self, bounds: Bounds) -> None:
        checked = validate_bounds(bounds)
        self.names = tuple(checked)
        self.lower = np.array([low for low, _ in checked.values()])
        self.upper = np.array([high for _, high in checked.values()])

    @property
    def bounds(self) -> dict[str, tuple[float, float]]:
        """name -> (low, high)."""
        return {
            name: (float(low), float(high))
            for name, low, high in zip(self.names, self.lower, self.upper, strict=True)
        }

    @property
    def ndim(self) -> int:
        """Number of parameters."""
        return len(self.names)

    @abstractmethod
    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` draws, array (n, d) in ``names`` order."""

    @abstractmethod
    def logpdf(self, x: np.ndarray) -> np.ndarray:
        """Log-density at points x (n, d) or (d,) in physical units; −inf outside the bounds."""

    def sample_in_box(
        self, box: Mapping[str, tuple[float, float]], n: int, rng: np.random.Generator
    ) -> np.ndarray | None:
        """``n`` draws (n, d) of this prior restricted to ``box`` (name -> (low, high)), by
        rejection; None if fewer than 1 in :data:`MAX_BOX_TRIES` draws falls inside."""
        low, high = _box_edges(self.names, box)
        kept: list[np.ndarray] = []
        found, tried, batch = 0, 0, max(_check_count(n), 64)
        while found < n:
            if tried >= MAX_BOX_TRIES * n:
                return None
            draws = self.sample(batch, rng)
            inside = draws[((draws >= low) & (draws <= high)).all(axis=1)]
            kept.append(inside)
            found += len(inside)
            tried += batch
        return np.concatenate(kept)[:n]

    @abstractmethod
    def to_dataset(self) -> xr.Dataset:
        """The prior as a Dataset (``attrs["kind"]`` names the class)."""

    def save(self, path: str | Path) -> None:
        """Write the prior to a netCDF file (read it back with :func:`load_prior`)."""
        self.to_dataset().to_netcdf(path, engine="h5netcdf")

    def _points(self, x: np.ndarray) -> np.ndarray:
        points = np.asarray(x, dtype=float)
        points = points[np.newaxis, :] if points.ndim == 1 else points
        if points.ndim != 2 or points.shape[1] != self.ndim:
            raise ValueError(
                f"points must have shape (n, {self.ndim}) for parameters {list(self.names)}, "
                f"got {np.shape(x)}"
            )
        return points

    def _bounds_dataset(self) -> xr.Dataset:
        return xr.Dataset(
            {
                "lower": ("parameter", self.lower, {"long_name": "lower bound"}),
                "upper": ("parameter", self.upper, {"long_name": "upper bound"}),
            },
            coords={"parameter": list(self.names)},
            attrs={"kind": self.kind},
        )

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.bounds})"


def _drift_fractions(drift: float | Mapping[str, float], names: Sequence[str]) -> np.ndarray:
    """Per parameter of ``names``, the drift step's sd in fractions of its range."""
    given = drift if isinstance(drift, Mapping) else dict.fromkeys(names, drift)
    unknown = sorted(set(given) - set(names))
    if unknown:
        raise ValueError(f"drift names parameter(s) {unknown} the bounds do not ({list(names)})")
    steps = np.array([float(given.get(name, 0.0)) for name in names])
    for name, step in zip(names, steps, strict=True):
        if not (np.isfinite(step) and step >= 0):
            raise ValueError(f"drift of {name!r} must be a finite fraction >= 0, got {step}")
    return steps


def _log_normal_mass(below: np.ndarray, above: np.ndarray) -> np.ndarray:
    """log(Φ(above) − Φ(below)) elementwise, accurate far into either tail."""
    upper_tail = below > 0  # there Φ(above) − Φ(below) = Φ(−below) − Φ(−above)
    high = np.where(upper_tail, -below, above)
    low = np.where(upper_tail, -above, below)
    log_high, log_low = log_ndtr(high), log_ndtr(low)
    with np.errstate(divide="ignore", invalid="ignore"):
        mass = log_high + np.log1p(-np.exp(log_low - log_high))
    return np.where(high > low, mass, -np.inf)


def _check_count(n: int) -> int:
    if int(n) != n or n < 0:
        raise ValueError(f"number of draws must be a non-negative integer, got {n}")
    return int(n)


class UniformPrior(Prior):
    """Independent uniform distributions on [low, high] per parameter (SI units).

    Args:
        bounds: name -> (low, high); the order of the mapping is the parameter order.
    """

    kind = "uniform"

    def __init__(self, bounds: Bounds) -> None:
        self._set_bounds(bounds)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        return rng.uniform(self.lower, self.upper, size=(_check_count(n), self.ndim))

    def sample_in_box(
        self, box: Mapping[str, tuple[float, float]], n: int, rng: np.random.Generator
    ) -> np.ndarray:
        """Uniform draws on the box's overlap with the bounds (exact, however small the box)."""
        low, high = _box_edges(self.names, box)
        low, high = np.maximum(low, self.lower), np.minimum(high, self.upper)
        return rng.uniform(low, high, size=(_check_count(n), self.ndim))

    def logpdf(self, x: np.ndarray) -> np.ndarray:
        points = self._points(x)
        density = -np.log(self.upper - self.lower).sum()
        inside = ((points >= self.lower) & (points <= self.upper)).all(axis=1)
        return np.where(inside, density, -np.inf)

    def extended(self, bounds: Bounds) -> UniformPrior:
        """This box with more parameters appended (e.g. output-noise scales)."""
        clash = sorted(set(bounds) & set(self.names))
        if clash:
            raise ValueError(f"parameters {clash} are already in the prior")
        return UniformPrior({**self.bounds, **bounds})

    def to_dataset(self) -> xr.Dataset:
        return self._bounds_dataset()

    @classmethod
    def from_dataset(cls, dataset: xr.Dataset) -> UniformPrior:
        """Inverse of :meth:`to_dataset`."""
        return cls(_bounds_from_dataset(dataset))


def _bounds_from_dataset(dataset: xr.Dataset) -> dict[str, tuple[float, float]]:
    return {
        str(name): (float(low), float(high))
        for name, low, high in zip(
            dataset["parameter"].values,
            dataset["lower"].values,
            dataset["upper"].values,
            strict=True,
        )
    }


def _samples_matrix(samples: object, names: Sequence[str]) -> np.ndarray:
    """Samples as an (n, d) array in ``names`` order, from an array, a mapping or a Dataset."""
    if isinstance(samples, xr.DataTree):
        samples = samples["posterior"].to_dataset()
    if isinstance(samples, xr.Dataset | Mapping):
        missing = [name for name in names if name not in samples]
        if missing:
            raise ValueError(f"samples lack parameter(s) {missing}; the bounds name {list(names)}")
        return np.column_stack([np.asarray(samples[name], dtype=float).ravel() for name in names])
    matrix = np.asarray(samples, dtype=float)
    if matrix.ndim != 2 or matrix.shape[1] != len(names):
        raise ValueError(
            f"samples must have shape (n, {len(names)}) for parameters {list(names)}, "
            f"got {matrix.shape}"
        )
    return matrix


class GMMPrior(Prior):
    """A Gaussian mixture in the logit space of the bounds (see the module docstring).

    Build it with :meth:`fit`; the constructor takes fitted parameters.

    Args:
        bounds: name -> (low, high), physical units.
        weights: mixture weights (k,), summing to 1.
        means: component means in logit space (k, d).
        covariances: component covariances in logit space (k, d, d).
    """

    kind = "gmm"

    def __init__(
        self, bounds: Bounds, weights: np.ndarray, means: np.ndarray, covariances: np.ndarray
    ) -> None:
        self._set_bounds(bounds)
        self.weights = np.asarray(weights, dtype=float)
        self.means = np.asarray(means, dtype=float)
        self.covariances = np.asarray(covariances, dtype=float)
        k, d = self.weights.size, self.ndim
        if self.means.shape != (k, d) or self.covariances.shape != (k, d, d):
            raise ValueError(
                f"mixture of {k} components over {d} parameters needs means ({k}, {d}) and "
                f"covariances ({k}, {d}, {d}); got {self.means.shape} and {self.covariances.shape}"
            )
        if not np.isclose(self.weights.sum(), 1.0) or (self.weights < 0).any():
            raise ValueError(f"mixture weights must be >= 0 and sum to 1, got {self.weights}")
        self._cholesky = np.linalg.cholesky(self.covariances)
        self._log_det = 2 * np.log(np.diagonal(self._cholesky, axis1=1, axis2=2)).sum(axis=1)

    @property
    def n_components(self) -> int:
        """Number of mixture components."""
        return self.weights.size

    @classmethod
    def fit(
        cls,
        samples: object,
        bounds: Bounds | Prior,
        *,
        max_components: int = 5,
        seed: int | None = None,
        moment_tolerance: float = 0.05,
        drift: float | Mapping[str, float] = 0.0,
        covariance: str | None = None,
    ) -> GMMPrior:
        """Fit a mixture to samples: the best by BIC of those that keep the marginal moments.

        Components get full covariances when there are at least 10 samples per free parameter of
        one, diagonal ones otherwise (unless ``covariance`` says which), and at most one component
        per 10 × its free parameters (so 3 samples in 2-D give one diagonal Gaussian as wide as the
        samples, not a 1e-6-wide spike). Covariances are floored at 1e-3 of each parameter's logit
        variance. Among the fits, in order of BIC, the first whose marginal means and standard
        deviations (physical units, from 20000 draws) are within ``moment_tolerance`` sample
        standard deviations of the samples' is chosen; if none is, the best by BIC with each logit
        coordinate mapped affinely so that the marginal means and sds match.

        Args:
            samples: an array (n, d) in the order of ``bounds``, a mapping name -> values, a
                Dataset (e.g. a posterior with chain and draw dims) or a DataTree (its
                posterior group).
            bounds: name -> (low, high), or a prior whose bounds to use.
            max_components: largest number of components tried.
            seed: seeds scikit-learn's initialisation and the moment check (same seed, same fit).
            moment_tolerance: largest gap of a marginal mean or sd, in sample sds.
            drift: how far the parameters may have moved since the samples (the next dataset
                is of a drifted or another unit): the sd of a normal step, in fractions of each
                range (one for all, or name -> fraction, others 0). Each sample is moved by such
                a step, clipped to the bounds, before the fit.
            covariance: ``"full"`` or ``"diag"`` whatever the number of samples (e.g. full
                for one component whose correlations matter), None to choose by it.
        """
        from sklearn.mixture import GaussianMixture  # heavy import, needed only here

        checked = validate_bounds(bounds.bounds if isinstance(bounds, Prior) else bounds)
        names = list(checked)
        if int(max_components) != max_components or max_components < 1:
            raise ValueError(f"max_components must be a positive integer, got {max_components}")
        matrix = _samples_matrix(samples, names)
        if matrix.shape[0] < 2:
            raise ValueError(f"a mixture needs at least 2 samples, got {matrix.shape[0]}")
        if not np.isfinite(matrix).all():
            raise ValueError("samples contain NaN or infinite values")
        lower = np.array([low for low, _ in checked.values()])
        upper = np.array([high for _, high in checked.values()])
        outside = (matrix < lower) | (matrix > upper)
        if outside.any():
            column = int(np.flatnonzero(outside.any(axis=0))[0])
            raise ValueError(
                f"{int(outside[:, column].sum())} sample(s) of {names[column]!r} lie outside its "
                f"bounds [{lower[column]}, {upper[column]}]"
            )
        steps = _drift_fractions(drift, names)
        if steps.any():
            moved = np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0])
            matrix = matrix + steps * (upper - lower) * moved.standard_normal(matrix.shape)
            matrix = np.clip(matrix, lower, upper)
        fraction = np.clip((matrix - lower) / (upper - lower), _EDGE, 1 - _EDGE)
        unbounded = logit(fraction)
        # Fit on standardised logits, so that the covariance floor is relative to the spread.
        centre = unbounded.mean(axis=0)
        spread = unbounded.std(axis=0)
        spread[spread <= 0] = 1.0
        standard = (unbounded - centre) / spread
        n, d = matrix.shape
        if covariance not in (None, "full", "diag"):
            raise ValueError(f"covariance must be 'full', 'diag' or None, got {covariance!r}")
        enough = n >= _SAMPLES_PER_FREE_PARAMETER * (d + d * (d + 1) // 2)
        covariance_type = covariance or ("full" if enough else "diag")
        per_component = d + (d * (d + 1) // 2 if covariance_type == "full" else d) + 1
        largest = max(
            1, min(int(max_components), n // (_SAMPLES_PER_FREE_PARAMETER * per_component))
        )
        fitted = []
        for k in range(1, largest + 1):
            mixture = GaussianMixture(
                n_components=k,
                covariance_type=covariance_type,
                reg_covar=_COVARIANCE_FLOOR,
                random_state=seed,
            ).fit(standard)
            covariances = mixture.covariances_
            if covariance_type == "diag":
                covariances = np.stack([np.diag(row) for row in covariances])
            scale = np.outer(spread, spread)
            prior = cls(
                checked, mixture.weights_, centre + spread * mixture.means_, covariances * scale
            )
            fitted.append((mixture.bic(standard), prior))
        fitted.sort(key=lambda pair: pair[0])
        check = np.random.default_rng(seed)
        gaps = [_moment_gap(prior, matrix, check) for _, prior in fitted]
        faithful = [i for i, gap in enumerate(gaps) if gap <= moment_tolerance]
        if faithful:
            return fitted[faithful[0]][1]
        return _with_marginal_moments(fitted[0][1], matrix, check)

    def with_slabs(
        self,
        groups: Sequence[Sequence[str]],
        probability: float,
        *,
        most: int = 2,
        downward: Sequence[Sequence[str]] = (),
    ) -> GMMPrior:
        """This mixture as the spike of a spike-and-slab prior: each group of parameters,
        independently with ``probability``, instead spread over its whole range (a logit
        normal of sd :data:`SLAB_SD` about the range's middle: near-uniform), at most ``most``
        groups at once. A group also in ``downward`` spreads below the component's own values
        only (a fault that only lowers them): each logit normal about the value halfway between
        the range's low end and the component's, its sd half the logit distance from there to
        the component's value (2.3 % of it above that value).

        Each component of this mixture is repeated once per set of at most ``most`` groups,
        those groups' logits replaced by the slab (independent of the rest), with weight
        ∝ probability^k (1 − probability)^(groups − k) for a set of k groups.

        Args:
            groups: groups of parameter names (each group is moved or kept together).
            probability: each group's prior probability of being spread, in (0, 1).
            most: largest number of groups spread at once.
            downward: those of ``groups`` that spread downward only.
        """
        if not 0.0 < probability < 1.0:
            raise ValueError(f"a slab's probability must lie in (0, 1), got {probability}")
        unknown = sorted({n for group in groups for n in group} - set(self.names))
        if unknown:
            raise ValueError(f"slab group(s) name {unknown}; the prior has {list(self.names)}")
        index = {name: i for i, name in enumerate(self.names)}
        groups = [tuple(group) for group in groups]
        lowering = {tuple(group) for group in downward}
        if not lowering <= set(groups):
            raise ValueError(f"downward group(s) {sorted(lowering - set(groups))} are not slabs")
        weights, means, covariances = [], [], []
        for k in range(min(most, len(groups)) + 1):
            chance = probability**k * (1.0 - probability) ** (len(groups) - k)
            for spread in itertools.combinations(groups, k):
                columns = [index[name] for group in spread for name in group]
                mean, covariance = self.means.copy(), self.covariances.copy()
                covariance[:, columns, :] = 0.0
                covariance[:, :, columns] = 0.0
                for group in spread:
                    at = [index[name] for name in group]
                    if group in lowering:
                        # halfway between the low end and the component's value, in the range
                        half = logit(expit(self.means[:, at]) / 2.0)
                        mean[:, at] = half
                        covariance[:, at, at] = ((self.means[:, at] - half) / 2.0) ** 2
                    else:
                        mean[:, at] = 0.0
                        covariance[:, at, at] = SLAB_SD**2
                weights.append(chance * self.weights)
                means.append(mean)
                covariances.append(covariance)
        total = np.concatenate(weights)
        return GMMPrior(
            self.bounds, total / total.sum(), np.concatenate(means), np.concatenate(covariances)
        )

    def _log_unbounded_density(self, unbounded: np.ndarray) -> np.ndarray:
        terms = np.empty((unbounded.shape[0], self.n_components))
        d = self.ndim
        for j in range(self.n_components):
            centred = unbounded - self.means[j]
            whitened = np.linalg.solve(self._cholesky[j], centred.T)
            terms[:, j] = (
                np.log(self.weights[j])
                - 0.5 * (whitened**2).sum(axis=0)
                - 0.5 * (d * np.log(2 * np.pi) + self._log_det[j])
            )
        return logsumexp(terms, axis=1)

    @property
    def is_diagonal(self) -> bool:
        """Whether every component's covariance is diagonal (its logits independent)."""
        return bool((self.covariances[:, ~np.eye(self.ndim, dtype=bool)] == 0).all())

    def sample_in_box(
        self, box: Mapping[str, tuple[float, float]], n: int, rng: np.random.Generator
    ) -> np.ndarray | None:
        """``n`` draws (n, d) of the mixture restricted to ``box`` (name -> (low, high)).

        With diagonal components (what :meth:`fit` gives below 10 samples per free parameter of
        a full one, e.g. 250 draws in 35 dimensions) the draws are exact however little mass
        the box holds: a component with probability ∝ its weight × its mass in the box, then
        each logit from its normal truncated to the box's edges. Full covariances fall back to
        rejection (:meth:`Prior.sample_in_box`). None if the box holds no mass at all.
        """
        if not self.is_diagonal:
            return super().sample_in_box(box, n, rng)
        n = _check_count(n)
        low, high = _box_edges(self.names, box)
        width = self.upper - self.lower
        edges = [
            logit(np.clip((edge - self.lower) / width, 0.0, 1.0))[np.newaxis, :]
            for edge in (low, high)
        ]
        sds = np.sqrt(np.diagonal(self.covariances, axis1=1, axis2=2))
        below, above = ((edge - self.means) / sds for edge in edges)
        log_mass = _log_normal_mass(below, above).sum(axis=1) + np.log(self.weights)
        if not np.isfinite(log_mass).any():
            return None
        chances = np.exp(log_mass - logsumexp(log_mass))
        components = rng.choice(self.n_components, size=n, p=chances / chances.sum())
        unbounded = truncnorm.rvs(
            below[components],
            above[components],
            loc=self.means[components],
            scale=sds[components],
            random_state=rng,
        )
        return np.clip(self.lower + width * expit(unbounded), low, high)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        n = _check_count(n)
        components = rng.choice(self.n_components, size=n, p=self.weights)
        normal = rng.standard_normal((n, self.ndim))
        unbounded = self.means[components] + np.einsum(
            "nij,nj->ni", self._cholesky[components], normal
        )
        return self.lower + (self.upper - self.lower) * expit(unbounded)

    def logpdf(self, x: np.ndarray) -> np.ndarray:
        points = self._points(x)
        inside = ((points > self.lower) & (points < self.upper)).all(axis=1)
        result = np.full(points.shape[0], -np.inf)
        if inside.any():
            width = self.upper - self.lower
            fraction = (points[inside] - self.lower) / width
            log_jacobian = -(np.log(width) + np.log(fraction) + np.log1p(-fraction)).sum(axis=1)
            result[inside] = self._log_unbounded_density(logit(fraction)) + log_jacobian
        return result

    def to_dataset(self) -> xr.Dataset:
        dataset = self._bounds_dataset()
        dataset["weights"] = ("component", self.weights)
        dataset["means"] = (("component", "parameter"), self.means, {"space": "logit"})
        dataset["covariances"] = (
            ("component", "parameter", "parameter_"),
            self.covariances,
            {"space": "logit"},
        )
        return dataset

    @classmethod
    def from_dataset(cls, dataset: xr.Dataset) -> GMMPrior:
        """Inverse of :meth:`to_dataset`."""
        return cls(
            _bounds_from_dataset(dataset),
            dataset["weights"].values,
            dataset["means"].values,
            dataset["covariances"].values,
        )

    def __repr__(self) -> str:
        return f"GMMPrior({self.n_components} components over {list(self.names)})"


PRIOR_KINDS: dict[str, type[Prior]] = {"uniform": UniformPrior, "gmm": GMMPrior}


def prior_from_dataset(dataset: xr.Dataset) -> Prior:
    """The prior a Dataset from ``Prior.to_dataset`` describes."""
    kind = dataset.attrs.get("kind")
    if kind not in PRIOR_KINDS:
        raise ValueError(f"unknown prior kind {kind!r}; expected one of {list(PRIOR_KINDS)}")
    return PRIOR_KINDS[kind].from_dataset(dataset)


def load_prior(path: str | Path) -> Prior:
    """Read a prior written by ``Prior.save``.

    Parameters
    ----------
    path
        The netCDF file ``Prior.save`` wrote.
    """
    with xr.open_dataset(path, engine="h5netcdf") as dataset:
        return prior_from_dataset(dataset.load())
