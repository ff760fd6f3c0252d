"""PyMC integration: the simulator node and the parallel SMC kernel."""
