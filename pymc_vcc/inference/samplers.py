"""The samplers a study calibrates with and the mutation kernels of its SMC, by name.

Names only, importing nothing heavy: the command line offers them before PyMC loads.
"""

from __future__ import annotations

from typing import Literal, get_args

Sampler = Literal["rejection", "smc", "likelihood"]
SAMPLERS: tuple[str, ...] = get_args(Sampler)
"""The paper's ABC rejection, SMC-ABC, or tempered SMC on the exact likelihood of noisy data
(both SMC samplers are PyMC's, with the parallel kernels of :mod:`.pymc.smc`)."""

SmcKernel = Literal["imh", "mh"]
SMC_KERNELS: tuple[str, ...] = get_args(SmcKernel)
"""SMC mutation kernels: independent Metropolis–Hastings (proposals from a Gaussian fitted to
the particles, PyMC's default) or random-walk Metropolis–Hastings (local steps)."""
