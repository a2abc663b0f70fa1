"""NumPy's random streams inside compiled code: the same numbers a ``Generator`` returns.

A bit generator exposes C functions that take its state pointer
(``BitGenerator.ctypes``, NumPy's "extending via Numba" interface); calling them from a
kernel advances the very state the Python ``Generator`` uses, so the ``Generator`` stays
the single source of truth. On top of the raw draws this module repeats NumPy's own
algorithms step for step: the 256-layer ziggurat for normals and Lemire's bounded draw
for integers, so :func:`standard_normal`, :func:`random` and :func:`integers` return
exactly what ``Generator.standard_normal()``, ``.random()`` and ``.integers(high)`` would
(tests/compiled/test_rng.py holds them equal).

With ``NUMBA_DISABLE_JIT=1`` (debug mode) the same functions run as Python: the C functions are
called through ctypes instead of intrinsics, and ``exp``/``log1p`` are libm's (the ``math``
module, as NumPy's C code calls them), so the draws stay bit for bit the ``Generator``'s.

A kernel receives a generator as its :func:`bit_generator_row`: the addresses of the
three C functions and of the state, in the columns :data:`G_NEXT_UINT64` ... :data:`G_STATE`.

The ziggurat tables are NumPy's (``ziggurat_constants.h``) as Numba ships them for its
own ``np.random.Generator`` support, in a private module: this is the one place that
imports them, and tests/compiled/test_rng.py fails if an upgrade changes them.
"""

from __future__ import annotations

import ctypes
import math
from typing import Any

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core.extending import intrinsic
from numba.np.random._constants import fi_double, ki_double, wi_double, ziggurat_nor_inv_r, ziggurat_nor_r
from numpy.typing import NDArray

from estimator.compiled.background import run_as_python
from estimator.compiled.cache import guard_kernel_cache

__all__ = [
    "G_NEXT_DOUBLE",
    "G_NEXT_UINT32",
    "G_NEXT_UINT64",
    "G_STATE",
    "LOW32",
    "U1",
    "U32",
    "ZIGGURAT_TABLES",
    "bit_generator_row",
    "integers",
    "random",
    "standard_normal",
]

G_NEXT_UINT64, G_NEXT_UINT32, G_NEXT_DOUBLE, G_STATE = range(4)
"""Columns of a bit-generator row: addresses of its C functions, then of its state (0: no generator)."""

ZIGGURAT_TABLES: dict[str, Any] = {
    "ki_double": ki_double,
    "wi_double": wi_double,
    "fi_double": fi_double,
    "ziggurat_nor_r": ziggurat_nor_r,
    "ziggurat_nor_inv_r": ziggurat_nor_inv_r,
}
"""NumPy's normal-ziggurat tables, as the kernels use them (read-only; for the tests)."""


def _state_function_caller(name: str, numba_type: Any, llvm_type: ir.Type) -> Any:
    """An intrinsic ``f(function_address, state_address) -> numba_type`` calling a bit generator's C function.

    ``next_uint64``, ``next_uint32`` and ``next_double`` differ only in their return type.
    """

    def typing(typingctx: Any, function_address: Any, state_address: Any) -> Any:
        sig = numba_type(types.uint64, types.uint64)

        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            function_type = ir.FunctionType(llvm_type, (ir.IntType(8).as_pointer(),))
            function = builder.inttoptr(args[0], function_type.as_pointer())
            return builder.call(function, (builder.inttoptr(args[1], ir.IntType(8).as_pointer()),))

        return sig, codegen

    typing.__name__ = typing.__qualname__ = name
    return intrinsic(typing)


def _python_caller(restype: Any) -> Any:
    """``f(function_address, state_address)`` through ctypes: the intrinsics' pure-Python twin.

    With ``NUMBA_DISABLE_JIT=1`` the kernels run as Python and an intrinsic cannot be called; ctypes
    calls the same C function on the same state, so the draws stay the ``Generator``'s own.
    """
    prototype = ctypes.CFUNCTYPE(restype, ctypes.c_void_p)
    functions: dict[int, Any] = {}

    def call(function_address: Any, state_address: Any) -> Any:
        address = int(function_address)
        function = functions.get(address)
        if function is None:
            function = functions[address] = prototype(address)
        return function(int(state_address))

    return call


# The kernels' Python twins (NUMBA_DISABLE_JIT=1, or their first calls while they compile: see
# estimator.compiled.background) call the same C functions through ctypes, and libm's exp and log1p
# (the math module), as NumPy's C code does: a NumPy ufunc may not be libm.
_call_uint64: Any = run_as_python(
    _state_function_caller("_call_uint64", types.uint64, ir.IntType(64)), _python_caller(ctypes.c_uint64)
)
_call_uint32: Any = run_as_python(
    _state_function_caller("_call_uint32", types.uint32, ir.IntType(32)), _python_caller(ctypes.c_uint32)
)
_call_double: Any = run_as_python(
    _state_function_caller("_call_double", types.float64, ir.DoubleType()), _python_caller(ctypes.c_double)
)
_exp: Any = run_as_python(np.exp, math.exp)
_log1p: Any = run_as_python(np.log1p, math.log1p)

# uint64 constants (a Python int beside a uint64 would make Numba compute in int64 or float);
# U1, U32 and LOW32 serve coop_gym.envs.kernels.seeding too.
U1 = np.uint64(1)
U32 = np.uint64(32)
LOW32 = np.uint64(0xFFFFFFFF)
_U8 = np.uint64(8)
_BYTE = np.uint64(0xFF)
_MANTISSA = np.uint64(0x000FFFFFFFFFFFFF)


@njit(cache=True, error_model="numpy")
def random(g: NDArray[np.uint64]) -> float:
    """``Generator.random()``: a double in [0, 1) from the bit generator row ``g``."""
    return _call_double(g[G_NEXT_DOUBLE], g[G_STATE])


@njit(cache=True, error_model="numpy")
def standard_normal(g: NDArray[np.uint64]) -> float:
    """``Generator.standard_normal()``: NumPy's 256-layer ziggurat, step for step."""
    while True:
        r = _call_uint64(g[G_NEXT_UINT64], g[G_STATE])
        idx = r & _BYTE
        r >>= _U8
        sign = r & U1
        rabs = (r >> U1) & _MANTISSA
        x = rabs * wi_double[idx]
        if sign:
            x = -x
        if rabs < ki_double[idx]:
            return x
        if idx == 0:
            # The tail beyond the base layer.
            while True:
                xx = -ziggurat_nor_inv_r * _log1p(-random(g))
                yy = -_log1p(-random(g))
                if yy + yy > xx * xx:
                    if (rabs >> _U8) & U1:
                        return -(ziggurat_nor_r + xx)
                    return ziggurat_nor_r + xx
        elif (fi_double[idx - 1] - fi_double[idx]) * random(g) + fi_double[idx] < _exp(-0.5 * x * x):
            return x


@njit(cache=True, error_model="numpy")
def integers(g: NDArray[np.uint64], high: int) -> int:
    """``Generator.integers(high)`` for ``1 <= high < 2**32``: Lemire's bounded draw on 32 bits."""
    span = np.uint64(high - 1)
    if span == 0:
        return 0
    bound = span + U1
    m = np.uint64(_call_uint32(g[G_NEXT_UINT32], g[G_STATE])) * bound
    leftover = m & LOW32
    if leftover < bound:
        threshold = (LOW32 - span) % bound
        while leftover < threshold:
            m = np.uint64(_call_uint32(g[G_NEXT_UINT32], g[G_STATE])) * bound
            leftover = m & LOW32
    return int(m >> U32)


def bit_generator_row(rng: np.random.Generator) -> NDArray[np.uint64]:
    """The addresses a kernel needs to draw from ``rng`` (columns :data:`G_NEXT_UINT64` ... :data:`G_STATE`)."""
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"an env's random source must be a numpy.random.Generator, got {type(rng).__name__}")
    c = rng.bit_generator.ctypes
    return np.array(
        [
            ctypes.cast(c.next_uint64, ctypes.c_void_p).value,
            ctypes.cast(c.next_uint32, ctypes.c_void_p).value,
            ctypes.cast(c.next_double, ctypes.c_void_p).value,
            c.state_address,
        ],
        dtype=np.uint64,
    )


guard_kernel_cache(__name__)
