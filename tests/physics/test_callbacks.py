"""CVODE's C callbacks compute what the bound Numba kernels compute, bit for bit."""

import ctypes

import numpy as np
from numba import njit

from pymc_vcc.physics.inputs import builtin_inputs, input_segments
from pymc_vcc.physics.integration.callbacks import BoundCycle, _table_record, tables_at
from pymc_vcc.physics.integration.sundials import as_pointer, dense_matrix_data, library
from pymc_vcc.physics.integration.warmup import ensure_compiled
from pymc_vcc.physics.refrigerant import load_refrigerant
from pymc_vcc.physics.unit import HEAT_PUMP_UNIT, load_unit

_RHS = ctypes.CFUNCTYPE(ctypes.c_int32, ctypes.c_double, *(ctypes.c_void_p,) * 3)
_JAC = ctypes.CFUNCTYPE(ctypes.c_int32, ctypes.c_double, *(ctypes.c_void_p,) * 7)


def test_the_tables_come_back_from_their_addresses_field_by_field():
    tables = load_refrigerant("R410A").tables
    rebuilt = tables_at(_table_record(tables))
    assert rebuilt._fields == tables._fields
    for name, value, back in zip(tables._fields, tables, rebuilt, strict=True):
        if isinstance(value, np.ndarray):
            assert back.shape == value.shape, name
            assert back.ctypes.data == value.ctypes.data, name  # the same memory, no copy
        else:
            assert back == value, name


@njit
def _columns(matrix, n):
    """A copy of a dense SUNMatrix's data: row j is column j."""
    return dense_matrix_data(as_pointer(matrix), n).copy()


def _serial_vector(lib, context, values):
    vector = lib.N_VNew_Serial(values.size, context)
    data = np.ctypeslib.as_array(lib.N_VGetArrayPointer_Serial(vector), (values.size,))
    data[:] = values
    return vector, data


def test_c_callbacks_match_the_kernels_at_box_draws_of_both_cycles():
    lib = library()
    context = ctypes.c_void_p()
    assert lib.SUNContext_Create(0, ctypes.byref(context)) == 0
    for unit_file in (None, HEAT_PUMP_UNIT):
        unit = load_unit() if unit_file is None else load_unit(unit_file)
        ensure_compiled(unit)
        model = unit.cycle_model
        tables = load_refrigerant(unit.refrigerant).tables
        u = input_segments(builtin_inputs())[1][0]
        thetas = [unit.parameters.nominal] + [
            unit.parameters.vector(draw)
            for draw in unit.parameters.sample_uniform(3, np.random.default_rng(5))
        ]
        for theta in thetas:
            c = model.constants(unit, theta)
            y = model.initial_state(c, unit.discretisation.n_volumes, u, tables)
            cycle = BoundCycle(model, y, u, c, tables)
            callbacks = cycle.c_callbacks()
            expected = np.empty(y.size)
            assert cycle.rhs(y, expected)
            y_vector, _ = _serial_vector(lib, context, y)
            f_vector, f = _serial_vector(lib, context, np.zeros(y.size))
            assert _RHS(callbacks.rhs)(0.0, y_vector, f_vector, callbacks.user_data) == 0
            np.testing.assert_array_equal(f, expected)
            matrix = lib.SUNDenseMatrix(y.size, y.size, context)
            arguments = (0.0, y_vector, f_vector, matrix, callbacks.user_data, None, None, None)
            assert _JAC(callbacks.jac)(*arguments) == 0
            np.testing.assert_array_equal(_columns(matrix, y.size).T, cycle.jac(y, expected))
            lib.SUNMatDestroy_Dense(matrix)
            lib.N_VDestroy_Serial(y_vector)
            lib.N_VDestroy_Serial(f_vector)
    lib.SUNContext_Free(ctypes.byref(context))
