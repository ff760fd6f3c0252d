"""Refrigerant property tables against CoolProp's Helmholtz equation of state (HEOS)."""

from pathlib import Path

import CoolProp.CoolProp as CP
import numpy as np
import pytest
from numba import njit

from pymc_vcc.physics.refrigerant import (
    SUPPORTED_FLUIDS,
    TableResolution,
    density_h_derivatives,
    density_h_derivatives_along,
    density_h_derivatives_at,
    entropy,
    entropy_at,
    h_from_ps,
    h_from_ps_at,
    h_from_pT,
    h_from_pT_at,
    load_refrigerant,
    p_sat_from_T,
    saturation_point,
    saturation_state,
    state,
    state_array,
    state_at,
    state_values,
    state_values_at,
)
from pymc_vcc.physics.refrigerant.cache import CACHE_ENV, cache_directory, load_tables

FLUIDS = ("R410A", "R32", "R134a")
T_TOLERANCE = 0.05  # K
RHO_TOLERANCE = 1e-3  # relative
DERIVATIVE_TOLERANCE = 1e-2  # relative
SMALL = TableResolution(n_sat=60, n_p=20, n_liquid=8, n_vapour=8)


@pytest.fixture(scope="session")
def fluids(tmp_path_factory):
    """All supported fluids at the default resolution, built once into a private cache."""
    cache = tmp_path_factory.mktemp("refrigerant-cache")
    return {name: load_refrigerant(name, cache_dir=cache) for name in FLUIDS}


def random_states(fluid, n, rng):
    """n random (p, h): log-uniform p over the valid range (a third of them in its top 10 %),
    h uniform between the enthalpy bounds."""
    n_top = n // 3
    p = np.concatenate(
        [
            np.exp(rng.uniform(np.log(fluid.p_min), np.log(fluid.p_max), n - n_top)),
            rng.uniform(0.9 * fluid.p_max, fluid.p_max, n_top),
        ]
    )
    h = fluid.h_min(p) + rng.uniform(0.0, 1.0, n) * (fluid.h_max(p) - fluid.h_min(p))
    return p, h


def heos(name):
    return CP.AbstractState("HEOS", name)


def heos_density(state_heos, p, h):
    state_heos.update(CP.HmassP_INPUTS, h, p)
    return state_heos.rhomass()


def heos_temperature(state_heos, p, h):
    state_heos.update(CP.HmassP_INPUTS, h, p)
    return state_heos.T()


def test_supported_fluids_are_the_three_named():
    assert set(SUPPORTED_FLUIDS) == set(FLUIDS)


def test_unknown_refrigerant_names_the_supported_ones():
    with pytest.raises(ValueError, match=r"unknown refrigerant 'R22'.*R410A, R32, R134a"):
        load_refrigerant("R22")


def test_names_are_case_insensitive(tmp_path):
    assert load_refrigerant("r410a", cache_dir=tmp_path, resolution=SMALL).name == "R410A"


@pytest.mark.parametrize("name", FLUIDS)
def test_valid_range_is_below_the_critical_point(fluids, name):
    fluid = fluids[name]
    assert fluid.p_min == pytest.approx(1e5)
    assert 0.975 * fluid.p_crit < fluid.p_max < fluid.p_crit
    assert fluid.T_crit == pytest.approx(heos(name).T_critical())
    assert fluid.saturation(fluid.p_min).T_sat > fluid.T_min
    p = np.array([fluid.p_min, fluid.p_max])
    sat = fluid.saturation(p)
    assert np.all((fluid.h_min(p) < sat.h_l) & (sat.h_v < fluid.h_max(p)))


def test_r410a_reaches_flooded_condenser_pressures(fluids):
    assert fluids["R410A"].p_max >= 47e5
    assert np.isfinite(fluids["R410A"].props(46e5, 3.3e5).rho)


@pytest.mark.parametrize("name", FLUIDS)
def test_temperature_density_quality_entropy_match_heos(fluids, name):
    fluid = fluids[name]
    p, h = random_states(fluid, 3000, np.random.default_rng(1))
    ref = heos(name)
    expected = np.empty((p.size, 4))
    for k in range(p.size):
        ref.update(CP.HmassP_INPUTS, h[k], p[k])
        expected[k] = ref.T(), ref.rhomass(), ref.Q(), ref.smass()
    got = fluid.props(p, h)
    two_phase = (got.quality >= 0.0) & (got.quality <= 1.0)
    assert 300 < two_phase.sum() < 2700  # every region is well sampled
    assert np.max(np.abs(got.T - expected[:, 0])) < T_TOLERANCE
    assert np.max(np.abs(got.rho / expected[:, 1] - 1.0)) < RHO_TOLERANCE
    assert np.max(np.abs(got.quality[two_phase] - expected[two_phase, 2])) < 1e-6
    assert np.all(expected[~two_phase, 2] == -1.0)  # HEOS: single phase
    assert np.max(np.abs(got.s - expected[:, 3])) < 1e-3  # J/(kg K)


@pytest.mark.parametrize("name", FLUIDS)
def test_density_derivatives_match_finite_differences_of_heos(fluids, name):
    """drho/dp|h and drho/dh|p within 1 % of central differences of HEOS density (HEOS's own
    two-phase first_partial_deriv is not the derivative of its density), stencils that cross
    the saturation line left out."""
    fluid = fluids[name]
    p, h = random_states(fluid, 1200, np.random.default_rng(2))
    dp, dh = 2e-4 * p, 20.0

    def region(p, h):  # 0 liquid, 1 two-phase, 2 vapour, 3 outside the tables
        quality = state_array(fluid.tables, p, h)[4]
        return np.where(np.isnan(quality), 3, np.digitize(quality, [0.0, 1.0]))

    centre = region(p, h)
    same_region = centre < 3
    for p_step, h_step in ((dp, 0.0), (-dp, 0.0), (0.0, dh), (0.0, -dh)):
        same_region &= region(p + p_step, h + h_step) == centre
    p, h, dp = p[same_region], h[same_region], dp[same_region]
    assert p.size > 1000
    ref = heos(name)
    fd_p = np.array(
        [
            (heos_density(ref, a + d, b) - heos_density(ref, a - d, b)) / (2 * d)
            for a, b, d in zip(p, h, dp, strict=True)
        ]
    )
    fd_h = np.array(
        [
            (heos_density(ref, a, b + dh) - heos_density(ref, a, b - dh)) / (2 * dh)
            for a, b in zip(p, h, strict=True)
        ]
    )
    got = fluid.props(p, h)
    assert np.max(np.abs(got.drho_dp / fd_p - 1.0)) < DERIVATIVE_TOLERANCE
    assert np.max(np.abs(got.drho_dh / fd_h - 1.0)) < DERIVATIVE_TOLERANCE


@pytest.mark.parametrize("name", FLUIDS)
def test_single_phase_right_next_to_the_dome_matches_heos(fluids, name):
    """Subcooled and superheated states 10 J/kg and 1 kJ/kg from the saturation lines."""
    fluid = fluids[name]
    p = np.geomspace(fluid.p_min, fluid.p_max, 60)
    sat = fluid.saturation(p)
    ref = heos(name)
    for offset in (10.0, 1000.0):
        for h in (sat.h_l - offset, sat.h_v + offset):
            got = fluid.props(p, h)
            rho = np.array([heos_density(ref, a, b) for a, b in zip(p, h, strict=True)])
            T = np.array([heos_temperature(ref, a, b) for a, b in zip(p, h, strict=True)])
            assert np.max(np.abs(got.rho / rho - 1.0)) < RHO_TOLERANCE
            assert np.max(np.abs(got.T - T)) < T_TOLERANCE
            if offset > 100.0:  # the derivative stencil stays on one side of the line
                fd_h = [
                    (heos_density(ref, a, b + 20.0) - heos_density(ref, a, b - 20.0)) / 40.0
                    for a, b in zip(p, h, strict=True)
                ]
                assert np.max(np.abs(got.drho_dh / fd_h - 1.0)) < DERIVATIVE_TOLERANCE


@pytest.mark.parametrize("name", FLUIDS)
def test_saturation_matches_heos(fluids, name):
    fluid = fluids[name]
    p = np.geomspace(fluid.p_min, fluid.p_max, 150)
    ref = heos(name)
    expected = np.empty((p.size, 6))
    for k, pressure in enumerate(p):
        ref.update(CP.PQ_INPUTS, pressure, 0.0)
        expected[k, [0, 2, 4]] = ref.T(), ref.hmass(), ref.rhomass()
        ref.update(CP.PQ_INPUTS, pressure, 1.0)
        expected[k, [1, 3, 5]] = ref.T(), ref.hmass(), ref.rhomass()
    sat = fluid.saturation(p)
    np.testing.assert_allclose(sat.T_sat, expected[:, :2].mean(axis=1), rtol=0, atol=1e-4)
    np.testing.assert_allclose(sat.h_l, expected[:, 2], rtol=1e-7)
    np.testing.assert_allclose(sat.h_v, expected[:, 3], rtol=1e-7)
    np.testing.assert_allclose(sat.rho_l, expected[:, 4], rtol=1e-6)
    np.testing.assert_allclose(sat.rho_v, expected[:, 5], rtol=1e-6)
    # bubble and dew temperatures are the ends of the two-phase temperature
    np.testing.assert_allclose(fluid.props(p, sat.h_l).T, expected[:, 0], atol=1e-4)
    np.testing.assert_allclose(fluid.props(p, sat.h_v).T, expected[:, 1], atol=1e-4)


@pytest.mark.parametrize("name", FLUIDS)
def test_round_trips(fluids, name):
    fluid = fluids[name]
    p, h = random_states(fluid, 500, np.random.default_rng(3))
    props = fluid.props(p, h)
    np.testing.assert_allclose(fluid.h_ps(p, props.s), h, rtol=0, atol=1e-5)
    single = (props.quality < 0.0) | (props.quality > 1.0)
    np.testing.assert_allclose(fluid.h_pT(p[single], props.T[single]), h[single], atol=1e-5)
    np.testing.assert_allclose(fluid.p_sat(fluid.saturation(p).T_sat), p, rtol=1e-10)
    # the bounding isotherms themselves are inside
    np.testing.assert_allclose(fluid.h_pT(p, fluid.T_min), fluid.h_min(p), rtol=1e-9)
    np.testing.assert_allclose(fluid.h_pT(p, fluid.T_max), fluid.h_max(p), rtol=1e-9)


@pytest.mark.parametrize("name", FLUIDS)
def test_h_from_pT_and_isentropic_compression_match_heos(fluids, name):
    fluid = fluids[name]
    ref = heos(name)
    p_suction, p_discharge = 0.3 * fluid.p_max, 0.7 * fluid.p_max
    T_suction = float(fluid.saturation(p_suction).T_sat) + 8.0
    ref.update(CP.PT_INPUTS, p_suction, T_suction)
    h_suction, s_suction = ref.hmass(), ref.smass()
    ref.update(CP.PSmass_INPUTS, p_discharge, s_suction)
    assert fluid.h_pT(p_suction, T_suction) == pytest.approx(h_suction, abs=0.1)
    assert fluid.h_ps(p_discharge, fluid.props(p_suction, h_suction).s) == pytest.approx(
        ref.hmass(), abs=0.5
    )


def test_pure_fluid_at_saturation_temperature_is_saturated_vapour(fluids):
    fluid = fluids["R32"]
    sat = fluid.saturation(20e5)
    assert fluid.h_pT(20e5, sat.T_sat) == pytest.approx(sat.h_v, rel=1e-9)


@pytest.mark.parametrize("name", FLUIDS)
def test_quality_is_unclipped_and_density_continuous_at_the_saturation_line(fluids, name):
    fluid = fluids[name]
    p = np.geomspace(fluid.p_min, fluid.p_max, 40)
    sat = fluid.saturation(p)
    for h_sat in (sat.h_l, sat.h_v):
        below = fluid.props(p, h_sat * (1 - 1e-9))
        above = fluid.props(p, h_sat * (1 + 1e-9))
        np.testing.assert_allclose(below.rho, above.rho, rtol=1e-6)
        np.testing.assert_allclose(below.T, above.T, atol=1e-5)
    step = 0.5 * np.minimum(sat.h_l - fluid.h_min(p), fluid.h_max(p) - sat.h_v)
    subcooled = fluid.props(p, sat.h_l - step)
    superheated = fluid.props(p, sat.h_v + step)
    np.testing.assert_allclose(subcooled.quality, -step / (sat.h_v - sat.h_l))
    np.testing.assert_allclose(superheated.quality, 1 + step / (sat.h_v - sat.h_l))


def test_derivatives_are_continuous_across_table_nodes(fluids):
    """The interpolant is C1: value and first derivatives agree on both sides of every node."""
    fluid = fluids["R410A"]
    tables = fluid.tables
    p_nodes = tables.table_p[1:-1]
    sat = fluid.saturation(p_nodes)
    for h in (0.5 * (sat.h_l + fluid.h_min(p_nodes)), 0.5 * (sat.h_v + fluid.h_max(p_nodes))):
        below = np.array(fluid.props(p_nodes * (1 - 1e-10), h)[:4])
        above = np.array(fluid.props(p_nodes * (1 + 1e-10), h)[:4])
        np.testing.assert_allclose(below, above, rtol=1e-6)
    p = np.full(tables.vapour_xi.size - 2, 20e5)
    h_v, h_max = fluid.saturation(20e5).h_v, fluid.h_max(20e5)
    h_nodes = h_v + tables.vapour_xi[1:-1] * (h_max - h_v)
    below = np.array(fluid.props(p, h_nodes - 1e-6)[:4])
    above = np.array(fluid.props(p, h_nodes + 1e-6)[:4])
    np.testing.assert_allclose(below, above, rtol=1e-6)


@pytest.mark.parametrize("name", FLUIDS)
def test_density_h_derivatives_are_the_state_and_its_slope(fluids, name):
    """ρ and ∂ρ/∂h as ``state`` gives them; ∂²ρ/∂h² the central difference of its ∂ρ/∂h, in
    both single phases and under the dome."""
    tables = fluids[name].tables
    for p in (8e5, 20e5):
        _, h_l, h_v, _, _ = saturation_state(tables, p)
        for x in (-0.12, -0.08, 0.08, 0.5, 0.92, 1.08, 1.4):
            h = h_l + x * (h_v - h_l)
            rho, slope, curvature = density_h_derivatives(tables, p, h)
            _, rho_state, _, slope_state, _ = state(tables, p, h)
            assert (rho, slope) == pytest.approx((rho_state, slope_state), rel=1e-12)
            difference = (state(tables, p, h + 1.0)[3] - state(tables, p, h - 1.0)[3]) / 2.0
            assert curvature == pytest.approx(difference, rel=1e-4)
    assert np.isnan(density_h_derivatives(tables, 0.1 * fluids[name].p_min, 4e5)).all()


def test_out_of_range_inputs_raise_clear_errors(fluids):
    fluid = fluids["R410A"]
    with pytest.raises(ValueError, match=r"p = 5e\+06 Pa is outside the valid range \[100000, "):
        fluid.props([20e5, 50e5], 3e5)
    with pytest.raises(ValueError, match=r"p = nan Pa is outside"):
        fluid.saturation(np.nan)
    with pytest.raises(ValueError, match=r"h = 900000 J/kg at p = 2e\+06 Pa is outside .*T_max"):
        fluid.props(20e5, [3e5, 9e5, 9.5e5])
    with pytest.raises(ValueError, match=r"2 of 3 values"):
        fluid.props(20e5, [3e5, 9e5, 9.5e5])
    with pytest.raises(ValueError, match=r"T = 500 K is outside the valid range \[220, 430\] K"):
        fluid.h_pT(20e5, 500.0)
    with pytest.raises(ValueError, match=r"T = 400 K is outside the saturation range"):
        fluid.p_sat(400.0)
    with pytest.raises(ValueError, match=r"s = 5000 J/\(kg K\) at p = 2e\+06 Pa is outside"):
        fluid.h_ps(20e5, 5000.0)
    with pytest.raises(ValueError, match=r"p = 100 Pa is outside"):
        fluid.h_min(100.0)


def test_outputs_follow_the_broadcast_input_shape(fluids):
    fluid = fluids["R410A"]
    props = fluid.props(np.full((2, 1), 20e5), np.linspace(2e5, 4.5e5, 3))
    assert all(field.shape == (2, 3) for field in props)
    assert np.ndim(fluid.props(20e5, 3e5).rho) == 0
    assert fluid.saturation([10e5, 20e5, 30e5]).T_sat.shape == (3,)


@njit
def _kernels_in_numba(tables, p, h):
    """Every kernel called from inside Numba code, one row per point."""
    out = np.empty((p.size, 14))
    for k in range(p.size):
        out[k, 0], out[k, 1], out[k, 2], out[k, 3], out[k, 4] = state(tables, p[k], h[k])
        out[k, 5], out[k, 6], out[k, 7], out[k, 8], out[k, 9] = saturation_state(tables, p[k])
        out[k, 10] = entropy(tables, p[k], h[k])
        out[k, 11] = h_from_ps(tables, p[k], out[k, 10])
        out[k, 12] = h_from_pT(tables, p[k], out[k, 0])
        out[k, 13] = p_sat_from_T(tables, out[k, 5])
    return out


def test_numba_kernels_agree_with_the_python_api(fluids):
    fluid = fluids["R410A"]
    p, h = random_states(fluid, 300, np.random.default_rng(4))
    out = _kernels_in_numba(fluid.tables, p, h)
    props = fluid.props(p, h)
    np.testing.assert_array_equal(out[:, 0:5].T, np.array(props[:5]))
    np.testing.assert_array_equal(out[:, 5:10].T, np.array(fluid.saturation(p)))
    np.testing.assert_array_equal(out[:, 10], props.s)
    np.testing.assert_allclose(out[:, 11], h, atol=1e-5)
    single = (props.quality < 0.0) | (props.quality > 1.0)
    np.testing.assert_allclose(out[single, 12], h[single], atol=1e-5)
    np.testing.assert_allclose(out[:, 13], p, rtol=1e-10)


def test_numba_kernels_return_nan_outside_the_tables(fluids):
    tables = fluids["R410A"].tables
    outside = [(0.5e5, 3e5), (49e5, 3.5e5), (20e5, 0.0), (20e5, 9e5), (np.nan, 3e5), (20e5, np.nan)]
    out = _kernels_in_numba(tables, *map(np.array, zip(*outside, strict=True)))
    assert np.all(np.isnan(out[:, 0:5]))
    assert np.all(np.isnan(out[:, 10:13]))
    pressure_outside = [0, 1, 4]
    assert np.all(np.isnan(out[pressure_outside, 5:10]))
    assert np.all(np.isnan(out[pressure_outside, 13]))
    assert np.isnan(h_from_pT(tables, 20e5, 500.0))
    assert np.isnan(h_from_pT(tables, 20e5, 200.0))
    assert np.isnan(h_from_ps(tables, 20e5, 1e4))
    assert np.isnan(p_sat_from_T(tables, 400.0))
    assert np.isnan(p_sat_from_T(tables, 150.0))


def test_one_saturation_point_serves_every_lookup_at_its_pressure(fluids):
    """Lookups sharing a pressure's saturation point (as a zone's cells do) give bit for bit
    the one-off lookups, across the dome, and NaN outside the tables."""
    tables = fluids["R410A"].tables
    for p in (0.5e5, 8e5, 27e5, 49e5, np.nan):
        point = saturation_point(tables, p)
        assert point.inside == (8e5 <= p <= 27e5)
        for h in np.linspace(1.0e5, 5.5e5, 41):
            np.testing.assert_array_equal(state_at(tables, point, p, h), state(tables, p, h))
            T, rho, _, _, x = state(tables, p, h)
            np.testing.assert_array_equal(state_values_at(tables, point, p, h), (T, rho, x))
            np.testing.assert_array_equal(state_values(tables, p, h), (T, rho, x))
            s = entropy(tables, p, h)
            np.testing.assert_array_equal(entropy_at(tables, point, p, h), s)
            np.testing.assert_array_equal(
                h_from_ps_at(tables, point, p, s), h_from_ps(tables, p, s)
            )
            np.testing.assert_array_equal(
                h_from_pT_at(tables, point, p, T), h_from_pT(tables, p, T)
            )
            np.testing.assert_array_equal(
                density_h_derivatives_at(tables, point, p, h), density_h_derivatives(tables, p, h)
            )


def test_cache_build_then_reload_gives_identical_tables(tmp_path, monkeypatch):
    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    assert cache_directory() == tmp_path
    built = load_refrigerant("R134a", resolution=SMALL)
    (path,) = tmp_path.glob("R134a_*.npz")
    assert "CoolProp-" in path.name and "_60-20-8-8_" in path.name
    assert not list(tmp_path.glob("*.tmp"))
    reloaded = load_tables(path)
    for name, value in built.tables._asdict().items():
        np.testing.assert_array_equal(getattr(reloaded, name), value)
    # another process (no in-memory copy) gets the same tables from the file
    from pymc_vcc.physics.refrigerant.fluid import Refrigerant

    again = Refrigerant("R134a", reloaded)
    p, h = random_states(built, 50, np.random.default_rng(5))
    np.testing.assert_array_equal(np.array(again.props(p, h)), np.array(built.props(p, h)))


def test_a_corrupt_cache_file_is_rebuilt(tmp_path):
    built = load_refrigerant("R32", cache_dir=tmp_path / "a", resolution=SMALL)
    (path,) = (tmp_path / "a").glob("*.npz")
    damaged = tmp_path / "b" / path.name
    damaged.parent.mkdir()
    damaged.write_bytes(path.read_bytes()[:1000])
    assert load_tables(damaged) is None
    rebuilt = load_refrigerant("R32", cache_dir=tmp_path / "b", resolution=SMALL)
    np.testing.assert_array_equal(rebuilt.tables.liquid, built.tables.liquid)
    assert load_tables(damaged) is not None


def test_default_cache_directory_is_in_the_home_cache(monkeypatch):
    monkeypatch.delenv(CACHE_ENV, raising=False)
    assert cache_directory() == Path.home() / ".cache" / "pymc_vcc"


@pytest.mark.parametrize("name", FLUIDS)
def test_density_derivatives_along_a_path_match_differences(fluids, name):
    """d/dp of ρ, ∂ρ/∂h and ∂²ρ/∂h² along h(p) = h_l(p) + x (h_v(p) - h_l(p)) and at constant
    h, in the liquid, the dome and the vapour, equal central differences (±1e-5 p): to 1e-5,
    the curvature's to 1e-3 (the tables' ∂²ρ/∂h² is only piecewise smooth in p)."""
    tables = fluids[name].tables

    def values(q, h):
        return np.array(density_h_derivatives_at(tables, saturation_point(tables, q), q, h))

    def on_line(q, x):
        _, h_l, h_v, _, _ = saturation_state(tables, q)
        return h_l + x * (h_v - h_l)

    for p in np.geomspace(0.1 * fluids[name].p_max, 0.8 * fluids[name].p_max, 5):
        sat = saturation_point(tables, p)
        dp = 1e-5 * p
        for x in (-0.15, -0.1, 0.1, 0.5, 0.9, 1.1, 1.3):
            h = on_line(p, x)
            h_p = sat.h_l_p + x * (sat.h_v_p - sat.h_l_p)
            paths = ((h_p, on_line(p + dp, x), on_line(p - dp, x)), (0.0, h, h))
            for slope, h_up, h_down in paths:
                found = density_h_derivatives_along(tables, sat, p, h, slope)
                np.testing.assert_array_equal(found[:3], values(p, h))
                differences = (values(p + dp, h_up) - values(p - dp, h_down)) / (2.0 * dp)
                where = str((p, x, slope))
                np.testing.assert_allclose(found[3:5], differences[:2], rtol=1e-5, err_msg=where)
                assert found[5] == pytest.approx(differences[2], rel=1e-3), where
