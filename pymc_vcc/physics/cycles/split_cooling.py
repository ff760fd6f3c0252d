"""Split air conditioner in cooling mode: the outdoor coil condenses, the indoor coil evaporates.

Two pressure zones (N = cells per heat exchanger):

* high side: the condenser's N cells, then the liquid line (one adiabatic cell); outflow: valve;
* low side: the evaporator's N cells, the vapour line and the suction tank; outflow: compressor.

The balances, Jacobian and outputs are the split unit's (:mod:`.split_balances`); this module
gives the cooling mode's state layout, charge and start-up state.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from pymc_vcc.physics.components.density import cell_values, fillet_memo
from pymc_vcc.physics.cycles.base import (
    Block,
    BlockKind,
    StateLayout,
    place_charge,
    quality_enthalpy,
)
from pymc_vcc.physics.cycles.split_balances import SplitUnitCycle, U
from pymc_vcc.physics.cycles.split_unit import filled_coils
from pymc_vcc.physics.refrigerant import p_sat_from_T, saturation_point


@functools.cache
def layout(n_volumes: int) -> StateLayout:
    """The state: two zones (pressure, then cell enthalpies in flow order), walls, integral;
    one shared layout per size (see :func:`~.split_unit.split_unit_dtype`)."""
    return StateLayout(
        [
            Block("p_cond", 1, BlockKind.PRESSURE),
            Block("h_cond", n_volumes, BlockKind.ENTHALPY),
            Block("h_liquid_line", 1, BlockKind.ENTHALPY),
            Block("Tw_cond", n_volumes, BlockKind.TEMPERATURE),
            Block("p_evap", 1, BlockKind.PRESSURE),
            Block("h_evap", n_volumes, BlockKind.ENTHALPY),
            Block("h_vapor_line", 1, BlockKind.ENTHALPY),
            Block("h_tank", 1, BlockKind.ENTHALPY),
            Block("Tw_evap", n_volumes, BlockKind.TEMPERATURE),
            Block("z", 1, BlockKind.INTEGRAL),
        ]
    )


@njit(cache=True, error_model="numpy")
def total_mass(y, constants, tables):
    """Total refrigerant mass M(y), kg (NaN if a property left the tables). Summed coil cell by
    coil cell, then the lines and the tank: the order the regression reference was made with."""
    c = constants[0]
    at = c.layout
    n = at.h_liquid_line - at.h_cond
    p_c, p_e = y[at.p_cond], y[at.p_evap]
    sat_c, sat_e = saturation_point(tables, p_c), saturation_point(tables, p_e)
    memo_c, memo_e = fillet_memo(), fillet_memo()
    mass = 0.0
    for i in range(n):
        h_c, h_e = y[at.h_cond + i], y[at.h_evap + i]
        mass += c.condenser.cell_volume * cell_values(tables, sat_c, p_c, h_c, memo_c)[1]
        mass += c.evaporator.cell_volume * cell_values(tables, sat_e, p_e, h_e, memo_e)[1]
    h_liquid, h_vapor, h_tank = y[at.h_liquid_line], y[at.h_vapor_line], y[at.h_tank]
    mass += c.liquid_line.volume * cell_values(tables, sat_c, p_c, h_liquid, memo_c)[1]
    mass += c.vapor_line.volume * cell_values(tables, sat_e, p_e, h_vapor, memo_e)[1]
    mass += c.tank.volume * cell_values(tables, sat_e, p_e, h_tank, memo_e)[1]
    return mass


@njit(cache=True, error_model="numpy")
def filled_state(s, p_c, p_e, constants, tables):
    """:func:`~.split_unit.filled_coils` at fill level ``s``, the vapour line (low side)
    superheated."""
    at = constants[0].layout
    y = filled_coils(s, p_c, p_e, at, tables)
    y[at.h_vapor_line] = quality_enthalpy(tables, p_e, 1.05)
    return y


class SplitCooling(SplitUnitCycle):
    """The built-in 3.5 kW split air conditioner in cooling mode."""

    name = "split-cooling"
    description = "split air conditioner, cooling: outdoor coil condenses, indoor evaporates"
    condenser_fan = "outdoor"
    capacity = "Q_evap"
    total_mass = staticmethod(total_mass)

    def layout(self, n_volumes: int) -> StateLayout:
        return layout(n_volumes)

    def initial_state(
        self, c: np.ndarray, n_volumes: int, inputs: np.ndarray, tables
    ) -> np.ndarray:
        """The paper's initialisation by M0 alone: condensing 12 K above the outdoor air,
        evaporating 18 K below the indoor air, the fill level of :func:`filled_state` found
        by root-finding on the total mass (:func:`~.base.place_charge`)."""
        p_c = p_sat_from_T(tables, inputs[U.T_ambient] + 12.0)
        p_e = p_sat_from_T(tables, inputs[U.T_indoor] - 18.0)
        return place_charge(
            lambda s: filled_state(s, p_c, p_e, c, tables),
            lambda y: total_mass(y, c, tables),
            self.charge(c),
        )


CYCLE = SplitCooling()
"""This module's cycle, found by the registry (:mod:`pymc_vcc.physics.cycles`)."""
