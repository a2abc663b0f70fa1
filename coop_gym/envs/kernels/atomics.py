"""Atomic operations on int64 array elements inside kernels: how threads share work without the GIL.

A threaded step hands out blocks of envs through a counter that every thread claims from
with a compare-and-swap, and the calling thread waits for the last block with atomic loads
in a ``nogil`` kernel -- not through Python locks, whose wake-up on every step would be paid
again by every small batch (``python bench/run.py`` measures the threaded step's scaling).

Each operation is sequentially consistent (LLVM's ``seq_cst``). With ``NUMBA_DISABLE_JIT=1``
the kernels run as Python and these are plain reads and writes under one lock.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
from numba import types
from numba.core import cgutils
from numba.core.extending import intrinsic
from numpy.typing import NDArray

from estimator.compiled.background import run_as_python

__all__ = ["atomic_add", "atomic_cas", "atomic_load"]

_ORDER = "seq_cst"


def _element_pointer(context: Any, builder: Any, array_type: Any, array: Any, index: Any, index_type: Any) -> Any:
    view = context.make_array(array_type)(context, builder, array)
    at = context.cast(builder, index, index_type, types.intp)
    return cgutils.get_item_pointer(context, builder, array_type, view, [at], wraparound=False)


def _check_int64_vector(array: Any) -> None:
    if not (isinstance(array, types.Array) and array.ndim == 1 and array.dtype == types.int64):
        raise TypeError(f"atomic operations take a 1-D int64 array, got {array}")


def _load_intrinsic(typingctx: Any, array: Any, index: Any) -> Any:
    _check_int64_vector(array)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        pointer = _element_pointer(context, builder, signature.args[0], args[0], args[1], signature.args[1])
        return builder.load_atomic(pointer, _ORDER, 8)

    return types.int64(array, index), codegen


def _cas_intrinsic(typingctx: Any, array: Any, index: Any, expected: Any, new: Any) -> Any:
    _check_int64_vector(array)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        pointer = _element_pointer(context, builder, signature.args[0], args[0], args[1], signature.args[1])
        old = context.cast(builder, args[2], signature.args[2], types.int64)
        value = context.cast(builder, args[3], signature.args[3], types.int64)
        result = builder.cmpxchg(pointer, old, value, _ORDER, _ORDER)
        return builder.extract_value(result, 0)

    return types.int64(array, index, expected, new), codegen


def _add_intrinsic(typingctx: Any, array: Any, index: Any, amount: Any) -> Any:
    _check_int64_vector(array)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        pointer = _element_pointer(context, builder, signature.args[0], args[0], args[1], signature.args[1])
        value = context.cast(builder, args[2], signature.args[2], types.int64)
        return builder.atomic_rmw("add", pointer, value, _ORDER)

    return types.int64(array, index, amount), codegen


_python_lock = threading.Lock()


def _python_load(array: NDArray[np.int64], index: int) -> int:
    with _python_lock:
        return int(array[index])


def _python_cas(array: NDArray[np.int64], index: int, expected: int, new: int) -> int:
    with _python_lock:
        old = int(array[index])
        if old == expected:
            array[index] = new
        return old


def _python_add(array: NDArray[np.int64], index: int, amount: int) -> int:
    with _python_lock:
        old = int(array[index])
        array[index] = old + amount
        return old


# The Python twins run in debug mode and in a kernel's first calls while it compiles
# (estimator.compiled.background).
atomic_load: Any = run_as_python(intrinsic(_load_intrinsic), _python_load)
atomic_cas: Any = run_as_python(intrinsic(_cas_intrinsic), _python_cas)
atomic_add: Any = run_as_python(intrinsic(_add_intrinsic), _python_add)

atomic_load.__doc__ = """``array[index]``, read atomically."""
atomic_cas.__doc__ = """If ``array[index] == expected`` set it to ``new``, atomically; returns the old value."""
atomic_add.__doc__ = """``array[index] += amount``, atomically; returns the old value."""
