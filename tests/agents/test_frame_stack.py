"""A frame-stacked agent plays what it trained on: SB3Agent rebuilds VecFrameStack's stack from plain observations."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from stable_baselines3.common.vec_env import VecFrameStack

from agents.evaluate import evaluate
from agents.hyperparams import hyperparams_for
from agents.rl import SB3Agent, find_vec_normalize, load_agent, load_to_continue, make_model, make_train_env, save_agent

torch.set_num_threads(1)

ENV_ID = "CoopGym/SitToStandHard-v2"
RAW = {"observation_mode": "raw"}
K = 3


def _stacked_model(seed: int = 0, n_envs: int = 4):
    config = hyperparams_for("ppo", ENV_ID)
    env = make_train_env(ENV_ID, n_envs, seed, personas=config.personas, normalize=True, env_kwargs=RAW)
    env = VecFrameStack(env, K)
    model = make_model(config, env, seed, overrides={"n_steps": 32, "batch_size": 64, "n_epochs": 1})
    model.learn(128)
    return model, env


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    model, env = _stacked_model()
    path = save_agent(model, tmp_path_factory.mktemp("stacked"), algo="ppo", env_id=ENV_ID)
    return model, env, path


def test_the_loaded_agent_builds_the_training_stack(saved):
    """Across episode ends, the stack the agent feeds its policy is the one VecFrameStack gave in training."""
    _, env, path = saved
    agent = load_agent(path)
    assert agent.frame_stack == K
    normalize = find_vec_normalize(env)
    normalize.training = False  # the statistics stay those the agent saved
    stacked = env.reset()
    state, episode_start, ends = None, np.ones(env.num_envs, dtype=bool), 0
    for _ in range(700):  # past every env's first episode (30 s of 0.1-s steps at most)
        actions, state = agent.predict(normalize.get_original_obs(), state, episode_start)
        np.testing.assert_allclose(state, stacked, rtol=0, atol=1e-5)
        stacked, _, dones, _ = env.step(actions)
        episode_start = dones
        ends += int(dones.sum())
    assert ends >= env.num_envs


def test_state_none_callers_get_the_same_actions(saved):
    """A caller that passes no state (``action, _ = agent.predict(obs)``) gets the agent's own memory."""
    _, _, path = saved
    kept, own = load_agent(path), load_agent(path)
    env = make_train_env(ENV_ID, 2, 7, personas="train", env_kwargs=RAW)
    obs = env.reset()
    state, episode_start = None, np.ones(2, dtype=bool)
    for _ in range(350):
        a, state = kept.predict(obs, state, episode_start)
        b, _ = own.predict(obs)
        np.testing.assert_array_equal(a, b)
        obs, _, episode_start, _ = env.step(a)


def test_evaluate_and_continue_a_stacked_model(saved, tmp_path):
    """The evaluation path scores it; resuming rebuilds the stack around the training env."""
    _, _, path = saved
    result = evaluate(load_agent(path), ENV_ID, "test", 8, 0, env_kwargs=RAW)
    assert result.episodes == 8
    env = make_train_env(ENV_ID, 4, 1, personas="train_wide", env_kwargs=RAW)
    model, wrapped = load_to_continue(path, env)
    assert isinstance(wrapped, VecFrameStack) and wrapped.observation_space.shape == (K * 5,)
    model.learn(128, reset_num_timesteps=False)


def test_bad_frame_stack_and_state():
    model, _ = _stacked_model(n_envs=2)
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="frame_stack"):
            SB3Agent(model, "ppo", ENV_ID, frame_stack=bad)
    agent = SB3Agent(model, "ppo", ENV_ID, frame_stack=K)
    obs = np.zeros((2, 5), dtype=np.float32)
    with pytest.raises(ValueError, match="frame stack"):
        agent.predict(obs, state=np.zeros((2, 4)))
