"""Cycle models: one module per topology, all integrated by the same driver.

:mod:`.base` holds the contract (:class:`~.base.CycleModel`, :class:`~.base.StateLayout`);
:mod:`.split_unit` the split unit's components as records, :mod:`.split_balances` its
balances, Jacobian and outputs in either mode; :mod:`.split_cooling` and
:mod:`.heat_pump_heating` the two modes' layouts, charges and start-up states. A unit
description names its cycle in ``[unit] cycle``.
"""

from __future__ import annotations

from pymc_vcc.physics.cycles.base import CycleModel, StateLayout
from pymc_vcc.physics.cycles.heat_pump_heating import HeatPumpHeating
from pymc_vcc.physics.cycles.split_cooling import SplitCooling
from pymc_vcc.physics.cycles.split_unit import DIAGNOSTIC_INFO, OPTIONAL_OUTPUT_IDS, OUTPUT_INFO

CYCLE_MODELS: dict[str, CycleModel] = {
    model.name: model for model in (SplitCooling(), HeatPumpHeating())
}
"""The shipped cycle models by the name a unit description gives in ``[unit] cycle``."""

OUTPUT_IDS: tuple[str, ...] = tuple(OUTPUT_INFO)
"""The nine model outputs of the paper, in order (every shipped cycle has them)."""

MEASURABLE_OUTPUT_INFO: dict[str, tuple[str, str]] = {
    **OUTPUT_INFO,
    **{name: DIAGNOSTIC_INFO[name] for name in OPTIONAL_OUTPUT_IDS},
}
"""Outputs a simulator may return and a logger may measure -> (long name, SI unit): the nine,
then the optional ones (``W_comp``)."""


def cycle_model(name: str) -> CycleModel:
    """The cycle model called ``name``; ``ValueError`` naming the allowed ones otherwise."""
    if name not in CYCLE_MODELS:
        raise ValueError(f"unknown cycle {name!r}; allowed cycles are {sorted(CYCLE_MODELS)}")
    return CYCLE_MODELS[name]


__all__ = [
    "CYCLE_MODELS",
    "MEASURABLE_OUTPUT_INFO",
    "OUTPUT_IDS",
    "OUTPUT_INFO",
    "CycleModel",
    "StateLayout",
    "cycle_model",
]
