"""The Gaussian mixture a tempered SMC starts from instead of the prior.

:func:`~pymc_vcc.inference.pymc.laplace.fit_reference` makes one (Laplace approximations at the
modes of a least-squares fit), :meth:`GaussianReference.of_mixture` another (a mixture prior
broader than the one sampled, e.g. with its faults likelier); ``sample_smc_abc(reference=...)``
(:class:`~pymc_vcc.inference.pymc.smc.ParallelKernel`) draws its initial particles from it and
tempers from its density to the posterior.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
from scipy.special import logsumexp

from pymc_vcc.execution.output_folder import atomic_path
from pymc_vcc.inference.priors import GMMPrior


@dataclass(frozen=True)
class GaussianReference:
    """A mixture of Gaussians over the model's value space (the flat vector of its free
    variables' unconstrained values, in ``model.value_vars`` order), e.g. one per mode found,
    and what finding them cost.

    Attributes:
        means, covariances: of the components, (K, d) and (K, d, d); one component may be
            given as (d,) and (d, d).
        weights: of the components, (K,) summing to 1 (default: equal).
        simulations, failed_simulations: simulations the fit ran, and how many failed.
        iterations: least-squares iterations over all starts.
        costs: ½ Σ w² of the whitened residuals at each component's fit.
    """

    means: np.ndarray
    covariances: np.ndarray
    simulations: int = 0
    failed_simulations: int = 0
    iterations: int = 0
    costs: tuple[float, ...] = ()
    weights: np.ndarray | None = None

    def __post_init__(self) -> None:
        means = np.atleast_2d(np.asarray(self.means, dtype=float))
        covariances = np.asarray(self.covariances, dtype=float)
        if covariances.ndim == 2:
            covariances = covariances[np.newaxis]
        k, d = means.shape
        if covariances.shape != (k, d, d) or not np.isfinite(covariances).all():
            raise ValueError(
                f"covariances must be {k} finite {d} x {d} matrices for {k} mean(s) of {d} "
                f"values, got shape {covariances.shape}"
            )
        weights = np.full(k, 1.0 / k) if self.weights is None else np.asarray(self.weights, float)
        if weights.shape != (k,) or (weights < 0).any() or not np.isclose(weights.sum(), 1.0):
            raise ValueError(f"weights must be {k} non-negative numbers summing to 1")
        object.__setattr__(self, "means", means)
        object.__setattr__(self, "covariances", covariances)
        object.__setattr__(self, "weights", weights)
        object.__setattr__(self, "costs", tuple(float(c) for c in self.costs))
        np.linalg.cholesky(covariances)  # positive definite, or LinAlgError here

    @classmethod
    def of_mixture(cls, prior: GMMPrior) -> GaussianReference:
        """The mixture ``prior`` itself over the value space of
        :func:`~pymc_vcc.inference.pymc.model.gmm_prior_variable` (the logit space of its
        bounds, where it is Gaussian): for a model whose only free variable is such a prior."""
        return cls(prior.means, prior.covariances, weights=prior.weights)

    @cached_property
    def _equal_weights(self) -> bool:
        """Equal weights: drawn and digested as before the weights existed."""
        return bool(np.allclose(self.weights, 1.0 / len(self.means)))

    @cached_property
    def _factors(self) -> np.ndarray:
        return np.linalg.cholesky(self.covariances)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` draws, (n, dimension), each component drawn with its weight's probability."""
        if self._equal_weights:
            component = rng.integers(len(self.means), size=n)
        else:
            component = rng.choice(len(self.means), size=n, p=self.weights)
        noise = rng.standard_normal(self.means[component].shape)
        return self.means[component] + np.einsum("nij,nj->ni", self._factors[component], noise)

    def logpdf(self, points: np.ndarray) -> np.ndarray:
        """Log density at each row of ``points``."""
        points = np.atleast_2d(points)
        per_component = []
        for mean, factor in zip(self.means, self._factors, strict=True):
            whitened = np.linalg.solve(factor, (points - mean).T)
            log_det = 2.0 * np.log(np.diag(factor)).sum()
            per_component.append(
                -0.5 * (np.sum(whitened**2, axis=0) + log_det + mean.size * np.log(2 * np.pi))
            )
        return logsumexp(per_component, axis=0, b=self.weights[:, np.newaxis])

    def digest(self) -> str:
        """Digest of the components (a checkpoint names the reference it sampled)."""
        parts = self.means.tobytes() + self.covariances.tobytes()
        if not self._equal_weights:
            parts += self.weights.tobytes()
        return hashlib.sha256(parts).hexdigest()

    def save(self, path: str | Path, fingerprint: str) -> None:
        """Write as JSON (atomically), with the ``fingerprint`` of the fit that made it."""
        payload = {**asdict(self), "fingerprint": fingerprint}
        for name in ("means", "covariances", "weights"):
            payload[name] = getattr(self, name).tolist()
        with atomic_path(path) as temporary:
            temporary.write_text(json.dumps(payload))

    @classmethod
    def load(cls, path: str | Path, fingerprint: str) -> GaussianReference | None:
        """The reference saved at ``path`` by a fit with this ``fingerprint``; None if there is
        none or it came from another fit."""
        path = Path(path)
        if not path.is_file():
            return None
        payload = json.loads(path.read_text())
        if payload.pop("fingerprint", None) != fingerprint:
            return None
        return cls(**payload)


__all__ = ["GaussianReference"]
