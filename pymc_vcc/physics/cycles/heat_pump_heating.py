"""The split unit as a heat pump in heating mode: the reversing valve sends the discharge gas
through the vapour line to the indoor coil, which condenses; the outdoor coil evaporates.

Two pressure zones (N = cells per heat exchanger):

* high side: the vapour line (hot gas to the indoor unit), the condenser's N cells (indoor
  coil), then the liquid line; outflow: expansion valve;
* low side: the evaporator's N cells (outdoor coil) and the suction tank; outflow: compressor.

The balances, Jacobian and outputs are the split unit's (:mod:`.split_balances`), with the indoor
fan over the condenser and the outdoor fan over the evaporator; the compressor shell loses heat
to the outdoor air. The indoor coil condenses, so there is no latent load: the indoor relative
humidity is read but changes nothing (``Q_latent`` = 0, ``SHR`` = 1). This module gives the
heating mode's state layout, charge and start-up state.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from pymc_vcc.physics.cycles.base import (
    N_PROPERTIES,
    Block,
    BlockKind,
    StateLayout,
    cell_properties,
    place_charge,
    quality_enthalpy,
    stored_mass,
)
from pymc_vcc.physics.cycles.split_balances import SplitUnitCycle, U, cell_volumes
from pymc_vcc.physics.cycles.split_unit import filled_coils
from pymc_vcc.physics.refrigerant import p_sat_from_T


@functools.cache
def layout(n_volumes: int) -> StateLayout:
    """The state: two zones (pressure, then cell enthalpies in flow order), walls, integral;
    one shared layout per size (see :func:`~.split_unit.split_unit_dtype`)."""
    return StateLayout(
        [
            Block("p_cond", 1, BlockKind.PRESSURE),
            Block("h_vapor_line", 1, BlockKind.ENTHALPY),
            Block("h_cond", n_volumes, BlockKind.ENTHALPY),
            Block("h_liquid_line", 1, BlockKind.ENTHALPY),
            Block("Tw_cond", n_volumes, BlockKind.TEMPERATURE),
            Block("p_evap", 1, BlockKind.PRESSURE),
            Block("h_evap", n_volumes, BlockKind.ENTHALPY),
            Block("h_tank", 1, BlockKind.ENTHALPY),
            Block("Tw_evap", n_volumes, BlockKind.TEMPERATURE),
            Block("z", 1, BlockKind.INTEGRAL),
        ]
    )


@njit(cache=True, error_model="numpy")
def total_mass(y, constants, tables):
    """Total refrigerant mass M(y), kg (NaN if a property left the tables)."""
    c = constants[0]
    props = np.empty((N_PROPERTIES, c.layout.zones[:, 1].sum()))
    cell_properties(y, c.layout.zones, tables, props, False)
    volumes = np.empty(props.shape[1])
    cell_volumes(c, volumes)
    return stored_mass(volumes, props[1])


@njit(cache=True, error_model="numpy")
def filled_state(s, p_c, p_e, constants, tables):
    """:func:`~.split_unit.filled_coils` at fill level ``s``, the vapour line (high side)
    full of hot gas."""
    at = constants[0].layout
    y = filled_coils(s, p_c, p_e, at, tables)
    y[at.h_vapor_line] = quality_enthalpy(tables, p_c, 1.2)
    return y


class HeatPumpHeating(SplitUnitCycle):
    """The split unit as a heat pump in heating mode (indoor coil condenses)."""

    name = "heat-pump-heating"
    description = "split heat pump, heating: indoor coil condenses, outdoor coil evaporates"
    condenser_fan = "indoor"
    capacity = "Q_cond"
    total_mass = staticmethod(total_mass)

    def layout(self, n_volumes: int) -> StateLayout:
        return layout(n_volumes)

    def initial_state(
        self, c: np.ndarray, n_volumes: int, inputs: np.ndarray, tables
    ) -> np.ndarray:
        """Initialisation by M0 alone: condensing 20 K above the indoor air, evaporating 8 K
        below the outdoor air, the fill level of :func:`filled_state` found by root-finding on the
        total mass (:func:`~.base.place_charge`)."""
        p_c = p_sat_from_T(tables, inputs[U.T_indoor] + 20.0)
        p_e = p_sat_from_T(tables, inputs[U.T_ambient] - 8.0)
        return place_charge(
            lambda s: filled_state(s, p_c, p_e, c, tables),
            lambda y: total_mass(y, c, tables),
            self.charge(c),
        )


CYCLE = HeatPumpHeating()
"""This module's cycle, found by the registry (:mod:`pymc_vcc.physics.cycles`)."""
