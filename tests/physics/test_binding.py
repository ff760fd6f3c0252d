"""Kernels bound once per simulation: the same machine code as the dispatcher, one record type
per cycle layout."""

import numba
import numpy as np
import pytest

from pymc_vcc.physics.cycles import CYCLE_MODELS
from pymc_vcc.physics.integration.binding import bind, numba_type
from pymc_vcc.physics.refrigerant import load_refrigerant
from pymc_vcc.physics.unit import HEAT_PUMP_UNIT, load_unit

UNITS = {"split-cooling": None, "heat-pump-heating": HEAT_PUMP_UNIT}


@pytest.fixture(scope="module", params=sorted(UNITS))
def setup(request):
    unit = load_unit(UNITS[request.param])
    model = unit.cycle_model
    tables = load_refrigerant(unit.refrigerant).tables
    c = model.constants(unit, unit.parameters.nominal)
    u = np.array([0.40, 55.0, 303.15, 297.15, 0.0])
    y = model.initial_state(c, unit.discretisation.n_volumes, u, tables)
    return unit, model, tables, c, u, y


def test_every_shipped_cycle_is_covered():
    assert set(UNITS) == set(CYCLE_MODELS)


def test_simulations_share_one_constants_record_type(setup):
    # Numba's dispatcher compares a new dtype object field by field on every call
    unit, model, _, c, _, _ = setup
    other = model.constants(unit, unit.parameters.nominal * 1.01)
    assert other.dtype is c.dtype
    assert model.layout(unit.discretisation.n_volumes) is model.layout(
        unit.discretisation.n_volumes
    )


def test_numba_type_is_numba_typeof(setup):
    _, _, tables, c, u, y = setup
    for value in (y, u, c, tables, y[::2], np.zeros((2, 3), order="F")):
        assert numba_type(value) == numba.typeof(value)
    read_only = y.copy()
    read_only.flags.writeable = False
    assert numba_type(read_only) == numba.typeof(read_only) != numba_type(y)


def test_bound_kernel_gives_the_dispatchers_results(setup):
    _, model, tables, c, u, y = setup
    f, out = np.empty(y.size), np.empty(model.n_eval)
    f_bound, out_bound = np.empty(y.size), np.empty(model.n_eval)
    evaluate = bind(model.evaluate, y, u, c, tables, f_bound, out_bound)
    assert evaluate is not model.evaluate
    assert model.evaluate(y, u, c, tables, f, out) and evaluate(y, u, c, tables, f_bound, out_bound)
    np.testing.assert_array_equal(f_bound, f)
    np.testing.assert_array_equal(out_bound, out)
    jacobian = bind(model.jacobian, y, u, c, tables, f)
    np.testing.assert_array_equal(jacobian(y, u, c, tables, f), model.jacobian(y, u, c, tables, f))
