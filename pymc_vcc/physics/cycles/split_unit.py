"""The split unit's description and its components as Numba records, shared by its cooling and
heating cycles.

Both modes run the same hardware: one compressor, one expansion valve, a suction tank (with a
bleed hole), two coils with their fans and two connecting lines (:class:`SplitUnitHardware`,
one section of the unit file each). The unit description names the coils by their function in
the cycle's mode (``[condenser]``, ``[evaporator]``) and the fans by where they sit
(``[outdoor_fan]``, ``[indoor_fan]``); both modes take the paper's Table III parameters
(:data:`PARAMETERS`), read the same inputs (:data:`INPUTS`) and write the same outputs
(:data:`OUTPUTS`), and the same three faults (:data:`FAULTS`: a liquid-line restriction,
non-condensable gas in the condenser, leaking compressor valves). :func:`split_unit_constants`
turns a unit, a Table III vector and a fault vector into one record whose fields the cycle
modules read by name. The kernels both modes share (suction tank outlet, compressor flow
through the lumped pressure drops, a coil cell's wall heat, the start-up fill profile) are here
too.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numba import njit

from pymc_vcc.physics.components.compressor import (
    COMPRESSOR_RECORD,
    compressor_mass_flow,
    delivered_mass_flow,
    volumetric_efficiency,
)
from pymc_vcc.physics.components.fan import air_capacity_rate, fan_operating_point
from pymc_vcc.physics.components.heat_transfer import FLUX_KINKS, air_effectiveness, cell_heat
from pymc_vcc.physics.components.pipe import (
    friction_coefficient,
    pipe_volume,
    pressure_drop,
    rated_drop_coefficient,
)
from pymc_vcc.physics.components.suction_tank import liquid_level, tank_outlet_enthalpy
from pymc_vcc.physics.cycles.base import (
    FRACTION,
    InputLayout,
    InputSpec,
    OutputLayout,
    StateLayout,
    UnitDescription,
    quality_enthalpy_at,
)
from pymc_vcc.physics.parameters import ParameterSpec, declared_table
from pymc_vcc.physics.records import record_array
from pymc_vcc.physics.refrigerant import (
    load_refrigerant,
    p_sat_from_T,
    saturation_point,
    saturation_state,
    state_at,
    state_values_at,
)


@dataclass(frozen=True)
class CompressorGeometry:
    """Fixed compressor data (its correction factors are calibration parameters)."""

    displacement: float  # m3 per revolution
    clearance: float = field(metadata=FRACTION)  # clearance ratio of the volumetric efficiency
    polytropic_exponent: float  # re-expansion exponent, -
    isentropic_efficiency: float = field(metadata=FRACTION)  # -
    # share of the losses (power above W_s) heating the gas, -
    loss_share_to_refrigerant: float = field(metadata=FRACTION)
    shell_ua: float  # shell heat-loss conductance to ambient, W/K
    max_discharge_temperature: float  # thermal limit of the discharge gas, K
    protection_pressure_start: float  # discharge pressure where the speed droop starts, Pa
    protection_pressure_stop: float  # discharge pressure of 5 % speed, Pa


@dataclass(frozen=True)
class ValveGeometry:
    """Electronic expansion valve: flow area at full opening (m2), ṁ = A a sqrt(2 ρ Δp)."""

    flow_area: float


@dataclass(frozen=True)
class HeatExchangerGeometry:
    """Fixed heat-exchanger data; coil length per path is a calibration parameter."""

    tube_inner_diameter: float  # m
    n_paths: int  # parallel refrigerant circuits
    air_side_area_per_length: float  # air-side (fin and tube) area per m of tube, m2/m
    wall_heat_capacity_per_length: float  # tube and fin heat capacity per m of tube, J/(K m)
    nominal_mass_flow: float  # refrigerant flow at which the nominal HTCs hold, kg/s


@dataclass(frozen=True)
class PipeGeometry:
    """Connecting line; its length is a calibration parameter."""

    inner_diameter: float  # m


@dataclass(frozen=True)
class TankGeometry:
    """Suction accumulator with a bleed (oil-return) hole in its J-tube."""

    volume: float  # m3
    # liquid mass fraction of the outflow with a full tank, -
    bleed_fraction_full: float = field(metadata=FRACTION)


@dataclass(frozen=True)
class FanSettings:
    """Fan running speed as a fraction of its rated ("nominal") speed; the fan laws scale the
    rated flow and power (Table III) to it."""

    speed_fraction: float


@dataclass(frozen=True)
class AirProperties:
    """Constant moist-air properties on both coils."""

    density: float  # kg/m3
    specific_heat: float  # J/(kg K)


@dataclass(frozen=True)
class PressureDrop:
    """Lumped pressure drops: Darcy friction factor of straight tube, and the ratio of a coil's
    drop to straight-tube homogeneous friction (return bends, headers, two-phase slip)."""

    darcy_friction_factor: float
    coil_multiplier: float


@dataclass(frozen=True)
class SplitUnitHardware:
    """The split unit's sections of the unit file, in the file's order (SI units)."""

    compressor: CompressorGeometry
    expansion_valve: ValveGeometry
    condenser: HeatExchangerGeometry
    evaporator: HeatExchangerGeometry
    liquid_line: PipeGeometry
    vapor_line: PipeGeometry
    suction_tank: TankGeometry
    outdoor_fan: FanSettings
    indoor_fan: FanSettings
    air: AirProperties
    pressure_drop: PressureDrop


PARAMETERS: tuple[tuple[str, str], ...] = (
    ("M0", "kg"),
    ("CF_VOL", "1"),
    ("CF_POW", "1"),
    ("CF_PREF", "1"),
    ("CF_SHELL", "1"),
    ("CF_LEV", "1"),
    ("CF_DPC", "1"),
    ("CF_DPE", "1"),
    ("HTC_CV", "W/(m2 K)"),
    ("HTC_CTP", "W/(m2 K)"),
    ("HTC_CL", "W/(m2 K)"),
    ("HTC_EV", "W/(m2 K)"),
    ("HTC_ETP", "W/(m2 K)"),
    ("HTC_EL", "W/(m2 K)"),
    ("FO_FLOW", "m3/s"),
    ("FO_POW", "W"),
    ("FO_SPEED", "Hz"),
    ("FI_FLOW", "m3/s"),
    ("FI_POW", "W"),
    ("FI_SPEED", "Hz"),
    ("HTC_CA", "W/(m2 K)"),
    ("HTC_EA", "W/(m2 K)"),
    ("L_COND", "m"),
    ("L_EVAP", "m"),
    ("L_VAP", "m"),
    ("L_LIQ", "m"),
)
"""(id, unit) of the split unit's 26 calibration parameters in either mode, in the order of the
paper's Table III."""

FAULTS = declared_table(
    (
        ParameterSpec(
            "DP_RESTR",
            "Liquid-line restriction (clogged filter-drier): its pressure drop at the rated flow",
            "Pa",
            0.0,
            3.0e5,
            0.0,
        ),
        ParameterSpec(
            "P_NCG",
            "Non-condensable gas (air) in the condenser: its partial pressure",
            "Pa",
            0.0,
            2.0e5,
            0.0,
        ),
        ParameterSpec(
            "F_LEAK",
            "Compressor valve leakage: share of the displaced gas leaking back to the suction",
            "1",
            0.0,
            0.5,
            0.0,
        ),
    )
)
"""The split unit's fault parameters in either mode, apart from Table III (nominal 0: no fault;
the upper bounds are severe but physical faults). ``DP_RESTR``: an added flow resistance
upstream of the expansion valve, given as the pressure drop across it when the rated flow
(the condenser's ``nominal_mass_flow``) of saturated liquid at :data:`RESTRICTION_RATING_T`
passes it, what a service engineer reads across a filter-drier (3 bar: 5 K of saturation
temperature at 40 °C in R410A, a drier far past replacement). ``P_NCG``: the partial pressure
of air trapped in the condenser, added to every pressure the high side presents (2 bar: about
the air of a line set and indoor coil left unevacuated, 2.5 L at 1 bar, gathered in the
condenser's vapour space). ``F_LEAK``: the share of the gas the compressor displaces that
leaks back through its valves to the suction (0.5: half the flow lost, a compressor close to
failing); the compressor reads it from its own record
(:data:`~pymc_vcc.physics.components.compressor.COMPRESSOR_RECORD`). models/README.md,
"Faults", gives the physics and its limits."""

RESTRICTION_RATING_T = 313.15
"""Saturated-liquid temperature of the restriction's rated drop, K (40 °C: the liquid line at
the rating point)."""

INPUTS = InputLayout(
    [
        InputSpec("valve_opening", "Expansion valve opening", "1", 0.02, 1.0, stepped=True),
        InputSpec("compressor_speed", "Compressor speed", "Hz", 10.0, 150.0, stepped=True),
        InputSpec("T_ambient", "Outdoor (ambient) air temperature", "K", 253.15, 323.15),
        InputSpec("T_indoor", "Indoor air temperature", "K", 283.15, 313.15),
        InputSpec("RH_indoor", "Indoor relative humidity", "1", 0.0, 1.0, default=0.0),
    ]
)
"""The split unit's inputs: valve opening (fraction), compressor speed (Hz), outdoor and indoor
air temperature (K), and optionally the indoor relative humidity (fraction; default 0: dry
indoor air, as in the paper; with RH > 0 an evaporating indoor coil dehumidifies where it is
below the dew point)."""

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
        ("air_flow", np.float64),  # air flow of the fan blowing over the coil, m³/s
        ("air_capacity", np.float64),  # air capacity rate per cell, W/K
        ("fan_power", np.float64),  # power of the fan blowing over the coil, W
        ("friction", np.float64),  # K of Δp = K ṁ|ṁ|/ρ (coil multiplier and CF), 1/m⁴
    ]
)
"""A finite-volume coil with its air side."""

LINE_RECORD = np.dtype([("volume", np.float64), ("friction", np.float64)])
"""A connecting line: volume (m³) and friction coefficient (1/m⁴)."""

VALVE_RECORD = np.dtype([("flow_area", np.float64), ("cf_lev", np.float64)])
"""Expansion valve: flow area at full opening (m²) and its Table III correction factor."""

CONTROLLER_RECORD = np.dtype([("kp", np.float64), ("ki", np.float64), ("m0", np.float64)])
"""Virtual PI charge controller: gains (1/s, 1/s²) and the charge it holds (kg)."""

TANK_RECORD = np.dtype([("volume", np.float64), ("bleed_fraction_full", np.float64)])
"""Suction accumulator: volume (m³) and liquid mass fraction of its outflow when full (-)."""

FAULT_RECORD = np.dtype(
    [
        ("restriction", np.float64),  # K of Δp = K ṁ|ṁ|/ρ upstream of the valve, 1/m⁴
        ("noncondensable_pressure", np.float64),  # partial pressure in the condenser, Pa
    ]
)
"""The faults (:data:`FAULTS`) as the kernels read them."""

# regularisation widths and iteration counts of the split-unit kernels
FLOW_EPS = 1e-4  # kg/s, upwind weights and |ṁ| in pressure drops
SRC_EPS = 1e-5  # kg/s, sign of the charge-controller source
DP_REG = 2e4  # Pa, valve square root
TANK_WIDTH = 2e3  # J/kg, tank outlet smooth max
DP_ITERATIONS = 4  # secant steps for the flow through the lumped pressure drops
FILL_OUTLET_QUALITY = -0.15  # condenser outlet and liquid line at start-up, fill level >= 0

OUTPUTS = OutputLayout(
    {
        "TD": ("Compressor discharge temperature", "K"),
        "PD": ("Compressor discharge pressure", "Pa"),
        "TS": ("Compressor suction temperature", "K"),
        "PS": ("Compressor suction pressure", "Pa"),
        "TC": ("Condenser outlet refrigerant temperature", "K"),
        "PC": ("Condenser pressure", "Pa"),
        "TE": ("Evaporator outlet refrigerant temperature", "K"),
        "PE": ("Evaporator pressure", "Pa"),
        "MDOT": ("Compressor mass flow", "kg/s"),
    },
    {
        "Q_cond": ("Heat rejected by the condenser refrigerant", "W"),
        "Q_evap": ("Heat absorbed by the evaporator refrigerant", "W"),
        "W_comp": ("Compressor electrical power", "W"),
        "W_ref": ("Net compressor power to the refrigerant", "W"),
        "W_fans": ("Fan power", "W"),
        "M": ("Total refrigerant mass", "kg"),
        "mdot_src": ("Charge-controller mass source", "kg/s"),
        "mdot_valve": ("Expansion-valve mass flow", "kg/s"),
        "W_is": ("Compressor isentropic power", "W"),
        "Q_comp_amb": ("Compressor heat to the ambient (shell, drive, thermal limit)", "W"),
        "V_air_out": ("Outdoor-coil air flow", "m3/s"),
        "V_air_in": ("Indoor-coil air flow", "m3/s"),
        "tank_level": ("Suction-tank liquid volume fraction", "1"),
        "dp_cond": ("Condenser pressure drop", "Pa"),
        "dp_evap": ("Evaporator pressure drop", "Pa"),
        "dp_vap": ("Vapour-line pressure drop", "Pa"),
        "Q_latent": ("Latent heat of the indoor coil (condensation; 0 where it condenses)", "W"),
        "SHR": ("Sensible heat ratio of the indoor coil (1 where it condenses)", "1"),
    },
    optional=("W_comp",),
)
"""The nine outputs of the paper (coils named by their function in the mode), then the
diagnostics; field loggers measure the compressor's electrical power ``W_comp`` too, which
makes CF_POW observable."""

INERT_PARAMETERS: tuple[str, ...] = ("FO_SPEED", "FI_SPEED")
"""Table III parameters that change no output, by design: each fan runs at a fixed fraction of
its rated ("nominal") speed (``speed_fraction`` in the unit file), so the fan laws give its
flow and power from FO_FLOW/FO_POW (FI_...) alone. A separate rated speed against a fixed
running speed would only rescale those two parameters again, which made the box span
0.16-4.8 m³/s of outdoor air and 1.6 W-16 kW of fan power (models/README.md)."""


@functools.cache
def split_unit_dtype(layout: StateLayout) -> np.dtype:
    """The constants record type of a split-unit cycle with this state layout.

    One dtype object per layout (cached, as the layouts are): Numba's dispatcher knows a record
    argument's type by its dtype object, and a new but equal dtype in every simulation costs a
    deep dtype comparison (4 µs) on every kernel call."""
    return np.dtype(
        [
            ("layout", layout.dtype),
            ("condenser", COIL_RECORD),
            ("evaporator", COIL_RECORD),
            ("liquid_line", LINE_RECORD),
            ("vapor_line", LINE_RECORD),
            ("tank", TANK_RECORD),
            ("air_specific_heat", np.float64),  # J/(kg K)
            ("compressor", COMPRESSOR_RECORD),
            ("valve", VALVE_RECORD),
            ("controller", CONTROLLER_RECORD),
            ("faults", FAULT_RECORD),
        ]
    )


def split_unit_constants(
    unit: UnitDescription,
    theta: np.ndarray,
    layout: StateLayout,
    controller: bool | None,
    condenser_fan: Literal["outdoor", "indoor"],
    faults: np.ndarray | None = None,
) -> np.ndarray:
    """The constants record (a one-element structured array) of a split unit;
    ``condenser_fan`` says which fan (and Table III fan parameters, ``FO_*`` or ``FI_*``) serves
    the condenser, the other the evaporator; ``faults`` is ordered as :data:`FAULTS` (None: no
    fault)."""
    p = dict(zip((pid for pid, _ in PARAMETERS), np.asarray(theta, dtype=float), strict=True))
    fault = dict(
        zip(
            FAULTS.ids, FAULTS.nominal if faults is None else np.asarray(faults, float), strict=True
        )
    )
    n = unit.discretisation.n_volumes
    hw: SplitUnitHardware = unit.hardware
    fans = {
        "outdoor": fan_operating_point(
            p["FO_FLOW"],
            p["FO_POW"],
            p["FO_SPEED"],
            p["FO_SPEED"] * hw.outdoor_fan.speed_fraction,
        ),
        "indoor": fan_operating_point(
            p["FI_FLOW"], p["FI_POW"], p["FI_SPEED"], p["FI_SPEED"] * hw.indoor_fan.speed_fraction
        ),
    }
    evaporator_fan = "indoor" if condenser_fan == "outdoor" else "outdoor"
    f = hw.pressure_drop.darcy_friction_factor
    comp = hw.compressor
    enabled = unit.controller.enabled if controller is None else controller
    kp = unit.controller.kp if enabled else 0.0
    values = {
        "layout": layout.record,
        "condenser": _coil(hw, hw.condenser, p, "C", n, fans[condenser_fan]),
        "evaporator": _coil(hw, hw.evaporator, p, "E", n, fans[evaporator_fan]),
        "liquid_line": {
            "volume": pipe_volume(p["L_LIQ"], hw.liquid_line.inner_diameter),
            "friction": friction_coefficient(f, p["L_LIQ"], hw.liquid_line.inner_diameter),
        },
        "vapor_line": {
            "volume": pipe_volume(p["L_VAP"], hw.vapor_line.inner_diameter),
            "friction": friction_coefficient(f, p["L_VAP"], hw.vapor_line.inner_diameter),
        },
        "tank": {
            "volume": hw.suction_tank.volume,
            "bleed_fraction_full": hw.suction_tank.bleed_fraction_full,
        },
        "air_specific_heat": hw.air.specific_heat,
        "compressor": {
            "displacement": comp.displacement,
            "clearance": comp.clearance,
            "exponent": comp.polytropic_exponent,
            "isentropic_efficiency": comp.isentropic_efficiency,
            "loss_share": comp.loss_share_to_refrigerant,
            "shell_ua": comp.shell_ua,
            "cf_vol": p["CF_VOL"],
            "cf_pow": p["CF_POW"],
            "cf_pref": p["CF_PREF"],
            "cf_shell": p["CF_SHELL"],
            "valve_leakage": fault["F_LEAK"],
            "T_discharge_max": comp.max_discharge_temperature,
            "p_protection_start": comp.protection_pressure_start,
            "p_protection_stop": comp.protection_pressure_stop,
        },
        "valve": {"flow_area": hw.expansion_valve.flow_area, "cf_lev": p["CF_LEV"]},
        "controller": {"kp": kp, "ki": kp * kp / 4.0, "m0": p["M0"]},
        "faults": {
            "restriction": rated_drop_coefficient(
                fault["DP_RESTR"],
                hw.condenser.nominal_mass_flow,
                rated_liquid_density(unit.refrigerant),
            ),
            "noncondensable_pressure": fault["P_NCG"],
        },
    }
    return record_array(split_unit_dtype(layout), values)


def air_conductance(
    constants: np.ndarray, coil: Literal["condenser", "evaporator"], n_cells: int
) -> float:
    """A coil's effective air-side conductance in a constants record, W/K: n C (1 − e^(−hA/C))
    over its ``n_cells`` cells, the heat its air takes per kelvin between the inlet air and the
    wall. Fouling (its HTC) and airflow (its fan's flow) both lower it; the data see it, not
    each of the two (the air side's ε-NTU, models/README.md)."""
    record = constants[0][coil]
    capacity = float(record["air_capacity"])
    effectiveness = air_effectiveness(capacity, float(record["htc_air"]), float(record["air_area"]))
    return n_cells * capacity * effectiveness


@functools.cache
def rated_liquid_density(refrigerant: str) -> float:
    """Density of saturated liquid at :data:`RESTRICTION_RATING_T`, kg/m³: the fluid of a
    liquid-line restriction's rated drop."""
    tables = load_refrigerant(refrigerant).tables
    return float(saturation_state(tables, p_sat_from_T(tables, RESTRICTION_RATING_T))[3])


def _coil(
    hw: SplitUnitHardware,
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
    drop = hw.pressure_drop
    friction = friction_coefficient(
        drop.darcy_friction_factor * drop.coil_multiplier,
        length,
        hx.tube_inner_diameter,
        hx.n_paths,
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
        "air_flow": flow,
        "air_capacity": air_capacity_rate(flow, hw.air.density, hw.air.specific_heat) / n,
        "fan_power": power,
        "friction": p[f"CF_DP{side}"] * friction,
    }


@njit(cache=True, error_model="numpy")
def suction_outlet(sat_e, h_tank, rho_tank, c):
    """(enthalpy leaving the suction tank J/kg, its liquid level -): vapour carrying the bleed
    liquid, the more the fuller the tank; ``sat_e`` is the
    :func:`~pymc_vcc.physics.refrigerant.saturation_point` of the tank's pressure."""
    level = liquid_level(rho_tank, sat_e.rho_l, sat_e.rho_v)
    h_out = tank_outlet_enthalpy(
        h_tank, sat_e.h_l, sat_e.h_v, level, c.tank.bleed_fraction_full, TANK_WIDTH
    )
    return h_out, level


@njit(cache=True, error_model="numpy")
def lumped_drops(
    flow, p_high, p_e, rho_vapor_line, rho_friction_c, rho_friction_e, c, hot_gas_line
):
    """(p_s, p_d, Δp_cond, Δp_evap, Δp_vap), Pa, when ``flow`` (kg/s) passes the lumped drops:
    the condenser's before the high-side pressure ``p_high`` (the condensing pressure, plus the
    partial pressure of any non-condensable gas), the evaporator's after the evaporating one;
    the vapour line's on the discharge side when it carries the hot gas (``hot_gas_line``,
    heating), on the suction side otherwise (cooling). ``rho_friction_*`` are the coils'
    friction densities (mean specific volume), ``rho_vapor_line`` the line's density."""
    dp_cond = pressure_drop(c.condenser.friction, flow, rho_friction_c, FLOW_EPS)
    dp_evap = pressure_drop(c.evaporator.friction, flow, rho_friction_e, FLOW_EPS)
    dp_vap = pressure_drop(c.vapor_line.friction, flow, rho_vapor_line, FLOW_EPS)
    if hot_gas_line:
        return p_e - dp_evap, p_high + dp_cond + dp_vap, dp_cond, dp_evap, dp_vap
    return p_e - dp_evap - dp_vap, p_high + dp_cond, dp_cond, dp_evap, dp_vap


@njit(cache=True, error_model="numpy")
def flow_through_drops(
    p_high,
    p_e,
    rho_out,
    drho_dp_out,
    rho_vapor_line,
    rho_friction_c,
    rho_friction_e,
    speed,
    c,
    hot_gas_line,
):
    """The compressor flow that, passing the lumped drops (:func:`lumped_drops`), sets the
    suction and discharge pressures that give that flow, kg/s: the secant method on g(ṁ) - ṁ
    from ṁ = 0, with g the compressor's flow at the pressures ṁ causes (g decreases with ṁ, so
    the root is unique). The suction density is ρ at the tank outlet (``rho_out``, slope
    ``drho_dp_out`` in pressure), linear in the drop (second-order error)."""
    comp = c.compressor

    def compressor_flow(flow):
        p_s, p_d = lumped_drops(
            flow, p_high, p_e, rho_vapor_line, rho_friction_c, rho_friction_e, c, hot_gas_line
        )[:2]
        eta = volumetric_efficiency(p_d / p_s, comp.clearance, comp.exponent, comp.cf_vol)
        rho_s = rho_out + drho_dp_out * (p_s - p_e)
        displaced = compressor_mass_flow(rho_s, speed, comp.displacement, eta)
        return delivered_mass_flow(displaced, comp.valve_leakage)

    m_a = 0.0
    r_a = compressor_flow(m_a)
    m_b = r_a
    r_b = compressor_flow(m_b) - m_b
    for _ in range(DP_ITERATIONS):
        if m_b == m_a or r_b == r_a:
            break
        m_a, r_a, m_b = m_b, r_b, m_b - r_b * (m_b - m_a) / (r_b - r_a)
        r_b = compressor_flow(m_b) - m_b
    return m_b


@njit(cache=True, error_model="numpy", inline="always")
def coil_cell_heat(tables, sat, p, coil, T_wall, scale, h_in, x_in, T_in, h, x, T):
    """Heat from the wall to one coil cell's refrigerant, W: the cell-mean flux, its enthalpy
    running linearly from its inlet (``h_in``, ``x_in``, ``T_in``) to its own state (``h``,
    ``x``, ``T``) at pressure ``p`` (saturation point ``sat``) and flow ``scale``
    (:func:`~pymc_vcc.physics.components.heat_transfer.flow_scale`), by
    :func:`~pymc_vcc.physics.components.heat_transfer.cell_heat` on each stretch between the
    :data:`~pymc_vcc.physics.components.heat_transfer.FLUX_KINKS` it holds, weighted by
    length.

    A cell spanning a blend or a saturation line so sees the exact mix of the phases' fluxes,
    which changes as smoothly as its inlet and outlet do. With one Simpson rule over the whole
    cell, its middle point switched most of the cell between two coefficients as it crossed
    a blend (in a flooded condenser whose first cell holds the whole of desuperheating and
    condensation: a limit cycle at N = 10).
    """
    rising = x >= x_in
    total = 0.0
    h_a, x_a, T_a = h_in, x_in, T_in
    for k in range(len(FLUX_KINKS) + 1):
        if k < len(FLUX_KINKS):
            edge = FLUX_KINKS[k if rising else len(FLUX_KINKS) - 1 - k]
            if (edge - x_a) * (x - edge) <= 0.0:
                continue  # not strictly ahead of this stretch's start and before the outlet
            x_b = edge
            h_b = h_in + (edge - x_in) / (x - x_in) * (h - h_in)
            T_b = state_values_at(tables, sat, p, h_b)[0]
        else:
            h_b, x_b, T_b = h, x, T
        T_mid = state_values_at(tables, sat, p, 0.5 * (h_a + h_b))[0]
        weight = (h_b - h_a) / (h - h_in) if h != h_in else 1.0
        total += weight * cell_heat(
            T_wall,
            coil.refrigerant_area,
            x_a,
            x_b,
            T_a,
            T_mid,
            T_b,
            coil.htc_liquid,
            coil.htc_two_phase,
            coil.htc_vapor,
            scale,
        )
        h_a, x_a, T_a = h_b, x_b, T_b
    return total


@njit(cache=True, error_model="numpy")
def coil_friction_density(rho, n):
    """Density of homogeneous friction along a coil of ``n`` cells of densities ``rho``, kg/m³:
    the inverse of their mean specific volume."""
    volume = 0.0
    for i in range(n):
        volume += 1.0 / rho[i]
    return n / volume


@njit(cache=True, error_model="numpy")
def filled_coils(s, p_c, p_e, at, tables):
    """A running-cycle state at pressures p_c, p_e (Pa), all but the vapour line, whose charge
    grows monotonically with the fill level ``s`` in [-1, 2]: s < 0 leaves the condenser outlet
    and liquid line two-phase (up to quality 0.3), s in [0, 1] moves the end of condensation
    from the outlet to a fifth of the coil, s > 1 fills the suction tank with liquid. Walls
    start at the fluid temperature; ``at`` is the layout record (the vapour line is the cycle
    module's: its zone differs between the modes)."""
    n = at.h_liquid_line - at.h_cond
    y = np.zeros(at.size)
    x_end = FILL_OUTLET_QUALITY + 0.45 * max(-s, 0.0)
    reach = 1.0 - 0.8 * min(max(s, 0.0), 1.0)
    sat_c, sat_e = saturation_point(tables, p_c), saturation_point(tables, p_e)
    y[at.p_cond] = p_c
    for i in range(n):
        xi = (i + 0.5) / n
        x = max(1.05 - (1.05 - x_end) * xi / reach, x_end)
        y[at.h_cond + i] = quality_enthalpy_at(sat_c, x)
        y[at.Tw_cond + i] = state_at(tables, sat_c, p_c, y[at.h_cond + i])[0]
    y[at.h_liquid_line] = quality_enthalpy_at(sat_c, x_end)
    y[at.p_evap] = p_e
    x_in = (y[at.h_liquid_line] - sat_e.h_l) / (sat_e.h_v - sat_e.h_l)
    for i in range(n):
        xi = (i + 0.5) / n
        y[at.h_evap + i] = quality_enthalpy_at(sat_e, x_in + (1.05 - x_in) * xi)
        y[at.Tw_evap + i] = state_at(tables, sat_e, p_e, y[at.h_evap + i])[0]
    y[at.h_tank] = quality_enthalpy_at(sat_e, 1.05 - 1.1 * min(max(s - 1.0, 0.0), 1.0))
    return y
