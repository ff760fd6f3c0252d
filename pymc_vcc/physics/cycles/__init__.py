"""Cycle models: one module per topology, all integrated by the same driver.

:mod:`.base` holds the contract (:class:`~.base.CycleModel`, its layouts and sections);
:mod:`.split_unit` the split unit's description and components as records,
:mod:`.split_balances` its balances, Jacobian and outputs in either mode; :mod:`.split_cooling`
and :mod:`.heat_pump_heating` the two modes' layouts, charges and start-up states.

The registry finds the cycles itself: every module of this package that defines ``CYCLE`` (a
:class:`~.base.CycleModel` instance) adds it under its name, the one a unit description gives
in ``[unit] cycle``. The catalogues below (inputs, outputs) are the union of the cycles' own.
"""

from __future__ import annotations

import importlib
import pkgutil

from pymc_vcc.physics.cycles.base import CycleModel, InputLayout, InputSpec, StateLayout


def _discover() -> dict[str, CycleModel]:
    models: dict[str, CycleModel] = {}
    for module_info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{__name__}.{module_info.name}")
        model = getattr(module, "CYCLE", None)
        if isinstance(model, CycleModel):
            if model.name in models:
                raise ValueError(f"two cycle models are called {model.name!r}")
            models[model.name] = model
    return models


CYCLE_MODELS: dict[str, CycleModel] = _discover()
"""The shipped cycle models by the name a unit description gives in ``[unit] cycle``."""


def _union_inputs() -> InputLayout:
    specs: dict[str, InputSpec] = {}
    for model in CYCLE_MODELS.values():
        for spec in model.inputs:
            known = specs.setdefault(spec.id, spec)
            if {**vars(known), "default": None} != {**vars(spec), "default": None}:
                raise ValueError(f"cycles declare input {spec.id!r} differently")
    required = [
        spec
        for spec in specs.values()
        if all(spec.id in model.inputs.required_ids for model in CYCLE_MODELS.values())
    ]
    optional = [
        spec if spec.default is not None else InputSpec(**{**vars(spec), "default": float("nan")})
        for spec in specs.values()
        if spec not in required
    ]
    return InputLayout(required + optional)


INPUTS: InputLayout = _union_inputs()
"""Every input some cycle reads: required where every cycle requires it, else optional (at the
cycle's default, NaN where a cycle requires it and another does not read it)."""

QUANTITY_INFO: dict[str, tuple[str, str]] = {
    name: info for model in CYCLE_MODELS.values() for name, info in model.outputs.info.items()
}
"""Long name and SI unit of every output and diagnostic of any cycle."""

OUTPUT_IDS: tuple[str, ...] = tuple(
    dict.fromkeys(name for model in CYCLE_MODELS.values() for name in model.output_ids)
)
"""The outputs of the cycles, in order: the paper's nine, which every shipped cycle has."""

MEASURABLE_OUTPUT_INFO: dict[str, tuple[str, str]] = {
    name: info
    for model in CYCLE_MODELS.values()
    for name, info in model.outputs.measurable_info.items()
}
"""Outputs a simulator may return and a logger may measure -> (long name, SI unit): the
outputs, then the optional ones (``W_comp``)."""


def cycle_model(name: str) -> CycleModel:
    """The cycle model called ``name``; ``ValueError`` naming the allowed ones otherwise."""
    if name not in CYCLE_MODELS:
        raise ValueError(f"unknown cycle {name!r}; allowed cycles are {sorted(CYCLE_MODELS)}")
    return CYCLE_MODELS[name]


__all__ = [
    "CYCLE_MODELS",
    "INPUTS",
    "MEASURABLE_OUTPUT_INFO",
    "OUTPUT_IDS",
    "QUANTITY_INFO",
    "CycleModel",
    "StateLayout",
    "cycle_model",
]
