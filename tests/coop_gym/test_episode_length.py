"""Episodes last what their ``timing`` says, through the registered ids, single and vector.

The ids register no ``TimeLimit``: the env truncates at its own length, so a longer, shorter or
finer ``timing`` is honoured (a ``TimeLimit`` of the default 300 steps used to cut a 60 s
episode at 30 s with outcome ``"none"``).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import coop_gym
from coop_gym.model.params import Timing

ENV_ID = "CoopGym/SitToStand-v0"

TIMINGS: list[dict[str, Any]] = [
    {},  # the default: 30 s, 300 steps
    {"episode_s": 60.0},  # longer
    {"episode_s": 2.0},  # shorter
    {"dt_s": 0.01},  # finer step: 600 actions of 0.05 s
    {"substeps": 10},  # coarser action: 150 actions of 0.2 s
    {"dt_s": 0.05, "substeps": 2, "episode_s": 7.0},  # coarser step
    {"episode_s": 1.05},  # not a whole number of actions: the step that passes it ends the episode
]
IDS = ["default", "longer", "shorter", "finer-dt", "coarser-substeps", "coarser-dt", "partial-action"]


def _expected(timing: dict[str, Any]) -> tuple[int, float]:
    t = Timing(**timing)
    return t.max_episode_steps, t.max_episode_steps * t.action_period_s


@pytest.mark.parametrize("timing", TIMINGS, ids=IDS)
def test_the_single_env_ends_by_its_clock_with_a_timeout(timing: dict[str, Any]) -> None:
    steps, episode_s = _expected(timing)
    env = gym.make(ENV_ID, timing=timing) if timing else gym.make(ENV_ID)
    assert env.spec is not None and env.spec.max_episode_steps == steps
    for seed in (0, 1):  # the second episode too: the step count restarts at reset
        env.reset(seed=seed)
        for step in range(1, steps + 1):
            _, _, terminated, truncated, info = env.step(np.array([0, 0, 0]))
            assert not terminated
            if step < steps:
                assert not truncated and info["outcome"] == "none", step
        assert truncated and info["outcome"] == "timeout"
        assert info["elapsed_s"] == pytest.approx(episode_s, abs=1e-6)
        assert info["elapsed_s"] >= Timing(**timing).episode_s - 1e-6


@pytest.mark.parametrize("timing", TIMINGS, ids=IDS)
def test_the_vector_env_ends_by_its_clock_with_a_timeout(timing: dict[str, Any]) -> None:
    steps, episode_s = _expected(timing)
    n = 3
    envs = gym.make_vec(ENV_ID, num_envs=n, autoreset_mode="SameStep", timing=timing)
    assert envs.unwrapped.max_episode_steps == steps
    envs.reset(seed=4)
    for step in range(1, steps + 1):
        _, _, terminated, truncated, infos = envs.step(np.zeros((n, 3), dtype=np.int64))
        assert not terminated.any()
        if step < steps:
            assert not truncated.any(), step
    assert truncated.all()
    final = infos["final_info"]
    assert list(final["outcome"]) == ["timeout"] * n
    np.testing.assert_allclose(final["elapsed_s"], episode_s, atol=1e-6)


def test_a_lift_on_the_last_step_is_terminated_and_truncated_as_under_a_time_limit() -> None:
    env = gym.make(ENV_ID, timing={"episode_s": 1.0})
    env.reset(seed=2)
    for _ in range(9):
        env.step(np.array([0, 0, 0]))
    _, _, terminated, truncated, info = env.step(np.array([0, 0, 1]))
    assert terminated and truncated and info["outcome"] != "timeout"


def test_the_registry_adds_no_time_limit_but_make_still_takes_one() -> None:
    env = gym.make(ENV_ID)
    assert "TimeLimit" not in str(env)
    limited = gym.make(ENV_ID, max_episode_steps=7, timing={"episode_s": 60.0})
    assert limited.spec is not None and limited.spec.max_episode_steps == 7
    limited.reset(seed=0)
    ends = [limited.step(np.array([0, 0, 0]))[3] for _ in range(7)]
    assert ends == [False] * 6 + [True]
    # A spec read back off an env rebuilds an env with the same episode length.
    again = gym.make(gym.make(ENV_ID, timing={"episode_s": 3.0}).spec)
    assert again.spec is not None and again.spec.max_episode_steps == 30
    assert again.unwrapped.timing.episode_s == 3.0
    assert coop_gym  # the ids are registered on import
