"""The threaded step: worker threads that claim blocks of envs from an atomic counter and step them.

Each thread runs one ``nogil`` kernel (:func:`step_claimed`) that claims the next unclaimed
block of about :data:`ENVS_PER_BLOCK` envs until none is left, and runs
:func:`coop_gym.envs.kernels.step.step_envs` on it. Env ``i``'s numbers depend only on its own row and
generator, so the results are bit-identical whatever the thread count
(tests/coop_gym/test_threads.py).
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from coop_gym.envs.kernels.atomics import atomic_add, atomic_cas, atomic_load
from coop_gym.envs.kernels.step import step_envs
from estimator.compiled.cache import guard_kernel_cache
from estimator.compiled.rng import G_STATE
from estimator.validate import is_integer

__all__ = [
    "ENVS_PER_BLOCK",
    "MIN_ENVS_PER_THREAD",
    "available_threads",
    "check_threads",
    "plan_threads",
    "step_threaded",
]

MIN_ENVS_PER_THREAD = 512
"""Fewer envs per thread than this step on one thread. A threaded step costs a worker's wake-up
and moves the envs' rows between the cores' caches (~2 KB per env), so a second thread pays
only for batches of several hundred envs per thread; the single env and SB3-sized batches step
on one. ``python bench/run.py`` reports 2 threads over 1 at 1024 envs (512 per thread)."""

ENVS_PER_BLOCK = 64
"""Envs per block a thread claims at a time (small enough that the threads finish together,
large enough that claiming costs little)."""

# The control words of a threaded step (an int64 array per core): the claim word -- the step's
# number in the high bits, the next unclaimed block in the low 32 -- and the blocks done. Step
# numbers wrap at 2**31, so the claim word stays a non-negative int64.
_CLAIM, _DONE = 0, 1
_LOW32 = (1 << 32) - 1
_STEP_NUMBERS = 1 << 31

_WAIT_SPINS = 20_000
"""Reads of the done count before the waiting thread yields its core (tens of microseconds: about
one block's work, the usual wait; on a busy machine a worker holding a block gets the core)."""


def available_threads() -> int:
    """The threads a batched core uses by default: the cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def check_threads(threads: Any) -> int:
    """``threads`` validated: ``None`` (:func:`available_threads`) or a positive int."""
    if threads is None:
        return available_threads()
    if not is_integer(threads) or threads < 1:
        raise ValueError(f"threads must be None or a positive int, got {threads!r}")
    return int(threads)


def plan_threads(threads: int, n_envs: int, generators: NDArray[np.uint64]) -> int:
    """How many threads a step of ``n_envs`` uses: 1 unless it pays and is safe."""
    chunks = min(threads, n_envs // MIN_ENVS_PER_THREAD)
    if chunks > 1:
        # Two envs drawing from one generator must draw in env order: one thread.
        drawing = generators[:, G_STATE]
        drawing = drawing[drawing != 0]
        if np.unique(drawing).shape[0] != drawing.shape[0]:
            chunks = 1
    return max(chunks, 1)


# The worker threads of threaded steps, shared by every core of the process and started at
# the first threaded step. Python threads calling a ``nogil`` kernel, not Numba's OpenMP
# ``parallel=True``: OpenMP's threads spin between steps, and once torch has loaded its own
# OpenMP runtime (Numba then uses that one, whose wait policy is already fixed) a threaded
# step becomes several times slower. GNU OpenMP also aborts children forked after a parallel
# region; these threads are simply gone in a child.
_workers: ThreadPoolExecutor | None = None
_workers_lock = threading.Lock()


def _worker_pool(count: int) -> ThreadPoolExecutor:
    """A pool of at least ``count`` worker threads."""
    global _workers
    with _workers_lock:
        if _workers is None or _workers._max_workers < count:
            if _workers is not None:
                _workers.shutdown(wait=False)
            _workers = ThreadPoolExecutor(count, thread_name_prefix="coop_gym-step")
        return _workers


def _forget_workers() -> None:
    # In a forked child the parent's threads do not exist: start new ones when needed.
    global _workers, _workers_lock
    _workers = None
    _workers_lock = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_workers)


@njit(cache=True, error_model="numpy", nogil=True)
def step_claimed(
    step: int,
    blocks: int,
    control: NDArray[np.int64],
    cmd: NDArray[np.float64],
    state: NDArray[np.float64],
    generators: NDArray[np.uint64],
    obs: NDArray[np.float32],
    consts: NDArray[np.float64],
) -> None:
    """Step blocks of envs, claimed one at a time, until step ``step`` has none left.

    A worker that starts after its step is over finds another step's number in the claim word
    and does nothing.
    """
    n = cmd.shape[0]
    while True:
        word = atomic_load(control, _CLAIM)
        block = word & _LOW32
        if word >> 32 != step or block >= blocks:
            return
        if atomic_cas(control, _CLAIM, word, word + 1) == word:
            step_envs(block * n // blocks, (block + 1) * n // blocks, cmd, state, generators, obs, consts)
            atomic_add(control, _DONE, 1)


@njit(cache=True, error_model="numpy", nogil=True)
def _close_step(control: NDArray[np.int64], blocks: int) -> int:
    # Leave no block of the current step to claim; returns how many were claimed (all of them,
    # unless the calling thread was interrupted before it had claimed the rest).
    while True:
        word = atomic_load(control, _CLAIM)
        claimed = word & _LOW32
        if claimed >= blocks:
            return blocks
        if atomic_cas(control, _CLAIM, word, word - claimed + blocks) == word:
            return claimed


@njit(cache=True, error_model="numpy", nogil=True)
def _blocks_done(control: NDArray[np.int64], blocks: int, spins: int) -> bool:
    # Whether every block is done, read up to ``spins`` times: a wait too short to sleep through.
    for _ in range(spins):
        if atomic_load(control, _DONE) >= blocks:
            return True
    return False


def _yield_core() -> None:
    # The scheduler may run another thread on this core now (the GIL is released meanwhile).
    if hasattr(os, "sched_yield"):
        os.sched_yield()
    else:  # Windows
        time.sleep(0)


def step_threaded(
    chunks: int,
    control: NDArray[np.int64],
    arrays: tuple[
        NDArray[np.float64], NDArray[np.float64], NDArray[np.uint64], NDArray[np.float32], NDArray[np.float64]
    ],
    meanwhile: Callable[[], None] | None = None,
) -> None:
    """Step the envs on up to ``chunks`` threads (this one and ``chunks - 1`` workers).

    On a busy machine a worker that is not scheduled in time finds the step over and does
    nothing, and this thread steps every block (one thread's speed, not a wait for the
    slowest); with a free core the blocks are shared. ``meanwhile`` (the resets of envs not
    active in ``cmd``) runs on this thread first, while the workers wake up. This thread then
    waits for the workers' last blocks in a kernel, not on a lock: a lock's wake-up would cost
    as much again (after :data:`_WAIT_SPINS` reads it yields the core between reads).

    Args:
        chunks: Threads to use (at least 2).
        control: The core's two control words (claim, done).
        arrays: ``(cmd, state, generators, obs, consts)`` of :func:`~coop_gym.envs.kernels.step.step_envs`.
        meanwhile: Work for this thread before it claims blocks.
    """
    n = arrays[0].shape[0]
    blocks = max(chunks, n // ENVS_PER_BLOCK)
    step = (int(control[_CLAIM] >> 32) + 1) % _STEP_NUMBERS  # the last step's number, plus one
    control[_DONE] = 0
    control[_CLAIM] = step << 32  # after the done count: a worker may claim as soon as it sees this
    args = (step, blocks, control, *arrays)
    pool = _worker_pool(chunks - 1)
    for _ in range(chunks - 1):
        pool.submit(step_claimed, *args)
    try:
        if meanwhile is not None:
            meanwhile()
        step_claimed(*args)
    finally:
        # Every block is claimed -- or, if this thread was interrupted (Ctrl-C), none will be
        # from now on: no worker goes on changing the envs once this call has returned.
        claimed = _close_step(control, blocks)
        while not _blocks_done(control, claimed, _WAIT_SPINS):
            _yield_core()


guard_kernel_cache(__name__)
