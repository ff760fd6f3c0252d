"""The cycle right-hand side: state layout, charge initialisation, exact mass balance."""

import numpy as np
import pytest

from pymc_vcc.physics.cycle import (
    C_KI,
    C_KP,
    C_M0,
    N_EVAL,
    build_constants,
    evaluate,
    initial_state,
    jacobian,
    n_states,
    state_slices,
    total_mass,
)
from pymc_vcc.physics.refrigerant import load_refrigerant
from pymc_vcc.physics.unit import load_unit

U_RATED = np.array([0.40, 55.0, 308.15, 300.15, 0.0])


@pytest.fixture(scope="module")
def setup():
    unit = load_unit()
    tables = load_refrigerant(unit.refrigerant).tables
    c = build_constants(unit, unit.parameters.nominal)
    y = initial_state(c, unit.discretisation.n_volumes, 308.15, 300.15, tables)
    return unit, tables, c, y


def test_state_layout_covers_every_index_once():
    for n in (3, 10):
        covered = np.zeros(n_states(n), dtype=int)
        for where in state_slices(n).values():
            covered[where] += 1
        assert np.all(covered == 1)


@pytest.mark.parametrize("charge", [0.9, 1.3, 2.2])
def test_initial_state_holds_exactly_m0(setup, charge):
    unit, tables, _, _ = setup
    theta = unit.parameters.vector({"M0": charge})
    c = build_constants(unit, theta)
    y = initial_state(c, unit.discretisation.n_volumes, 308.15, 300.15, tables)
    assert total_mass(y, c, tables) == pytest.approx(charge, rel=1e-12)


def test_charge_that_does_not_fit_is_an_error(setup):
    unit, tables, _, _ = setup
    c = build_constants(unit, unit.parameters.vector({"M0": 9.0}))
    with pytest.raises(ValueError, match="cannot be placed"):
        initial_state(c, unit.discretisation.n_volumes, 308.15, 300.15, tables)


def test_mass_changes_only_by_the_controller_source(setup):
    _, tables, c, y = setup
    c = c.copy()
    c[C_M0] *= 1.01  # a mass error, so the source is non-zero
    y = y.copy()
    y[-1] = 0.3  # and an integral term
    dydt = np.empty(y.size)
    out = np.empty(N_EVAL)
    assert evaluate(y, U_RATED, c, tables, dydt, out)
    source = out[15]
    assert abs(source) > 1e-5
    eps = 1e-3
    rate = (total_mass(y + eps * dydt, c, tables) - total_mass(y - eps * dydt, c, tables)) / (
        2 * eps
    )
    # exact up to the finite difference: a millionth of the compressor flow
    assert rate == pytest.approx(source, abs=1e-6 * out[8])


def test_controller_switch_and_gains(setup):
    unit, _, _, _ = setup
    on = build_constants(unit, unit.parameters.nominal)
    off = build_constants(unit, unit.parameters.nominal, controller=False)
    assert on[C_KP] == unit.controller.kp and on[C_KI] == pytest.approx(on[C_KP] ** 2 / 4)
    assert off[C_KP] == 0.0 and off[C_KI] == 0.0


def test_jacobian_matches_central_differences(setup):
    _, tables, c, y = setup
    dydt = np.empty(y.size)
    out = np.empty(N_EVAL)
    evaluate(y, U_RATED, c, tables, dydt, out)
    jac = jacobian(y, U_RATED, c, tables, dydt.copy())
    for j in (0, 3, 12, 22, 30, y.size - 1):
        step = 1e-6 * max(abs(y[j]), 1.0)
        up, down = np.empty(y.size), np.empty(y.size)
        shifted = y.copy()
        shifted[j] += step
        evaluate(shifted, U_RATED, c, tables, up, out)
        shifted[j] -= 2 * step
        evaluate(shifted, U_RATED, c, tables, down, out)
        central = (up - down) / (2 * step)
        scale = np.abs(central).max() + 1e-12
        assert np.max(np.abs(jac[:, j] - central)) < 1e-3 * scale


def test_out_of_range_state_is_flagged_not_raised(setup):
    _, tables, c, y = setup
    y = y.copy()
    y[0] = 80e5  # above the critical pressure
    dydt = np.empty(y.size)
    out = np.empty(N_EVAL)
    assert not evaluate(y, U_RATED, c, tables, dydt, out)
    assert np.isnan(out).all()
