"""A model's likelihood with its ``pm.Simulator`` nodes simulated in batches outside PyTensor.

What the parallel SMC kernels (:mod:`pymc_vcc.inference.pymc.smc`) and the least-squares fit of
their start (:mod:`pymc_vcc.inference.pymc.laplace`) share: :class:`BatchLikelihood` turns
points of a model's value space into one simulation task per node and point, runs them through
an executor of :mod:`pymc_vcc.execution.executors` (each with its own random stream, a crashed
worker's task an outcome like any other failure), and sums the log-likelihood terms of their
outputs; :func:`graph_digest` names the graphs a checkpoint or a saved fit was made with.
"""

from __future__ import annotations

import hashlib
import time
import warnings
from collections.abc import Callable, Generator, Iterator, Sequence
from contextlib import contextmanager
from functools import partial
from typing import Any

import numpy as np
import pytensor.tensor as pt
from pymc.distributions.simulator import SimulatorRV
from pymc.model import Model
from pymc.pytensorf import compile as compile_pytensor
from pymc.pytensorf import join_nonshared_inputs, make_shared_replacements
from pytensor.graph.basic import Constant
from pytensor.graph.traversal import ancestors
from pytensor.tensor.type_other import NoneTypeT

from pymc_vcc.execution.executors import Executor, WorkerCrash
from pymc_vcc.execution.outcomes import OK, SimulationOutcome, crash_outcome
from pymc_vcc.inference.pymc.model import SimulatorFunction
from pymc_vcc.physics.failures import FailureKind


@contextmanager
def python_ops_quiet() -> Iterator[None]:
    """Silence PyTensor's warning that Numba runs a Python Op in object mode: the simulator
    and likelihood Ops are Python by design (the simulations run outside PyTensor)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "Numba will use object mode", UserWarning)
        yield


def _generic_outcome(function: Callable[..., Any], rng, params, size) -> SimulationOutcome:
    """Run a ``pm.Simulator`` random function, capturing exceptions and non-finite outputs."""
    start = time.perf_counter()
    try:
        values = np.asarray(function(rng, *params, size), dtype=float)
    except Exception as exc:
        reason = f"{type(exc).__name__}: {exc}"
        return SimulationOutcome.failed(FailureKind.EXCEPTION, reason, time.perf_counter() - start)
    elapsed = time.perf_counter() - start
    if not np.isfinite(values).all():
        count = int((~np.isfinite(values)).sum())
        return SimulationOutcome.failed(
            FailureKind.NON_FINITE, f"{count} non-finite value(s)", elapsed
        )
    return SimulationOutcome(values, OK, "", elapsed)


def simulate_task(functions: Sequence[Callable[..., Any]], task: tuple) -> SimulationOutcome:
    """Worker side: one simulation of one ``pm.Simulator`` node, with its own random stream."""
    node, seed, size, params = task
    function = functions[node]
    rng = np.random.default_rng(seed)
    if isinstance(function, SimulatorFunction):
        return function.outcome(rng, *params)
    return _generic_outcome(function, rng, params, None if size is None else tuple(size))


class BatchLikelihood:
    """The model's likelihood with its ``pm.Simulator`` nodes evaluated outside PyTensor.

    Compiles two functions of the flat particle vector (in the order of ``value_vars``): the
    random-function inputs (size and parameters) of every simulator node, and the total
    log-likelihood given the simulated outputs of every node (distance kernels, plus the
    log-probability of any other observed variable and of potentials).
    """

    def __init__(self, model: Model, value_vars: list, compile_kwargs: dict | None) -> None:
        nodes = [rv for rv in model.observed_RVs if isinstance(rv.owner.op, SimulatorRV)]
        if not nodes:
            raise ValueError(
                "the model has no pm.Simulator node; the parallel kernels batch simulations only "
                "(use pm.sample_smc's default kernel for models with ordinary likelihoods)"
            )
        others = [rv for rv in model.observed_RVs if rv not in nodes]
        self.functions = tuple(type(rv.owner.op).fn for rv in nodes)
        self.n_nodes = len(nodes)
        limits = [getattr(fn, "time_limit_s", None) for fn in self.functions]
        self.time_limit = max((limit for limit in limits if limit is not None), default=None)

        node_inputs: list = []
        self._slices = []
        for rv in nodes:
            size = rv.owner.op.size_param(rv.owner)
            if size is None or isinstance(size.type, NoneTypeT):
                size = pt.constant(np.zeros(0, dtype="int64"))  # no size: an empty vector
            params = list(rv.owner.op.dist_params(rv.owner))
            first = len(node_inputs)
            node_inputs += [size, *params]
            self._slices.append(slice(first, len(node_inputs)))
        node_inputs = model.replace_rvs_by_values(node_inputs)

        terms = []
        for rv in nodes:
            op = rv.owner.op
            observed = model.rvs_to_values[rv]
            placeholder = rv.type()
            term = pt.sum(op.distance(op.epsilon, op.sum_stat(observed), op.sum_stat(placeholder)))
            terms.append((term, placeholder))
        other_terms = model.logp(vars=others) if others else pt.constant(0.0)
        rest = other_terms + model.potentiallogp

        point = model.initial_point()
        shared = make_shared_replacements(point, value_vars, model)
        outputs, flat = join_nonshared_inputs(
            point, [rest, *(term for term, _ in terms), *node_inputs], value_vars, shared
        )
        kwargs = {**(compile_kwargs or {}), "on_unused_input": "ignore"}
        self._rest = compile_pytensor([flat], outputs[0], **kwargs)
        self._terms = [
            compile_pytensor([flat, placeholder], outputs[1 + node], **kwargs)
            for node, (_, placeholder) in enumerate(terms)
        ]
        self._inputs = compile_pytensor([flat], outputs[1 + self.n_nodes :], **kwargs)
        for function in (self._rest, *self._terms, self._inputs):
            function.trust_input = True
        self._dtypes = [rv.type.dtype for rv in nodes]

    def tasks(self, points: np.ndarray, seeds: Sequence[np.random.SeedSequence]) -> list[tuple]:
        """One task (node, seed, size, params) per node and point, node-major."""
        inputs = [self._inputs(point) for point in points]
        tasks = []
        for node, where in enumerate(self._slices):
            for index, values in enumerate(inputs):
                size, *params = values[where]
                seed = seeds[node * len(points) + index]
                tasks.append((node, seed, None if size.size == 0 else size, params))
        return tasks

    def run(
        self, executor: Executor, tasks: Sequence[tuple]
    ) -> Generator[list[tuple[int, SimulationOutcome]], None, None]:
        """Run ``tasks`` through ``executor``; yield each finished chunk as ``(position,
        outcome)`` pairs, a task whose worker died (or was stopped for its time limit) as its
        failed outcome."""
        chunks = executor.imap_chunks(
            partial(simulate_task, self.functions), tasks, time_limit=self.time_limit
        )
        try:
            for chunk in chunks:
                yield [
                    (position, crash_outcome(result) if isinstance(result, WorkerCrash) else result)
                    for position, result in chunk
                ]
        finally:
            chunks.close()

    def term(self, node: int, point: np.ndarray, outcome: SimulationOutcome) -> float:
        """The log-likelihood term of one simulation of ``node`` at ``point``; NaN if failed."""
        if not outcome.ok:
            return np.nan
        values = np.asarray(outcome.values, dtype=self._dtypes[node])
        return float(self._terms[node](point, values))

    def evaluate(self, points: np.ndarray, terms: np.ndarray, ok: np.ndarray) -> np.ndarray:
        """Log-likelihood of each point from its nodes' terms (node-major, as the tasks); −inf
        where any simulation failed."""
        n = len(points)
        terms = terms.reshape(self.n_nodes, n)
        ok = ok.reshape(self.n_nodes, n).all(axis=0)
        loglik = np.full(n, -np.inf)
        for index in np.flatnonzero(ok):
            total = terms[0, index]
            for node in range(1, self.n_nodes):
                total = total + terms[node, index]
            loglik[index] = total + float(self._rest(points[index]))
        loglik[np.isnan(loglik)] = -np.inf
        return loglik


def graph_digest(variables: Sequence) -> str:
    """Digest of the graphs computing ``variables``: their operations and constants."""
    digest = hashlib.sha256()
    for variable in ancestors(variables):
        if isinstance(variable, Constant):
            data = np.asarray(variable.data)
            digest.update(str(data).encode() if data.dtype == object else data.tobytes())
        elif variable.owner is not None:
            digest.update(str(variable.owner.op).encode())
    return digest.hexdigest()


__all__ = ["BatchLikelihood", "graph_digest", "simulate_task"]
