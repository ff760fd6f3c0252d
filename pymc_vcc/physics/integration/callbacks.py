"""A cycle model's right-hand side and Jacobian as C callbacks for CVODE.

CVODE calls ``f(t, y, ydot, user_data)`` and ``J(t, y, fy, J, user_data, ...)``. The cycle's
Numba kernels need the inputs, the constants record and the refrigerant tables besides ``y``:
``user_data`` points at a :class:`CallbackData` record holding their addresses, and the
callbacks (Numba ``cfunc``\\ s, one pair per cycle model and constants type, cached on disk)
rebuild the arrays from them without copying. Between segments the driver writes the new
inputs into the array whose address the record holds.
"""

from __future__ import annotations

import functools
import hashlib
import inspect
from pathlib import Path
from typing import Any

import numpy as np
from numba import carray, njit
from numba.core import sigutils
from numba.core.caching import FunctionCache
from numba.core.ccallback import CFunc

from pymc_vcc.physics import source_digest
from pymc_vcc.physics.cycles.base import CycleModel
from pymc_vcc.physics.integration.binding import bind
from pymc_vcc.physics.integration.sundials import (
    JAC_SIGNATURE,
    RHS_SIGNATURE,
    Callbacks,
    as_pointer,
    dense_matrix_data,
    vector_data,
)
from pymc_vcc.physics.records import make_record, record_array
from pymc_vcc.physics.refrigerant.tables import PropertyTables


def _table_record(tables: PropertyTables) -> np.void:
    """The tables by address: floats as they are, each array as its address and shape."""
    fields: list[tuple] = []
    values: dict[str, Any] = {}
    for name, value in zip(tables._fields, tables, strict=True):
        if isinstance(value, np.ndarray):
            fields += [(f"{name}_address", np.int64), (f"{name}_shape", np.int64, (value.ndim,))]
            values |= {f"{name}_address": value.ctypes.data, f"{name}_shape": value.shape}
        else:
            fields.append((name, np.float64))
            values[name] = value
    return make_record(np.dtype(fields), values)


@njit(cache=True)
def _vector_at(address, shape):
    """The float64 vector at ``address`` of ``shape`` (one entry)."""
    return carray(as_pointer(address), (shape[0],), np.float64)


@njit(cache=True)
def _array3_at(address, shape):
    """The float64 3-D array at ``address`` of ``shape``."""
    return carray(as_pointer(address), (shape[0], shape[1], shape[2]), np.float64)


@njit(cache=True)
def _array4_at(address, shape):
    """The float64 4-D array at ``address`` of ``shape``."""
    return carray(as_pointer(address), (shape[0], shape[1], shape[2], shape[3]), np.float64)


@njit(cache=True)
def tables_at(r):
    """The :class:`PropertyTables` whose addresses record ``r`` (:func:`_table_record`)
    holds, no copy; its fields in the NamedTuple's order
    (``tests/physics/test_callbacks.py`` checks)."""
    return PropertyTables(
        r.p_min,
        r.p_max,
        r.p_crit,
        r.T_crit,
        r.T_min,
        r.T_max,
        _vector_at(r.sat_p_address, r.sat_p_shape),
        _array3_at(r.sat_curves_address, r.sat_curves_shape),
        _vector_at(r.table_p_address, r.table_p_shape),
        _vector_at(r.liquid_xi_address, r.liquid_xi_shape),
        _vector_at(r.vapour_xi_address, r.vapour_xi_shape),
        _array4_at(r.liquid_address, r.liquid_shape),
        _array4_at(r.vapour_address, r.vapour_shape),
    )


class CallbackData:
    """What the callbacks read through ``user_data``: the addresses of the inputs ``u``, the
    constants record ``c``, the output buffer and the tables, and a count of right-hand sides
    that were not finite. Keeps every array it points at alive; :attr:`address` is the
    ``user_data`` to give CVODE."""

    def __init__(
        self, n_states: int, u: np.ndarray, c: np.ndarray, out: np.ndarray, tables: PropertyTables
    ) -> None:
        self.arrays = (u, c, out, tables)
        tables_record = _table_record(tables)
        counts = ("n_states", "n_inputs", "n_eval", "bad_rhs")
        addresses = ("u", "c", "out")
        self.dtype = np.dtype(
            [(name, np.int64) for name in counts + addresses] + [("tables", tables_record.dtype)]
        )
        self.record = record_array(
            self.dtype,
            {"n_states": n_states, "n_inputs": u.size, "n_eval": out.size, "bad_rhs": 0}
            | {name: array.ctypes.data for name, array in zip(addresses, (u, c, out), strict=True)}
            | {"tables": tables_record},
        )
        self.address: int = self.record.ctypes.data

    @property
    def bad_rhs(self) -> int:
        """Right-hand sides that were not finite so far."""
        return int(self.record[0]["bad_rhs"])


class _CallbackCache(FunctionCache):
    """Numba's disk cache for a callback made by :func:`c_callbacks`, keyed by ``identity``.

    Numba keys a closure by its pickled cells, and a pickled dispatcher carries an id drawn
    afresh in every process: each process would compile the callbacks again (4 s). The
    identity names what the callback calls and digests its sources instead."""

    def __init__(self, py_func: Any, identity: str) -> None:
        super().__init__(py_func)
        self._identity = identity

    def _index_key(self, sig: Any, codegen: Any) -> tuple:
        code = hashlib.sha256(self._py_func.__code__.co_code).hexdigest()
        identity = hashlib.sha256(self._identity.encode()).hexdigest()
        return (sig, codegen.magic_tuple(), (code, identity))


def _compiled(function: Any, signature: Any, identity: str) -> CFunc:
    """``function`` compiled as a C callback with ``signature``, cached on disk."""
    arguments = sigutils.normalize_signature(signature)
    callback = CFunc(function, arguments, locals={}, options={"error_model": "numpy"})
    callback._cache = _CallbackCache(function, identity)  # type: ignore[attr-defined]
    callback.compile()
    return callback


def _identity(kernels: tuple[Any, ...], dtypes: tuple[np.dtype, ...]) -> str:
    """What a callback's machine code depends on: the kernels it calls (by name and by the
    digest of their modules' sources and of the physics package's) and the record types."""
    digest = hashlib.blake2b(source_digest().encode(), digest_size=16)
    names = []
    for kernel in kernels:
        function = kernel.py_func
        names.append(f"{function.__module__}.{function.__qualname__}")
        digest.update(Path(inspect.getfile(function)).read_bytes())
    return f"{names} {[dtype.descr for dtype in dtypes]} {digest.hexdigest()}"


@functools.cache
def c_callbacks(evaluate: Any, jacobian: Any, data_dtype: np.dtype, c_dtype: np.dtype):
    """The C callbacks (right-hand side, Jacobian) around a cycle's ``evaluate`` and
    ``jacobian`` kernels, for :class:`CallbackData` and constants records of these types."""

    def rhs(t, y_vector, dydt_vector, user_data):
        data = carray(user_data, (1,), data_dtype)
        d = data[0]
        y = vector_data(y_vector, d.n_states)
        dydt = vector_data(dydt_vector, d.n_states)
        u = carray(as_pointer(d.u), (d.n_inputs,), np.float64)
        c = carray(as_pointer(d.c), (1,), c_dtype)
        out = carray(as_pointer(d.out), (d.n_eval,), np.float64)
        if evaluate(y, u, c, tables_at(d.tables), dydt, out):
            return 0
        data[0].bad_rhs += 1
        return 1  # recoverable: CVODE retries with a shorter step

    def jac(t, y_vector, f_vector, matrix, user_data, tmp1, tmp2, tmp3):
        d = carray(user_data, (1,), data_dtype)[0]
        n = d.n_states
        y = vector_data(y_vector, n)
        f = vector_data(f_vector, n)
        u = carray(as_pointer(d.u), (d.n_inputs,), np.float64)
        c = carray(as_pointer(d.c), (1,), c_dtype)
        derivatives = jacobian(y, u, c, tables_at(d.tables), f)
        columns = dense_matrix_data(matrix, n)
        for j in range(n):
            for i in range(n):
                value = derivatives[i, j]
                # entries that left the property tables are zeroed: the step control backs off
                columns[j, i] = value if np.isfinite(value) else 0.0
        return 0

    identity = _identity((evaluate, jacobian), (data_dtype, c_dtype))
    return _compiled(rhs, RHS_SIGNATURE, identity), _compiled(jac, JAC_SIGNATURE, identity)


class BoundCycle:
    """A cycle's kernels bound to one simulation (constants ``c``, ``tables``) and to the
    inputs of the current segment, :attr:`u` (overwrite it between segments): the
    :class:`~pymc_vcc.physics.integration.segments.SegmentModel` both solvers integrate."""

    def __init__(self, model: CycleModel, y: np.ndarray, u: np.ndarray, c: np.ndarray, tables):
        self.model, self.c, self.tables, self.n_states = model, c, tables, y.size
        self.u = u.copy()
        self.out = np.empty(model.n_eval)
        # every segment and both solvers pass arrays of these same types
        self._evaluate = bind(model.evaluate, y, self.u, c, tables, y, self.out)
        self._jacobian = bind(model.jacobian, y, self.u, c, tables, y)
        self._data: CallbackData | None = None

    def rhs(self, y: np.ndarray, dydt: np.ndarray) -> bool:
        """f(y) into ``dydt`` under the current inputs; False when it is not finite."""
        return self._evaluate(y, self.u, self.c, self.tables, dydt, self.out)

    def jac(self, y: np.ndarray, f: np.ndarray) -> np.ndarray:
        """∂f/∂y at ``y`` given ``f = f(y)``."""
        return self._jacobian(y, self.u, self.c, self.tables, f)

    def c_callbacks(self) -> Callbacks:
        """The right-hand side and Jacobian as C callbacks reading this object's arrays."""
        if self._data is None:
            self._data = CallbackData(self.n_states, self.u, self.c, self.out, self.tables)
        model = self.model
        rhs, jac = c_callbacks(model.evaluate, model.jacobian, self._data.dtype, self.c.dtype)
        return Callbacks(rhs.address, jac.address, self._data.address, self._data)

    @property
    def bad_rhs(self) -> int:
        """C right-hand sides so far that were not finite."""
        return 0 if self._data is None else self._data.bad_rhs
