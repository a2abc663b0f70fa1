"""The atomic operations the threaded step shares work with: exact under contention."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from numba import njit

from coop_gym.envs.kernels.atomics import atomic_add, atomic_cas, atomic_load


@njit(nogil=True)
def _count(counters: np.ndarray, rounds: int) -> None:
    # Each round: +1 on counter 0 by compare-and-swap (retrying on a lost race), +2 on counter 1 by add.
    for _ in range(rounds):
        while True:
            seen = atomic_load(counters, 0)
            if atomic_cas(counters, 0, seen, seen + 1) == seen:
                break
        atomic_add(counters, 1, 2)


def test_two_threads_lose_no_update() -> None:
    counters = np.zeros(2, dtype=np.int64)
    rounds = 200_000
    threads = [threading.Thread(target=_count, args=(counters, rounds)) for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    # Plain read-modify-writes from two threads lose updates; these must not.
    assert counters.tolist() == [2 * rounds, 4 * rounds]


@njit
def _swap(values: np.ndarray, expected: int, new: int) -> tuple[int, int]:
    old = atomic_cas(values, 1, expected, new)
    return old, atomic_load(values, 1)


def test_compare_and_swap_only_swaps_the_expected_value() -> None:
    values = np.array([0, 5], dtype=np.int64)
    assert _swap(values, 4, 9) == (5, 5)  # not the expected value: unchanged, the old value returned
    assert _swap(values, 5, 9) == (5, 9)


@njit
def _load_float(values: np.ndarray) -> int:
    return atomic_load(values, 0)


def test_only_int64_vectors_are_accepted() -> None:
    with pytest.raises(TypeError, match="1-D int64 array"):
        _load_float(np.zeros(2))
