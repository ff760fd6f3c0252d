"""Inference: distances, priors, samplers, sequential calibration, predictive, sensitivity."""
