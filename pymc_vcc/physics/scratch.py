"""Kernels and arrays without Numba's reference counts.

Numba counts the references to every array that owns its memory, with an atomic add or subtract
each time a compiled function takes one in or lets it go. The cycle's kernels pass their cell
properties and scratch arrays through many small functions: on a nominal CVODE run those counts
took 29 % of the time (sampled by perf). An array that owns nothing has its counts skipped: the
kernels keep their scratch arrays on the stack (:func:`stack_empty`, :func:`stack_full`) and
look at what a caller passes in through views that own nothing (:func:`borrowed`). The calls
of the counting functions that remain, on arrays that own nothing, cost a sixth of a run more:
the innermost kernels are compiled without them (:data:`uncounted`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar, cast

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic
from numba.np.arrayobj import populate_array


def _view(context, builder, array_type, value):
    """A view of the array ``value`` (of ``array_type``) that owns nothing."""
    source = context.make_array(array_type)(context, builder, value=value)
    view = context.make_array(array_type)(context, builder)
    populate_array(
        view,
        data=source.data,
        shape=source.shape,
        strides=source.strides,
        itemsize=source.itemsize,
        meminfo=None,
    )
    return view._getvalue()


def _borrow(context, builder, value_type, value):
    """``value`` with every array in it, at any depth of tuples, a view that owns nothing;
    anything else is handed on with a reference of its own."""
    if isinstance(value_type, types.Array):
        return _view(context, builder, value_type, value)
    if isinstance(value_type, types.BaseTuple):
        items = [
            _borrow(context, builder, item_type, builder.extract_value(value, k))
            for k, item_type in enumerate(value_type)
        ]
        return context.make_tuple(builder, value_type, items)
    context.nrt.incref(builder, value_type, value)
    return value


@intrinsic
def _borrowed(typingctx, value):
    """``value`` (an array, or a tuple or named tuple holding arrays) with each array seen
    through a view that owns nothing. The caller keeps the arrays alive for as long as the
    views are used: use it on a kernel's arguments."""

    def codegen(context, builder, signature, args):
        return _borrow(context, builder, value, args[0])

    return value(value), codegen


def _stack_array_type(shape):
    """The array type of a stack array of ``shape``'s type (an int or a tuple of ints), or None."""
    if isinstance(shape, types.Integer):
        return types.Array(types.float64, 1, "C")
    if isinstance(shape, types.UniTuple) and isinstance(shape.dtype, types.Integer):
        return types.Array(types.float64, shape.count, "C")
    return None


def _stack_array(context, builder, array_type, shape_type, shape, fill=None):
    """A C-ordered float64 array of ``shape`` on the stack, each element ``fill`` (a double) if
    given."""
    intp = types.intp
    if isinstance(shape_type, types.Integer):
        dims = [context.cast(builder, shape, shape_type, intp)]
    else:
        dims = [
            context.cast(builder, dim, shape_type.dtype, intp)
            for dim in cgutils.unpack_tuple(builder, shape, shape_type.count)
        ]
    itemsize = context.get_constant(intp, 8)
    strides = [itemsize]
    for dim in reversed(dims[1:]):
        strides.insert(0, builder.mul(strides[0], dim))
    count = dims[0]
    for dim in dims[1:]:
        count = builder.mul(count, dim)
    data = builder.alloca(ir.DoubleType(), size=count)
    if fill is not None:
        with cgutils.for_range(builder, count) as loop:
            builder.store(fill, builder.gep(data, [loop.index]))
    array = context.make_array(array_type)(context, builder)
    populate_array(array, data=data, shape=dims, strides=strides, itemsize=itemsize, meminfo=None)
    return array._getvalue()


@intrinsic
def _stack_empty(typingctx, shape):
    """An uninitialised C-ordered float64 array of ``shape`` (an int or a tuple of ints) on the
    stack of the function that calls this: it owns nothing and lives until that function
    returns. Never return it, and call this outside loops (each call takes new stack)."""
    array_type = _stack_array_type(shape)
    if array_type is None:
        return None

    def codegen(context, builder, signature, args):
        return _stack_array(context, builder, array_type, shape, args[0])

    return array_type(shape), codegen


@intrinsic
def _stack_full(typingctx, shape, value):
    """:func:`stack_empty` with every element ``value`` (a number)."""
    array_type = _stack_array_type(shape)
    if array_type is None or not isinstance(value, types.Number):
        return None

    def codegen(context, builder, signature, args):
        fill = context.cast(builder, args[1], value, types.float64)
        return _stack_array(context, builder, array_type, shape, args[0], fill)

    return array_type(shape, value), codegen


uncounted = njit(cache=True, error_model="numpy", _nrt=False)  # type: ignore[call-overload]
"""Compile a kernel with no reference counts (Numba's ``_nrt`` flag): it may not allocate (Numba
refuses to compile one that does) and must return no array (a caller that counts would give up a
reference it was never given). The kernels it calls keep their own counts: one called in the
right-hand side's loops is marked itself (the saturation point's counts were 1.5 % of a run),
and it must not call one that returns an array (that reference would never be given back)."""


@njit(cache=True, error_model="numpy", inline="always")
def all_finite(values: np.ndarray) -> bool:
    """Whether every element of the 1-D ``values`` is finite (no temporary array)."""
    for value in values:  # noqa: SIM110 (a generator would not compile)
        if not np.isfinite(value):
            return False
    return True


_T = TypeVar("_T")

# as compiled code calls them (an intrinsic's own signature starts with the typing context)
borrowed = cast(Callable[[_T], _T], _borrowed)
stack_empty = cast(Callable[[int | tuple[int, ...]], np.ndarray], _stack_empty)
stack_full = cast(Callable[[int | tuple[int, ...], float], np.ndarray], _stack_full)
