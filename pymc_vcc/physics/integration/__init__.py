"""Integrating a cycle model in time: the stiff solvers, their C callbacks, the compile ahead.

* :mod:`.solver`: which solver, at which tolerances (a :class:`~.solver.Solver` value).
* :mod:`.segments`: scipy's Radau or SUNDIALS CVODE over one input segment, never raising.
* :mod:`.sundials`: CVODE called directly through ``ctypes``.
* :mod:`.callbacks`: a cycle's kernels bound to one simulation, as Python and C callbacks.
* :mod:`.binding`: Numba kernels bound to their argument types once.
* :mod:`.warmup`: the cycle compiled once per process, before any wall clock starts.
"""
