"""Each component on its own: zero input, conservation, a hand-checked number."""

import math

import numpy as np
import pytest

from pymc_vcc.physics.components.compressor import (
    COMPRESSOR_RECORD,
    compressor,
    compressor_mass_flow,
    electrical_power,
    loss_share_to_refrigerant,
    protection_speed_factor,
    shell_loss,
    volumetric_efficiency,
)
from pymc_vcc.physics.components.density import (
    QUALITY_BAND,
    cell_state,
    cell_values,
    fillet_memo,
)
from pymc_vcc.physics.components.expansion_valve import valve_mass_flow
from pymc_vcc.physics.components.fan import air_inlet_temperature, fan_operating_point
from pymc_vcc.physics.components.heat_exchanger import zone_derivatives, zone_pair_derivatives
from pymc_vcc.physics.components.heat_transfer import (
    LIQUID_BLEND,
    air_effectiveness,
    air_side_heat,
    cell_heat,
    flow_scale,
    refrigerant_htc,
)
from pymc_vcc.physics.components.moist_air import (
    humidity_ratio,
    latent_heat,
    saturation_pressure_water,
)
from pymc_vcc.physics.components.pipe import (
    friction_coefficient,
    pipe_volume,
    pressure_drop,
    rated_drop_coefficient,
)
from pymc_vcc.physics.components.smooth import (
    signed_sqrt,
    smooth_max,
    smooth_pos,
    smooth_step,
    soft_cap,
)
from pymc_vcc.physics.components.suction_tank import liquid_level, tank_outlet_enthalpy
from pymc_vcc.physics.cycles.split_unit import COIL_RECORD, coil_cell_heat
from pymc_vcc.physics.records import make_record
from pymc_vcc.physics.refrigerant import (
    entropy,
    h_from_ps,
    load_refrigerant,
    saturation_point,
    saturation_state,
    state,
)


@pytest.fixture(scope="module")
def tables():
    return load_refrigerant("R410A").tables


def test_smooth_helpers():
    assert smooth_pos(0.0, 2.0) == 1.0
    assert smooth_pos(100.0, 1e-3) == pytest.approx(100.0)
    assert smooth_pos(-100.0, 1e-3) == pytest.approx(0.0, abs=1e-8)
    assert smooth_max(1.0, 3.0, 0.1) >= 3.0
    assert signed_sqrt(-4.0, 1e-6) == pytest.approx(-2.0)
    assert signed_sqrt(0.0, 1.0) == 0.0
    assert smooth_step(-1.0) == 0.0 and smooth_step(0.5) == 0.5 and smooth_step(2.0) == 1.0


def test_fan_laws():
    assert fan_operating_point(0.6, 80.0, 1600.0, 1600.0) == (0.6, 80.0)
    flow, power = fan_operating_point(0.6, 80.0, 1600.0, 3200.0)
    assert flow == pytest.approx(1.2) and power == pytest.approx(640.0)
    assert air_inlet_temperature(300.0, 0.0, 500.0) == 300.0
    assert air_inlet_temperature(300.0, 1000.0, 1000.0) == pytest.approx(301.0)


def test_pipe_volume_and_friction_by_hand():
    assert pipe_volume(20.0, 4.83e-3) == pytest.approx(20.0 * math.pi / 4 * 4.83e-3**2)
    area = math.pi / 4 * 0.01**2
    k = friction_coefficient(0.02, 10.0, 0.01)
    assert k == pytest.approx(0.02 * 1000.0 / (2 * area**2))
    assert pressure_drop(k, 0.0, 1000.0, 1e-4) == 0.0
    assert pressure_drop(k, -0.02, 40.0, 1e-6) == pytest.approx(-pressure_drop(k, 0.02, 40.0, 1e-6))
    # Δp = f L/D ρ v²/2 with v = ṁ/(ρ A)
    velocity = 0.02 / (40.0 * area)
    assert pressure_drop(k, 0.02, 40.0, 1e-9) == pytest.approx(
        0.02 * 1000.0 * 40.0 * velocity**2 / 2, rel=1e-6
    )


def test_valve_by_hand_and_in_series_with_the_line():
    assert valve_mass_flow(0.0, 1e-6, 1.0, 1000.0, 1e6, 0.0, 1e4) == 0.0
    flow = valve_mass_flow(0.5, 1e-6, 1.0, 1000.0, 1e6, 0.0, 1e4)
    # the square root is regularised below 1e4 Pa: 2.5e-5 relative at 1e6 Pa
    assert flow == pytest.approx(0.5e-6 * math.sqrt(2 * 1000.0 * 1e6), rel=1e-4)
    assert valve_mass_flow(0.5, 1e-6, 1.0, 1000.0, -1e6, 0.0, 1e4) == pytest.approx(-flow)
    assert valve_mass_flow(0.5, 1e-6, 1.4, 1000.0, 1e6, 0.0, 1e4) == pytest.approx(1.4 * flow)
    k_line = 3e9
    series = valve_mass_flow(0.5, 1e-6, 1.0, 1000.0, 1e6, k_line, 1e4)
    dp_line = k_line * series**2 / 1000.0
    dp_valve = (series / 0.5e-6) ** 2 / (2 * 1000.0)
    assert dp_line + dp_valve == pytest.approx(1e6, rel=1e-4)


def test_a_restriction_drops_its_rated_drop_and_scales_as_an_orifice():
    k = rated_drop_coefficient(1.5e5, 0.021, 1000.0)
    assert pressure_drop(k, 0.021, 1000.0, 0.0) == pytest.approx(1.5e5, rel=1e-12)
    # the same restriction at half the flow of flashing liquid of half the density
    assert pressure_drop(k, 0.0105, 500.0, 0.0) == pytest.approx(1.5e5 / 4 * 2, rel=1e-12)
    assert rated_drop_coefficient(0.0, 0.021, 1000.0) == 0.0


def test_a_liquid_line_restriction_lowers_the_valve_flow_monotonically():
    """The cycle adds the restriction's K to the liquid line's in series with the valve: at 0
    the flow is the line's alone exactly, and every larger restriction passes less."""
    args = (0.4, 9e-7, 1.0, 1000.0, 17e5)
    k_line = 3e9
    alone = valve_mass_flow(*args, k_line, 2e4)
    drops = [0.0, 1e3, 1e4, 5e4, 1e5, 2e5, 3e5]
    flows = [
        valve_mass_flow(*args, k_line + rated_drop_coefficient(dp, 0.021, 1000.0), 2e4)
        for dp in drops
    ]
    assert flows[0] == alone
    assert np.all(np.diff(flows) < 0.0)
    # line, restriction and orifice in series take the whole pressure difference
    flow = flows[-1]
    restricted = rated_drop_coefficient(3e5, 0.021, 1000.0)
    dp_valve = (flow / (0.4 * 9e-7)) ** 2 / (2 * 1000.0)
    dp_series = (k_line + restricted) * flow**2 / 1000.0
    assert dp_series + dp_valve == pytest.approx(17e5, rel=1e-4)


def test_compressor_pieces_by_hand():
    assert volumetric_efficiency(1.0, 0.04, 1.1, 1.0) == pytest.approx(1.0, abs=1e-4)
    loss = 0.04 * (3.0 ** (1 / 1.1) - 1)
    assert volumetric_efficiency(3.0, 0.04, 1.1, 1.2) == pytest.approx(1 - 1.2 * loss, rel=1e-4)
    # CF_VOL scales the losses: never above 1 at the top of its range, floored at 0.02
    assert volumetric_efficiency(3.0, 0.04, 1.1, 1.5) < 1.0
    assert 0.02 <= volumetric_efficiency(40.0, 0.04, 1.1, 1.5) < 0.03
    assert compressor_mass_flow(37.0, 55.0, 11.5e-6, 0.9) == pytest.approx(0.9 * 37 * 11.5e-6 * 55)
    assert electrical_power(600.0, 0.72, 1.0) == pytest.approx(600.0 / 0.72)
    assert electrical_power(600.0, 0.72, 0.0) == 600.0  # no losses: isentropic work
    assert electrical_power(0.0, 0.72, 1.0) == 0.0
    assert loss_share_to_refrigerant(0.5, 1.0) == 0.5
    assert loss_share_to_refrigerant(0.5, 3.0) == pytest.approx(0.75)  # odds 1 -> 3
    assert 0.0 < loss_share_to_refrigerant(0.9, 0.3) < loss_share_to_refrigerant(0.9, 1.5) < 1.0
    assert shell_loss(2.0, 1.0, 300.0, 350.0, 100.0) == pytest.approx(0.0, abs=0.02)
    assert shell_loss(2.0, 1.0, 350.0, 300.0, 1e6) == pytest.approx(100.0, rel=1e-4)
    assert shell_loss(2.0, 1.5, 400.0, 300.0, 50.0) < 50.0  # capped by the heat in the gas


def _compressor(**changes):
    """A compressor record of the built-in unit's class, with some fields changed."""
    values = {
        "displacement": 11.5e-6,
        "clearance": 0.04,
        "exponent": 1.1,
        "isentropic_efficiency": 0.72,
        "loss_share": 0.5,
        "shell_ua": 2.0,
        "cf_vol": 1.0,
        "cf_pow": 1.0,
        "cf_pref": 1.0,
        "cf_shell": 1.0,
        "valve_leakage": 0.0,
        "T_discharge_max": 430.0,
        "p_protection_start": 41e5,
        "p_protection_stop": 46e5,
    }
    return make_record(COMPRESSOR_RECORD, values | changes)


def _compress(tables, cf_vol, cf_pow, cf_pref, cf_shell, t_max=430.0, leakage=0.0):
    p_s, p_d, h_s = 9.5e5, 27.5e5, 4.30e5
    rho_s = state(tables, p_s, h_s)[1]
    params = _compressor(
        cf_vol=cf_vol,
        cf_pow=cf_pow,
        cf_pref=cf_pref,
        cf_shell=cf_shell,
        T_discharge_max=t_max,
        valve_leakage=leakage,
    )
    suction, discharge = saturation_point(tables, p_s), saturation_point(tables, p_d)
    return h_s, compressor(tables, p_s, suction, h_s, rho_s, p_d, discharge, 55.0, 308.15, params)


def test_compressor_by_hand(tables):
    h_s, (m, h_d, power, net, w_is, ambient) = _compress(tables, 1.0, 1.0, 1.0, 0.0)
    h_is = h_from_ps(tables, 27.5e5, entropy(tables, 9.5e5, h_s))
    assert w_is == pytest.approx(m * (h_is - h_s), rel=1e-5)  # Δh_s smoothly floored at 0
    assert power == pytest.approx(w_is / 0.72, rel=1e-9)
    # no shell loss: half the losses heat the gas, the other half leave to the ambient
    assert net == pytest.approx(w_is + 0.5 * (power - w_is), rel=1e-3)
    assert net + ambient == pytest.approx(power, rel=1e-12)
    assert m * (h_d - h_s) == pytest.approx(net, rel=1e-12)
    assert 0.015 < m < 0.025


def test_leaking_valves_deliver_less_and_hotter_gas_for_the_same_power(tables):
    """A share f of the displaced gas leaks back: the delivered flow is (1 - f) of the sound
    compressor's, the power is the same (all the gas is compressed), and the work on the gas
    that leaked back heats the gas delivered; both laws hold."""
    h_s, (m, h_d, power, _, w_is, _) = _compress(tables, 1.0, 1.0, 1.0, 1.0)
    _, (m_f, h_d_f, power_f, net_f, w_is_f, ambient_f) = _compress(
        tables, 1.0, 1.0, 1.0, 1.0, leakage=0.25
    )
    assert m_f == pytest.approx(0.75 * m, rel=1e-12)
    assert power_f == pytest.approx(power, rel=1e-12)
    assert w_is_f == pytest.approx(0.75 * w_is, rel=1e-12)  # of the gas delivered
    assert h_d_f - h_s > (h_d - h_s) / 0.75 * 0.95  # hotter: nearly all the work in less gas
    assert net_f + ambient_f == pytest.approx(power_f, rel=1e-12)
    assert m_f * (h_d_f - h_s) == pytest.approx(net_f, rel=1e-12)
    assert net_f >= w_is_f  # the delivered gas leaves above its isentropic state


@pytest.mark.parametrize("cf_vol", [0.5, 1.5])
@pytest.mark.parametrize("cf_pow", [0.3, 1.0, 2.0])
@pytest.mark.parametrize("cf_pref", [0.3, 1.5])
@pytest.mark.parametrize("cf_shell", [0.3, 1.5])
@pytest.mark.parametrize("leakage", [0.0, 0.5])
def test_compressor_laws_at_the_corners_of_the_box(
    tables, cf_vol, cf_pow, cf_pref, cf_shell, leakage
):
    h_s, (_, h_d, power, net, w_is, ambient) = _compress(
        tables, cf_vol, cf_pow, cf_pref, cf_shell, leakage=leakage
    )
    h_is = h_from_ps(tables, 27.5e5, entropy(tables, 9.5e5, h_s))
    assert net <= power  # first law: no more to the refrigerant than the drive takes
    assert h_d >= h_is  # second law: discharge never below the isentropic state
    assert ambient >= 0.0  # shell and drive losses leave, never enter
    assert power >= w_is


def test_cf_pow_and_cf_pref_have_distinct_signatures(tables):
    _, base = _compress(tables, 1.0, 1.0, 1.0, 1.0)
    _, more_power = _compress(tables, 1.0, 1.3, 1.0, 1.0)
    _, more_to_gas = _compress(tables, 1.0, 1.0, 1.3, 1.0)
    assert more_power[1] > base[1] and more_to_gas[1] > base[1]  # both heat the discharge
    assert more_power[2] > base[2]  # only CF_POW draws more electrical power
    assert more_to_gas[2] == pytest.approx(base[2], rel=1e-12)


def test_compressor_thermal_limit_keeps_the_second_law(tables):
    h_s, (_, h_free, *_) = _compress(tables, 1.0, 2.0, 1.5, 0.3)
    _, (_, h_capped, *_) = _compress(tables, 1.0, 2.0, 1.5, 0.3, t_max=350.0)
    h_is = h_from_ps(tables, 27.5e5, entropy(tables, 9.5e5, h_s))
    assert state(tables, 27.5e5, h_capped)[0] < 351.0 < state(tables, 27.5e5, h_free)[0]
    assert h_capped >= h_is


def test_protection_speed_factor():
    assert protection_speed_factor(30e5, 41e5, 46e5) == 1.0
    assert protection_speed_factor(43.5e5, 41e5, 46e5) == pytest.approx(1 - 0.95 / 2)
    assert protection_speed_factor(47e5, 41e5, 46e5) == pytest.approx(0.05)


def test_refrigerant_htc_blend():
    args = (300.0, 3000.0, 800.0, flow_scale(1.0))
    assert refrigerant_htc(-0.1, *args) == pytest.approx(300.0, rel=2e-3)
    assert refrigerant_htc(0.6, *args) == pytest.approx(3000.0, rel=2e-3)
    assert refrigerant_htc(1.1, *args) == pytest.approx(800.0, rel=2e-3)
    mid = sum(LIQUID_BLEND) / 2  # halfway up the smooth step
    assert refrigerant_htc(mid, *args) == pytest.approx(1650.0, rel=2e-3)
    xs = np.linspace(-0.2, 1.2, 2801)
    values = np.array([refrigerant_htc(x, *args) for x in xs])
    assert np.max(np.abs(np.diff(values))) < 3000.0 * 0.01  # continuous
    half = refrigerant_htc(0.6, 300.0, 3000.0, 800.0, flow_scale(0.5))
    assert half == pytest.approx(3000.0 * math.sqrt(0.25 + 0.0025) ** 0.8)
    assert flow_scale(0.0) == pytest.approx(0.05**0.8)  # the wall never decouples


def test_air_side_heat_limits():
    assert air_side_heat(500.0, 300.0, 300.0, air_effectiveness(500.0, 60.0, 10.0)) == 0.0
    large = air_effectiveness(500.0, 1e6, 10.0)
    assert air_side_heat(500.0, 310.0, 300.0, large) == pytest.approx(500.0 * 10.0)
    small = air_effectiveness(1e9, 60.0, 10.0)
    assert air_side_heat(1e9, 310.0, 300.0, small) == pytest.approx(60.0 * 10.0 * 10.0, 1e-6)


def test_tank_outlet(tables):
    _, h_l, h_v, _, _ = saturation_state(tables, 1e6)
    # superheated content leaves as it is (smooth max: off by width²/(4 distance) = 33 J/kg)
    assert tank_outlet_enthalpy(h_v + 30e3, h_l, h_v, 0.0, 0.3, 2e3) == pytest.approx(
        h_v + 30e3, abs=40.0
    )
    # a dry tank delivers saturated vapour; the bleed wets the outflow with the level
    assert tank_outlet_enthalpy(h_v - 1e3, h_l, h_v, 0.0, 0.3, 2e3) == pytest.approx(h_v, abs=1e3)
    wet = tank_outlet_enthalpy(h_l + 0.2 * (h_v - h_l), h_l, h_v, 0.5, 0.3, 2e3)
    assert wet == pytest.approx(h_v - 0.15 * (h_v - h_l), abs=20.0)
    levels = [0.0, 0.1, 0.2, 0.4]
    outlets = [tank_outlet_enthalpy(h_l, h_l, h_v, lv, 0.3, 2e3) for lv in levels]
    assert np.all(np.diff(outlets) < 0)  # more liquid, wetter suction


def test_liquid_level_by_the_lever_rule(tables):
    _, _, _, rho_l, rho_v = saturation_state(tables, 1e6)
    assert liquid_level(rho_l, rho_l, rho_v) == pytest.approx(1.0, abs=1e-3)
    assert liquid_level(rho_v, rho_l, rho_v) == pytest.approx(0.0, abs=1e-3)
    assert liquid_level(0.8 * rho_v, rho_l, rho_v) == pytest.approx(0.0, abs=1e-4)  # superheated
    half = 0.5 * (rho_l + rho_v)
    assert liquid_level(half, rho_l, rho_v) == pytest.approx(0.5, abs=1e-5)


def test_cell_heat_averages_flux_over_the_cell():
    htcs = (300.0, 3000.0, 800.0, flow_scale(1.0))
    # a cell all in one phase at one temperature: α A (T_w - T)
    assert cell_heat(310.0, 2.0, 0.5, 0.6, 300.0, 300.0, 300.0, *htcs) == pytest.approx(
        3000.0 * 2.0 * 10.0, rel=2e-3
    )
    assert cell_heat(300.0, 2.0, 0.5, 0.6, 300.0, 300.0, 300.0, *htcs) == 0.0  # no driving ΔT
    # a cell that holds the dew point sees a mix of the vapour and two-phase fluxes
    mixed = cell_heat(300.0, 1.0, 1.2, 0.7, 330.0, 315.0, 310.0, *htcs)
    assert -3000.0 * 20.0 < mixed < -800.0 * 10.0
    # Simpson's rule by hand
    a_out = refrigerant_htc(0.7, *htcs)
    by_hand = (800.0 * -30.0 + 4 * refrigerant_htc(0.95, *htcs) * -15.0 + a_out * -10.0) / 6.0
    assert mixed == pytest.approx(by_hand, rel=2e-3)


def test_coil_cell_heat_is_exact_across_blends_and_saturation_lines(tables):
    # a flooded condenser's first cell: superheated inlet, subcooled outlet, all phases
    p = 27e5
    _, h_l, h_v, _, _ = saturation_state(tables, p)
    coil = make_record(
        COIL_RECORD,
        {name: 0.0 for name in COIL_RECORD.names}
        | {"refrigerant_area": 1.0, "htc_liquid": 2000.0, "htc_two_phase": 12000.0}
        | {"htc_vapor": 1000.0},
    )

    def quality(h):
        return (h - h_l) / (h_v - h_l)

    h_in, h_out, T_wall = h_v + 40e3, h_l - 5e3, 300.0
    fine = np.linspace(h_in, h_out, 20001)
    flux = [
        refrigerant_htc(quality(h), 2000.0, 12000.0, 1000.0, flow_scale(1.0))
        * (T_wall - state(tables, p, h)[0])
        for h in fine
    ]
    exact = np.trapezoid(flux, fine) / (h_out - h_in)
    ends = [(h, quality(h), state(tables, p, h)[0]) for h in (h_in, h_out)]
    heat = coil_cell_heat(
        tables, saturation_point(tables, p), p, coil, T_wall, flow_scale(1.0), *ends[0], *ends[1]
    )
    assert heat == pytest.approx(exact, rel=1e-4)
    # one Simpson rule over the whole cell is 8 % off (its middle is two-phase)
    T_mid = state(tables, p, 0.5 * (h_in + h_out))[0]
    htcs = (2000.0, 12000.0, 1000.0, flow_scale(1.0))
    one_rule = cell_heat(T_wall, 1.0, ends[0][1], ends[1][1], ends[0][2], T_mid, ends[1][2], *htcs)
    assert abs(one_rule / exact - 1) > 0.05
    # a cell inside one smooth stretch is the plain rule
    inside = [(h, quality(h), state(tables, p, h)[0]) for h in (h_l + 2e4, h_l + 4e4)]
    mid = state(tables, p, h_l + 3e4)[0]
    plain = cell_heat(
        T_wall,
        1.0,
        inside[0][1],
        inside[1][1],
        inside[0][2],
        mid,
        inside[1][2],
        2000.0,
        12000.0,
        1000.0,
        1.0,
    )
    assert coil_cell_heat(
        tables, saturation_point(tables, p), p, coil, T_wall, 1.0, *inside[0], *inside[1]
    ) == pytest.approx(plain, rel=1e-12)

    # proportional to the flow scale, across every stretch: the Jacobian rescales a remembered
    # heat when a column moves the flows alone
    for scale in (0.05, 0.37, 2.0):
        assert coil_cell_heat(
            tables, saturation_point(tables, p), p, coil, T_wall, scale, *ends[0], *ends[1]
        ) == pytest.approx(scale * heat / flow_scale(1.0), rel=1e-14)


def test_soft_cap():
    assert soft_cap(0.0, 1.0) == 0.0
    assert soft_cap(0.3, 1.0) == pytest.approx(0.3, rel=0.003)
    assert soft_cap(100.0, 1.0) == pytest.approx(1.0, rel=1e-6)
    xs = np.linspace(0.0, 5.0, 101)
    capped = np.array([soft_cap(x, 1.0) for x in xs])
    assert np.all(capped <= np.minimum(xs, 1.0) + 1e-15) and np.all(np.diff(capped) > 0)


def test_moist_air_by_hand():
    # 27 degC, 50 % RH: humidity ratio 0.0112 kg/kg (ASHRAE psychrometric chart)
    assert humidity_ratio(300.15, 0.5) == pytest.approx(0.0112, abs=1e-4)
    assert saturation_pressure_water(293.15) == pytest.approx(2339.2, rel=0.004)  # steam tables
    assert humidity_ratio(300.15, 0.0) == 0.0
    # a wall above the dew point (15.7 degC here) stays dry; below it, latent heat flows
    assert latent_heat(200.0, 1006.0, 0.0112, 293.15, 60.0, 1.0) == pytest.approx(0.0, abs=0.01)
    wet = latent_heat(200.0, 1006.0, 0.0112, 283.15, 60.0, 1.0)
    W_wall = humidity_ratio(283.15, 1.0)
    effectiveness = 1 - math.exp(-60.0 / 200.0)
    assert wet == pytest.approx(200.0 / 1006.0 * 2.45e6 * (0.0112 - W_wall) * effectiveness, 0.01)


def _cell(tables, p, h):
    """:func:`cell_state` with a fresh memo: nothing carried over from another call."""
    return cell_state(tables, saturation_point(tables, p), p, h, fillet_memo())


def test_cell_state_memo_is_exact_across_cells_and_pressures(tables):
    """One memo shared by the cells of both zones (as in a right-hand side) gives bit for bit
    what a fresh memo gives, in and out of both bands, as the pressure alternates."""
    memo = fillet_memo()
    for p in (2.7e6, 1.0e6, 2.7e6, 1.0e6 * (1 + 1e-7)):
        _, h_l, h_v, _, _ = saturation_state(tables, p)
        for x in (-0.15, -0.05, 0.0, 0.04, 0.5, 0.93, 1.0, 1.06, 1.2):
            h = h_l + x * (h_v - h_l)
            assert cell_state(tables, saturation_point(tables, p), p, h, memo) == _cell(
                tables, p, h
            )


def test_cell_values_are_the_cell_state_without_its_slopes(tables):
    """The outputs' and the charge's cheaper lookup gives bit for bit the T, ρ and x of the
    full one, in and out of both bands and outside the tables, sharing a memo with it either
    way round."""
    memo = fillet_memo()
    for p in (2.7e6, 1.0e6, 2.7e6, 1.0e6 * (1 + 1e-7), 4.6e6):
        _, h_l, h_v, _, _ = saturation_state(tables, p)
        sat = saturation_point(tables, p)
        for x in (-0.6, -0.15, -0.05, 0.0, 0.04, 0.5, 0.93, 1.0, 1.06, 1.2, 1.5):
            h = h_l + x * (h_v - h_l)
            T, rho, _, _, quality = _cell(tables, p, h)
            np.testing.assert_array_equal(cell_values(tables, sat, p, h, memo), (T, rho, quality))
            np.testing.assert_array_equal(cell_state(tables, sat, p, h, memo)[1], rho)


def _zone(tables, p, hs):
    props = np.array([_cell(tables, p, h) for h in hs])
    return props[:, 1].copy(), props[:, 2].copy(), props[:, 3].copy()


def test_zone_steady_uniform_flow_is_at_rest(tables):
    h = np.full(5, 4.3e5)
    rho, rp, rh = _zone(tables, 1e6, h)
    dh = np.empty(5)
    dp = zone_derivatives(np.full(5, 1e-4), rho, rp, rh, h, np.zeros(5), 0.02, 0.02, 1e-4, dh)
    assert dp == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(dh, 0.0, atol=1e-9)


@pytest.mark.parametrize(("inflow", "outflow"), [(0.03, 0.02), (-0.01, 0.02), (0.02, -0.005)])
def test_zone_conserves_mass(tables, inflow, outflow):
    h = np.array([4.4e5, 3.8e5, 2.9e5, 2.2e5, 2.1e5])
    volume = np.array([1e-4, 1e-4, 1e-4, 1e-4, 4e-4])
    rho, rp, rh = _zone(tables, 2.7e6, h)
    source = np.array([-300.0, -500.0, -400.0, -100.0, 0.0])
    dh = np.empty(5)
    dp = zone_derivatives(volume, rho, rp, rh, h, source, inflow, outflow, 1e-4, dh)
    stored = np.sum(volume * (rp * dp + rh * dh))
    assert stored == pytest.approx(inflow - outflow, rel=1e-10, abs=1e-14)


def test_zone_pair_is_each_zone_alone(tables):
    """The two zones stepped in one loop give each zone's own numbers, bit for bit, whichever
    is longer."""
    high_h = np.array([4.4e5, 3.8e5, 2.9e5, 2.2e5, 2.1e5])
    low_h = np.array([2.6e5, 3.0e5, 3.5e5, 4.0e5, 4.2e5, 4.25e5, 4.3e5])
    high = (np.full(5, 1e-4), *_zone(tables, 2.7e6, high_h), high_h, np.linspace(-400, 0, 5))
    low = (np.full(7, 2e-4), *_zone(tables, 1.0e6, low_h), low_h, np.linspace(300, 50, 7))
    for first, second in ((high, low), (low, high)):
        alone = [np.empty(z[4].size) for z in (first, second)]
        expected = [
            zone_derivatives(*first, 0.03, 0.02, 1e-4, alone[0]),
            zone_derivatives(*second, 0.02, 0.03, 1e-4, alone[1]),
        ]
        paired = [np.empty(z[4].size) for z in (first, second)]
        found = zone_pair_derivatives(
            (*first, 0.03, 0.02, paired[0]), (*second, 0.02, 0.03, paired[1]), 1e-4
        )
        assert list(found) == expected
        for a, b in zip(alone, paired, strict=True):
            np.testing.assert_array_equal(a, b)


def test_cell_density_is_c2_across_the_saturation_lines(tables):
    """ρ, ∂ρ/∂h and ∂²ρ/∂h² continuous at the band edges (a C¹ fillet jumps there: the
    right-hand side's kink let mass errors of 3.5e-4 through the step-size control)."""
    p = 2.7e6
    _, h_l, h_v, _, _ = saturation_state(tables, p)

    def curvature(h, step):  # one-sided second difference of the density
        rho = [_cell(tables, p, h + k * step)[1] for k in range(3)]
        return (rho[0] - 2.0 * rho[1] + rho[2]) / step**2

    for h_line in (h_l, h_v):
        width = QUALITY_BAND * (h_v - h_l)
        for h in (h_line - width * 1.0001, h_line + width * 1.0001):
            assert _cell(tables, p, h)[1] == state(tables, p, h)[1]
        slopes = [_cell(tables, p, h_line + side * width)[3] for side in (-1, 1)]
        mean_curvature = abs(slopes[1] - slopes[0]) / (2.0 * width)
        for side in (-1.0, 1.0):
            edge = h_line + side * width
            below, above = (_cell(tables, p, edge + d)[1] for d in (-1e-6, 1e-6))
            assert below == pytest.approx(above, rel=1e-9)
            outside, inside = curvature(edge, side), curvature(edge, -side)
            assert inside == pytest.approx(outside, abs=0.05 * max(abs(outside), mean_curvature))
        for h in np.linspace(h_line - 0.95 * width, h_line + 0.95 * width, 7):
            _, _, rp, rh, _ = _cell(tables, p, h)
            fd_h = (_cell(tables, p, h + 0.01)[1] - _cell(tables, p, h - 0.01)[1]) / 0.02
            fd_p = (_cell(tables, p + 10, h)[1] - _cell(tables, p - 10, h)[1]) / 20
            assert rh == pytest.approx(fd_h, rel=1e-4)
            assert rp == pytest.approx(fd_p, rel=1e-3, abs=1e-9)


def test_cell_density_pressure_slope_is_exact_in_the_bands(tables):
    """∂ρ/∂p at constant h inside both fillet bands, from 7 to 38 bar, equals a central
    difference of the fillet's own density to 1e-6 (measured: 3e-8): the mass balances see
    the derivative of the density whose Σ V ρ is the charge."""
    for p in np.linspace(0.7e6, 3.8e6, 13):
        _, h_l, h_v, _, _ = saturation_state(tables, p)
        width = QUALITY_BAND * (h_v - h_l)
        for h in np.concatenate(
            [np.linspace(-0.99, 0.99, 15) * width + line for line in (h_l, h_v)]
        ):
            fd_p = (_cell(tables, p + 2.0, h)[1] - _cell(tables, p - 2.0, h)[1]) / 4.0
            assert _cell(tables, p, h)[2] == pytest.approx(fd_p, rel=1e-6), (p, h)
