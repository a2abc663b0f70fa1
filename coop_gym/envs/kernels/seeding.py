"""Many seeded generators at once: ``PCG64(seed)`` for every env of a batch in one compiled call.

``numpy.random.Generator(PCG64(seed))`` costs Python work per env (the ``SeedSequence``, the bit
generator object, its ctypes interface), many times what a step of the env costs, so seeding
many envs that way takes longer than stepping them (``python bench/reset.py``).
:class:`EnvGenerators` holds the generators of ``N`` envs instead as NumPy's own
C state structs in two arrays, seeded by :func:`seed_states` -- NumPy's ``SeedSequence`` hash and
PCG64 seeding repeated step for step (tests/coop_gym/test_seeding.py holds them equal, seed by
seed) -- and the kernels draw from them through NumPy's PCG64 C functions, exactly as from a
``Generator``'s state (:mod:`estimator.compiled.rng`). An env's ``Generator`` object is made only when one is
asked for (``generators[i]``): it takes over the env's state where the stream stands, and the
env draws from it from then on. So the numbers are those of ``Generator(PCG64(seed))`` either way.

The C layout of NumPy's PCG64 state (``pcg64_state``: a pointer to the 128-bit LCG state, then
``has_uint32`` and ``uinteger``; the 128-bit words native or as ``{high, low}``) is read off a live
``PCG64`` at import; if it is not one of the two known layouts the arrays are not used and every
generator is a ``Generator`` object (:data:`LAYOUT` is None then).
"""

from __future__ import annotations

import ctypes
from collections.abc import Iterator
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from estimator.compiled.background import run_as_python
from estimator.compiled.cache import guard_kernel_cache
from estimator.compiled.rng import G_STATE, LOW32, U1, U32, bit_generator_row

__all__ = ["LAYOUT", "MAX_BATCH_SEED", "MIN_BATCH_ENVS", "EnvGenerators", "seed_states"]

MAX_BATCH_SEED = 2**63 - 1
"""Seeds up to this are seeded in the batch; a larger one gets its ``Generator`` object."""

MIN_BATCH_ENVS = 10_000
"""Fewer envs than this are seeded with a ``Generator`` object each (the same numbers).

On a fresh install :func:`seed_states` costs a compile (``python bench/cold_start.py --num-envs 1024
--kernels``), about what 10^4 ``Generator`` objects cost (``python bench/reset.py``); a smaller
batch would only pay it on the first step of every fresh install.
"""

# NumPy's SeedSequence (numpy/random/bit_generator.pyx): a pool of 4 uint32 words hashed from
# the seed's 32-bit words, then hashed out into the bit generator's seed words.
# (np.uint64 constants: a Python int beside a uint64 would make Numba compute in int64 or float.)
_INIT_A = np.uint64(0x43B0D7E5)
_MULT_A = np.uint64(0x931E8875)
_INIT_B = np.uint64(0x8B51F9DD)
_MULT_B = np.uint64(0x58F38DED)
_MIX_MULT_L = np.uint64(0xCA01F9DD)
_MIX_MULT_R = np.uint64(0x4973F715)
_XSHIFT = np.uint64(16)
_U0 = np.uint64(0)
_U63 = np.uint64(63)
_POOL_SIZE = 4
# PCG64's 128-bit LCG multiplier (numpy/random/src/pcg64/pcg64.h), as high and low words.
_MULT_HIGH = np.uint64(2549297995355413924)
_MULT_LOW = np.uint64(4865540595714422341)


@njit(cache=True, error_model="numpy", inline="always")
def _hashmix(value: np.uint64, hash_const: NDArray[np.uint64]) -> np.uint64:
    value = (value ^ hash_const[0]) & LOW32
    hash_const[0] = (hash_const[0] * _MULT_A) & LOW32
    value = (value * hash_const[0]) & LOW32
    return value ^ (value >> _XSHIFT)


@njit(cache=True, error_model="numpy", inline="always")
def _mix(x: np.uint64, y: np.uint64) -> np.uint64:
    result = (_MIX_MULT_L * x - _MIX_MULT_R * y) & LOW32
    return result ^ (result >> _XSHIFT)


@njit(cache=True, error_model="numpy", inline="always")
def _mul64(a: np.uint64, b: np.uint64) -> tuple[np.uint64, np.uint64]:
    # The 128-bit product of two 64-bit words, as (high, low), from 32-bit halves.
    a_lo, a_hi = a & LOW32, a >> U32
    b_lo, b_hi = b & LOW32, b >> U32
    lo_lo = a_lo * b_lo
    hi_lo = a_hi * b_lo
    lo_hi = a_lo * b_hi
    hi_hi = a_hi * b_hi
    cross = (lo_lo >> U32) + (hi_lo & LOW32) + lo_hi
    high = hi_hi + (hi_lo >> U32) + (cross >> U32)
    low = (cross << U32) | (lo_lo & LOW32)
    return high, low


@njit(cache=True, error_model="numpy", inline="always")
def _lcg_step(
    state_high: np.uint64, state_low: np.uint64, inc_high: np.uint64, inc_low: np.uint64
) -> tuple[np.uint64, np.uint64]:
    # state = state * MULT + inc (mod 2^128): pcg_setseq_128_step_r.
    high, low = _mul64(state_low, _MULT_LOW)
    high = high + state_low * _MULT_HIGH + state_high * _MULT_LOW
    new_low = low + inc_low
    carry = U1 if new_low < low else _U0
    return high + inc_high + carry, new_low


@njit(cache=True, error_model="numpy")
def seed_states(seeds: NDArray[np.uint64], out: NDArray[np.uint64]) -> None:
    """``out[r] = (state_high, state_low, inc_high, inc_low)`` of ``PCG64(seeds[r])``.

    ``SeedSequence(seed).generate_state(4, np.uint64)`` (the seed's 32-bit words hashed into a
    pool of 4, the pool hashed out into 8 words read as 4 little-endian uint64 ``s0 s1 i0 i1``),
    then ``pcg64_set_seed``: ``state = 0; inc = (i << 1) | 1; step; state += s; step`` with
    ``s = s0 << 64 | s1`` and ``i = i0 << 64 | i1``.
    """
    hash_const = np.empty(1, dtype=np.uint64)
    entropy = np.empty(2, dtype=np.uint64)
    pool = np.empty(_POOL_SIZE, dtype=np.uint64)
    words = np.empty(8, dtype=np.uint64)
    for r in range(seeds.shape[0]):
        seed = seeds[r]
        # _coerce_to_uint32_array: 0 is one word [0]; else the nonzero 32-bit words, lowest first.
        entropy[0] = seed & LOW32
        entropy[1] = seed >> U32
        n_entropy = 2 if entropy[1] != _U0 else 1
        hash_const[0] = _INIT_A
        for i in range(_POOL_SIZE):
            pool[i] = _hashmix(entropy[i] if i < n_entropy else _U0, hash_const)
        for i_src in range(_POOL_SIZE):
            for i_dst in range(_POOL_SIZE):
                if i_src != i_dst:
                    pool[i_dst] = _mix(pool[i_dst], _hashmix(pool[i_src], hash_const))
        out_const = _INIT_B
        for i in range(8):
            value = (pool[i % _POOL_SIZE] ^ out_const) & LOW32
            out_const = (out_const * _MULT_B) & LOW32
            value = (value * out_const) & LOW32
            words[i] = value ^ (value >> _XSHIFT)
        s_high = words[0] | (words[1] << U32)
        s_low = words[2] | (words[3] << U32)
        i_high = words[4] | (words[5] << U32)
        i_low = words[6] | (words[7] << U32)
        inc_high = (i_high << U1) | (i_low >> _U63)
        inc_low = (i_low << U1) | U1
        high, low = _lcg_step(_U0, _U0, inc_high, inc_low)
        low_sum = low + s_low
        high = high + s_high + (U1 if low_sum < low else _U0)
        high, low = _lcg_step(high, low_sum, inc_high, inc_low)
        out[r, 0] = high
        out[r, 1] = low
        out[r, 2] = inc_high
        out[r, 3] = inc_low


def _python_seed_states(seeds: NDArray[np.uint64], out: NDArray[np.uint64]) -> None:
    # Under NUMBA_DISABLE_JIT the kernel's uint64 arithmetic would warn on every wrap: NumPy's own.
    for r, seed in enumerate(seeds.tolist()):
        state = np.random.PCG64(seed).state["state"]
        s, i = state["state"], state["inc"]
        out[r] = (s >> 64, s & (2**64 - 1), i >> 64, i & (2**64 - 1))


seed_states = run_as_python(seed_states, _python_seed_states)


def _read_layout() -> tuple[int, ...] | None:
    """Where NumPy's PCG64 keeps (state_high, state_low, inc_high, inc_low) among its 4 words, or None.

    Read off a live ``PCG64`` set to a known state: ``pcg64_state`` is a pointer to the LCG's 4
    words, then ``has_uint32`` (int) and ``uinteger`` (uint32) in the next word.
    """
    try:
        bits = np.random.PCG64(0)
        s = (0x0123456789ABCDEF << 64) | 0x1122334455667788
        i = (0x0FEDCBA987654321 << 64) | 0x99AABBCCDDEEFF01
        bits.state = {"bit_generator": "PCG64", "state": {"state": s, "inc": i}, "has_uint32": 1, "uinteger": 7}
        head = (ctypes.c_uint64 * 2).from_address(bits.ctypes.state_address)
        if head[1] != 1 | (7 << 32):
            return None
        words = list((ctypes.c_uint64 * 4).from_address(head[0]))
        wanted = [s >> 64, s & (2**64 - 1), i >> 64, i & (2**64 - 1)]
        layout = tuple(words.index(w) for w in wanted)
        return layout if sorted(layout) == [0, 1, 2, 3] else None
    except Exception:  # an unexpected build: use Generator objects
        return None


LAYOUT: tuple[int, ...] | None = _read_layout()
"""Word of (state_high, state_low, inc_high, inc_low) in NumPy's PCG64 LCG state (native 128-bit:
``(1, 0, 3, 2)``), or None when this NumPy's layout is not recognised."""

_TEMPLATE = bit_generator_row(np.random.Generator(np.random.PCG64(0)))  # PCG64's C functions


class EnvGenerators:
    """The random generators of ``n`` envs and their kernel rows (:func:`estimator.compiled.rng.bit_generator_row`).

    ``rows`` (n, 4) are what the kernels draw through (a zero state address: no generator yet).
    An env seeded by :meth:`seed` draws from a PCG64 C state kept in this object's arrays; one
    given a ``Generator`` (:meth:`set` or ``generators[i] = rng``) draws from that object's state.
    ``generators[i]`` returns env ``i``'s ``Generator`` (None if it has none), making it from the
    arrays the first time: the object then carries the stream on.
    """

    def __init__(self, n: int) -> None:
        """No generator for any env yet."""
        self.rows = np.zeros((n, 4), dtype=np.uint64)
        self._objects: list[np.random.Generator | None] = [None] * n
        self._in_arrays = np.zeros(n, dtype=bool)
        # NumPy's pcg64_state of each env (pointer to its LCG words; has_uint32 | uinteger << 32)
        # and its LCG words (pcg64_random_t) in NumPy's layout.
        self._heads = np.zeros((n, 2), dtype=np.uint64)
        self._lcg = np.zeros((n, 4), dtype=np.uint64)
        self._heads[:, 0] = self._lcg.ctypes.data + 32 * np.arange(n, dtype=np.uint64)

    def __len__(self) -> int:
        """The number of envs."""
        return len(self._objects)

    def __iter__(self) -> Iterator[np.random.Generator | None]:
        """Every env's ``Generator`` (made from the arrays where needed), or None."""
        return (self[i] for i in range(len(self)))

    def __getitem__(self, i: int) -> np.random.Generator | None:
        """Env ``i``'s ``Generator`` (made from the arrays the first time), or None if it has none."""
        if self._in_arrays[i]:
            self._take_out(i)
        return self._objects[i]

    def __setitem__(self, i: int, rng: np.random.Generator) -> None:
        """Env ``i`` draws from ``rng`` from now on (:meth:`set`)."""
        self.set(i, rng)

    def has(self, i: int) -> bool:
        """Whether env ``i`` has a generator (without making its object)."""
        return bool(self.rows[i, G_STATE] != 0)

    def is_object(self, i: int, rng: Any) -> bool:
        """Whether env ``i`` draws from the object ``rng``."""
        return not self._in_arrays[i] and self._objects[i] is rng

    def set(self, i: int, rng: np.random.Generator) -> None:
        """Env ``i`` draws from ``rng`` from now on."""
        self.rows[i] = bit_generator_row(rng)
        self._objects[i] = rng
        self._in_arrays[i] = False

    def seed(self, indices: NDArray[np.int64], seeds: NDArray[np.uint64]) -> None:
        """Env ``indices[r]`` draws from ``Generator(PCG64(seeds[r]))`` (seeds up to :data:`MAX_BATCH_SEED`)."""
        if LAYOUT is None or indices.shape[0] < MIN_BATCH_ENVS:
            for i, s in zip(indices.tolist(), seeds.tolist(), strict=True):
                self.set(i, np.random.Generator(np.random.PCG64(s)))
            return
        words = np.empty((indices.shape[0], 4), dtype=np.uint64)
        seed_states(np.ascontiguousarray(seeds, dtype=np.uint64), words)
        self._lcg[indices[:, None], np.array(LAYOUT)] = words
        self._heads[indices, 1] = 0  # has_uint32 = 0, uinteger = 0: a fresh PCG64
        self.rows[indices, :G_STATE] = _TEMPLATE[:G_STATE]
        self.rows[indices, G_STATE] = self._heads.ctypes.data + 16 * indices.astype(np.uint64)
        self._in_arrays[indices] = True
        for i in indices.tolist():
            self._objects[i] = None

    def _take_out(self, i: int) -> None:
        # Env i's state as a Generator object, which the env draws from from now on.
        state_high, state_low, inc_high, inc_low = (int(self._lcg[i, w]) for w in LAYOUT or ())
        flags = int(self._heads[i, 1])
        bits = np.random.PCG64(0)
        bits.state = {
            "bit_generator": "PCG64",
            "state": {"state": (state_high << 64) | state_low, "inc": (inc_high << 64) | inc_low},
            "has_uint32": flags & 0xFFFFFFFF,
            "uinteger": flags >> 32,
        }
        self.set(i, np.random.Generator(bits))


guard_kernel_cache(__name__)
