"""SUNDIALS CVODE called directly through ``ctypes``, with C callbacks compiled by Numba.

scikit-sundae's wheel carries the SUNDIALS 7.9 shared libraries; scikit-sundae itself calls the
right-hand side and Jacobian through Python (~13 µs a call on top of the model's 20-34 µs, from
the difference of whole runs). Here CVODE calls C callbacks compiled by Numba directly, and its
whole step loop runs in machine code; Python only asks for each output time.

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

import numpy as np
from llvmlite import ir
from numba import carray, njit, types
from numba.core import cgutils
from numba.extending import intrinsic

CV_BDF = 2
CV_NORMAL = 1

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


@intrinsic
def _call_cvode(typingctx, function, memory, target, vector, reached):
    """``CVode(memory, target, vector, reached, CV_NORMAL)`` through its address ``function``
    (all four pointers as int64): one call from machine code, no ctypes."""

    def codegen(context, builder, signature, args):
        function, memory, target, vector, reached = args
        pointer = cgutils.voidptr_t
        cvode_type = ir.FunctionType(
            ir.IntType(32), [pointer, ir.DoubleType(), pointer, pointer, ir.IntType(32)]
        )
        cvode = builder.inttoptr(function, cvode_type.as_pointer())
        return builder.call(
            cvode,
            [
                builder.inttoptr(memory, pointer),
                target,
                builder.inttoptr(vector, pointer),
                builder.inttoptr(reached, pointer),
                ir.Constant(ir.IntType(32), CV_NORMAL),
            ],
        )

    return types.int32(types.int64, types.int64, types.float64, types.int64, types.int64), codegen


@njit(cache=True)
def _advance(function, memory, vector, reached, targets, first, last, out):
    """Call CVODE for ``targets[first:last]`` in turn, the state at each target whose index is
    a row of ``out`` copied there; returns (the first target not reached, CVODE's last flag)."""
    y = vector_data(as_pointer(vector), out.shape[1])
    flag = 0
    for row in range(first, last):
        flag = _call_cvode(function, memory, targets[row], vector, reached)
        if flag < 0:
            return row, flag
        if row < out.shape[0]:
            out[row] = y
    return last, flag


_ADVANCE_TYPES = (
    *(types.int64,) * 4,
    types.float64[::1],
    types.int64,
    types.int64,
    types.float64[:, ::1],
)
"""The argument types :meth:`Cvode.advance_through` passes to the compiled output loop."""


def compile_output_loop() -> None:
    """Compile (or load from the cache) the output loop for the types the driver passes, so that
    no simulation's wall clock counts it (see :mod:`pymc_vcc.physics.integration.warmup`)."""
    _advance.compile(_ADVANCE_TYPES)


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
    """Output times integrated by one compiled call between two looks at the wall clock."""

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
        self._addresses = (  # what the compiled output loop passes to CVode
            ctypes.cast(lib.CVode, ctypes.c_void_p).value,
            memory,
            y,
            self._t.ctypes.data,
        )
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

    def restart(self, t0: float, y0: np.ndarray, t_stop: float) -> None:
        """Start afresh from ``y0`` at ``t0`` (s), never stepping past ``t_stop``; the counts
        of :meth:`statistics` start again from zero."""
        self.y[:] = y0
        self._t[0] = t0
        _check(self._lib.CVodeReInit(self._memory, t0, self._vector), "CVodeReInit")
        _check(self._lib.CVodeSetStopTime(self._memory, t_stop), "CVodeSetStopTime")

    @property
    def t(self) -> float:
        """The time reached, s."""
        return float(self._t[0])

    def advance_through(
        self, targets: np.ndarray, out: np.ndarray, deadline: float
    ) -> tuple[int, int, bool]:
        """Integrate to each of ``targets`` (s) in turn, the state interpolated at the first
        ``len(out)`` of them into ``out``'s rows; stop at a failure, or before the next
        :attr:`CHUNK` of targets once ``time.perf_counter()`` has passed ``deadline``. Returns
        the targets reached, CVODE's last flag (negative: failed) and whether the deadline
        stopped it."""
        addresses = self._addresses
        done, flag = 0, 0
        while done < len(targets):
            if time.perf_counter() > deadline:
                return done, flag, True
            done, flag = _advance(
                *addresses, targets, done, min(done + self.CHUNK, len(targets)), out
            )
            if flag < 0:
                return done, flag, False
        return done, flag, False

    def statistics(self) -> tuple[int, int, int]:
        """Steps, right-hand sides and Jacobians since the last :meth:`restart`."""
        counts = []
        for name in ("CVodeGetNumSteps", "CVodeGetNumRhsEvals", "CVodeGetNumJacEvals"):
            count = ctypes.c_long()
            getattr(self._lib, name)(self._memory, ctypes.byref(count))
            counts.append(count.value)
        return counts[0], counts[1], counts[2]


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
