"""The SB3 VecEnv adapter over the natively batched env."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
import torch
from gymnasium.vector import AutoresetMode
from stable_baselines3 import PPO
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor, VecNormalize

import coop_gym
from agents.rl.sb3_vec import SB3VecEnvAdapter, make_sb3_vec_env

SHORT = {"timing": {"episode_s": 2.0}, "max_episode_steps": 20}  # truncation within a short test


def _dummy(env_id: str, n: int, seed: int, **kwargs: Any) -> DummyVecEnv:
    venv = DummyVecEnv([lambda: Monitor(gym.make(env_id, **kwargs)) for _ in range(n)])
    venv.seed(seed)
    return venv


def _assert_same_info(got: dict[str, Any], expected: dict[str, Any]) -> None:
    assert set(got) == set(expected), set(got) ^ set(expected)
    for key, value in expected.items():
        if key == "episode":
            assert got["episode"]["r"] == pytest.approx(value["r"]) and got["episode"]["l"] == value["l"]
        elif isinstance(value, np.ndarray):
            assert np.array_equal(got[key], value), key
        else:
            assert got[key] == value and type(got[key]) is type(value), key


@pytest.mark.parametrize(
    ("env_id", "options"),
    [
        ("CoopGym/SitToStand-v0", {}),
        ("CoopGym/SitToStandMM-v0", {}),
        # The env's info contract holds through the adapter: unscaled_obs on a unit id, numeric infos.
        ("CoopGym/SitToStandUnit-v0", {}),
        ("CoopGym/SitToStandUnit-v0", {"info_mode": "numeric"}),
        ("CoopGym/SitToStandMM-v0", {"info_mode": "numeric"}),
    ],
)
def test_adapter_steps_exactly_like_dummy_vec_env_of_single_envs(env_id: str, options: dict[str, Any]) -> None:
    n, seed = 3, 40
    adapter = make_sb3_vec_env(env_id, n, seed, env_kwargs={**SHORT, **options})
    dummy = _dummy(env_id, n, seed, **SHORT, **options)
    assert np.array_equal(adapter.reset(), dummy.reset())
    for i in range(n):
        _assert_same_info(adapter.reset_infos[i], dummy.reset_infos[i])
    rng = np.random.default_rng(0)
    finished = truncated_seen = 0
    for _ in range(60):
        actions = np.column_stack([rng.integers(0, 3, n), rng.integers(0, 3, n), rng.random(n) < 0.05])
        obs_a, rew_a, done_a, infos_a = adapter.step(actions)
        obs_d, rew_d, done_d, infos_d = dummy.step(actions)
        assert np.array_equal(obs_a, obs_d) and np.array_equal(rew_a, rew_d) and np.array_equal(done_a, done_d)
        assert rew_a.dtype == rew_d.dtype and done_a.dtype == np.bool_
        for i in range(n):
            if done_d[i]:
                assert np.array_equal(infos_a[i]["terminal_observation"], infos_d[i]["terminal_observation"])
                assert infos_a[i]["episode"]["l"] == infos_d[i]["episode"]["l"]
                _assert_same_info(adapter.reset_infos[i], dummy.reset_infos[i])
                finished += 1
                truncated_seen += infos_d[i]["TimeLimit.truncated"]
            _assert_same_info(
                {k: v for k, v in infos_a[i].items() if k != "terminal_observation"},
                {k: v for k, v in infos_d[i].items() if k != "terminal_observation"},
            )
    assert finished >= 5 and truncated_seen >= 1
    final = infos_a[int(np.flatnonzero(done_a)[0])] if done_a.any() else infos_a[0]
    for info in (infos_a[0], final, adapter.reset_infos[0]):
        if gym.spec(env_id).kwargs.get("observation_scale") == "unit":
            assert info["unscaled_obs"].dtype == np.float32
        if options.get("info_mode") == "numeric":
            assert "outcome_code" in info and "outcome" not in info and "reward_terms" not in info


def test_terminal_observation_is_the_real_final_observation() -> None:
    adapter = make_sb3_vec_env("CoopGym/SitToStand-v0", 2, seed=1)
    adapter.reset()
    for _ in range(3):
        obs, *_ = adapter.step(np.array([[1, 2, 0], [1, 2, 0]]))
    last = obs[0].copy()
    obs, rewards, dones, infos = adapter.step(np.array([[0, 0, 1], [0, 0, 0]]))
    assert dones.tolist() == [True, False]
    final = infos[0]["terminal_observation"]
    # A lift ends the episode without simulating: the final observation is the last one.
    assert np.array_equal(final, last) and not np.array_equal(obs[0], final)
    assert obs[0][coop_gym.SitToStandEnv().features.index("elapsed_s")] == 0.0  # already reset
    assert infos[0]["episode"] == {"r": pytest.approx(rewards[0] + 3 * -0.0015), "l": 4, "t": infos[0]["episode"]["t"]}
    assert infos[0]["TimeLimit.truncated"] is False and infos[0]["outcome"] in ("unsafe", "premature", "success")
    assert "terminal_observation" not in infos[1] and "episode" not in infos[1]


def test_ppo_learns_through_the_adapter_and_counts_steps() -> None:
    torch.set_num_threads(1)
    adapter = make_sb3_vec_env("CoopGym/SitToStand-v0", 4, seed=0)
    model = PPO("MlpPolicy", adapter, n_steps=16, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(64)
    assert model.num_timesteps == 64
    episodes = list(model.ep_info_buffer)
    assert episodes and all(set(e) == {"r", "l", "t"} for e in episodes)
    # Random early policies lift often: every episode has 1..300 steps and a finite return.
    assert all(1 <= e["l"] <= 300 and np.isfinite(e["r"]) for e in episodes)


def test_adapter_works_under_vec_monitor_and_vec_normalize() -> None:
    venv = VecNormalize(VecMonitor(make_sb3_vec_env("CoopGym/SitToStandDiscrete-v0", 2, seed=3)), norm_reward=False)
    obs = venv.reset()
    assert obs.shape == (2, 11)
    for _ in range(5):
        obs, _, dones, _ = venv.step(np.array([1, 1]))
    assert obs.shape == (2, 11) and dones.shape == (2,)
    venv.close()


def test_attributes_methods_and_seeds() -> None:
    adapter = make_sb3_vec_env("CoopGym/SitToStand-v0", 3, seed=None)
    assert adapter.get_attr("num_envs") == [3, 3, 3]
    assert adapter.get_attr("features", indices=[1]) == [adapter.venv.unwrapped.features]
    assert adapter.has_attr("personas") and not adapter.has_attr("no_such_attribute")
    assert adapter.env_is_wrapped(Monitor) == [False, False, False]
    assert adapter.seed(7) == [7, 8, 9]
    obs = adapter.reset()
    single = [gym.make("CoopGym/SitToStand-v0").reset(seed=7 + i)[0] for i in range(3)]
    assert np.array_equal(obs, np.stack(single))
    adapter.set_attr("max_episode_steps", 50)
    assert adapter.venv.unwrapped.max_episode_steps == 50
    with pytest.raises(ValueError, match="shared"):
        adapter.set_attr("max_episode_steps", 10, indices=[0])
    with pytest.warns(UserWarning, match="render_mode"):
        assert adapter.env_method("render") == [None, None, None]  # no render mode: warns, draws nothing
    adapter.close()


def test_per_env_options_reset_each_group_with_its_options() -> None:
    adapter = make_sb3_vec_env("CoopGym/SitToStand-v0", 3, seed=5)
    names = ["anxious", "typical", "anxious"]
    adapter.set_options([{"persona": name} for name in names])
    obs = adapter.reset()
    assert [info["persona"] for info in adapter.reset_infos] == names
    for i, name in enumerate(names):
        single_obs, single_info = gym.make("CoopGym/SitToStand-v0").reset(seed=5 + i, options={"persona": name})
        assert np.array_equal(obs[i], single_obs) and adapter.reset_infos[i]["true_x_m"] == single_info["true_x_m"]


def test_bad_construction_raises_naming_the_problem() -> None:
    with pytest.raises(TypeError, match="VectorEnv"):
        SB3VecEnvAdapter(gym.make("CoopGym/SitToStand-v0"))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="SAME_STEP"):
        SB3VecEnvAdapter(gym.make_vec("CoopGym/SitToStand-v0", num_envs=2))
    with pytest.raises(ValueError, match="n_envs"):
        make_sb3_vec_env("CoopGym/SitToStand-v0", 0)
    with pytest.raises(ValueError, match="autoreset_mode"):
        make_sb3_vec_env("CoopGym/SitToStand-v0", 2, env_kwargs={"autoreset_mode": AutoresetMode.NEXT_STEP})
    with pytest.raises(ValueError, match="seed"):
        make_sb3_vec_env("CoopGym/SitToStand-v0", 2).seed(-1)


def test_generic_vector_envs_go_through_the_dict_of_arrays_path_with_the_same_result() -> None:
    """A SyncVectorEnv of single envs (generic path) and the batched env (fast path) agree."""
    n, seed = 2, 11
    fast = make_sb3_vec_env("CoopGym/SitToStand-v0", n, seed)
    sync = gym.make_vec(
        "CoopGym/SitToStand-v0",
        num_envs=n,
        vectorization_mode="sync",
        vector_kwargs={"autoreset_mode": AutoresetMode.SAME_STEP},
    )
    generic = SB3VecEnvAdapter(sync)
    assert generic._rows_env is None and fast._rows_env is not None
    generic.seed(seed)
    assert np.array_equal(fast.reset(), generic.reset())
    rng = np.random.default_rng(1)
    done_count = 0
    for _ in range(30):
        _, infos_f, infos_g = _step_alike(fast, generic, rng, 0.2)
        for got, expected in zip(infos_f, infos_g, strict=True):
            if "terminal_observation" in expected:
                assert np.array_equal(got.pop("terminal_observation"), expected.pop("terminal_observation"))
                assert got.pop("episode")["l"] == expected.pop("episode")["l"]
                done_count += 1
            _assert_same_info(got, expected)
    assert done_count >= 3


def _step_alike(
    first: SB3VecEnvAdapter, second: SB3VecEnvAdapter, rng: np.random.Generator, lift_probability: float
) -> tuple[Any, list[dict[str, Any]], list[dict[str, Any]]]:
    """One random step of both adapters; their observations, rewards and dones must agree."""
    n = first.num_envs
    actions = np.column_stack([rng.integers(0, 3, n), rng.integers(0, 3, n), rng.random(n) < lift_probability])
    obs_a, rew_a, done_a, infos_a = first.step(actions)
    obs_b, rew_b, done_b, infos_b = second.step(actions)
    assert np.array_equal(obs_a, obs_b) and np.array_equal(rew_a, rew_b) and np.array_equal(done_a, done_b)
    return done_a, infos_a, infos_b


@pytest.mark.parametrize("generic", [False, True])
def test_finished_step_infos_keep_every_finished_episodes_info_and_nothing_else(generic: bool) -> None:
    """``step_infos="finished"``: the same steps; a finished env's info as ``"all"`` gives it, others empty."""
    n, seed = 4, 21

    def adapter(step_infos: str) -> SB3VecEnvAdapter:
        if not generic:
            return make_sb3_vec_env("CoopGym/SitToStand-v0", n, seed, env_kwargs=SHORT, step_infos=step_infos)
        sync = gym.make_vec(
            "CoopGym/SitToStand-v0",
            num_envs=n,
            vectorization_mode="sync",
            vector_kwargs={"autoreset_mode": AutoresetMode.SAME_STEP},
            **SHORT,
        )
        made = SB3VecEnvAdapter(sync, step_infos=step_infos)
        made.seed(seed)
        return made

    full, lean = adapter("all"), adapter("finished")
    assert np.array_equal(full.reset(), lean.reset())
    rng = np.random.default_rng(2)
    finished = 0
    for _ in range(60):
        dones, infos_a, infos_l = _step_alike(full, lean, rng, 0.1)
        for done, got, expected in zip(dones, infos_l, infos_a, strict=True):
            if not done:
                assert got == {}
                continue
            finished += 1
            assert np.array_equal(got.pop("terminal_observation"), expected.pop("terminal_observation"))
            assert got.pop("episode")["l"] == expected.pop("episode")["l"]
            _assert_same_info(got, expected)
    assert finished >= 4
    with pytest.raises(ValueError, match="step_infos"):
        make_sb3_vec_env("CoopGym/SitToStand-v0", 2, step_infos="some")
