"""A simulator as a node of a PyMC model: priors, output-noise scales and a ``pm.Simulator``.

:func:`add_simulator` puts any simulator ``simulator(theta, rng) -> outputs`` (the VCC model or
one of :mod:`pymc_vcc.testing`) into the current PyMC model:

* one PyMC variable per calibrated parameter, from a uniform box (by default the bounds of the
  unit description or of the simulator) or from a :class:`~pymc_vcc.inference.priors.GMMPrior` (a
  mixture
  of multivariate normals in the logit space of the bounds, see :func:`gmm_prior_variable`);
* optional output-noise scales ν (one per output, named ``nu_<output>``): the paper's learnable
  noise, Y ← Y + ν·|Y|·Z with Z ~ N(0, 1), drawn with the simulation's own random stream;
* a ``pm.Simulator`` whose pseudo-log-likelihood is the Gaussian kernel −½ (d/ε)² of the
  distance d between simulated and observed outputs (by default the paper's KS distance
  averaged over outputs); failed simulations give −inf (zero likelihood), never an error.

The node samples with the stock ``pm.sample_smc`` (one particle after another) and with
:class:`pymc_vcc.inference.pymc.smc.ParallelIMH`, which simulates all particles of a stage in one
parallel batch.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
import pymc as pm
import pytensor.tensor as pt
from pymc.distributions import simulator as pymc_simulator
from pymc.distributions.shape_utils import rv_size_is_none
from pymc.logprob.transforms import Transform
from pytensor.graph.basic import Apply, Variable
from pytensor.graph.op import Op
from pytensor.tensor.variable import TensorVariable

from pymc_vcc.execution.outcomes import SimulationOutcome
from pymc_vcc.inference.distances import BatchDistance, ks_distances
from pymc_vcc.inference.noise import (
    NOISE_PREFIX,
    SENSOR_PREFIX,
    OutputNoise,
    SensorNoise,
    add_output_noise,
    extended_prior,
    is_noise_parameter,
    noise_parameter,
    sensor_parameter,
    with_noise,
)
from pymc_vcc.inference.priors import Bounds, GMMPrior, Prior, UniformPrior, check_prior_support
from pymc_vcc.inference.series import ObservedData, OutputData, prepare_observed
from pymc_vcc.inference.simulator import Simulator, check_simulator, run_simulation


def gaussian_log_kernel(distance: np.ndarray | float, epsilon: float) -> np.ndarray:
    """ABC log-kernel −½ (d/ε)² of distances d (higher is closer); non-finite d gives −inf."""
    d = np.asarray(distance, dtype=float)
    return np.where(np.isfinite(d), -0.5 * (d / epsilon) ** 2, -np.inf)


class DistanceKernel(Op):
    """PyTensor op ``(epsilon, observed, simulated) -> [−½ (d/ε)²]`` for ``pm.Simulator``.

    ``d = distance(simulated[None], observed)[0]`` with a batch distance of
    :mod:`pymc_vcc.inference.distances` (default: KS averaged over outputs). A simulation with any
    non-finite value (a failed run) gives −inf, which both ``pm.sample_smc`` and
    :class:`pymc_vcc.inference.pymc.smc.ParallelIMH` treat as zero likelihood.
    """

    __props__ = ("distance",)

    def __init__(self, distance: BatchDistance = ks_distances) -> None:
        self.distance = distance

    def make_node(self, epsilon, observed, simulated) -> Apply:
        inputs = [pt.as_tensor_variable(value) for value in (epsilon, observed, simulated)]
        return Apply(self, inputs, [pt.dvector()])

    def perform(self, node, inputs, output_storage) -> None:
        epsilon, observed, simulated = inputs
        output_storage[0][0] = np.atleast_1d(self.log_kernel(float(epsilon), observed, simulated))

    def log_kernel(self, epsilon: float, observed: np.ndarray, simulated: np.ndarray) -> float:
        """The log-kernel of one simulation (n_outputs, m) against observed (n_outputs, n)."""
        simulated = np.asarray(simulated, dtype=float)
        if not np.isfinite(simulated).all():
            return -np.inf
        distance = self.distance(simulated[np.newaxis], np.asarray(observed, dtype=float))[0]
        return float(gaussian_log_kernel(distance, epsilon))


@dataclass(frozen=True)
class SimulatorFunction:
    """The random function of the ``pm.Simulator`` node: parameters in, noisy outputs out.

    Called by PyTensor as ``fn(rng, theta, [noise,] [sensor,] size)`` with ``theta`` the
    parameter vector in ``parameter_names`` order, ``noise`` the ν vector in ``noise_outputs``
    order and ``sensor`` the learnable sensor scales in ``observed.names`` order; returns the
    selected outputs (n_outputs, n_time), all NaN when the run failed.
    :meth:`outcome` gives the same result with the failure kind and reason.

    Attributes:
        simulator: ``simulator(theta, rng) -> Dataset | array``.
        parameter_names: names of the entries of ``theta``.
        observed: the validated observed data (selects and orders the outputs).
        noise_outputs: outputs with a noise scale, a subset of ``observed.names``.
        time_limit_s: wall-time limit of one run, s (None: none).
        sensor_noise: sensor noise added after the paper's noise (None: none).
        learn_sensor: whether the sensor scales come as an argument (learnable).
    """

    simulator: Simulator
    parameter_names: tuple[str, ...]
    observed: ObservedData
    noise_outputs: tuple[str, ...] = ()
    time_limit_s: float | None = None
    sensor_noise: OutputNoise | None = None
    learn_sensor: bool = False

    def __post_init__(self) -> None:
        if not self.parameter_names:
            raise ValueError("parameter_names is empty; name at least one parameter")
        unknown = [name for name in self.noise_outputs if name not in self.observed.names]
        if unknown:
            raise ValueError(
                f"noise_outputs {unknown} are not among the observed outputs "
                f"{list(self.observed.names)}"
            )

    def outcome(self, rng: np.random.Generator, theta, *scales) -> SimulationOutcome:
        """Run one simulation; failures are captured as in :func:`run_simulation`."""
        scales = list(scales)
        noise = scales.pop(0) if self.noise_outputs else None
        sensor = scales.pop(0) if self.learn_sensor else None
        values = np.asarray(theta, dtype=float).reshape(-1, len(self.parameter_names))[0]
        parameters = dict(zip(self.parameter_names, map(float, values), strict=True))
        result = run_simulation(
            self.simulator, parameters, rng, self.observed, time_limit_s=self.time_limit_s
        )
        if not result.ok:
            return result
        values = result.values
        if self.noise_outputs:
            relative = np.zeros(len(self.observed.names))
            given = np.asarray(noise, dtype=float).reshape(-1, len(self.noise_outputs))[0]
            for output, scale in zip(self.noise_outputs, given, strict=True):
                relative[self.observed.names.index(output)] = scale
            values = add_output_noise(values, relative, rng)
        if self.sensor_noise is not None:
            learned = None
            if self.learn_sensor:
                learned = np.asarray(sensor, dtype=float).reshape(-1, len(self.observed.names))[0]
            values = self.sensor_noise.sample(values, rng, learned)
        return replace(result, values=values)

    def __call__(self, rng: np.random.Generator, *args) -> np.ndarray:
        params = args[:-1]  # the last argument is PyTensor's ``size``, fixed by the observed
        result = self.outcome(rng, *params)
        if result.ok:
            return result.values
        return np.full(self.observed.values.shape, np.nan)


# --- GMM prior as a PyMC distribution -------------------------------------------------------


def _gmm_logp(value, weights, means, inverse_cholesky, log_det, lower, upper):
    """Log-density in physical space of the logit-space mixture (see :class:`GMMPrior`)."""
    width = upper - lower
    fraction = (value - lower) / width
    inside = pt.all(pt.and_(pt.gt(fraction, 0.0), pt.lt(fraction, 1.0)), axis=-1)
    safe = pt.switch(pt.and_(pt.gt(fraction, 0.0), pt.lt(fraction, 1.0)), fraction, 0.5)
    unbounded = pt.log(safe) - pt.log1p(-safe)
    centred = unbounded[..., None, :] - means  # (..., k, d)
    whitened = pt.sum(centred[..., None, :] * inverse_cholesky, axis=-1)  # (..., k, d)
    d = means.shape[-1]
    component = (
        pt.log(weights)
        - 0.5 * pt.sum(whitened**2, axis=-1)
        - 0.5 * (d * np.log(2 * np.pi) + log_det)
    )
    log_jacobian = -pt.sum(pt.log(width) + pt.log(safe) + pt.log1p(-safe), axis=-1)
    density = pt.logsumexp(component, axis=-1) + log_jacobian
    return pt.switch(inside, density, -np.inf)


def _gmm_support_point(rv, size, weights, means, inverse_cholesky, log_det, lower, upper):
    """A start inside the box: the mixture's mean in logit space, mapped to the bounds.

    (Not an ``initval``: SMC would start every particle there instead of drawing the prior.)
    """
    centre = lower + (upper - lower) * pt.sigmoid(pt.sum(weights[..., None] * means, axis=-2))
    if rv_size_is_none(size):
        return centre
    return pt.broadcast_to(centre, pt.concatenate([size, centre.shape[-1:]]))


@dataclass(frozen=True)
class _GMMRandom:
    """Random draws of a :class:`GMMPrior` in the form ``pm.CustomDist`` expects."""

    prior: GMMPrior

    def __call__(self, *params, rng: np.random.Generator, size) -> np.ndarray:
        shape = () if size is None else tuple(size)
        draws = self.prior.sample(int(np.prod(shape, dtype=int)), rng)
        return draws.reshape((*shape, self.prior.ndim))


class LogitBox(Transform):
    """Vector transform of a box [lower, upper]^d to R^d: u = log((x − lower) / (upper − x)).

    PyMC's own interval transform is univariate and refuses multivariate variables; this one
    sums its log-Jacobian over the vector, as a multivariate transform must.
    """

    name = "logit_box"
    ndim_supp = 1

    def __init__(self, lower: np.ndarray, upper: np.ndarray) -> None:
        self.lower = np.asarray(lower, dtype=float)
        self.upper = np.asarray(upper, dtype=float)

    def forward(self, value, *inputs):
        return pt.log(value - self.lower) - pt.log(self.upper - value)

    def backward(self, value, *inputs):
        return self.lower + (self.upper - self.lower) * pt.sigmoid(value)

    def log_jac_det(self, value, *inputs):
        width = np.log(self.upper - self.lower)
        return pt.sum(width - pt.softplus(-value) - pt.softplus(value), axis=-1)


def gmm_prior_variable(name: str, prior: GMMPrior, **kwargs) -> TensorVariable:
    """A vector PyMC variable distributed as ``prior`` (in its ``names`` order).

    Its log-density equals :meth:`GMMPrior.logpdf`; it is sampled in the logit space of the
    bounds (the :class:`LogitBox` transform), where the mixture is Gaussian. Must be called inside a
    model context; ``kwargs`` go to ``pm.CustomDist`` (e.g. ``dims``).

    Parameters
    ----------
    name
        Name of the PyMC variable.
    prior
        The mixture, e.g. fitted to a previous posterior (``GMMPrior.fit``); values in its
        parameters' units.
    """
    if not isinstance(prior, GMMPrior):
        raise TypeError(f"prior must be a GMMPrior, got {type(prior).__name__}")
    inverse_cholesky = np.linalg.inv(np.linalg.cholesky(prior.covariances))
    log_det = np.linalg.slogdet(prior.covariances)[1]
    return pm.CustomDist(
        name,
        prior.weights,
        prior.means,
        inverse_cholesky,
        log_det,
        prior.lower,
        prior.upper,
        logp=_gmm_logp,
        random=_GMMRandom(prior),
        support_point=_gmm_support_point,
        signature="(k),(k,d),(k,d,d),(k),(d),(d)->(d)",
        transform=LogitBox(prior.lower, prior.upper),
        **kwargs,
    )


def prior_variables(prior: Prior, *, joint_name: str = "theta") -> dict[str, TensorVariable]:
    """One PyMC variable per parameter of ``prior``, in the current model; name -> variable.

    A :class:`UniformPrior` gives independent ``pm.Uniform`` variables; a :class:`GMMPrior`
    gives one joint vector variable ``joint_name`` and a ``pm.Deterministic`` per parameter, so
    the posterior holds one variable per parameter name either way.
    """
    if isinstance(prior, UniformPrior):
        return {
            name: pm.Uniform(name, lower=low, upper=high)
            for name, (low, high) in prior.bounds.items()
        }
    if isinstance(prior, GMMPrior):
        joint = gmm_prior_variable(joint_name, prior)
        return {
            name: pm.Deterministic(name, joint[index]) for index, name in enumerate(prior.names)
        }
    raise TypeError(f"prior must be a UniformPrior or a GMMPrior, got {type(prior).__name__}")


def _known_bounds(simulator: Simulator) -> dict[str, tuple[float, float]]:
    """Every parameter bound the simulator knows (its ``bounds``; none if it has none)."""
    return check_simulator(simulator).bounds or {}


def simulator_bounds(
    simulator: Simulator, parameters: Sequence[str] | None = None
) -> dict[str, tuple[float, float]]:
    """Physical bounds of a simulator's parameters (its ``bounds``, see
    :class:`~pymc_vcc.inference.simulator.BoundedSimulator`).

    Args:
        simulator: a simulator with ``bounds`` (name -> (low, high)), as those of
            :mod:`pymc_vcc.testing` and :class:`pymc_vcc.physics.simulate.VCCSimulator` (its
            unit's parameter table) have.
        parameters: names to keep, in this order (default: the simulator's
            ``parameter_names`` if it has them, else all).
    """
    info = check_simulator(simulator)
    available = info.bounds or {}
    if not available:
        raise ValueError(
            f"{type(simulator).__name__} has neither `bounds` nor a unit description; "
            "pass prior= explicitly"
        )
    if parameters is None:
        parameters = info.parameter_names or list(available)
    if isinstance(parameters, str):
        raise TypeError(f"parameters must be a sequence of names, got the string {parameters!r}")
    unknown = [name for name in parameters if name not in available]
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown}; the simulator has {list(available)}")
    return {name: available[name] for name in parameters}


DISTANCES = ("ks", "gaussian", "laplace")
"""Distance names :func:`add_simulator` accepts: the paper's KS distance and PyMC's kernels."""

SUM_STATS = ("identity", "sort", "mean", "median")
"""PyMC's summary statistic names, with PyMC's meaning."""

PRIOR_CHECK_DRAWS = 2000
"""Prior draws of a user's PyMC variable checked against the bounds of its parameter."""


def _zero_likelihood_if_failed(log_kernel):
    """−inf (zero likelihood) where a failed run left NaN outputs, instead of NaN."""
    return pt.switch(pt.isnan(log_kernel), -np.inf, log_kernel)


def gaussian_kernel(epsilon, observed, simulated):
    """PyMC's ``"gaussian"`` distance −½ ((obs − sim)/ε)², elementwise; −inf for a failed run."""
    return _zero_likelihood_if_failed(pymc_simulator.gaussian(epsilon, observed, simulated))


def laplace_kernel(epsilon, observed, simulated):
    """PyMC's ``"laplace"`` distance −|obs − sim|/ε, elementwise; −inf for a failed run."""
    return _zero_likelihood_if_failed(pymc_simulator.laplace(epsilon, observed, simulated))


_PYMC_KERNELS = {"gaussian": gaussian_kernel, "laplace": laplace_kernel}


def _distance_op(
    distance: str | BatchDistance, sum_stat: str | Callable, observed: ObservedData
) -> tuple[Op | Callable, str | Callable]:
    """The ``distance`` and ``sum_stat`` to give ``pm.Simulator``, checked on ``observed``.

    ``"ks"`` and batch callables ``(sims (N, n_outputs, m), obs (n_outputs, n)) -> (N,)`` compare
    whole series, so only the order-free statistics ``identity`` and ``sort`` suit them; PyMC's
    ``"gaussian"`` and ``"laplace"`` take every ``sum_stat`` of PyMC.
    """
    if isinstance(distance, str):
        if distance not in DISTANCES:
            hint = " (PyMC does not implement it yet)" if distance == "kullback_leibler" else ""
            raise ValueError(
                f"distance {distance!r} is not available{hint}; use one of {list(DISTANCES)} "
                "or a batch distance (sims (N, n_outputs, m), obs (n_outputs, n)) -> (N,)"
            )
    elif not callable(distance):
        raise TypeError(f"distance must be a name or a callable, got {type(distance).__name__}")
    if isinstance(sum_stat, str) and sum_stat not in SUM_STATS:
        raise ValueError(
            f"sum_stat {sum_stat!r} is not available; use one of {list(SUM_STATS)} or a callable"
        )
    if distance in _PYMC_KERNELS:
        return _PYMC_KERNELS[distance], sum_stat
    if sum_stat not in ("identity", "sort"):
        raise ValueError(
            f"sum_stat {sum_stat!r} does not suit distance "
            f"{getattr(distance, '__name__', distance)!r}, which compares whole series; use "
            "'identity' or 'sort', or distance='gaussian' or 'laplace' with this statistic"
        )
    batch = ks_distances if distance == "ks" else distance
    _check_batch_distance(batch, observed)
    return DistanceKernel(batch), sum_stat


def _check_batch_distance(distance: BatchDistance, observed: ObservedData) -> None:
    """Refuse a batch distance that does not give one finite number per simulation."""
    name = getattr(distance, "__name__", type(distance).__name__)
    sims = np.stack([observed.values, observed.values])
    try:
        result = np.asarray(distance(sims, observed.values), dtype=float)
    except Exception as error:
        raise ValueError(
            f"distance {name} fails on the observed data itself (sims of shape {sims.shape}, obs "
            f"{observed.values.shape}): {type(error).__name__}: {error}"
        ) from None
    if result.shape != (2,) or not np.isfinite(result).all():
        raise ValueError(
            f"distance {name} must return one finite number per simulation: for sims of shape "
            f"{sims.shape} it returned {result.shape if result.shape != (2,) else result}, "
            "expected shape (2,)"
        )


def _check_outputs_produced(simulator: Simulator, observed: ObservedData) -> None:
    """Refuse observed outputs that the simulator does not produce (when it names them)."""
    produced = check_simulator(simulator).output_names
    if produced is None:
        return
    missing = [name for name in observed.names if name not in produced]
    if missing:
        raise ValueError(
            f"observed output(s) {missing} are not produced by the simulator, which gives "
            f"{list(produced)}; choose outputs= among them (or simulate those outputs)"
        )


def _check_within_bounds(
    name: str, variable: TensorVariable, bounds: tuple[float, float] | None
) -> None:
    """Refuse a user's prior variable that is not a scalar or puts mass outside ``bounds``."""
    if not isinstance(variable, TensorVariable) or variable.ndim != 0:
        shape = getattr(getattr(variable, "type", None), "shape", type(variable).__name__)
        raise ValueError(
            f"prior of {name!r} must be a scalar PyMC variable, got shape {shape}; index a "
            f"vector variable, e.g. theta[0]"
        )
    draws = np.asarray(pm.draw(variable, draws=PRIOR_CHECK_DRAWS, random_seed=0), dtype=float)
    if bounds is None:
        return
    low, high = bounds
    outside = float(np.mean((draws < low) | (draws > high)))
    if outside > 0:
        raise ValueError(
            f"prior of {name!r} puts {outside:.1%} of its draws outside the bounds "
            f"[{low:g}, {high:g}] of the parameter (draws from {draws.min():.4g} to "
            f"{draws.max():.4g}); truncate it, e.g. pm.TruncatedNormal(..., lower={low:g}, "
            f"upper={high:g})"
        )


def _prior_parts(
    prior: Prior | Mapping | None,
    simulator: Simulator,
    parameters: Sequence[str] | None,
    model: pm.Model,
) -> tuple[dict[str, TensorVariable], Prior | None]:
    """Split ``prior`` into the user's PyMC variables (name -> variable) and a box or GMM
    prior for the other calibrated names (None when every name has a variable)."""
    if isinstance(prior, Prior):
        return {}, prior
    if prior is not None and not isinstance(prior, Mapping):
        raise TypeError(
            "prior must be a UniformPrior, a GMMPrior or a mapping name -> (low, high) or PyMC "
            f"variable, got {type(prior).__name__}"
        )
    entries = dict(prior or {})
    offered = check_simulator(simulator).parameter_names or list(_known_bounds(simulator))
    declared = [n for n in offered if n in model.named_vars and n not in entries]
    if parameters is not None:
        names = list(parameters)
    elif entries:
        names = [*entries, *declared]
    else:
        names = list(simulator_bounds(simulator))
    given = {n: v for n, v in entries.items() if isinstance(v, Variable)}
    given.update({n: model[n] for n in names if n in declared})
    rest = [n for n in names if n not in given]
    bounds = {n: entries[n] for n in rest if n in entries}
    missing = [n for n in rest if n not in bounds]
    if missing:
        bounds.update(simulator_bounds(simulator, missing))
    return given, UniformPrior({n: bounds[n] for n in rest}) if rest else None


def _with_noise_bounds(
    prior: Prior | None, noise: Mapping | None, outputs: Sequence[str]
) -> Prior | None:
    if prior is not None:
        return with_noise(prior, noise, outputs)
    if not noise:
        return None
    scales = {noise_parameter(out): tuple(map(float, pair)) for out, pair in noise.items()}
    return with_noise(UniformPrior(scales), noise, outputs)  # with_noise checks the bounds


@dataclass(frozen=True)
class SimulatorNode:
    """What :func:`add_simulator` added to the model.

    Attributes:
        variable: the ``pm.Simulator`` random variable (observed).
        prior: the box or GMM prior of the names without a user's PyMC variable (None if
            every calibrated name has one).
        parameter_names: simulator parameters calibrated, in the order the simulator gets them.
        noise_outputs: outputs with a noise scale ``nu_<output>``.
        observed: the validated observed data.
        function: the node's random function (runs one simulation).
        variables: every calibrated name (parameters and noise scales) -> its PyMC variable.
    """

    variable: TensorVariable
    prior: Prior | None
    parameter_names: tuple[str, ...]
    noise_outputs: tuple[str, ...]
    observed: ObservedData
    function: SimulatorFunction
    variables: Mapping[str, TensorVariable]


def add_simulator(
    name: str,
    simulator: Simulator,
    observed: OutputData,
    *,
    parameters: Sequence[str] | None = None,
    prior: Prior | Mapping[str, tuple[float, float] | TensorVariable] | None = None,
    outputs: Sequence[str] | None = None,
    noise: Bounds | tuple[float, float] | None = None,
    sensor_noise: SensorNoise | None = None,
    epsilon: float = 0.05,
    distance: str | BatchDistance = "ks",
    sum_stat: str | Callable = "identity",
    time_limit_s: float | None = None,
) -> SimulatorNode:
    """Add ``simulator`` to the current PyMC model as a ``pm.Simulator`` named ``name``.

    Everything is checked here, before any sampling: observed outputs the simulator does not
    produce, parameters it lacks, a distance that does not give one number per simulation, and
    user priors with mass outside the parameter bounds (refused, not truncated: a prior is what
    the user says it is).

    Args:
        name: name of the observed node (its coords are ``<name>_output``, ``<name>_time``).
        simulator: ``simulator(theta, rng) -> Dataset | array (outputs, time)``, picklable.
        observed: observed outputs (Dataset with one variable per output, or an array).
        parameters: simulator parameters to calibrate (default: all those named in ``prior``,
            or those of the simulator's bounds / unit description when ``prior`` is None); the
            others keep the simulator's nominal values.
        prior: a :class:`UniformPrior`, a :class:`GMMPrior` (e.g. the fitted posterior of the
            previous dataset; its names may include noise scales ``nu_<output>``), or a mapping
            name -> (low, high) or PyMC variable already in the model (any distribution, e.g.
            ``pm.TruncatedNormal`` or an entry of :func:`gmm_prior_variable`), mixed freely. A
            model variable that bears the name of a simulator parameter is that parameter's
            prior (and calibrates it); any other parameter without an entry gets a uniform
            prior on the simulator's bounds. A PyMC variable
            must stay within the simulator's bounds of its parameter (checked on
            :data:`PRIOR_CHECK_DRAWS` draws); an unnamed expression (``theta[0]``) becomes a
            ``pm.Deterministic`` named as the parameter, so the posterior holds it by name.
        outputs: outputs compared (default: all outputs of ``observed``).
        noise: bounds of uniform priors on the noise scales ν: one pair for every output or a
            mapping output -> (low, high); None: no noise (unless ``prior`` names them).
            Relative to the SI reading (the paper's ν); prefer ``sensor_noise``.
        sensor_noise: sensor noise in engineering units added to every simulation before the
            distance; learnable scales become variables ``sigma_<output>``.
        epsilon: width ε of the kernel, in distance units (KS: [0, 1]).
        distance: ``"ks"`` (the paper's KS distance averaged over outputs, with the Gaussian
            kernel −½ (d/ε)²), PyMC's ``"gaussian"`` or ``"laplace"`` (elementwise kernels of
            the summary statistics, PyMC's meaning: simulated and observed series on the same
            grid), or a batch distance ``(sims (N, n_out, m), obs (n_out, n)) -> (N,)``.
        sum_stat: PyMC's summary statistic (``"identity"``, ``"sort"``, ``"mean"``,
            ``"median"`` or a callable), applied to simulated and observed outputs before the
            distance; KS and batch distances take ``"identity"`` or ``"sort"``.
        time_limit_s: wall-time limit of one simulation, s; longer runs count as failed.

    Returns:
        A :class:`SimulatorNode` describing the node and the variables it created or used.
    """
    model = pm.modelcontext(None)
    if not np.isfinite(epsilon) or epsilon <= 0:
        raise ValueError(f"epsilon must be a positive number, got {epsilon}")
    info = check_simulator(simulator)
    if isinstance(parameters, str):
        raise TypeError(f"parameters must be a sequence of names, got the string {parameters!r}")
    data = prepare_observed(observed, outputs, info.output_names)
    _check_outputs_produced(simulator, data)
    kernel, sum_stat = _distance_op(distance, sum_stat, data)

    given, prior = _prior_parts(prior, simulator, parameters, model)
    if noise is not None and not isinstance(noise, Mapping):
        noise = dict.fromkeys(data.names, noise)
    prior = _with_noise_bounds(prior, noise, data.names)
    output_noise = None if sensor_noise is None else sensor_noise.resolve(data)
    if sensor_noise is not None:
        sensor_bounds = sensor_noise.prior_bounds(data)
        prior = (
            UniformPrior(sensor_bounds) if prior is None else extended_prior(prior, sensor_bounds)
        )
    if prior is not None:
        check_prior_support(info.support, prior.bounds)
    names = [*given, *(prior.names if prior is not None else ())]
    learn_sensor = sensor_noise is not None and sensor_parameter(data.names[0]) in names

    noise_outputs = tuple(out for out in data.names if noise_parameter(out) in names)
    stray_noise = [
        n for n in names if n.startswith(NOISE_PREFIX) and n[len(NOISE_PREFIX) :] not in data.names
    ]
    if stray_noise:
        raise ValueError(
            f"prior names noise scales {stray_noise} of outputs not compared; outputs: "
            f"{list(data.names)}"
        )
    sensor_scales = [n for n in names if n.startswith(SENSOR_PREFIX)]
    if sensor_noise is None and sensor_scales:
        raise ValueError(
            f"prior names sensor-noise scales {sensor_scales} but no sensor_noise was given; "
            "pass sensor_noise=SensorNoise(..., learnable=True)"
        )
    model_parameters = tuple(n for n in names if not is_noise_parameter(n))
    if parameters is not None and set(parameters) != set(model_parameters):
        raise ValueError(
            f"parameters {list(parameters)} differ from the prior's parameters "
            f"{list(model_parameters)}"
        )
    known = info.parameter_names
    if known is not None:
        unknown = [n for n in model_parameters if n not in known]
        if unknown:
            raise ValueError(f"unknown parameter(s) {unknown}; the simulator has {list(known)}")
    if not model_parameters:
        raise ValueError("the prior holds no simulator parameter to calibrate")
    bounds = _known_bounds(simulator)
    for parameter, variable in given.items():
        limits = (0.0, np.inf) if is_noise_parameter(parameter) else bounds.get(parameter)
        _check_within_bounds(parameter, variable, limits)
        if variable.name not in model.named_vars:  # an expression such as theta[0]: name it
            given[parameter] = pm.Deterministic(parameter, variable)

    variables = {
        **given,
        **(prior_variables(prior, joint_name=f"{name}_theta") if prior is not None else {}),
    }
    function = SimulatorFunction(
        simulator,
        model_parameters,
        data,
        noise_outputs,
        time_limit_s=time_limit_s,
        sensor_noise=output_noise,
        learn_sensor=learn_sensor,
    )
    params = [pt.stack([variables[n] for n in model_parameters])]
    if noise_outputs:
        params.append(pt.stack([variables[noise_parameter(out)] for out in noise_outputs]))
    if learn_sensor:
        params.append(pt.stack([variables[sensor_parameter(out)] for out in data.names]))
    cores = ",".join(f"({chr(ord('p') + k)})" for k in range(len(params)))

    time = data.dataset["time"].values if "time" in data.dataset.coords else None
    model.add_coord(f"{name}_output", list(data.names))
    model.add_coord(f"{name}_time", time if time is not None else np.arange(data.values.shape[1]))
    variable = pm.Simulator(
        name,
        function,
        *params,
        distance=kernel,
        sum_stat=sum_stat,
        epsilon=float(epsilon),
        signature=f"{cores}->()",
        observed=data.values,
        dims=(f"{name}_output", f"{name}_time"),
    )
    return SimulatorNode(
        variable, prior, model_parameters, noise_outputs, data, function, variables
    )


__all__ = [
    "DISTANCES",
    "PRIOR_CHECK_DRAWS",
    "SUM_STATS",
    "DistanceKernel",
    "SimulatorFunction",
    "SimulatorNode",
    "add_simulator",
    "gaussian_log_kernel",
    "gmm_prior_variable",
    "prior_variables",
    "simulator_bounds",
]
