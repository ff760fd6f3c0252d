"""Output noise of the simulations: sensor noise in engineering units, and the paper's ν.

:class:`SensorNoise` states each sensor's error as an engineer does (0.3 K on temperatures,
0.5 % of the reading on pressures, 1 % on mass flow and power), per output kind with per-output
overrides, optionally correlated in time (AR(1)) or heavy-tailed (Student-t), and optionally
learnable (a uniform prior per scale, ``sigma_<output>``). Every sampler, the exact likelihood
(:mod:`pymc_vcc.inference.likelihood`) and the predictive use it.

The paper's relative scales ν (``S ⊙ Z``) remain for fidelity: per noisy output j a scale ν_j
named ``nu_<output>``; a simulated output Y becomes Y + ν·|Y|·Z, Z ~ N(0, 1), before the
distance (Algorithm 1). ν is dimensionless relative to the SI reading, so 0.3 K at 300 K is
ν = 0.001: prefer :class:`SensorNoise`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import xarray as xr
from scipy.signal import lfilter

from pymc_vcc.inference.priors import Prior, UniformPrior
from pymc_vcc.inference.series import ObservedData, prepare_observed
from pymc_vcc.physics.sensors import KIND_OF_UNITS, RELATIVE_KINDS, TYPICAL_NOISE

NOISE_PREFIX = "nu_"


def noise_parameter(output: str) -> str:
    """Name of the noise scale ν of an output: ``nu_<output>``."""
    return f"{NOISE_PREFIX}{output}"


def add_output_noise(
    values: np.ndarray, scales: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """The paper's output noise: values + ν_j·|values|·Z, Z ~ N(0, 1) per output j and time.

    Args:
        values: outputs (n_outputs, n_time).
        scales: ν per output (n_outputs,), dimensionless.
        rng: the simulation's random generator.
    """
    scales = np.asarray(scales, dtype=float).reshape(-1, 1)
    return values + scales * np.abs(values) * rng.standard_normal(values.shape)


def with_noise(
    prior: Prior, noise: Mapping[str, tuple[float, float]] | None, outputs: Sequence[str]
) -> Prior:
    """The prior over θ = [γ; ν]: ``prior`` with a uniform ν per noisy output, if not in it yet.

    A prior that already holds every ``nu_<output>`` (e.g. a GMM fitted to a previous posterior)
    is used as it is, provided its bounds match ``noise``.
    """
    if not noise:
        return prior
    unknown = [name for name in noise if name not in outputs]
    if unknown:
        raise ValueError(f"noise names unknown outputs {unknown}; the outputs are {list(outputs)}")
    bounds = {}
    for output, pair in noise.items():
        low, high = (float(value) for value in pair)
        if not 0.0 <= low < high or not np.isfinite(high):
            raise ValueError(
                f"noise bounds of {output!r} must satisfy 0 <= low < high < inf, got {pair}"
            )
        bounds[noise_parameter(output)] = (low, high)
    return extended_prior(prior, bounds)


def extended_prior(prior: Prior, bounds: Mapping[str, tuple[float, float]]) -> Prior:
    """``prior`` with uniform ``bounds`` for names it lacks (all of them or none).

    A prior that already holds every name (e.g. a GMM fitted to a previous posterior) is used as
    it is, provided its bounds match.
    """
    if not bounds:
        return prior
    present = [name for name in bounds if name in prior.names]
    if len(present) == len(bounds):
        for name, pair in bounds.items():
            if prior.bounds[name] != pair:
                raise ValueError(
                    f"the prior bounds {prior.bounds[name]} of {name!r} differ from the noise "
                    f"bounds {pair}"
                )
        return prior
    if present:
        raise ValueError(
            f"the prior holds some noise scales {present} but not all of {list(bounds)}"
        )
    if isinstance(prior, UniformPrior):
        return prior.extended(bounds)
    raise ValueError(
        f"a {type(prior).__name__} without the noise scales {list(bounds)} cannot be extended; "
        "fit it to samples that include them, or use a UniformPrior"
    )


# --- sensor noise in engineering units -------------------------------------------------------

SENSOR_PREFIX = "sigma_"
KINDS: tuple[str, ...] = tuple(TYPICAL_NOISE)


def is_noise_parameter(name: str) -> bool:
    """Whether a prior name is a noise scale (``nu_<output>`` or ``sigma_<output>``)."""
    return name.startswith((NOISE_PREFIX, SENSOR_PREFIX))


def model_drift(prior: Prior, drift: float) -> dict[str, float]:
    """``drift`` for each of the prior's model parameters, none for its noise scales (the
    sensors do not change with the unit): the ``drift`` of
    :meth:`~pymc_vcc.inference.priors.GMMPrior.fit`."""
    return {name: drift for name in prior.names if not is_noise_parameter(name)}


def sensor_parameter(output: str) -> str:
    """Name of the learnable sensor-noise scale of an output: ``sigma_<output>``."""
    return f"{SENSOR_PREFIX}{output}"


def _positive(name: str, value: float) -> float:
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise ValueError(f"SensorNoise {name} must be a positive finite number, got {value}")
    return value


@dataclass(frozen=True)
class SensorNoise:
    """Measurement noise of the sensors, in engineering terms.

    Each output's error is ``σ·e_t`` with ``e`` a unit-scale series: Gaussian, or Student-t with
    ``dof`` degrees of freedom (outliers, model error); first-order autoregressive with lag-1
    coefficient ``correlation`` per time step of the data (sensor errors on a 1 s grid are
    correlated); ``correlation=0`` gives independent errors. ``σ`` is the output kind's scale:

    Attributes:
        temperature: standard deviation of temperatures, K (absolute).
        pressure: fraction of the reading (0.005 = 0.5 %).
        mass_flow: fraction of the reading.
        power: fraction of the reading.
        outputs: per-output overrides, output -> scale in its kind's terms.
        kinds: output -> kind for outputs whose ``units`` attribute does not tell it
            (``"temperature"``, ``"pressure"``, ``"mass_flow"``, ``"power"``).
        correlation: lag-1 autocorrelation of each sensor's error, in [0, 1).
        dof: Student-t degrees of freedom (> 2); None: Gaussian.
        learnable: give each scale a uniform prior ``sigma_<output>`` and calibrate it.
        prior_factor: a learnable scale's prior is Uniform(scale / f, scale · f), f > 1.
    """

    temperature: float = TYPICAL_NOISE["temperature"]
    pressure: float = TYPICAL_NOISE["pressure"]
    mass_flow: float = TYPICAL_NOISE["mass_flow"]
    power: float = TYPICAL_NOISE["power"]
    outputs: Mapping[str, float] = field(default_factory=dict)
    kinds: Mapping[str, str] = field(default_factory=dict)
    correlation: float = 0.0
    dof: float | None = None
    learnable: bool = False
    prior_factor: float = 3.0

    def __post_init__(self) -> None:
        for kind in KINDS:
            _positive(kind, getattr(self, kind))
        for output, scale in self.outputs.items():
            _positive(f"outputs[{output!r}]", scale)
        for output, kind in self.kinds.items():
            if kind not in KINDS:
                raise ValueError(
                    f"SensorNoise kinds[{output!r}] is {kind!r}; allowed kinds: {list(KINDS)}"
                )
        if not 0.0 <= float(self.correlation) < 1.0:
            raise ValueError(f"SensorNoise correlation must lie in [0, 1), got {self.correlation}")
        if self.dof is not None and not float(self.dof) > 2.0:
            raise ValueError(
                f"SensorNoise dof must be > 2 (finite variance) or None, got {self.dof}"
            )
        if not float(self.prior_factor) > 1.0:
            raise ValueError(f"SensorNoise prior_factor must be > 1, got {self.prior_factor}")

    @classmethod
    def typical(cls, **overrides) -> SensorNoise:
        """Typical field sensors: 0.3 K, 0.5 % of pressure, 1 % of mass flow and power."""
        return cls(**overrides)

    def resolve(self, observed: ObservedData) -> OutputNoise:
        """The noise of each observed output, its kind told by its ``units`` attribute."""
        return self.for_outputs(
            {name: observed.dataset[name].attrs.get("units") for name in observed.names}
        )

    def for_outputs(self, units: Mapping[str, str | None]) -> OutputNoise:
        """The noise of outputs named by ``units`` (output -> its SI units), in that order."""
        kinds, scales = [], []
        names = tuple(units)
        for name in names:
            kind = self.kinds.get(name) or KIND_OF_UNITS.get(units[name] or "")
            if kind is None:
                raise ValueError(
                    f"output {name!r} has units {units[name]!r}; SensorNoise knows "
                    f"{list(KIND_OF_UNITS)}: give SensorNoise(kinds={{{name!r}: ...}}) one of "
                    f"{list(KINDS)}"
                )
            kinds.append(kind)
            scales.append(float(self.outputs.get(name, getattr(self, kind))))
        unknown = [name for name in (*self.outputs, *self.kinds) if name not in names]
        if unknown:
            raise ValueError(
                f"SensorNoise names outputs {unknown} that are not observed; the observed "
                f"outputs are {list(names)}"
            )
        return OutputNoise(
            names=names,
            scales=tuple(scales),
            relative=tuple(kind in RELATIVE_KINDS for kind in kinds),
            correlation=float(self.correlation),
            dof=None if self.dof is None else float(self.dof),
        )

    def measure(self, outputs: xr.Dataset, rng: np.random.Generator) -> xr.Dataset:
        """What the sensors read of noise-free ``outputs`` (variables with ``units``): a copy."""
        data = prepare_observed(outputs)
        noisy = self.resolve(data).sample(data.values, rng)
        measured = outputs.copy()
        for name, row in zip(data.names, noisy, strict=True):
            measured[name] = measured[name].copy(data=row)
        return measured

    def prior_bounds(self, observed: ObservedData) -> dict[str, tuple[float, float]]:
        """Bounds of the learnable scales ``sigma_<output>`` (empty unless ``learnable``)."""
        if not self.learnable:
            return {}
        noise = self.resolve(observed)
        factor = float(self.prior_factor)
        return {
            sensor_parameter(name): (scale / factor, scale * factor)
            for name, scale in zip(noise.names, noise.scales, strict=True)
        }


@dataclass(frozen=True)
class OutputNoise:
    """A :class:`SensorNoise` resolved for the rows of an (outputs, time) array.

    Attributes:
        names: the outputs, in row order.
        scales: scale σ of each output: K or the output's own unit if absolute, else a fraction.
        relative: whether each scale is a fraction of the (noise-free) reading.
        correlation: lag-1 autocorrelation φ of the errors.
        dof: Student-t degrees of freedom, or None for Gaussian errors.
    """

    names: tuple[str, ...]
    scales: tuple[float, ...]
    relative: tuple[bool, ...]
    correlation: float = 0.0
    dof: float | None = None

    def std(self, values: np.ndarray, scales: np.ndarray | None = None) -> np.ndarray:
        """Scale σ of each error (n_outputs, n_time) around the noise-free ``values``, SI units.

        ``scales`` replaces :attr:`scales` (learnable scales drawn from their prior).
        """
        given = np.asarray(self.scales if scales is None else scales, dtype=float)[:, None]
        relative = np.asarray(self.relative)[:, None]
        return np.where(relative, given * np.abs(values), given * np.ones_like(values))

    def unit_errors(self, shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
        """Unit-scale error series (n_outputs, n_time): AR(1) with Gaussian or t innovations."""
        if self.dof is None:
            innovations = rng.standard_normal(shape)
        else:
            innovations = rng.standard_t(self.dof, shape)
        phi = self.correlation
        if phi == 0.0:
            return innovations
        innovations[:, 0] /= np.sqrt(1.0 - phi**2)  # the first error has the stationary scale
        return lfilter([np.sqrt(1.0 - phi**2)], [1.0, -phi], innovations, axis=1)

    def sample(
        self, values: np.ndarray, rng: np.random.Generator, scales: np.ndarray | None = None
    ) -> np.ndarray:
        """Noisy readings of noise-free ``values`` (n_outputs, n_time), SI units."""
        values = np.asarray(values, dtype=float)
        return values + self.std(values, scales) * self.unit_errors(values.shape, rng)
