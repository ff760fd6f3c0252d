"""Each component on its own: zero input, conservation, a hand-checked number."""

import math

import numpy as np
import pytest

from pymc_vcc.physics.components.compressor import (
    COMPRESSOR_RECORD,
    compressor,
    compressor_mass_flow,
    protection_speed_factor,
    shaft_power,
    volumetric_efficiency,
)
from pymc_vcc.physics.components.density import QUALITY_BAND, cell_state
from pymc_vcc.physics.components.expansion_valve import valve_mass_flow
from pymc_vcc.physics.components.fan import air_inlet_temperature, fan_operating_point
from pymc_vcc.physics.components.heat_exchanger import zone_derivatives
from pymc_vcc.physics.components.heat_transfer import LIQUID_BLEND, air_side_heat, refrigerant_htc
from pymc_vcc.physics.components.pipe import friction_coefficient, pipe_volume, pressure_drop
from pymc_vcc.physics.components.smooth import signed_sqrt, smooth_max, smooth_pos, smooth_step
from pymc_vcc.physics.components.suction_tank import tank_outlet_enthalpy
from pymc_vcc.physics.records import make_record
from pymc_vcc.physics.refrigerant import (
    entropy,
    h_from_ps,
    load_refrigerant,
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


def test_compressor_pieces_by_hand():
    assert volumetric_efficiency(1.0, 0.04, 1.1, 1.0) == pytest.approx(1.0, abs=1e-4)
    assert volumetric_efficiency(3.0, 0.04, 1.1, 1.2) == pytest.approx(
        1.2 * (1 - 0.04 * (3.0 ** (1 / 1.1) - 1)), rel=1e-4
    )
    assert compressor_mass_flow(37.0, 55.0, 11.5e-6, 0.9) == pytest.approx(0.9 * 37 * 11.5e-6 * 55)
    assert shaft_power(0.02, 30e3, 0.7, 1.0) == pytest.approx(0.02 * 30e3 / 0.7, rel=1e-4)
    assert shaft_power(0.0, 30e3, 0.7, 1.0) == 0.0


def _compressor(**changes):
    """A compressor record of the built-in unit's class, with some fields changed."""
    values = {
        "displacement": 11.5e-6,
        "clearance": 0.04,
        "exponent": 1.1,
        "isentropic_efficiency": 0.72,
        "refrigerant_fraction": 0.92,
        "shell_ua": 4.0,
        "cf_vol": 1.0,
        "cf_pow": 1.0,
        "cf_pref": 1.0,
        "cf_shell": 1.0,
        "T_discharge_max": 430.0,
        "p_protection_start": 41e5,
        "p_protection_stop": 46e5,
    }
    return make_record(COMPRESSOR_RECORD, values | changes)


def test_compressor_energy_balance(tables):
    p_s, p_d = 9.5e5, 27.5e5
    h_s = 4.30e5
    rho_s = state(tables, p_s, h_s)[1]
    # no shell loss, all power to the refrigerant: h_d = h_s + Δh_s / η_s
    adiabatic = _compressor(refrigerant_fraction=1.0, cf_shell=0.0)
    m, h_d, power, net = compressor(tables, p_s, h_s, rho_s, p_d, 55.0, 308.15, adiabatic)
    h_is = h_from_ps(tables, p_d, entropy(tables, p_s, h_s))
    assert h_d - h_s == pytest.approx((h_is - h_s) / 0.72, rel=1e-3)
    assert net == pytest.approx(power, rel=1e-3)  # the smooth thermal cap costs < 0.1 %
    assert 0.015 < m < 0.025
    # shell loss removes heat: discharge enthalpy lower, balance closes
    m, h_d2, power2, net2 = compressor(tables, p_s, h_s, rho_s, p_d, 55.0, 308.15, _compressor())
    assert h_d2 < h_d and net2 < 0.92 * power2
    assert m * (h_d2 - h_s) == pytest.approx(net2, rel=1e-9)
    # the thermal limit caps the discharge temperature
    hot = _compressor(cf_pow=2.0, cf_pref=1.5, cf_shell=0.3, T_discharge_max=340.0)
    m, h_d3, _, _ = compressor(tables, p_s, h_s, rho_s, p_d, 55.0, 308.15, hot)
    assert state(tables, p_d, h_d3)[0] < 340.0 < state(tables, p_d, h_d)[0]


def test_protection_speed_factor():
    assert protection_speed_factor(30e5, 41e5, 46e5) == 1.0
    assert protection_speed_factor(43.5e5, 41e5, 46e5) == pytest.approx(1 - 0.95 / 2)
    assert protection_speed_factor(47e5, 41e5, 46e5) == pytest.approx(0.05)


def test_refrigerant_htc_blend():
    args = (300.0, 3000.0, 800.0, 1.0)
    assert refrigerant_htc(-0.1, *args) == pytest.approx(300.0, rel=2e-3)
    assert refrigerant_htc(0.6, *args) == pytest.approx(3000.0, rel=2e-3)
    assert refrigerant_htc(1.1, *args) == pytest.approx(800.0, rel=2e-3)
    mid = sum(LIQUID_BLEND) / 2  # halfway up the smooth step
    assert refrigerant_htc(mid, *args) == pytest.approx(1650.0, rel=2e-3)
    xs = np.linspace(-0.2, 1.2, 2801)
    values = np.array([refrigerant_htc(x, *args) for x in xs])
    assert np.max(np.abs(np.diff(values))) < 3000.0 * 0.01  # continuous
    half = refrigerant_htc(0.6, 300.0, 3000.0, 800.0, 0.5)
    assert half == pytest.approx(3000.0 * math.sqrt(0.25 + 0.0025) ** 0.8)


def test_air_side_heat_limits():
    assert air_side_heat(500.0, 300.0, 300.0, 60.0, 10.0) == 0.0
    assert air_side_heat(500.0, 310.0, 300.0, 1e6, 10.0) == pytest.approx(500.0 * 10.0)
    assert air_side_heat(1e9, 310.0, 300.0, 60.0, 10.0) == pytest.approx(60.0 * 10.0 * 10.0, 1e-6)


def test_tank_outlet(tables):
    h_v = saturation_state(tables, 1e6)[2]
    # smooth max: off by width²/(4 distance) = 33 J/kg at 30 kJ/kg from the dew line
    assert tank_outlet_enthalpy(h_v + 30e3, h_v, 2e3) == pytest.approx(h_v + 30e3, abs=40.0)
    assert tank_outlet_enthalpy(h_v - 100e3, h_v, 2e3) == pytest.approx(h_v, abs=20.0)


def _zone(tables, p, hs):
    props = np.array([cell_state(tables, p, h) for h in hs])
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


def test_cell_density_is_c1_across_the_saturation_lines(tables):
    p = 2.7e6
    _, h_l, h_v, _, _ = saturation_state(tables, p)
    for h_line in (h_l, h_v):
        width = QUALITY_BAND * (h_v - h_l)
        for h in (h_line - width * 1.0001, h_line + width * 1.0001):
            assert cell_state(tables, p, h)[1] == state(tables, p, h)[1]
        edge = h_line + width * 0.9999
        assert cell_state(tables, p, edge)[1] == pytest.approx(state(tables, p, edge)[1], 1e-5)
        for h in np.linspace(h_line - 0.95 * width, h_line + 0.95 * width, 7):
            _, _, rp, rh, _ = cell_state(tables, p, h)
            fd_h = (cell_state(tables, p, h + 0.01)[1] - cell_state(tables, p, h - 0.01)[1]) / 0.02
            fd_p = (cell_state(tables, p + 10, h)[1] - cell_state(tables, p - 10, h)[1]) / 20
            assert rh == pytest.approx(fd_h, rel=1e-4)
            assert rp == pytest.approx(fd_p, rel=1e-3, abs=1e-9)
