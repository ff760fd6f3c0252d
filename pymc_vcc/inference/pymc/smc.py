"""SMC-ABC with the simulations of each stage run as one parallel batch.

``pm.sample_smc`` evaluates the (pseudo-)likelihood of its particles one after another in a Python
loop, and its ``cores`` only run whole independent SMC runs side by side. With a simulator that
costs a second, that loop is the bottleneck. :class:`ParallelIMH` and :class:`ParallelMH` are
PyMC's independent and random-walk Metropolis–Hastings SMC kernels with the likelihood
evaluated differently: where the stock kernel calls a compiled likelihood per particle (running
the simulator inside PyTensor), each

1. evaluates the parameters of every ``pm.Simulator`` node for all particles (compiled, cheap),
2. runs all their simulations in one batch through an executor of
   :mod:`pymc_vcc.execution.executors` (serial, local processes or Dask), each with its own random
   stream from ``SeedSequence.spawn`` (results do not depend on which worker ran them),
3. computes the log-likelihoods from the simulated outputs (the node's distance kernel and any
   other observed terms, compiled), with −inf for a failed simulation: zero likelihood, so
   the particle is dropped at resampling or the proposal rejected, never a crash.

Everything else (tempering, resampling, proposals, tuning, acceptance) is the stock kernel's,
drawing from the same random generator in the same order: with a simulator that does not use
its random stream, the same seed gives the same posterior as the stock kernel, bit for bit.

Simulations run and failed per stage are recorded in ``sample_stats`` (``simulations``,
``failed_simulations``, ``resumed_simulations``, ``stage_seconds``) and their totals in its
attributes; :func:`sample_smc_abc` returns them over ``(chain, stage)``, totals over all chains,
and the observed data as one variable per output (see :mod:`pymc_vcc.inference.pymc.layout`).

Checkpoints (``sample_smc_abc(checkpoint=path)``): with a fixed seed, a run proposes the same
particles in the same order, each simulation with the same random stream; so a run started again
requests the same simulations. Each finished one is persisted, chunk by chunk as the executor
returns them, in a :class:`~pymc_vcc.execution.store.LikelihoodStore` under a key digesting its
particle,
its node and its random stream, with its log-likelihood term and failure status (not its
outputs). A run resumed after a crash takes those from the file instead of simulating them again
(``resumed_simulations``) and gives the uninterrupted run's posterior, bit for bit; a run with
other settings (draws, prior, observed data, ε, simulator, seed...) is refused, naming them.

Why one chain by default (:func:`sample_smc_abc`): an SMC stage already offers ``draws``
independent simulations to run in parallel, so one chain keeps every worker busy; each extra
chain is a whole second SMC run (as many simulations again) that improves the posterior less
than doubling ``draws`` would. PyMC's own parallel chains run in daemonic processes, which
cannot start worker processes of their own, so a kernel sent to them simulates serially.
Run several chains (for convergence diagnostics) one after another with ``cores=1``: each
uses the whole executor.
"""

from __future__ import annotations

import hashlib
import logging
import time
import warnings
import weakref
from collections import Counter
from collections.abc import Callable
from contextlib import closing
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pymc as pm
from pymc.blocking import DictToArrayBijection
from pymc.distributions.simulator import SimulatorRV
from pymc.model import Model, modelcontext
from pymc.pytensorf import floatX
from pymc.smc.kernels import IMH, MH, Pearson
from xarray import DataTree

from pymc_vcc.execution.executors import (
    Executor,
    ExecutorKind,
    ProcessExecutor,
    SerialExecutor,
)
from pymc_vcc.execution.options import RunOptions
from pymc_vcc.execution.outcomes import OK
from pymc_vcc.execution.store import LikelihoodRecord, LikelihoodStore, describe_callable
from pymc_vcc.inference.pymc.batch import BatchLikelihood, graph_digest, python_ops_quiet
from pymc_vcc.inference.pymc.layout import standard_layout
from pymc_vcc.inference.pymc.model import DistanceKernel, SimulatorFunction
from pymc_vcc.inference.pymc.reference import GaussianReference
from pymc_vcc.inference.samplers import SMC_KERNELS, SmcKernel

logger = logging.getLogger(__name__)

_MAX_REASONS = 5


def _simulation_key(point: np.ndarray, node: int, seed: np.random.SeedSequence) -> str:
    """Checkpoint key of one simulation: digest of the particle, the node and the random stream."""
    digest = hashlib.sha256(np.ascontiguousarray(point, dtype=float).tobytes())
    digest.update(f"{node}|{seed.entropy}|{tuple(seed.spawn_key)}".encode())
    return digest.hexdigest()


def check_max_steps(max_steps: int | None, name: str = "max_steps") -> int | None:
    """``max_steps`` if it is None or a positive integer, else ValueError naming it ``name``."""
    if max_steps is not None and (
        isinstance(max_steps, bool) or int(max_steps) != max_steps or max_steps < 1
    ):
        raise ValueError(f"{name} must be a positive integer or None, got {max_steps!r}")
    return max_steps


_BATCH_STATS: dict[str, tuple[type, list]] = {
    "simulations": (int, []),
    "failed_simulations": (int, []),
    "resumed_simulations": (int, []),
    "stage_seconds": (float, []),
    "ess": (float, []),
}
"""Per-stage statistics both parallel kernels add to the stock kernel's."""


def check_kernel(kernel: str, name: str = "kernel") -> str:
    """``kernel`` if it names one of :data:`KERNELS`, else ValueError naming it ``name``."""
    if kernel not in KERNELS:
        raise ValueError(f"{name} must be one of {list(KERNELS)}, got {kernel!r}")
    return kernel


class ParallelKernel:
    """What :class:`ParallelIMH` and :class:`ParallelMH` share: the simulations of all
    particles of a mutation step run as one batch through an executor, checkpointed, their
    failures counted; and the stock kernels' mutation loop around it (a subclass supplies the
    proposal). Mixed in before a stock PyMC SMC kernel.

    Args:
        executor: where simulations run, an executor of :mod:`pymc_vcc.execution.executors`
            (the caller opens and closes it); None: local worker processes on every core
            (``make_executor("processes")``), opened at the first simulation, kept for every
            chain of the run and closed with the kernel (when ``pm.sample_smc`` returns).
        checkpoint: an open :class:`~pymc_vcc.execution.store.LikelihoodStore` (the caller opens
            and closes it, fingerprinting the run: :func:`sample_smc_abc` does): each finished
            simulation is persisted there, and one already there is not run again.
        correlation_threshold: as for the stock kernel.
        max_steps: at most this many mutation steps per stage (default: PyMC's rule alone,
            stepping until the particles' correlation with the stage's start stops falling,
            which in many dimensions with low acceptance takes dozens of steps).
        max_simulations: a chain's simulation budget (default: none). A stage's mutation
            steps after its first stop where another would leave less than one step for each
            stage still to come, those estimated from the last stage's growth of β (a soft
            cap: every stage still makes one step).
        reference: temper from this Gaussian mixture over the value space instead of the prior
            (:mod:`pymc_vcc.inference.pymc.laplace`): the initial particles are its draws, and
            the tempering term is prior + likelihood − reference, so that β = 1 is still the
            posterior.
        **kwargs: the stock kernel's arguments (``draws``, ``model``, ``threshold``, ...).
    """

    def __init__(
        self,
        *args,
        executor: Executor | None = None,
        checkpoint: LikelihoodStore | None = None,
        correlation_threshold=0.01,
        max_steps: int | None = None,
        max_simulations: int | None = None,
        reference: GaussianReference | None = None,
        **kwargs,
    ) -> None:
        self.max_steps = check_max_steps(max_steps)
        self.max_simulations = check_max_steps(max_simulations, "max_simulations")
        self.reference = reference
        compile_kwargs = dict(kwargs.get("compile_kwargs") or {})
        super().__init__(*args, correlation_threshold=correlation_threshold, **kwargs)
        if executor is not None and not isinstance(executor, Executor):
            raise TypeError(
                "executor must be a pymc_vcc.execution.executors.Executor "
                f"(make_executor(...)) or None, "
                f"got {type(executor).__name__}; sample_smc_abc also accepts a kind name"
            )
        self.executor = executor
        self.checkpoint = checkpoint
        self._finished: dict[str, LikelihoodRecord] = {}
        self._likelihood = BatchLikelihood(
            modelcontext(kwargs.get("model")), self.variables, compile_kwargs
        )
        self._seeds = np.random.SeedSequence()
        self._reset_counters()

    def _reset_counters(self) -> None:
        """Zero the counts of a stage and the failure record (over every chain this kernel
        runs)."""
        self._reset_stage_counters()
        self.failure_kinds: Counter[str] = Counter()
        self.failure_reasons: list[str] = []

    def _reset_stage_counters(self) -> None:
        self._stage_simulations = 0
        self._stage_failures = 0
        self._stage_resumed = 0
        self._stage_start = time.perf_counter()

    def __getstate__(self) -> dict:
        if self.checkpoint is not None:
            raise ValueError(
                f"a {type(self).__name__} kernel with a checkpoint cannot run in another "
                "process; pass cores=1 to pm.sample_smc (or use "
                "pymc_vcc.inference.pymc.smc.sample_smc_abc)"
            )
        state = self.__dict__.copy()
        if self.executor is not None and not isinstance(self.executor, SerialExecutor):
            warnings.warn(
                "pm.sample_smc runs chains in separate (daemonic) processes here (cores > 1 and "
                "chains > 1); they cannot use the executor, so each chain simulates its "
                "particles one after another. Pass cores=1 (chains then run one after another, "
                "each using the executor) or use pymc_vcc.inference.pymc.smc.sample_smc_abc.",
                RuntimeWarning,
                stacklevel=2,
            )
        state["executor"] = SerialExecutor()
        return state

    def initialize(self, start: dict | None, rng: np.random.Generator) -> None:
        # Simulation streams are children of the chain's seed: they neither consume nor shift
        # the chain generator that drives proposals and resampling.
        self._seeds = rng.bit_generator.seed_seq.spawn(1)[0]
        self._reset_stage_counters()
        self._spent = 0  # the chain's simulations, run or resumed, against max_simulations
        self._previous_beta = 0.0
        self._finished = self.checkpoint.load() if self.checkpoint is not None else {}
        super().initialize(start, rng)

    def _workers(self) -> Executor:
        """The executor simulating: the caller's, else a pool on every core, opened now and
        closed when this kernel is gone."""
        if self.executor is None:
            self.executor = ProcessExecutor()
            weakref.finalize(self, self.executor.close)
        return self.executor

    def _simulated_loglik(self, points: np.ndarray, prior_logp: np.ndarray) -> np.ndarray:
        """Log-likelihood of points, simulating (in one batch) only those the prior allows and
        the checkpoint does not hold yet."""
        loglik = np.full(len(points), -np.inf)
        allowed = np.flatnonzero(np.isfinite(prior_logp))
        if allowed.size == 0:
            return loglik
        batch = points[allowed]
        seeds = self._seeds.spawn(len(batch) * self._likelihood.n_nodes)
        tasks = self._likelihood.tasks(batch, seeds)
        keys = [
            _simulation_key(batch[number % len(batch)], task[0], task[1])
            for number, task in enumerate(tasks)
        ]
        records: list[LikelihoodRecord | None] = [self._finished.get(key) for key in keys]
        todo = [number for number, record in enumerate(records) if record is None]
        with closing(self._likelihood.run(self._workers(), [tasks[n] for n in todo])) as chunks:
            for chunk in chunks:
                finished = []
                for position, outcome in chunk:
                    number = todo[position]
                    point = batch[number % len(batch)]
                    term = self._likelihood.term(tasks[number][0], point, outcome)
                    finished.append(
                        LikelihoodRecord(
                            keys[number], term, outcome.status, outcome.reason, outcome.elapsed
                        )
                    )
                    records[number] = finished[-1]
                if self.checkpoint is not None:
                    self.checkpoint.append(finished)
                    self._finished.update((record.key, record) for record in finished)
        for record in records:
            if record.status != OK:
                self.failure_kinds[str(record.status)] += 1
                if len(self.failure_reasons) < _MAX_REASONS:
                    self.failure_reasons.append(f"{record.status}: {record.reason}")
        failures = sum(record.status != OK for record in records)
        resumed = len(tasks) - len(todo)
        self._stage_simulations += len(todo)
        self._spent += len(tasks)
        self._stage_resumed += resumed
        self._stage_failures += failures
        loglik[allowed] = self._likelihood.evaluate(
            batch,
            np.array([record.loglik for record in records]),
            np.array([record.status == OK for record in records]),
        )
        return loglik

    def _tempering_terms(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The two terms of the tempered target ``base + β · increment`` at ``points``: the
        prior and the simulated log-likelihood, or with a :attr:`reference` its log density and
        prior + likelihood − reference."""
        prior_logp = np.array([self.prior_logp_func(point) for point in points]).reshape(-1)
        loglik = self._simulated_loglik(points, prior_logp)
        if self.reference is None:
            return prior_logp, loglik
        base = self.reference.logpdf(points)
        return base, prior_logp + loglik - base

    def _initialize_kernel(self) -> None:
        """Initial particles (draws of the prior or of the reference, or ``start``) with the
        terms of their tempered target."""
        if self.reference is not None and not self.start:
            particles = self.reference.sample(self.draws, self.rng)
        else:
            population = self.start or self.initialize_population()
            particles = [
                DictToArrayBijection.map(
                    {v.name: population[v.name][i] for v in self.variables}
                ).data
                for i in range(self.draws)
            ]
        self.tempered_posterior = np.array(floatX(particles))
        self.prior_logp, self.likelihood_logp = self._tempering_terms(self.tempered_posterior)
        if not np.isfinite(self.likelihood_logp).any():
            raise RuntimeError(
                f"all {self.draws} simulations of the initial population failed or have zero "
                f"likelihood; failures: {dict(self.failure_kinds)}, e.g. "
                f"{self.failure_reasons[:2]}. Check the simulator, the prior bounds and epsilon."
            )

    def _propose(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One proposal per particle, with the log densities of proposing it from its particle
        (forward) and the particle from it (backward); zeros for a symmetric proposal."""
        raise NotImplementedError

    def _record_acceptance(self, accepted_steps: np.ndarray) -> None:
        """Keep the stage's acceptance (``accepted_steps``: steps × particles) as the stock
        kernel does."""
        raise NotImplementedError

    def mutate(self) -> None:
        """The stock kernel's Metropolis–Hastings moves, each step's proposals simulated as one
        batch, at most ``max_steps`` steps."""
        self.n_steps = 1
        old_correlation = 2
        correlation = Pearson(self.tempered_posterior)
        accepted_steps = []
        while True:
            log_uniform = np.log(self.rng.random(self.draws))
            proposal, forward_logp, backward_logp = self._propose()
            prior_logp, loglik = self._tempering_terms(proposal)
            proposal_logp = prior_logp + loglik * self.beta
            accepted = log_uniform < (
                (proposal_logp + backward_logp) - (self.tempered_posterior_logp + forward_logp)
            )
            self.tempered_posterior[accepted] = proposal[accepted]
            self.tempered_posterior_logp[accepted] = proposal_logp[accepted]
            self.prior_logp[accepted] = prior_logp[accepted]
            self.likelihood_logp[accepted] = loglik[accepted]
            accepted_steps.append(accepted)
            self.n_steps += 1

            if self.max_steps is not None and len(accepted_steps) >= self.max_steps:
                break
            if not self._affords_step():
                break
            pearson_r = correlation.get(self.tempered_posterior)
            if np.mean((old_correlation - pearson_r) > self.correlation_threshold) > 0.9:
                old_correlation = pearson_r
            else:
                break
        self._record_acceptance(np.array(accepted_steps))

    def update_beta_and_weights(self) -> None:
        self._previous_beta = self.beta
        super().update_beta_and_weights()

    def _affords_step(self) -> bool:
        """Whether another mutation step leaves one step for each stage to come within
        :attr:`max_simulations` (always, without a budget)."""
        if self.max_simulations is None:
            return True
        to_come = 0
        if 0 < self._previous_beta < self.beta < 1:
            growth = np.log(self.beta / self._previous_beta)
            to_come = int(np.ceil(-np.log(self.beta) / growth))
        step = self.draws * self._likelihood.n_nodes
        return self._spent + step * (1 + to_come) <= self.max_simulations

    def sample_stats(self) -> dict[str, int | float]:
        now = time.perf_counter()
        stats = {
            **super().sample_stats(),
            "simulations": self._stage_simulations,
            "failed_simulations": self._stage_failures,
            "resumed_simulations": self._stage_resumed,
            "stage_seconds": now - self._stage_start,
            "ess": float(1.0 / np.sum(self.weights**2)),
        }
        self._stage_simulations = 0
        self._stage_failures = 0
        self._stage_resumed = 0
        self._stage_start = now
        return stats

    def _data_loglik(self) -> np.ndarray:
        """The particles' log-likelihoods (the tempering increment less the reference's part)."""
        if self.reference is None:
            return self.likelihood_logp
        prior_logp = np.array([self.prior_logp_func(p) for p in self.tempered_posterior])
        return self.likelihood_logp + self.prior_logp - prior_logp.reshape(-1)

    def sample_settings(self) -> dict[str, int | float | str]:
        return {
            **super().sample_settings(),
            "kernel": next(name for name, kind in KERNELS.items() if isinstance(self, kind)),
            "failure_kinds": ", ".join(f"{k}: {n}" for k, n in sorted(self.failure_kinds.items())),
            "failure_examples": " | ".join(self.failure_reasons),
            "median_log_likelihood": float(np.median(self._data_loglik())),
            "max_steps": self.max_steps or 0,  # 0: no cap
            "max_simulations": self.max_simulations or 0,
            "tempered_from": "prior" if self.reference is None else "reference",
            "executor": repr(self.executor),
        }


class ParallelIMH(ParallelKernel, IMH):
    """PyMC's independent Metropolis–Hastings SMC kernel (proposals from a Gaussian fitted to
    the particles) with the simulations of all particles run as one parallel batch.

    Use it as ``pm.sample_smc(kernel=ParallelIMH, chains=1, ...)`` on a model with
    ``pm.Simulator`` nodes (e.g. from :func:`pymc_vcc.inference.pymc.model.add_simulator`):
    without ``executor=`` its simulations run on every core; ``standard_layout(result, model)``
    (:func:`~pymc_vcc.inference.pymc.layout.standard_layout`) gives the result the layout of
    :func:`sample_smc_abc`, which runs it with defaults suited to expensive simulators. Its
    arguments are those of :class:`ParallelKernel`.
    """

    stats_dtypes_shapes: ClassVar[dict[str, tuple[type, list]]] = {
        **IMH.stats_dtypes_shapes,
        **_BATCH_STATS,
    }

    def _propose(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        proposal = floatX(self.proposal_dist.rvs(size=self.draws, random_state=self.rng))
        proposal = proposal.reshape(len(proposal), -1)
        forward_logp = self.proposal_dist.logpdf(proposal)
        backward_logp = self.proposal_dist.logpdf(self.tempered_posterior)
        return proposal, forward_logp, backward_logp

    def _record_acceptance(self, accepted_steps: np.ndarray) -> None:
        self.acc_rate = np.mean(accepted_steps)


class ParallelMH(ParallelKernel, MH):
    """PyMC's random-walk Metropolis–Hastings SMC kernel (Gaussian steps with the particles'
    covariance, each particle's scale tuned towards 23.4 % acceptance) with the simulations
    of all particles run as one parallel batch; arguments as :class:`ParallelIMH`'s.

    Its local steps suit posteriors far from Gaussian (curved), where independent proposals
    from the particles' Gaussian land in the tails; they explore more slowly where it is not.
    """

    stats_dtypes_shapes: ClassVar[dict[str, tuple[type, list]]] = {
        **MH.stats_dtypes_shapes,
        **_BATCH_STATS,
    }

    def _propose(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        steps = self.proposal_dist(num_draws=self.draws, rng=self.rng)
        proposal = floatX(self.tempered_posterior + steps * self.proposal_scales[:, None])
        return proposal, np.zeros(self.draws), np.zeros(self.draws)

    def _record_acceptance(self, accepted_steps: np.ndarray) -> None:
        self.chain_acc_rate = np.mean(accepted_steps, axis=0)


KERNELS: dict[str, type[ParallelKernel]] = dict(
    zip(SMC_KERNELS, (ParallelIMH, ParallelMH), strict=True)
)
"""The parallel kernel of each name in :data:`~pymc_vcc.inference.samplers.SMC_KERNELS`."""


def _describe(function: Callable[..., Any]) -> str:
    """What a checkpoint records of a node's simulator (see :func:`describe_callable`)."""
    return describe_callable(
        function.simulator if isinstance(function, SimulatorFunction) else function
    )


def _run_settings(
    model: Model,
    draws: int,
    chains: int,
    threshold: float,
    correlation: float,
    max_steps: int | None,
    max_simulations: int | None,
    kernel: str,
    reference: GaussianReference | None,
) -> dict[str, Any]:
    """What a resumed run must share with the checkpointed one (besides the seed)."""
    nodes = [rv for rv in model.observed_RVs if isinstance(rv.owner.op, SimulatorRV)]
    # step and simulation caps and a kernel other than IMH are named only when set, so runs
    # checkpointed before they existed still resume
    capped = {} if max_steps is None else {"max_steps": int(max_steps)}
    if max_simulations is not None:
        capped["max_simulations"] = int(max_simulations)
    other_kernel = {} if kernel == "imh" else {"kernel": kernel}
    start = {} if reference is None else {"reference": reference.digest()}
    return {
        **capped,
        **other_kernel,
        **start,
        "sampler": "smc_abc",
        "draws": int(draws),
        "chains": int(chains),
        "threshold": float(threshold),
        "correlation_threshold": float(correlation),
        "parameters": [rv.name for rv in model.free_RVs],
        "prior_digest": graph_digest(model.free_RVs),
        "observed_digest": graph_digest([model.rvs_to_values[rv] for rv in model.observed_RVs]),
        "epsilon": [
            float(getattr(rv.owner.op.epsilon, "data", rv.owner.op.epsilon)) for rv in nodes
        ],
        "simulator": [_describe(type(rv.owner.op).fn) for rv in nodes],
        "likelihood_digest": graph_digest(model.observed_RVs + model.potentials),
    }


def sample_smc_abc(
    draws: int = 500,
    *,
    executor: Executor | ExecutorKind = "processes",
    n_workers: int | None = None,
    chains: int = 1,
    random_seed: Any = None,
    checkpoint: str | Path | None = None,
    model: Model | None = None,
    threshold: float = 0.5,
    correlation_threshold: float = 0.01,
    max_steps: int | None = None,
    max_simulations: int | None = None,
    kernel: SmcKernel = "imh",
    reference: GaussianReference | None = None,
    progressbar: bool = True,
    **kwargs: Any,
) -> DataTree:
    """SMC-ABC of the current model with :class:`ParallelIMH` (or :class:`ParallelMH`) and
    defaults for costly simulators.

    Its executor, workers and checkpoint are keywords of their own, as ``pm.sample_smc``'s
    are, not a :class:`~pymc_vcc.execution.options.RunOptions`: the seed and the progress bar
    keep PyMC's names (``random_seed``, ``progressbar``), each simulator node carries its own
    time limit (``add_simulator(time_limit_s=...)``), and a failed simulation is a zero
    likelihood, not a failure rate to stop at.

    Args:
        draws: particles per stage (and posterior draws per chain). A run costs about
            draws × (1 + mutation steps over all stages) simulations, typically 10–40 × draws
            (PyMC's default of 2000 is sized for cheap likelihoods).
        executor: an open executor (left open), or a kind (``"serial"``, ``"processes"``,
            ``"dask"`` for a new local cluster) opened for this call and closed after.
        n_workers: workers of an executor opened here (default: every core).
        chains: independent SMC runs, one after another, each using the whole executor
            (default 1: see the module docstring for why).
        random_seed: seeds everything (proposals, resampling and every simulation); an
            integer (or None) with a checkpoint.
        checkpoint: SQLite file persisting each finished simulation's log-likelihood term; a
            run started again with the same arguments (and seed) resumes there and runs no
            finished simulation again. A run with other settings is refused
            (:class:`~pymc_vcc.execution.store.CheckpointMismatchError` naming them). Without
            ``random_seed``, the seed is drawn once and kept in the checkpoint.
        model: the PyMC model (default: the current context).
        threshold, correlation_threshold: as for ``pm.sample_smc``'s IMH kernel.
        max_steps: at most this many mutation steps per stage (see :class:`ParallelIMH`).
        max_simulations: each chain's simulation budget, a soft cap on its mutation steps
            (see :class:`ParallelKernel`).
        kernel: the mutation kernel, a name of :data:`KERNELS`: ``"imh"`` (independent
            proposals, PyMC's default) or ``"mh"`` (random-walk steps).
        reference: temper from this Gaussian mixture instead of the prior (see
            :class:`ParallelKernel`; :func:`~pymc_vcc.inference.pymc.laplace.fit_reference`
            makes one for an exact likelihood, ``GaussianReference.of_mixture`` one of a
            broader mixture prior); it must span the model's value space.
        progressbar: show PyMC's progress bar.
        **kwargs: other ``pm.sample_smc`` arguments (``start``, ``idata_kwargs``, ...).

    Returns:
        The DataTree of ``pm.sample_smc`` in the layout of
        :func:`~pymc_vcc.inference.pymc.layout.standard_layout`: ``posterior``,
        ``sample_stats`` over ``(chain, stage)`` (simulation counts and ESS per stage) with the
        run summary (``n_simulations``, ``n_failed`` and ``n_resumed`` over all chains,
        ``n_stages`` per chain, ``epsilon`` per simulator node, ``min_stage_ess``),
        ``observed_data`` with one variable per output. Warns (RuntimeWarning) when draws are
        fewer than the parameters, a stage's ESS falls below 30 or the final distances sit far
        above ε.
    """
    if int(chains) != chains or chains < 1:
        raise ValueError(f"chains must be a positive integer, got {chains}")
    if int(draws) != draws or draws < 2:
        raise ValueError(f"draws must be an integer >= 2, got {draws}")
    check_max_steps(max_steps)
    check_max_steps(max_simulations, "max_simulations")
    check_kernel(kernel)
    kwargs.setdefault("compute_convergence_checks", chains > 1)
    model = modelcontext(model)
    n_parameters = sum(model.initial_point()[v.name].size for v in model.value_vars)
    if reference is not None and reference.means.shape[1] != n_parameters:
        raise ValueError(
            f"reference over {reference.means.shape[1]} values; the model's value space has "
            f"{n_parameters}"
        )
    store = None
    if checkpoint is not None:
        if random_seed is not None and (
            isinstance(random_seed, bool)
            or not isinstance(random_seed, int | np.integer)
            or random_seed < 0
        ):
            raise ValueError(
                f"random_seed must be a non-negative integer or None with a checkpoint, got "
                f"{random_seed!r}"
            )
        settings = _run_settings(
            model,
            draws,
            chains,
            threshold,
            correlation_threshold,
            max_steps,
            max_simulations,
            kernel,
            reference,
        )
        store = LikelihoodStore(checkpoint, settings, random_seed)
        random_seed = store.entropy
    if draws < n_parameters:
        warnings.warn(
            f"draws={draws} particles for {n_parameters} parameters: a population smaller than "
            "the parameter count collapses onto a few points and reports a falsely narrow "
            f"posterior; use draws >= {10 * n_parameters}",
            RuntimeWarning,
            stacklevel=2,
        )
    try:
        opening = RunOptions(executor=executor, n_workers=n_workers).open_executor()
        with opening as opened, python_ops_quiet():
            tree = pm.sample_smc(
                draws=int(draws),
                kernel=KERNELS[kernel],
                chains=int(chains),
                cores=1,
                random_seed=random_seed,
                model=model,
                progressbar=progressbar,
                executor=opened,
                checkpoint=store,
                threshold=threshold,
                correlation_threshold=correlation_threshold,
                max_steps=max_steps,
                max_simulations=max_simulations,
                reference=reference,
                **kwargs,
            )
        return _with_run_summary(standard_layout(tree, model), model)
    finally:
        if store is not None:
            store.close()


MIN_ESS = 30
"""Effective sample size below which a stage's particles are too few to trust."""

MAX_DISTANCE_RATIO = 3.0
"""Median final distance over ε above which the ABC kernel is too narrow for the simulator."""


class PosteriorQualityWarning(RuntimeWarning):
    """An SMC posterior that rests on too few distinct particles, or whose final distances sit
    far above ε (filter this category to silence a run whose posterior is only a scout)."""


def _per_chain(values: np.ndarray) -> list[np.ndarray]:
    """A ``(chain, stage)`` statistic of the standard layout as one array of stages per chain
    (the padding after a chain's last stage dropped)."""
    return [row[np.isfinite(row)] for row in np.atleast_2d(np.asarray(values, dtype=float))]


def _with_run_summary(tree: DataTree, model: Model) -> DataTree:
    """Record ε, stages and simulations (run and resumed) over all chains in ``sample_stats``
    of the standard layout; warn on the
    signs of an untrustworthy posterior (stage ESS below :data:`MIN_ESS`, final distances far
    above ε)."""
    stats = tree["sample_stats"].to_dataset()
    per_chain = _per_chain(stats["simulations"].values)
    ess = np.concatenate(_per_chain(stats["ess"].values))
    nodes = [rv for rv in model.observed_RVs if isinstance(rv.owner.op, SimulatorRV)]
    epsilon = [float(getattr(rv.owner.op.epsilon, "data", rv.owner.op.epsilon)) for rv in nodes]
    summary = {
        "n_stages": ("chain", [row.size for row in per_chain]),
        "epsilon": ("simulator_node", epsilon),
        "min_stage_ess": ((), float(ess.min()) if ess.size else np.nan),
    }
    stats = stats.assign(summary).assign_coords(simulator_node=[rv.name for rv in nodes])
    tree["sample_stats"] = stats
    if ess.size and ess.min() < MIN_ESS:
        warnings.warn(
            f"an SMC stage's effective sample size fell to {ess.min():.0f} (< {MIN_ESS}): the "
            "posterior rests on too few distinct particles; raise draws",
            PosteriorQualityWarning,
            stacklevel=3,
        )
    if nodes and all(isinstance(rv.owner.op._distance, DistanceKernel) for rv in nodes):
        median = np.median(np.asarray(stats.attrs.get("median_log_likelihood", np.nan)))
        ratio = float(np.sqrt(max(-2.0 * median, 0.0)))
        if ratio > MAX_DISTANCE_RATIO:
            warnings.warn(
                f"the final particles' distances sit about {ratio:.1f} ε above ε = {epsilon}: "
                "the simulations cannot come as close to the data as ε asks (noisy data "
                "compared with noise-free simulations?); add sensor_noise or raise epsilon",
                PosteriorQualityWarning,
                stacklevel=3,
            )
    return tree


__all__ = [
    "KERNELS",
    "ParallelIMH",
    "ParallelKernel",
    "ParallelMH",
    "PosteriorQualityWarning",
    "sample_smc_abc",
]
