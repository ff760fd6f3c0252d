"""Measured data: logger files to SI inputs and observed outputs."""
