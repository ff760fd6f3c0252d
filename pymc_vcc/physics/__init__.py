"""Physics: refrigerant properties, components, the cycle, the simulation driver."""
