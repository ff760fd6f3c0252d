"""A Gaussian start for tempered SMC on the exact likelihood: a least-squares fit, then Laplace.

Tempered SMC from the prior needs many stages when the likelihood is sharp in many directions:
the 26 parameters of the split unit under typical sensor noise have log-likelihoods from −1e8 to
−5e3 over the prior box, and each stage only halves the effective sample size. Instead,

1. :func:`fit_reference` fits the parameters by nonlinear least squares on the whitened
   residuals of every exact-likelihood node (scipy's trust-region reflective
   ``least_squares``), over ``place = sigmoid(value)`` in the unit box, ``value`` being the
   model's value space (the unconstrained coordinates of its free variables; for the box priors
   here, ``place`` is each parameter's place in its box), with forward-difference Jacobians
   whose simulations run as one parallel batch through an executor. (In the value space itself
   the fit strays to the box edges, where the logit flattens every slope, and stalls there.)
2. the Laplace approximation at the fit, covariance ``inflation² (JᵀJ + P)⁻¹`` with ``P`` the
   prior's negative Hessian there, is the :class:`GaussianReference`;
3. SMC tempers from that reference ``q`` to the posterior (``sample_smc_abc(reference=q)``):
   ``π_β ∝ q^(1−β) (prior × likelihood)^β``, so ``β = 0`` is ``q``, drawn exactly, and
   ``β = 1`` the posterior. Importance weights and Metropolis–Hastings moves correct whatever
   ``q`` misses, provided it covers the posterior's mass; its evidence estimate stays that of
   the posterior.

The fit ignores a Student-t density (it fits the whitened innovations by least squares) and
any other observed term or potential of the model; the SMC does not.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from functools import cached_property, partial
from pathlib import Path
from typing import Any

import numpy as np
from pymc.blocking import DictToArrayBijection
from pymc.distributions.simulator import SimulatorRV
from pymc.model import Model, modelcontext
from pymc.pytensorf import compile as compile_pytensor
from pymc.pytensorf import join_nonshared_inputs, make_shared_replacements
from pytensor.gradient import hessian
from scipy.optimize import least_squares
from scipy.special import expit, logit

from pymc_vcc.execution.executors import Executor, ExecutorKind, WorkerCrash, executor_scope
from pymc_vcc.execution.outcomes import SimulationOutcome, crash_outcome
from pymc_vcc.execution.output_folder import atomic_path
from pymc_vcc.inference.likelihood import innovations
from pymc_vcc.inference.pymc.likelihood import LogLikelihoodKernel
from pymc_vcc.inference.pymc.smc import BatchLikelihood, graph_digest, simulate_task

FIT_BOUND = 10.0
"""Largest |value| of a fitted coordinate: logit 10 is 4.5e-5 of a box's width from its edge."""

FAILED_RESIDUAL = 1e3
"""Whitened residual given to every entry of a failed simulation: the fit steps back from it."""


@dataclass(frozen=True)
class GaussianReference:
    """A Gaussian over the model's value space (the flat vector of its free variables'
    unconstrained values, in ``model.value_vars`` order) and what fitting it cost.

    Attributes:
        mean, covariance: of the Gaussian.
        simulations, failed_simulations: simulations the fit ran, and how many failed.
        iterations: the least-squares iterations.
        cost: ½ Σ w² of the whitened residuals at the fit.
    """

    mean: np.ndarray
    covariance: np.ndarray
    simulations: int = 0
    failed_simulations: int = 0
    iterations: int = 0
    cost: float = float("nan")

    def __post_init__(self) -> None:
        mean = np.asarray(self.mean, dtype=float).reshape(-1)
        covariance = np.asarray(self.covariance, dtype=float)
        if covariance.shape != (mean.size, mean.size) or not np.isfinite(covariance).all():
            raise ValueError(
                f"covariance must be a finite {mean.size} x {mean.size} matrix for a mean of "
                f"{mean.size} values, got shape {covariance.shape}"
            )
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "covariance", covariance)
        np.linalg.cholesky(self.covariance)  # positive definite, or LinAlgError here

    @cached_property
    def _factor(self) -> np.ndarray:
        return np.linalg.cholesky(self.covariance)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` draws, (n, dimension)."""
        return self.mean + rng.standard_normal((n, self.mean.size)) @ self._factor.T

    def logpdf(self, points: np.ndarray) -> np.ndarray:
        """Log density at each row of ``points``."""
        whitened = np.linalg.solve(self._factor, (np.atleast_2d(points) - self.mean).T)
        log_det = 2.0 * np.log(np.diag(self._factor)).sum()
        return -0.5 * (np.sum(whitened**2, axis=0) + log_det + self.mean.size * np.log(2 * np.pi))

    def digest(self) -> str:
        """Digest of the mean and covariance (a checkpoint names the reference it sampled)."""
        return hashlib.sha256(self.mean.tobytes() + self.covariance.tobytes()).hexdigest()

    def save(self, path: str | Path, fingerprint: str) -> None:
        """Write as JSON (atomically), with the ``fingerprint`` of the fit that made it."""
        payload = {**asdict(self), "fingerprint": fingerprint}
        payload["mean"], payload["covariance"] = self.mean.tolist(), self.covariance.tolist()
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


class _Residuals:
    """The whitened residuals of every exact-likelihood node at points of the value space,
    simulated in batches through an executor, counted and remembered."""

    def __init__(self, model: Model, executor: Executor, seed: np.random.SeedSequence) -> None:
        self.likelihood = BatchLikelihood(model, model.value_vars, None)
        nodes = [rv for rv in model.observed_RVs if isinstance(rv.owner.op, SimulatorRV)]
        kernels = [rv.owner.op._distance for rv in nodes]
        if not all(isinstance(kernel, LogLikelihoodKernel) for kernel in kernels):
            raise ValueError(
                "fit_reference needs exact-likelihood nodes only (add_likelihood); the model "
                "has an ABC distance node, whose ε kernel has no residuals to fit"
            )
        self.noises = [kernel.noise for kernel in kernels]
        self.observed = [np.asarray(model.rvs_to_values[rv].data, dtype=float) for rv in nodes]
        self.executor, self.seed = executor, seed
        self.simulations = self.failures = 0
        self._known: dict[bytes, np.ndarray | None] = {}

    def of_node(self, node: int, values: np.ndarray) -> np.ndarray:
        """Whitened innovations of one node's simulated ``values`` against its data."""
        noise, observed = self.noises[node], self.observed[node]
        return innovations((observed - values) / noise.std(values), noise.correlation).ravel()

    def batch(self, points: np.ndarray) -> list[np.ndarray | None]:
        """The residual vector at each point (None where a simulation failed)."""
        todo = [p for p in dict.fromkeys(map(bytes, points)) if p not in self._known]
        if todo:
            fresh = np.array([np.frombuffer(p) for p in todo])
            n_nodes = self.likelihood.n_nodes
            tasks = self.likelihood.tasks(fresh, self.seed.spawn(len(fresh) * n_nodes))
            outcomes: list[SimulationOutcome | None] = [None] * len(tasks)
            chunks = self.executor.imap_chunks(
                partial(simulate_task, self.likelihood.functions),
                tasks,
                time_limit=self.likelihood.time_limit,
            )
            try:
                for chunk in chunks:
                    for position, result in chunk:
                        crashed = isinstance(result, WorkerCrash)
                        outcomes[position] = crash_outcome(result) if crashed else result
            finally:
                chunks.close()
            self.simulations += len(tasks)
            for index, key in enumerate(todo):
                per_node = [outcomes[node * len(todo) + index] for node in range(n_nodes)]
                if all(outcome is not None and outcome.ok for outcome in per_node):
                    self._known[key] = np.concatenate(
                        [self.of_node(node, o.values) for node, o in enumerate(per_node)]
                    )
                else:
                    self.failures += 1
                    self._known[key] = None
        return [self._known[bytes(point)] for point in points]


def fit_fingerprint(model: Model | None = None, **settings: Any) -> str:
    """What a saved fit must share with a new one: the model's prior and data, and
    ``settings``."""
    model = modelcontext(model)
    digest = hashlib.sha256(graph_digest(model.free_RVs).encode())
    digest.update(graph_digest([model.rvs_to_values[rv] for rv in model.observed_RVs]).encode())
    digest.update(json.dumps(settings, sort_keys=True).encode())
    return digest.hexdigest()


def fit_reference(
    model: Model | None = None,
    *,
    executor: Executor | ExecutorKind = "processes",
    n_workers: int | None = None,
    max_simulations: int = 3000,
    step: float = 1e-2,
    inflation: float = 1.2,
    seed: int = 0,
    checkpoint: str | Path | None = None,
) -> GaussianReference:
    """Fit the model's exact-likelihood nodes by least squares and return the Laplace
    approximation there, the start of ``sample_smc_abc(reference=...)``.

    Args:
        model: a model whose ``pm.Simulator`` nodes all come from
            :func:`~pymc_vcc.inference.pymc.likelihood.add_likelihood` (default: the current).
        executor: an open executor (left open) or a kind opened here (see
            :func:`~pymc_vcc.inference.pymc.smc.sample_smc_abc`).
        n_workers: workers of an executor opened here (default: every core).
        max_simulations: simulations the fit may run (about dimension + 1 per iteration).
        step: forward-difference step in the unit box (a fraction of a box's width).
        inflation: factor on the Laplace standard deviations (≥ 1: a wider start is safer).
        seed: seeds the simulations' random streams (the likelihood's are deterministic).
        checkpoint: JSON file keeping the finished fit; a later call with the same model, data
            and settings loads it instead of fitting again.

    Returns:
        The :class:`GaussianReference`, with the fit's simulations and failures counted.
    """
    if not inflation >= 1.0:
        raise ValueError(f"inflation must be >= 1, got {inflation}")
    if not step > 0:
        raise ValueError(f"step must be positive, got {step}")
    model = modelcontext(model)
    fingerprint = fit_fingerprint(
        model, max_simulations=max_simulations, step=step, inflation=inflation, seed=seed
    )
    if checkpoint is not None and (saved := GaussianReference.load(checkpoint, fingerprint)):
        return saved
    start = DictToArrayBijection.map(model.initial_point())
    dimension = start.data.size
    if max_simulations < 2 * (dimension + 1):
        raise ValueError(
            f"max_simulations must allow two iterations of {dimension + 1} simulations, "
            f"got {max_simulations}"
        )
    with executor_scope(executor, n_workers) as opened:
        residuals = _Residuals(model, opened, np.random.SeedSequence(seed))
        first = residuals.batch(start.data[np.newaxis])[0]
        if first is None:
            raise RuntimeError(
                "the fit's starting point (the prior's initial point) failed to simulate; "
                "check the simulator and the prior"
            )
        failed = np.full(first.size, FAILED_RESIDUAL)
        lower, upper = expit(-FIT_BOUND), expit(FIT_BOUND)

        def residual(place: np.ndarray) -> np.ndarray:
            found = residuals.batch(logit(place)[np.newaxis])[0]
            return failed if found is None else found

        def jacobian(place: np.ndarray) -> np.ndarray:
            steps = np.where(place + step <= upper, step, -step)
            base = residual(place)
            moved = residuals.batch(logit(place + np.diag(steps)))
            columns = [
                np.zeros_like(base) if shifted is None else (shifted - base) / h
                for shifted, h in zip(moved, steps, strict=True)
            ]
            return np.column_stack(columns)

        fit = least_squares(
            residual,
            expit(np.clip(start.data, -FIT_BOUND, FIT_BOUND)),
            jac=jacobian,
            bounds=(lower, upper),
            method="trf",
            x_scale="jac",
            max_nfev=max(2, max_simulations // (dimension + 1)),
        )
    mean = logit(fit.x)
    slopes = fit.jac * (fit.x * (1.0 - fit.x))  # ∂w/∂value = ∂w/∂place · ∂place/∂value
    precision = slopes.T @ slopes + _prior_precision(model, mean)
    values, vectors = np.linalg.eigh(0.5 * (precision + precision.T))
    values = np.maximum(values, 1e-6 * max(values.max(), 1e-12))
    covariance = inflation**2 * (vectors / values) @ vectors.T
    reference = GaussianReference(
        mean=mean,
        covariance=0.5 * (covariance + covariance.T),
        simulations=residuals.simulations,
        failed_simulations=residuals.failures,
        iterations=int(fit.nfev),
        cost=float(fit.cost),
    )
    if checkpoint is not None:
        reference.save(checkpoint, fingerprint)
    return reference


def _prior_precision(model: Model, point: np.ndarray) -> np.ndarray:
    """The prior's negative Hessian in value space at ``point`` (Jacobian terms included)."""
    initial = model.initial_point()
    shared = make_shared_replacements(initial, model.value_vars, model)
    [logp], flat = join_nonshared_inputs(
        initial, [model.logp(vars=model.free_RVs)], model.value_vars, shared
    )
    negative_hessian = compile_pytensor([flat], -hessian(logp, flat))
    return np.asarray(negative_hessian(point), dtype=float)


__all__ = ["GaussianReference", "fit_fingerprint", "fit_reference"]
