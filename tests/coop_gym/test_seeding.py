"""Generators seeded in a batch: NumPy's ``PCG64(seed)`` state, seed by seed, and its stream through the kernels."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from coop_gym.envs.kernels import seeding
from coop_gym.envs.kernels.seeding import LAYOUT, MAX_BATCH_SEED, EnvGenerators, seed_states
from estimator.compiled.rng import integers, random, standard_normal

EDGE_SEEDS = [0, 1, 2, 5, 42, 2**31, 2**32 - 1, 2**32, 2**32 + 7, 2**40 + 3, 2**62, MAX_BATCH_SEED]


def _words(seed: int) -> list[int]:
    state = np.random.PCG64(seed).state["state"]
    s, i = state["state"], state["inc"]
    return [s >> 64, s & (2**64 - 1), i >> 64, i & (2**64 - 1)]


def test_seed_states_are_numpy_pcg64_states_seed_by_seed() -> None:
    rng = np.random.default_rng(7)
    seeds = [*EDGE_SEEDS, *rng.integers(0, 2**32, 300).tolist(), *rng.integers(0, MAX_BATCH_SEED, 300).tolist()]
    out = np.empty((len(seeds), 4), dtype=np.uint64)
    seed_states(np.array(seeds, dtype=np.uint64), out)
    assert [[int(w) for w in row] for row in out] == [_words(s) for s in seeds]


def test_numpy_pcg64_layout_is_recognised() -> None:
    # A NumPy build with another layout still works (Generator objects), but slower to reset.
    assert LAYOUT is not None


@njit(cache=False)
def _draw(row: np.ndarray, out: np.ndarray, offset: int) -> None:
    # A mixed stream: 32-bit draws (integers) leave a buffered half-word in the state.
    for k in range(out.shape[0]):
        kind = (offset + k) % 3
        if kind == 0:
            out[k] = integers(row, 7)
        elif kind == 1:
            out[k] = standard_normal(row)
        else:
            out[k] = random(row)


def _generator_draws(rng: np.random.Generator, count: int, offset: int = 0) -> list[float]:
    out = []
    for k in range(offset, offset + count):
        if k % 3 == 0:
            out.append(float(rng.integers(7)))
        elif k % 3 == 1:
            out.append(float(rng.standard_normal()))
        else:
            out.append(float(rng.random()))
    return out


@pytest.fixture(autouse=True)
def _always_in_arrays(monkeypatch: pytest.MonkeyPatch) -> None:
    # Small batches here too: the arrays, not a Generator object each.
    monkeypatch.setattr(seeding, "MIN_BATCH_ENVS", 0)


@pytest.mark.parametrize("split", [1, 4, 10])
def test_seeded_envs_draw_the_generators_numbers_and_hand_over_mid_stream(split: int) -> None:
    seeds = [3, 2**32 + 1, 99]
    generators = EnvGenerators(5)
    indices = np.array([0, 2, 4], dtype=np.int64)
    generators.seed(indices, np.array(seeds, dtype=np.uint64))
    assert [generators.has(i) for i in range(5)] == [True, False, True, False, True]
    assert generators[1] is None
    for i, seed in zip(indices.tolist(), seeds, strict=True):
        want = _generator_draws(np.random.Generator(np.random.PCG64(seed)), 40)
        first = np.empty(split)
        _draw(generators.rows[i], first, 0)
        rng = generators[i]  # made from the arrays where the stream stands (a buffered half-word too)
        assert rng is generators[i] and generators.is_object(i, rng)
        middle = np.empty(10)
        _draw(generators.rows[i], middle, split)  # the kernel row now draws from the object
        tail = _generator_draws(rng, 40 - split - 10, split + 10)
        assert [*first.tolist(), *middle.tolist(), *tail] == want
