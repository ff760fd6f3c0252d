"""pymc_vcc: Bayesian, likelihood-free calibration of dynamic vapor-compression-cycle models.

The public API is re-exported here; see the README for a tour.
"""

__version__ = "0.1.0"

__all__ = ["__version__"]
