"""Components of the cycle as small, pure, Numba-jitted functions (SI units in and out).

Each module holds one component: :mod:`.compressor`, :mod:`.expansion_valve`,
:mod:`.heat_exchanger` (finite-volume pressure zone), :mod:`.heat_transfer` (refrigerant and
air side), :mod:`.suction_tank`, :mod:`.pipe`, :mod:`.fan`, and :mod:`.smooth` (the C¹
regularisations that keep the right-hand side smooth for a stiff solver).
"""
