"""The split unit's components as Numba records, shared by its cooling and heating cycles.

Both modes run the same hardware: one compressor, one expansion valve, a suction tank, two
coils with their fans and two connecting lines. The unit description names the coils by their
function in the cycle's mode (``[condenser]``, ``[evaporator]``) and the fans by where they
sit (``[outdoor_fan]``, ``[indoor_fan]``); :func:`split_unit_constants` turns it and a Table III
vector into one record whose fields the cycle modules read by name.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Literal

import numpy as np

from pymc_vcc.physics.components.compressor import COMPRESSOR_RECORD
from pymc_vcc.physics.components.fan import air_capacity_rate, fan_operating_point
from pymc_vcc.physics.components.pipe import friction_coefficient, pipe_volume
from pymc_vcc.physics.cycles.base import StateLayout
from pymc_vcc.physics.parameters import TABLE_III
from pymc_vcc.physics.records import record_array

if TYPE_CHECKING:
    from pymc_vcc.physics.unit import HeatExchangerGeometry, Unit

COIL_RECORD = np.dtype(
    [
        ("cell_volume", np.float64),  # m³
        ("refrigerant_area", np.float64),  # refrigerant-side area per cell, m²
        ("air_area", np.float64),  # air-side area per cell, m²
        ("wall_capacity", np.float64),  # wall heat capacity per cell, J/K
        ("htc_liquid", np.float64),  # refrigerant HTCs at the nominal flow, W/(m² K)
        ("htc_two_phase", np.float64),
        ("htc_vapor", np.float64),
        ("htc_air", np.float64),  # air-side HTC, W/(m² K)
        ("nominal_mass_flow", np.float64),  # flow of the nominal HTCs, kg/s
        ("air_capacity", np.float64),  # air capacity rate per cell, W/K
        ("fan_power", np.float64),  # power of the fan blowing over the coil, W
        ("friction", np.float64),  # K of Δp = K ṁ|ṁ|/ρ (correction factor included), 1/m⁴
    ]
)
"""A finite-volume coil with its air side."""

LINE_RECORD = np.dtype([("volume", np.float64), ("friction", np.float64)])
"""A connecting line: volume (m³) and friction coefficient (1/m⁴)."""

VALVE_RECORD = np.dtype([("flow_area", np.float64), ("cf_lev", np.float64)])
"""Expansion valve: flow area at full opening (m²) and its Table III correction factor."""

CONTROLLER_RECORD = np.dtype([("kp", np.float64), ("ki", np.float64), ("m0", np.float64)])
"""Virtual PI charge controller: gains (1/s, 1/s²) and the charge it holds (kg)."""

OUTPUT_INFO: dict[str, tuple[str, str]] = {
    "TD": ("Compressor discharge temperature", "K"),
    "PD": ("Compressor discharge pressure", "Pa"),
    "TS": ("Compressor suction temperature", "K"),
    "PS": ("Compressor suction pressure", "Pa"),
    "TC": ("Condenser outlet refrigerant temperature", "K"),
    "PC": ("Condenser pressure", "Pa"),
    "TE": ("Evaporator outlet refrigerant temperature", "K"),
    "PE": ("Evaporator pressure", "Pa"),
    "MDOT": ("Compressor mass flow", "kg/s"),
}
"""The nine outputs of the paper, in order (coils named by their function in the mode)."""

DIAGNOSTIC_INFO: dict[str, tuple[str, str]] = {
    "Q_cond": ("Heat rejected by the condenser refrigerant", "W"),
    "Q_evap": ("Heat absorbed by the evaporator refrigerant", "W"),
    "W_comp": ("Compressor shaft power", "W"),
    "W_ref": ("Net compressor power to the refrigerant", "W"),
    "W_fans": ("Fan power", "W"),
    "M": ("Total refrigerant mass", "kg"),
    "mdot_src": ("Charge-controller mass source", "kg/s"),
    "mdot_valve": ("Expansion-valve mass flow", "kg/s"),
}
"""Further quantities after the outputs."""

PARAMETERS = TABLE_III
"""The calibration parameters of the split unit in either mode (paper, Table III)."""


def split_unit_dtype(layout: StateLayout) -> np.dtype:
    """The constants record type of a split-unit cycle with this state layout."""
    return np.dtype(
        [
            ("layout", layout.dtype),
            ("condenser", COIL_RECORD),
            ("evaporator", COIL_RECORD),
            ("liquid_line", LINE_RECORD),
            ("vapor_line", LINE_RECORD),
            ("tank_volume", np.float64),  # m³
            ("compressor", COMPRESSOR_RECORD),
            ("valve", VALVE_RECORD),
            ("controller", CONTROLLER_RECORD),
        ]
    )


def split_unit_constants(
    unit: Unit,
    theta: np.ndarray,
    layout: StateLayout,
    controller: bool | None,
    condenser_fan: Literal["outdoor", "indoor"],
) -> np.ndarray:
    """The constants record (a one-element structured array) of a split unit;
    ``condenser_fan`` says which fan (and Table III fan parameters, ``FO_*`` or ``FI_*``) serves
    the condenser, the other the evaporator."""
    p = dict(zip((pid for pid, _ in PARAMETERS), np.asarray(theta, dtype=float), strict=True))
    n = unit.discretisation.n_volumes
    fans = {
        "outdoor": fan_operating_point(
            p["FO_FLOW"], p["FO_POW"], p["FO_SPEED"], unit.outdoor_fan.operating_speed
        ),
        "indoor": fan_operating_point(
            p["FI_FLOW"], p["FI_POW"], p["FI_SPEED"], unit.indoor_fan.operating_speed
        ),
    }
    evaporator_fan = "indoor" if condenser_fan == "outdoor" else "outdoor"
    f = unit.pressure_drop.darcy_friction_factor
    comp = unit.compressor
    enabled = unit.controller.enabled if controller is None else controller
    kp = unit.controller.kp if enabled else 0.0
    values = {
        "layout": layout.record,
        "condenser": _coil(unit, unit.condenser, p, "C", n, fans[condenser_fan]),
        "evaporator": _coil(unit, unit.evaporator, p, "E", n, fans[evaporator_fan]),
        "liquid_line": {
            "volume": pipe_volume(p["L_LIQ"], unit.liquid_line.inner_diameter),
            "friction": friction_coefficient(f, p["L_LIQ"], unit.liquid_line.inner_diameter),
        },
        "vapor_line": {
            "volume": pipe_volume(p["L_VAP"], unit.vapor_line.inner_diameter),
            "friction": friction_coefficient(f, p["L_VAP"], unit.vapor_line.inner_diameter),
        },
        "tank_volume": unit.suction_tank.volume,
        "compressor": {
            "displacement": comp.displacement,
            "clearance": comp.clearance,
            "exponent": comp.polytropic_exponent,
            "isentropic_efficiency": comp.isentropic_efficiency,
            "refrigerant_fraction": comp.refrigerant_power_fraction,
            "shell_ua": comp.shell_ua,
            "cf_vol": p["CF_VOL"],
            "cf_pow": p["CF_POW"],
            "cf_pref": p["CF_PREF"],
            "cf_shell": p["CF_SHELL"],
            "T_discharge_max": comp.max_discharge_temperature,
            "p_protection_start": comp.protection_pressure_start,
            "p_protection_stop": comp.protection_pressure_stop,
        },
        "valve": {"flow_area": unit.expansion_valve.flow_area, "cf_lev": p["CF_LEV"]},
        "controller": {"kp": kp, "ki": kp * kp / 4.0, "m0": p["M0"]},
    }
    return record_array(split_unit_dtype(layout), values)


def _coil(
    unit: Unit,
    hx: HeatExchangerGeometry,
    p: dict[str, float],
    side: Literal["C", "E"],
    n: int,
    fan: tuple[float, float],
) -> dict[str, float]:
    """A coil record's values: ``side`` "C" (condenser) or "E" (evaporator) picks its Table III
    ids (``L_COND``, ``HTC_CL``, ``CF_DPC``, ...); ``fan`` = (air flow m³/s, power W)."""
    length = p["L_COND" if side == "C" else "L_EVAP"]
    tube = length * hx.n_paths
    flow, power = fan
    friction = friction_coefficient(
        unit.pressure_drop.darcy_friction_factor, length, hx.tube_inner_diameter, hx.n_paths
    )
    return {
        "cell_volume": pipe_volume(length, hx.tube_inner_diameter, hx.n_paths) / n,
        "refrigerant_area": math.pi * hx.tube_inner_diameter * tube / n,
        "air_area": hx.air_side_area_per_length * tube / n,
        "wall_capacity": hx.wall_heat_capacity_per_length * tube / n,
        "htc_liquid": p[f"HTC_{side}L"],
        "htc_two_phase": p[f"HTC_{side}TP"],
        "htc_vapor": p[f"HTC_{side}V"],
        "htc_air": p[f"HTC_{side}A"],
        "nominal_mass_flow": hx.nominal_mass_flow,
        "air_capacity": air_capacity_rate(flow, unit.air.density, unit.air.specific_heat) / n,
        "fan_power": power,
        "friction": p[f"CF_DP{side}"] * friction,
    }
