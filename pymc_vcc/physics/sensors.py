"""Typical field-sensor noise in engineering terms: the one table that the physics probes
(:mod:`pymc_vcc.physics.probes`) and the samplers' ``SensorNoise``
(:mod:`pymc_vcc.inference.noise`) both read.
"""

from __future__ import annotations

KIND_OF_UNITS: dict[str, str] = {
    "K": "temperature",
    "Pa": "pressure",
    "kg/s": "mass_flow",
    "W": "power",
}
"""Sensor kind of each SI output unit."""

TYPICAL_NOISE: dict[str, float] = {
    "temperature": 0.3,
    "pressure": 0.005,
    "mass_flow": 0.01,
    "power": 0.01,
}
"""Standard deviation of a typical field sensor per kind: K for temperatures, a fraction of the
reading for the others (:data:`RELATIVE_KINDS`)."""

RELATIVE_KINDS = frozenset({"pressure", "mass_flow", "power"})
"""Kinds whose noise is a fraction of the reading; temperature noise is absolute (K)."""
