"""The vector env seeds its envs in one batch (coop_gym.envs.kernels.seeding): the same envs as one Generator each."""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest

import coop_gym  # noqa: F401  (registers the ids)
from coop_gym.envs.kernels import seeding
from coop_gym.envs.kernels.seeding import MAX_BATCH_SEED

ENV_ID = "CoopGym/SitToStand-v0"


@pytest.fixture(autouse=True, params=["in arrays", "objects"])
def _batch(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> None:
    # Both ways of seeding a batch: the compiled one (the arrays) and a Generator object each.
    if request.param == "in arrays":
        monkeypatch.setattr(seeding, "MIN_BATCH_ENVS", 0)


ACTIONS = np.array([[1, 2, 0], [2, 0, 0], [0, 1, 0]])


def test_each_env_matches_a_single_env_whatever_its_seed() -> None:
    """Batch-seeded, past the batch's range (an object of its own) and kept (None) alike."""
    seeds = [7, MAX_BATCH_SEED + 5, 2**32]
    envs = gym.make_vec(ENV_ID, num_envs=3)
    obs, _ = envs.reset(seed=seeds)
    singles = [gym.make(ENV_ID) for _ in seeds]
    for i, (env, seed) in enumerate(zip(singles, seeds, strict=True)):
        single_obs, _ = env.reset(seed=seed)
        np.testing.assert_array_equal(obs[i], single_obs)
    obs, _ = envs.reset(seed=[None, None, 3])  # envs 0 and 1 go on with their generators
    for i, seed in enumerate([None, None, 3]):
        single_obs, _ = singles[i].reset(seed=seed)
        np.testing.assert_array_equal(obs[i], single_obs)
    for _ in range(5):
        vector_obs = envs.step(ACTIONS)[0]
        for i, env in enumerate(singles):
            np.testing.assert_array_equal(vector_obs[i], env.step(ACTIONS[i])[0])
    # An env's Generator, asked for, carries its stream on where the single env's stands.
    core = envs.unwrapped.core
    assert core.rngs[0].bit_generator.state == singles[0].unwrapped.np_random.bit_generator.state


def test_unseeded_envs_get_distinct_fresh_generators() -> None:
    envs = gym.make_vec(ENV_ID, num_envs=4)
    envs.reset()
    states = [envs.unwrapped.core.rngs[i].bit_generator.state["state"]["state"] for i in range(4)]
    assert len(set(states)) == 4


def test_a_batch_seeded_vector_env_pickles_and_goes_on_alike() -> None:
    envs = gym.make_vec(ENV_ID, num_envs=3)
    envs.reset(seed=11)
    envs.step(ACTIONS)
    copy = pickle.loads(pickle.dumps(envs))
    for _ in range(5):
        a, b = envs.step(ACTIONS), copy.step(ACTIONS)
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[1], b[1])
