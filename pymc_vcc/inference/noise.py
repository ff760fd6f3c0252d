"""Output noise of the simulations: the paper's relative scales ν (``S ⊙ Z``) and their priors.

θ = [γ; ν]: per noisy output j a scale ν_j named ``nu_<output>``; a simulated output Y becomes
Y + ν·|Y|·Z, Z ~ N(0, 1), before the distance (Algorithm 1), in the SMC node and in the
posterior predictive alike.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from pymc_vcc.inference.priors import Prior, UniformPrior

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
