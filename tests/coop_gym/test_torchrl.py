"""TorchRL reads coop_gym envs with ``info_mode="numeric"``: the info lands in the TensorDict.

TorchRL's ``GymWrapper`` takes a Gymnasium vector env only with ``autoreset_mode`` ``SAME_STEP``
or ``DISABLED`` (it refuses coop_gym's default ``NEXT_STEP``); its info reader stacks every info
value into a tensor, so labels and nested dicts cannot pass.
"""

from __future__ import annotations

import gymnasium as gym
import pytest
from gymnasium.vector import AutoresetMode

import coop_gym
from coop_gym.envs.contract import NUMERIC_INFO_KEYS

torchrl_gym = pytest.importorskip(
    "torchrl.envs.libs.gym", reason="torchrl is not installed (pip install -e '.[test]' brings it)"
)
torchrl_utils = pytest.importorskip("torchrl.envs.utils")


def _wrapped(env_id: str, mode: AutoresetMode, num_envs: int = 8):  # type: ignore[no-untyped-def]
    venv = gym.make_vec(env_id, num_envs=num_envs, info_mode="numeric", autoreset_mode=mode)
    return torchrl_gym.GymWrapper(venv, categorical_action_encoding=True)


@pytest.mark.parametrize("mode", [AutoresetMode.SAME_STEP, AutoresetMode.DISABLED])
def test_gym_wrapper_rolls_out_the_batched_env_with_its_numeric_info(mode: AutoresetMode) -> None:
    env = _wrapped("CoopGym/SitToStandUnit-v0", mode)
    if mode == AutoresetMode.DISABLED:
        env.auto_register_info_dict()  # TorchRL registers the info reader itself only for autoresetting envs
    torchrl_utils.check_env_specs(env)
    rollout = env.rollout(60, break_when_any_done=False)
    assert rollout.batch_size == (8, 60)
    step = rollout["next"]
    assert set(NUMERIC_INFO_KEYS) | {"unscaled_obs"} <= set(step.keys())
    assert step["observation"].abs().max() <= 1.0
    assert step["unscaled_obs"].shape == (8, 60, 11)
    done = step["done"].squeeze(-1)
    assert done.any()
    # The episode's end is read as it happened (the final info, not the next episode's reset).
    codes = step["outcome_code"][done]
    assert bool((codes != int(coop_gym.Outcome.NONE)).all())
    assert bool((step["outcome_code"][~done] == int(coop_gym.Outcome.NONE)).all())


def test_gym_wrapper_refuses_the_default_next_step_autoreset() -> None:
    with pytest.raises(RuntimeError, match="SAME_STEP or DISABLED"):
        _wrapped("CoopGym/SitToStand-v0", AutoresetMode.NEXT_STEP, num_envs=2)


def test_gym_env_reads_the_single_envs_numeric_info() -> None:
    env = torchrl_gym.GymEnv("coop_gym:CoopGym/SitToStandIMM-v0", info_mode="numeric", categorical_action_encoding=True)
    env.auto_register_info_dict()
    torchrl_utils.check_env_specs(env)
    rollout = env.rollout(300)
    assert {"outcome_code", "persona_index", "p_cooperative", "reward_success"} <= set(rollout["next"].keys())
    assert int(rollout["next", "outcome_code"][-1]) != int(coop_gym.Outcome.NONE)


@pytest.mark.slow  # eight worker processes, each importing torch and compiling coop_gym: minutes on 2 cores
def test_gym_env_with_num_envs_rolls_out_numeric_infos() -> None:
    # GymEnv(num_envs=N) steps Gymnasium's AsyncVectorEnv in its NEXT_STEP mode, which TorchRL
    # 0.14.1 reads without the final infos (outcome_code 0 at episode ends): docs/integrations.md points
    # to GymWrapper over make_vec instead. This checks only that the numeric info is read in.
    env = torchrl_gym.GymEnv("coop_gym:CoopGym/SitToStand-v0", num_envs=8, info_mode="numeric")
    try:
        torchrl_utils.check_env_specs(env)
        rollout = env.rollout(50, break_when_any_done=False)
        assert rollout.batch_size == (8, 50)
        assert set(NUMERIC_INFO_KEYS) <= set(rollout["next"].keys())
    finally:
        env.close()
