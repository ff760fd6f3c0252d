"""A start for tempered SMC on the exact likelihood: least-squares fits, then Laplace.

Tempered SMC from the prior needs many stages when the likelihood is sharp in many directions
(a posterior 1/1000 of its prior box in five parameters took 16 stages), and each stage only
halves the effective sample size. Instead,

1. :func:`fit_reference` fits the parameters by nonlinear least squares on the whitened
   residuals of every exact-likelihood node (under sensor noise or an error budget; scipy's
   trust-region reflective ``least_squares``) from one or more starts, over
   ``place = sigmoid(value)`` in the unit box, ``value`` being the model's value space (the
   unconstrained coordinates of its free variables; for the box priors here, ``place`` is
   each parameter's place in its box), with forward-difference Jacobians whose simulations
   run as one parallel batch through an executor. (In the value space itself the fit strays
   to the box edges, where the logit flattens every slope, and stalls there.)
2. At each fit, the Laplace approximation (covariance ``(JᵀJ + P)⁻¹``, ``P`` the prior's
   negative Hessian there) is corrected along its principal axes by secants at ±2 sds, where
   the solver's own error no longer swamps weak directions, and widened by ``inflation``.
   Fits that end in the same mode are merged; the distinct modes make an equal-weight mixture,
   the :class:`~pymc_vcc.inference.pymc.reference.GaussianReference`.
3. SMC tempers from that reference ``q`` to the posterior (``sample_smc_abc(reference=q)``):
   ``π_β ∝ q^(1−β) (prior × likelihood)^β``, so ``β = 0`` is ``q``, drawn exactly, and
   ``β = 1`` the posterior. Importance weights and Metropolis–Hastings moves correct whatever
   ``q`` misses, provided it covers the posterior's mass; its evidence estimate stays that of
   the posterior. A mode no fit reached is missed: the reference-started posterior is that of
   the modes found.

:func:`laplace_draws` draws that mixture itself as the posterior, each mode weighted by its
Laplace evidence, where the likelihood is near Gaussian and SMC's particles would be too few
for its sharpness (a model's own record under the sensors' errors alone).

The fit ignores a Student-t density (it fits the whitened innovations by least squares) and
any other observed term or potential of the model; the SMC does not.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Mapping, Sequence
from contextlib import closing
from typing import Any

import numpy as np
import pytensor.tensor as pt
from pymc.blocking import DictToArrayBijection
from pymc.distributions.simulator import SimulatorRV
from pymc.model import Model, modelcontext
from pymc.pytensorf import compile as compile_pytensor
from pymc.pytensorf import join_nonshared_inputs, make_shared_replacements
from pytensor.gradient import hessian
from scipy.optimize import least_squares
from scipy.special import expit, logit
from scipy.stats import chi2

from pymc_vcc.execution.executors import Executor
from pymc_vcc.execution.options import RunOptions
from pymc_vcc.execution.outcomes import SimulationOutcome
from pymc_vcc.inference.pymc.batch import BatchLikelihood, graph_digest, python_ops_quiet
from pymc_vcc.inference.pymc.likelihood import LogLikelihoodKernel, SummaryLikelihoodKernel
from pymc_vcc.inference.pymc.reference import GaussianReference

FIT_BOUND = 10.0
"""Largest |value| of a fitted coordinate: logit 10 is 4.5e-5 of a box's width from its edge."""

AXIS_ROUNDS = 2
"""Rounds of :func:`_along_axes` after the fit (2 × dimension simulations each)."""

AXIS_REACH = 2.0
"""How far :func:`_along_axes` probes each principal axis, in its sds."""

EXACT_KERNELS = (LogLikelihoodKernel, SummaryLikelihoodKernel)
"""The likelihood nodes whose whitened residuals a fit can read (``residuals``)."""

FAILED_RESIDUAL = 1e3
"""Whitened residual given to every entry of a failed simulation: the fit steps back from it."""


class _Residuals:
    """The whitened residuals of every exact-likelihood node at points of the value space,
    simulated in batches through an executor, counted and remembered."""

    def __init__(self, model: Model, executor: Executor, seed: np.random.SeedSequence) -> None:
        self.likelihood = BatchLikelihood(model, model.value_vars, None)
        nodes = [rv for rv in model.observed_RVs if isinstance(rv.owner.op, SimulatorRV)]
        self.kernels = [rv.owner.op._distance for rv in nodes]
        if not all(isinstance(kernel, EXACT_KERNELS) for kernel in self.kernels):
            raise ValueError(
                "fit_reference needs exact-likelihood nodes only (add_likelihood); the model "
                "has an ABC distance node, whose ε kernel has no residuals to fit"
            )
        self.observed = [np.asarray(model.rvs_to_values[rv].data, dtype=float) for rv in nodes]
        self.executor, self.seed = executor, seed
        self.simulations = self.failures = 0
        pairs = zip(self.kernels, self.observed, strict=True)
        self.size = sum(kernel.n_residuals(data) for kernel, data in pairs)  # per point
        self._known: dict[bytes, np.ndarray | None] = {}

    def of_node(self, node: int, values: np.ndarray) -> np.ndarray:
        """Whitened residuals of one node's simulated ``values`` against its data."""
        return self.kernels[node].residuals(self.observed[node], values)

    def batch(self, points: np.ndarray) -> list[np.ndarray | None]:
        """The residual vector at each point (None where a simulation failed)."""
        todo = [p for p in dict.fromkeys(map(bytes, points)) if p not in self._known]
        if todo:
            fresh = np.array([np.frombuffer(p) for p in todo])
            n_nodes = self.likelihood.n_nodes
            tasks = self.likelihood.tasks(fresh, self.seed.spawn(len(fresh) * n_nodes))
            outcomes: list[SimulationOutcome | None] = [None] * len(tasks)
            with closing(self.likelihood.run(self.executor, tasks)) as chunks:
                for chunk in chunks:
                    for position, outcome in chunk:
                        outcomes[position] = outcome
            self.simulations += len(tasks)
            for index, key in enumerate(todo):
                per_node = [outcomes[node * len(todo) + index] for node in range(n_nodes)]
                done = [o for o in per_node if o is not None and o.ok]
                if len(done) == n_nodes:
                    self._known[key] = np.concatenate(
                        [self.of_node(node, np.asarray(o.values)) for node, o in enumerate(done)]
                    )
                else:
                    self.failures += n_nodes - len(done)
                    self._known[key] = None
        return [self._known[bytes(point)] for point in points]


def _fingerprint(model: Model | None = None, **settings: Any) -> str:
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
    starts: int = 1,
    points: Sequence[Mapping[str, float]] = (),
    max_simulations: int = 3000,
    step: float = 1e-2,
    inflation: float = 1.2,
    axis_rounds: int = AXIS_ROUNDS,
    run: RunOptions | None = None,
) -> GaussianReference:
    """Fit the model's exact-likelihood nodes by least squares from ``starts`` points and return
    the Laplace approximation at each distinct mode found, the start of
    ``sample_smc_abc(reference=...)``.

    Args:
        model: a model whose ``pm.Simulator`` nodes all come from
            :func:`~pymc_vcc.inference.pymc.likelihood.add_likelihood` (default: the current).
        starts: fits, the first from the prior's initial point, the others from uniform
            places in the middle 80 % of the unit box; fits ending within the 99.9 % ellipsoid
            of a better one are the same mode.
        points: more fits, from these parameter values (name -> value, every free
            variable; e.g. draws of a broader posterior, where a mode may lie that the other
            starts miss).
        max_simulations: simulations each fit may run (about dimension + 1 per iteration).
        step: forward-difference step in the unit box (a fraction of a box's width).
        inflation: factor on the Laplace standard deviations (≥ 1: a wider start is safer).
        axis_rounds: rounds of secant corrections along the principal axes (0: the Laplace
            approximation of the fit's own Jacobian, right when ``step`` is small enough for
            the solver's error).
        run: where the fits' simulations run (their time limit is the nodes' own); its
            ``seed`` seeds the other starts and the simulations' random streams, and its
            ``checkpoint`` is a JSON file keeping the finished fit (a later call with the same
            model, data and settings loads it instead of fitting again).

    Returns:
        The :class:`~pymc_vcc.inference.pymc.reference.GaussianReference`, with the fits'
        simulations and failures counted.
    """
    if not inflation >= 1.0:
        raise ValueError(f"inflation must be >= 1, got {inflation}")
    if not step > 0:
        raise ValueError(f"step must be positive, got {step}")
    if isinstance(starts, bool) or int(starts) != starts or starts < 1:
        raise ValueError(f"starts must be a positive integer, got {starts!r}")
    run = run or RunOptions()
    seed, checkpoint = run.seed, run.checkpoint
    model = modelcontext(model)
    fingerprint = _fingerprint(
        model,
        starts=starts,
        points=[dict(point) for point in points],
        max_simulations=max_simulations,
        step=step,
        inflation=inflation,
        axis_rounds=axis_rounds,
        seed=seed
        if not isinstance(seed, np.random.SeedSequence)
        else [str(seed.entropy), list(seed.spawn_key)],
    )
    if checkpoint is not None and (saved := GaussianReference.load(checkpoint, fingerprint)):
        return saved
    origin = DictToArrayBijection.map(model.initial_point()).data
    dimension = origin.size
    if max_simulations < 2 * (dimension + 1):
        raise ValueError(
            f"max_simulations must allow two iterations of {dimension + 1} simulations, "
            f"got {max_simulations}"
        )
    rng = np.random.default_rng(seed)
    places = [expit(np.clip(origin, -FIT_BOUND, FIT_BOUND))]
    places += [rng.uniform(0.1, 0.9, dimension) for _ in range(starts - 1)]
    places += [expit(np.clip(_value_point(model, p), -FIT_BOUND, FIT_BOUND)) for p in points]
    with run.open_executor() as opened, python_ops_quiet():
        residuals = _Residuals(model, opened, run.seed_sequence())
        if residuals.batch(origin[np.newaxis])[0] is None:
            raise RuntimeError(
                "the fit's starting point (the prior's initial point) failed to simulate; "
                "check the simulator and the prior"
            )
        log_prior, prior_precision = _prior_functions(model)

        def cost(points: np.ndarray) -> np.ndarray:
            """Negative log posterior (up to a constant) at value-space ``points``; inf where
            a simulation failed."""
            found = residuals.batch(points)
            data = np.array([np.inf if r is None else 0.5 * r @ r for r in found])
            return data - np.array([log_prior(point) for point in points])

        modes, iterations = [], 0
        for place in places:
            fit = _least_squares(residuals, place, step, max_simulations)
            iterations += int(fit.nfev)
            mean, covariance = _laplace(fit, prior_precision)
            for _ in range(axis_rounds):
                mean, covariance = _along_axes(cost, mean, covariance)
            modes.append((float(fit.cost), mean, covariance))
    modes = _distinct(modes)
    reference = GaussianReference(
        means=np.array([mean for _, mean, _ in modes]),
        covariances=np.array([inflation**2 * covariance for _, _, covariance in modes]),
        simulations=residuals.simulations,
        failed_simulations=residuals.failures,
        iterations=iterations,
        costs=tuple(fit_cost for fit_cost, _, _ in modes),
    )
    if checkpoint is not None:
        reference.save(checkpoint, fingerprint)
    return reference


def laplace_draws(
    reference: GaussianReference, n: int, rng: np.random.Generator, model: Model | None = None
) -> dict[str, np.ndarray]:
    """``n`` draws of the Laplace approximation of the posterior at the modes of ``reference``
    (a :func:`fit_reference` of ``model``, default the current), as parameter values (name ->
    array): each mode weighted by its Laplace evidence, exp(−cost) √det Σ (the prior taken
    as flat across the modes)."""
    model = modelcontext(model)
    log_det = np.linalg.slogdet(reference.covariances)[1]
    log_evidence = -np.asarray(reference.costs) + 0.5 * log_det
    weights = np.exp(log_evidence - log_evidence.max())
    weighted = GaussianReference(
        reference.means, reference.covariances, weights=weights / weights.sum()
    )
    if weighted.means.shape[1] != len(model.free_RVs):
        raise ValueError("laplace_draws needs a model whose free variables are all scalars")
    values = weighted.sample(n, rng)
    return {
        rv.name: _through_transform(model, rv, values[:, column], forward=False)
        for column, rv in enumerate(model.free_RVs)
    }


def _value_point(model: Model, point: Mapping[str, float]) -> np.ndarray:
    """The value-space vector of the parameter values ``point`` (each free variable's value
    through its transform)."""
    values = {
        model.rvs_to_values[rv].name: _through_transform(model, rv, point[rv.name], forward=True)
        for rv in model.free_RVs
    }
    return DictToArrayBijection.map(values).data


def _through_transform(model: Model, rv: Any, value: Any, *, forward: bool) -> np.ndarray:
    """A free variable's ``value`` taken into its value space (``forward``) or back out."""
    tensor = pt.as_tensor_variable(np.asarray(value, dtype=float))
    transform = model.rvs_to_transforms.get(rv)
    if transform is not None:
        move = transform.forward if forward else transform.backward
        tensor = move(tensor, *rv.owner.inputs)
    return np.asarray(tensor.eval(), dtype=float)


def _least_squares(residuals: _Residuals, place: np.ndarray, step: float, max_simulations: int):
    """scipy's trust-region fit of the whitened residuals over the unit box from ``place``,
    with batched forward-difference Jacobians; a failed simulation's residuals are
    :data:`FAILED_RESIDUAL`, so the fit steps back from it."""
    lower, upper = expit(-FIT_BOUND), expit(FIT_BOUND)
    failed = np.full(residuals.size, FAILED_RESIDUAL)

    def residual(at: np.ndarray) -> np.ndarray:
        found = residuals.batch(logit(at)[np.newaxis])[0]
        return failed if found is None else found

    def jacobian(at: np.ndarray) -> np.ndarray:
        steps = np.where(at + step <= upper, step, -step)
        base = residual(at)
        moved = residuals.batch(logit(at + np.diag(steps)))
        columns = [
            np.zeros_like(base) if shifted is None else (shifted - base) / h
            for shifted, h in zip(moved, steps, strict=True)
        ]
        return np.column_stack(columns)

    return least_squares(
        residual,
        np.clip(place, lower, upper),
        jac=jacobian,
        bounds=(lower, upper),
        method="trf",
        x_scale="jac",
        max_nfev=max(2, max_simulations // (place.size + 1)),
    )


def _laplace(fit, prior_precision: Callable) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance in value space of the Laplace approximation at a least-squares
    ``fit`` over the unit box (its Jacobian carried over by the chain rule)."""
    mean = logit(fit.x)
    slopes = fit.jac * (fit.x * (1.0 - fit.x))  # ∂w/∂value = ∂w/∂place · ∂place/∂value
    precision = slopes.T @ slopes + prior_precision(mean)
    values, vectors = np.linalg.eigh(0.5 * (precision + precision.T))
    values = np.maximum(values, 1e-6 * max(values.max(), 1e-12))
    return mean, (vectors / values) @ vectors.T


def _distinct(modes: list[tuple[float, np.ndarray, np.ndarray]]) -> list:
    """The modes (cost, mean, covariance), best first, without those whose mean lies inside
    the 99.9 % ellipsoid of a better one."""
    kept: list[tuple[float, np.ndarray, np.ndarray]] = []
    for mode in sorted(modes, key=lambda found: found[0]):
        _, mean, _ = mode
        limit = chi2.ppf(0.999, mean.size)
        if all(
            (mean - other) @ np.linalg.solve(covariance, mean - other) > limit
            for _, other, covariance in kept
        ):
            kept.append(mode)
    return kept


def _prior_functions(model: Model) -> tuple[Callable, Callable]:
    """The prior's log density and negative Hessian as functions of a value-space point
    (Jacobian terms included)."""
    initial = model.initial_point()
    shared = make_shared_replacements(initial, model.value_vars, model)
    [logp], flat = join_nonshared_inputs(
        initial, [model.logp(vars=model.free_RVs)], model.value_vars, shared
    )
    log_prior = compile_pytensor([flat], logp)
    negative_hessian = compile_pytensor([flat], -hessian(logp, flat))
    return (
        lambda point: float(log_prior(point)),
        lambda point: np.asarray(negative_hessian(point), dtype=float),
    )


def _along_axes(
    cost: Callable[[np.ndarray], np.ndarray], mean: np.ndarray, covariance: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance corrected along each principal axis of ``covariance``.

    The finite-difference Jacobian takes small steps, where the solver's own error (a few
    tenths of a whitened residual in norm) swamps the slope of weakly identified directions and
    adds precision that is not there. Here the ``cost`` is probed at ±:data:`AXIS_REACH` sds
    along each axis, where the data change it by about 2: the secant curvature sets that axis's
    sd (at most 10 times wider or narrower) and the secant slope moves the mean (at most to a
    probe). An axis whose probes failed or curve downwards keeps its sd.
    """
    values, vectors = np.linalg.eigh(covariance)
    sds = np.sqrt(values)
    reach = AXIS_REACH * sds
    steps = (vectors * reach).T  # row k: axis k, reach k long
    costs = cost(np.vstack([mean, mean + steps, mean - steps]))
    n = mean.size
    centre, up, down = costs[0], costs[1 : n + 1], costs[n + 1 :]
    curvature = (up + down - 2.0 * centre) / reach**2
    usable = np.isfinite(up) & np.isfinite(down) & (curvature > 0)
    curvature = np.where(usable, curvature, 1.0 / values)
    new_sds = np.clip(1.0 / np.sqrt(curvature), sds / 10.0, sds * 10.0)
    shift = np.where(usable, np.clip(-(up - down) / (2.0 * reach) / curvature, -reach, reach), 0.0)
    return mean + vectors @ shift, (vectors * new_sds**2) @ vectors.T


__all__ = ["fit_reference", "laplace_draws"]
