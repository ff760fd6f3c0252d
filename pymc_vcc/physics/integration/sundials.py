"""SUNDIALS CVODE called directly through ``ctypes``, with C callbacks compiled by Numba.

scikit-sundae's wheel carries the SUNDIALS 7.9 shared libraries; scikit-sundae itself calls the
right-hand side and Jacobian through Python (~13 µs a call on top of the model's 20-34 µs, from
the difference of whole runs). Here CVODE calls C callbacks compiled by Numba directly, and its
whole step loop runs in machine code, and so does the loop over the input segments and the
output times (:meth:`Cvode.run`); Python only reads the wall clock between its chunks.

The layouts below are those of that build (``sunindextype`` a 32-bit int, ``sunrealtype``
double): an ``N_Vector`` and a ``SUNMatrix`` start with a pointer to their content; a serial
vector's content is ``{length, own_data, data*}``, a dense matrix's ``{M, N, data*, ...}`` with
the data column-major. :func:`vector_data` and :func:`dense_matrix_data` read them in Numba.
"""

from __future__ import annotations

import ctypes
import functools
import importlib.util
import time
import weakref
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numba
import numpy as np
from llvmlite import ir
from numba import carray, njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from pymc_vcc.physics.integration.stops import StopPlan, stop_plan
from pymc_vcc.physics.scratch import all_finite, uncounted

CV_BDF = 2
CV_NORMAL = 1
CV_FIRST_RHSFUNC_ERR = -9

RHS_SIGNATURE = types.int32(types.float64, types.voidptr, types.voidptr, types.voidptr)
"""``int f(t, N_Vector y, N_Vector ydot, void *user_data)``: 0 ok, 1 recoverable error."""

JAC_SIGNATURE = types.int32(types.float64, *(types.voidptr,) * 4, *(types.voidptr,) * 3)
"""``int J(t, N_Vector y, N_Vector fy, SUNMatrix J, void *user_data, N_Vector tmp1..3)``."""

_void, _int, _long, _double = ctypes.c_void_p, ctypes.c_int, ctypes.c_long, ctypes.c_double
_PROTOTYPES: dict[str, dict[str, tuple]] = {
    "core": {
        "SUNContext_Create": (_int, [_int, ctypes.POINTER(_void)]),
        "SUNContext_Free": (_int, [ctypes.POINTER(_void)]),
        "SUNContext_ClearErrHandlers": (_int, [_void]),
    },
    "nvecserial": {
        "N_VNew_Serial": (_void, [ctypes.c_int32, _void]),
        "N_VGetArrayPointer_Serial": (ctypes.POINTER(_double), [_void]),
        "N_VDestroy_Serial": (None, [_void]),
    },
    "sunmatrixdense": {
        "SUNDenseMatrix": (_void, [ctypes.c_int32, ctypes.c_int32, _void]),
        "SUNMatDestroy_Dense": (None, [_void]),
    },
    "sunlinsoldense": {
        "SUNLinSol_Dense": (_void, [_void, _void, _void]),
        "SUNLinSolFree_Dense": (_int, [_void]),
    },
    "cvode": {
        "CVodeCreate": (_void, [_int, _void]),
        "CVodeInit": (_int, [_void, _void, _double, _void]),
        "CVodeReInit": (_int, [_void, _double, _void]),
        "CVodeSVtolerances": (_int, [_void, _double, _void]),
        "CVodeSetLinearSolver": (_int, [_void, _void, _void]),
        "CVodeSetJacFn": (_int, [_void, _void]),
        "CVodeSetUserData": (_int, [_void, _void]),
        "CVodeSetMaxOrd": (_int, [_void, _int]),
        "CVodeSetMaxNumSteps": (_int, [_void, _long]),
        "CVodeSetMinStep": (_int, [_void, _double]),
        "CVodeSetMaxStep": (_int, [_void, _double]),
        "CVodeSetStopTime": (_int, [_void, _double]),
        "CVode": (_int, [_void, _double, _void, ctypes.POINTER(_double), _int]),
        "CVodeGetNumSteps": (_int, [_void, ctypes.POINTER(_long)]),
        "CVodeGetNumRhsEvals": (_int, [_void, ctypes.POINTER(_long)]),
        "CVodeGetNumJacEvals": (_int, [_void, ctypes.POINTER(_long)]),
        "CVodeGetReturnFlagName": (ctypes.c_char_p, [_long]),
        "CVodeFree": (None, [ctypes.POINTER(_void)]),
    },
}


BUILD = {"SUNDIALS_VERSION": "7.", "SUNDIALS_INT_TYPE": "int", "SUNDIALS_FLOAT_TYPE": "double"}
"""The scikit-sundae build whose layouts this module reads (a version is matched by prefix)."""


def _library_folder() -> Path:
    """Where scikit-sundae's wheel keeps its SUNDIALS libraries, after checking its build."""
    spec = importlib.util.find_spec("sksundae")
    if spec is None or spec.origin is None:
        raise ImportError("the cvode solver needs scikit-sundae: pip install scikit-sundae")
    from sksundae import _cy_common

    for name, expected in BUILD.items():
        found = str(getattr(_cy_common, name, "unknown"))
        if not found.startswith(expected):
            raise ImportError(
                f"the cvode solver reads SUNDIALS' memory layout for {name} = {expected!r}..., "
                f"but scikit-sundae was built with {found!r}: install scikit-sundae 1.1 or 1.2"
            )
    return Path(spec.origin).parent.parent / "scikit_sundae.libs"


@functools.cache
def library() -> SimpleNamespace:
    """The SUNDIALS functions this module calls, typed (loaded once per process);
    ``ImportError`` naming the problem when scikit-sundae's build does not fit."""
    folder = _library_folder()
    functions = {}
    for part, prototypes in _PROTOTYPES.items():
        found = sorted(folder.glob(f"libsundials_{part}-*.so*"))
        if not found:
            raise ImportError(
                f"libsundials_{part} not found in {folder}: the cvode solver loads the SUNDIALS "
                "libraries of scikit-sundae's Linux wheel; elsewhere use the radau solver"
            )
        handle = ctypes.CDLL(str(found[0]), mode=ctypes.RTLD_GLOBAL)
        for name, (result, arguments) in prototypes.items():
            function = getattr(handle, name)
            function.restype, function.argtypes = result, arguments
            functions[name] = function
    return SimpleNamespace(**functions)


@intrinsic
def as_pointer(typingctx, address):
    """The address (int64) as a ``void*``."""

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], cgutils.voidptr_t)

    return types.voidptr(types.int64), codegen


@njit(cache=True)
def _content_pointer(handle, index):
    """Word ``index`` of the content of an N_Vector or SUNMatrix ``handle``, as a pointer."""
    content = carray(handle, (1,), np.int64)[0]
    return as_pointer(carray(as_pointer(content), (index + 1,), np.int64)[index])


@njit(cache=True)
def vector_data(vector, n):
    """The ``n`` values of a serial N_Vector as an array (no copy)."""
    return carray(_content_pointer(vector, 1), (n,), np.float64)


@njit(cache=True)
def dense_matrix_data(matrix, n):
    """The data of an ``n`` x ``n`` dense SUNMatrix as an array whose row ``j`` is column ``j``
    (no copy)."""
    return carray(_content_pointer(matrix, 1), (n, n), np.float64)


def _pointers(builder, values):
    """The int64 ``values`` as ``void*``."""
    return [builder.inttoptr(value, cgutils.voidptr_t) for value in values]


def _call(builder, function, result, arguments, values):
    """Call the C function at address ``function`` (int64) of LLVM type ``result(*arguments)``."""
    function_type = ir.FunctionType(result, arguments)
    return builder.call(builder.inttoptr(function, function_type.as_pointer()), values)


_POINTER = cgutils.voidptr_t
_INT = ir.IntType(32)


@intrinsic
def _call_cvode(typingctx, function, memory, target, vector, reached):
    """``CVode(memory, target, vector, reached, CV_NORMAL)`` through its address ``function``
    (all four pointers as int64): one call from machine code, no ctypes."""

    def codegen(context, builder, signature, args):
        function, memory, target, vector, reached = args
        memory, vector, reached = _pointers(builder, (memory, vector, reached))
        normal = ir.Constant(_INT, CV_NORMAL)
        arguments = [_POINTER, ir.DoubleType(), _POINTER, _POINTER, _INT]
        return _call(builder, function, _INT, arguments, [memory, target, vector, reached, normal])

    return types.int32(types.int64, types.int64, types.float64, types.int64, types.int64), codegen


@intrinsic
def _call_pointer_time(typingctx, function, memory, t):
    """``function(memory, t)`` (``CVodeSetStopTime``) through its address."""

    def codegen(context, builder, signature, args):
        function, memory, t = args
        (memory,) = _pointers(builder, (memory,))
        return _call(builder, function, _INT, [_POINTER, ir.DoubleType()], [memory, t])

    return types.int32(types.int64, types.int64, types.float64), codegen


@intrinsic
def _call_pointer_time_pointer(typingctx, function, memory, t, vector):
    """``function(memory, t, vector)`` (``CVodeReInit``) through its address."""

    def codegen(context, builder, signature, args):
        function, memory, t, vector = args
        memory, vector = _pointers(builder, (memory, vector))
        arguments = [_POINTER, ir.DoubleType(), _POINTER]
        return _call(builder, function, _INT, arguments, [memory, t, vector])

    return types.int32(types.int64, types.int64, types.float64, types.int64), codegen


@intrinsic
def _call_pointer_pointer(typingctx, function, memory, value):
    """``function(memory, value)`` (a ``CVodeGetNum...`` counter) through its address."""

    def codegen(context, builder, signature, args):
        function, memory, value = args
        values = _pointers(builder, (memory, value))
        return _call(builder, function, _INT, [_POINTER, _POINTER], values)

    return types.int32(types.int64, types.int64, types.int64), codegen


COUNTERS = ("CVodeGetNumSteps", "CVodeGetNumRhsEvals", "CVodeGetNumJacEvals")
"""CVODE's counts of steps, right-hand sides and Jacobians since its last restart."""

FUNCTIONS = ("CVode", "CVodeReInit", "CVodeSetStopTime", *COUNTERS)
"""The SUNDIALS functions the compiled loop calls, in the order of its ``functions``."""


@njit(cache=True)
def _add_counts(functions, memory, counts, totals):
    """Add CVODE's step, right-hand side and Jacobian counts since its last restart to
    ``totals`` (``counts``: scratch space for three)."""
    for k in range(3):
        _call_pointer_pointer(functions[3 + k], memory, counts.ctypes.data + 8 * k)
        totals[k] += counts[k]


@njit(cache=True, inline="always")
def _copy(source, target):
    """``target[:] = source`` for 1-D arrays, elementwise (a slice assignment needs Numba's
    reference counts)."""
    for j in range(source.size):
        target[j] = source[j]


@uncounted
def _advance(functions, memory, vector, reached, plan, first, last, out, counts, totals):
    """Call CVODE for stops ``first`` to ``last - 1`` of the :class:`StopPlan` ``plan`` in turn:
    at a segment's first stop write its inputs into ``plan.u``, put the state into its start
    row if it has one and restart CVODE there; after each stop copy the state into its row of
    ``out``, if any. Returns (the first stop not reached, CVODE's last flag, whether the state
    stayed finite); the counts of each finished segment are added to ``totals``."""
    y = vector_data(as_pointer(vector), out.shape[1])
    flag = 0
    for i in range(first, last):
        k = plan.starts[i]
        if k >= 0:
            if k > 0:
                _add_counts(functions, memory, counts, totals)
            _copy(plan.held[k], plan.u)
            if plan.start_rows[k] >= 0:
                _copy(y, out[plan.start_rows[k]])
            flag = _call_pointer_time_pointer(functions[1], memory, plan.edges[k], vector)
            if flag >= 0:
                flag = _call_pointer_time(functions[2], memory, plan.edges[k + 1])
            if flag < 0:
                return i, flag, True
        flag = _call_cvode(functions[0], memory, plan.times[i], vector, reached)
        if flag < 0:
            return i, flag, True
        if not all_finite(y):
            return i, flag, False
        if plan.rows[i] >= 0:
            _copy(y, out[plan.rows[i]])
    return last, flag, True


def compile_output_loop() -> None:
    """Compile (or load from the cache) the loop over the stops for the types the driver passes,
    so that no simulation's wall clock counts it (see
    :mod:`pymc_vcc.physics.integration.warmup`)."""
    counts = np.zeros(3, dtype=np.int64)
    plan = stop_plan(np.array([0.0, 1.0]), np.zeros((1, 1)), np.array([0.0, 1.0]), np.zeros(1))
    addresses = np.zeros(len(FUNCTIONS), dtype=np.int64)
    _add_counts.compile(tuple(map(numba.typeof, (addresses, 0, counts, counts))))
    arguments = (addresses, 0, 0, 0, plan, 0, 0, np.zeros((1, 1)), counts, counts)
    _advance.compile(tuple(map(numba.typeof, arguments)))


_MEANINGS = {
    "CV_TOO_MUCH_WORK": "too many steps before the next output time",
    "CV_TOO_CLOSE": "output time too close to the start",
    "CV_ERR_FAILURE": "error test failed repeatedly or at the smallest step",
    "CV_CONV_FAILURE": "Newton iteration failed repeatedly or at the smallest step",
    "CV_LSETUP_FAIL": "the Jacobian or its factorisation failed",
    "CV_LSOLVE_FAIL": "the linear solve failed",
    "CV_RHSFUNC_FAIL": "the right-hand side failed",
    "CV_FIRST_RHSFUNC_ERR": "the right-hand side failed at the first call",
    "CV_REPTD_RHSFUNC_ERR": "the right-hand side failed repeatedly",
    "CV_UNREC_RHSFUNC_ERR": "the right-hand side failed and could not recover",
}
"""Plain words for the failures CVODE returns most."""


def flag_name(flag: int) -> str:
    """CVODE's name of a return ``flag`` and what it means."""
    name = library().CVodeGetReturnFlagName(flag).decode()
    return f"{name}: {_MEANINGS[name]}" if name in _MEANINGS else name


@dataclass(frozen=True)
class Callbacks:
    """A model as CVODE calls it: the addresses of its C right-hand side and Jacobian and of
    their ``user_data``, and the object that keeps that data alive."""

    rhs: int
    jac: int
    user_data: int
    owner: object


class Cvode:
    """One CVODE instance (BDF, dense direct linear solver, the model's Jacobian) over ``n``
    states, freed with this object."""

    CHUNK = 64
    """Stops integrated by one compiled call between two looks at the wall clock."""

    def __init__(self, callbacks: Callbacks, n: int, rtol: float, atol: np.ndarray) -> None:
        lib = self._lib = library()
        self.callbacks = callbacks  # CVODE holds its addresses: keep them alive
        context = ctypes.c_void_p()
        _check(lib.SUNContext_Create(0, ctypes.byref(context)), "SUNContext_Create")
        lib.SUNContext_ClearErrHandlers(context)  # failures come back as flags, never printed
        y = lib.N_VNew_Serial(n, context)
        tolerances = lib.N_VNew_Serial(n, context)
        np.ctypeslib.as_array(lib.N_VGetArrayPointer_Serial(tolerances), (n,))[:] = atol
        matrix = lib.SUNDenseMatrix(n, n, context)
        solver = lib.SUNLinSol_Dense(y, matrix, context)
        memory = lib.CVodeCreate(CV_BDF, context)
        self._finalizer = weakref.finalize(
            self, _free, lib, memory, solver, matrix, (y, tolerances), context
        )
        if not all((y, tolerances, matrix, solver, memory)):
            raise MemoryError("SUNDIALS could not allocate a CVODE instance")
        self.y = np.ctypeslib.as_array(lib.N_VGetArrayPointer_Serial(y), (n,))
        """The current state (CVODE's own vector; copy it to keep it)."""
        self.y[:] = 0.0
        self._vector, self._memory, self._t = y, memory, np.zeros(1)
        self._functions = np.array(  # the addresses the compiled loop calls
            [ctypes.cast(getattr(lib, name), ctypes.c_void_p).value for name in FUNCTIONS]
        )
        self._counts = np.zeros(3, dtype=np.int64)
        self._totals = np.zeros(3, dtype=np.int64)
        for name, *arguments in (
            ("CVodeInit", callbacks.rhs, 0.0, y),
            ("CVodeSVtolerances", rtol, tolerances),
            ("CVodeSetLinearSolver", solver, matrix),
            ("CVodeSetJacFn", callbacks.jac),
            ("CVodeSetUserData", callbacks.user_data),
        ):
            _check(getattr(lib, name)(memory, *arguments), name)

    def configure(self, max_order: int, max_steps: int, min_step: float, max_step: float) -> None:
        """Highest BDF order, steps allowed per output time, smallest and largest step (s)."""
        lib, memory = self._lib, self._memory
        _check(lib.CVodeSetMaxOrd(memory, max_order), "CVodeSetMaxOrd")
        _check(lib.CVodeSetMaxNumSteps(memory, max_steps), "CVodeSetMaxNumSteps")
        _check(lib.CVodeSetMinStep(memory, min_step), "CVodeSetMinStep")
        _check(lib.CVodeSetMaxStep(memory, max_step), "CVodeSetMaxStep")

    @property
    def t(self) -> float:
        """The time reached, s."""
        return float(self._t[0])

    def run(
        self, y0: np.ndarray, plan: StopPlan, out: np.ndarray, deadline: float
    ) -> tuple[int, int, bool, bool]:
        """Integrate from ``y0`` at the plan's start through its stops (:class:`StopPlan`), the
        state at each output time into its row of ``out``, restarting at each segment; stop at
        a failure or a state not finite, or before the next :attr:`CHUNK` of stops once
        ``time.perf_counter()`` has passed ``deadline``. Returns the stops reached, CVODE's last
        flag (negative: failed), whether the state stayed finite and whether the deadline
        stopped it; :meth:`statistics` then counts the run's work."""
        self.y[:] = y0
        self._t[0] = plan.edges[0]
        self._totals[:] = 0
        arguments = (self._functions, self._memory, self._vector, self._t.ctypes.data, plan)
        done, flag, finite, late = 0, 0, True, False
        while done < plan.times.size and flag >= 0 and finite:
            if time.perf_counter() > deadline:
                late = True
                break
            last = min(done + self.CHUNK, plan.times.size)
            done, flag, finite = _advance(*arguments, done, last, out, self._counts, self._totals)
        if done or flag < 0:  # CVODE was restarted: count its last segment
            _add_counts(self._functions, self._memory, self._counts, self._totals)
        return done, flag, finite, late

    def statistics(self) -> tuple[int, int, int]:
        """Steps, right-hand sides and Jacobians of the last :meth:`run`."""
        steps, rhs, jacobians = map(int, self._totals)
        return steps, rhs, jacobians


def _check(flag: int, call: str) -> None:
    if flag < 0:
        raise RuntimeError(f"SUNDIALS {call} failed: {flag_name(flag)}")


def _free(lib, memory, solver, matrix, vectors, context) -> None:
    """Release a CVODE instance's memory (the pointers that were allocated)."""
    if memory:
        lib.CVodeFree(ctypes.byref(ctypes.c_void_p(memory)))
    if solver:
        lib.SUNLinSolFree_Dense(solver)
    if matrix:
        lib.SUNMatDestroy_Dense(matrix)
    for vector in vectors:
        if vector:
            lib.N_VDestroy_Serial(vector)
    lib.SUNContext_Free(ctypes.byref(context))
