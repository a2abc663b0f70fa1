"""Ray RLlib: the predict adapter, the loader, evaluation CLI dispatch, and train.py --framework rllib.

Skipped without the ``[rllib]`` extra, so the README's test command runs this file in an
``[rllib]`` venv of its own, the slow test included (``scripts/test_other_installs.sh``).
The end-to-end run starts a local Ray instance with two env runners, whose actors take
minutes to start, so it is marked ``slow``.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("ray.rllib")

from ray.rllib.connectors.env_to_module import MeanStdFilter
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.env.single_agent_episode import SingleAgentEpisode

import coop_gym  # noqa: F401
from agents.evaluate import evaluate
from agents.hyperparams import hyperparams_for
from agents.rl.rllib import (
    CHECKPOINT_DIR,
    DEFAULT_NUM_ENVS,
    OBS_CLIP,
    RLlibAgent,
    _filter_path,
    _module_path,
    envs_per_runner,
    filter_normalizer,
    is_rllib_run,
    load_rllib_agent,
    ppo_config,
)

ROOT = Path(__file__).resolve().parents[2]
ENV_ID = "CoopGym/SitToStand-v0"


def _module(env_id: str = ENV_ID):
    env = gym.make(env_id)
    spaces = {DEFAULT_MODULE_ID: (env.observation_space, env.action_space)}
    env.close()
    return ppo_config(env_id).get_rl_module_spec(spaces=spaces).build()


@pytest.mark.parametrize("env_id", [ENV_ID, "CoopGym/SitToStandDiscrete-v0", "CoopGym/SitToStandContinuous-v0"])
def test_adapter_follows_the_predict_protocol_and_is_scored_by_evaluate(env_id):
    agent = RLlibAgent(_module(env_id), env_id)
    env = gym.make(env_id)
    obs = np.stack([env.reset(seed=s)[0] for s in range(5)])
    actions, state = agent.predict(obs, state=None, episode_start=np.ones(5, dtype=bool), deterministic=True)
    assert state is None and len(actions) == 5
    assert all(env.action_space.contains(a) for a in actions)
    again, _ = agent.predict(obs, deterministic=True)
    assert np.array_equal(actions, again)
    single, _ = agent.predict(obs[0])
    assert env.action_space.contains(single)
    result = evaluate(agent, env_id, "test", 6, 0, name="rllib")
    assert result.episodes == 6 and result.agent == "rllib"


def test_a_saved_module_loads_from_a_run_folder_and_the_evaluate_cli_takes_it(tmp_path):
    module = _module()
    run_dir = tmp_path / "CoopGym-SitToStand-v0__rllib_ppo__0__1"
    module.save_to_path(str(_module_path(run_dir / CHECKPOINT_DIR)))
    info = {"framework": "rllib", "algo": "ppo", "env_id": ENV_ID, "checkpoint": CHECKPOINT_DIR}
    (run_dir / "agent.json").write_text(json.dumps(info))
    assert is_rllib_run(run_dir) and is_rllib_run(run_dir / CHECKPOINT_DIR)

    obs = np.random.default_rng(0).normal(size=(4, 11)).astype(np.float32)
    expected, _ = RLlibAgent(module).predict(obs)
    for path in (run_dir, run_dir / CHECKPOINT_DIR):
        loaded = load_rllib_agent(path)
        assert loaded.env_id == ENV_ID
        assert loaded.normalizer is None  # no filter saved: raw observations, as trained
        assert np.array_equal(loaded.predict(obs)[0], expected)

    cli = [sys.executable, "-m", "agents.evaluate", "--model", str(run_dir), "--episodes", "4", "--json"]
    out = subprocess.run(cli, capture_output=True, text=True, timeout=300, cwd=ROOT, check=False)
    assert out.returncode == 0, out.stderr[-2000:]
    assert '"episodes": 4' in out.stdout


def test_config_uses_the_new_api_stack_and_the_prefixed_id():
    config = ppo_config(ENV_ID, num_env_runners=2, num_envs_per_env_runner=3)
    assert config.enable_rl_module_and_learner and config.enable_env_runner_and_connector_v2
    assert config.env == "coop_gym:CoopGym/SitToStand-v0"  # workers import coop_gym before gym.make
    assert config.num_env_runners == 2 and config.num_envs_per_env_runner == 3
    with pytest.raises(ValueError, match="coop_gym id"):
        ppo_config("CartPole-v1")


def test_config_mirrors_sb3_ppo_lr_decay_no_kl_penalty_and_normalised_observations():
    sb3 = hyperparams_for("ppo", ENV_ID)
    config = ppo_config(ENV_ID, timesteps=300_000)
    # SB3's "lin_3e-4": from 3e-4 to 0 over the budget (RLlib interpolates between the points).
    assert config.lr == [[0, 3e-4], [300_000, 0.0]]
    assert ppo_config(ENV_ID).lr == 3e-4  # no budget: constant
    assert config.use_kl_loss is False  # SB3 has no KL penalty; RLlib's default adds one
    assert sb3.normalize
    env = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point")
    pipeline = config.build_env_to_module_connector(env=env, spaces=None, device=None)
    env.close()
    (obs_filter,) = [c for c in pipeline.connectors if isinstance(c, MeanStdFilter)]
    assert obs_filter.clip_by_value == OBS_CLIP == 10.0  # VecNormalize's clip_obs


def test_env_runners_share_64_envs_unless_told():
    # RLlib's sampler costs mostly per vector step (agents/rl/rllib.py), so 64 envs share it, not SB3's 8.
    assert DEFAULT_NUM_ENVS == 64
    assert envs_per_runner(None, 0) == 64  # sampling in the driver
    assert envs_per_runner(None, 1) == 64
    assert envs_per_runner(None, 2) == 32
    assert envs_per_runner(8, 2) == 4 and envs_per_runner(3, 4) == 1
    # One 4096-step batch: fragments of 4096 / 64 steps.
    config = ppo_config(ENV_ID, num_env_runners=2, num_envs_per_env_runner=envs_per_runner(None, 2))
    assert config.get_rollout_fragment_length(1) * 2 * 32 == config.train_batch_size_per_learner == 4096


def _trained_filter(rng: np.random.Generator, space: gym.spaces.Box, steps: int = 60) -> MeanStdFilter:
    """A MeanStdFilter that has seen ``steps`` observations, as in an env runner."""
    obs_filter = MeanStdFilter(clip_by_value=OBS_CLIP)
    obs_filter.input_observation_space = space
    observations = rng.normal(loc=np.linspace(-5, 100, 11), scale=np.linspace(0.1, 30, 11), size=(steps, 11))
    for x in observations.astype(np.float32):
        obs_filter(rl_module=None, batch={}, episodes=[SingleAgentEpisode(observations=[x], observation_space=space)])
    return obs_filter


def test_the_agent_normalises_observations_as_the_training_filter_did(tmp_path):
    rng = np.random.default_rng(3)
    module = _module()
    space = gym.spaces.Box(-np.inf, np.inf, (11,), np.float32)
    obs_filter = _trained_filter(rng, space)
    normalizer = filter_normalizer(obs_filter.get_state())

    # The frozen filter (update_stats=False) is what the policy saw; the agent must match it.
    frozen = MeanStdFilter(clip_by_value=OBS_CLIP, update_stats=False)
    frozen.input_observation_space = space
    frozen.set_state(obs_filter.get_state())
    probes = rng.normal(loc=np.linspace(-5, 100, 11), scale=60.0, size=(20, 11)).astype(np.float32)
    for x in probes:
        episode = SingleAgentEpisode(observations=[x], observation_space=space)
        frozen(rl_module=None, batch={}, episodes=[episode])
        np.testing.assert_allclose(normalizer(x), episode.get_observations(-1), rtol=1e-6, atol=1e-6)
    assert np.abs(normalizer(probes)).max() == pytest.approx(OBS_CLIP)  # some probes are clipped

    # Saved beside the module in a checkpoint, the loader finds it; the agent acts on normalised input.
    run_dir = tmp_path / "run"
    module.save_to_path(str(_module_path(run_dir / CHECKPOINT_DIR)))
    obs_filter.save_to_path(str(_filter_path(run_dir / CHECKPOINT_DIR)))
    info = {"framework": "rllib", "algo": "ppo", "env_id": ENV_ID, "checkpoint": CHECKPOINT_DIR}
    (run_dir / "agent.json").write_text(json.dumps(info))
    loaded = load_rllib_agent(run_dir)
    assert loaded.normalizer is not None
    np.testing.assert_array_equal(loaded.normalizer.mean, normalizer.mean)
    np.testing.assert_array_equal(loaded.normalizer.scale, normalizer.scale)
    expected, _ = RLlibAgent(module).predict(normalizer(probes))
    assert np.array_equal(loaded.predict(probes)[0], expected)


@pytest.mark.slow
def test_train_py_framework_rllib_with_two_env_runners(tmp_path):
    argv = [
        sys.executable,
        str(ROOT / "train.py"),
        "--framework",
        "rllib",
        # PPO's own env is the hard level since 521485a; this test names the -v0 run folder.
        "--env",
        ENV_ID,
        "--num-env-runners",
        "2",
        "--n-envs",
        "4",
        "--timesteps",
        "2000",
        "--eval-episodes",
        "8",
        "--baselines",
        "handbook",
        "--out",
        str(tmp_path),
    ]
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=1200, cwd=tmp_path, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    (run_dir,) = tmp_path.iterdir()
    assert run_dir.name.startswith("CoopGym-SitToStand-v0__rllib_ppo__0__")
    for name in ("args.json", "agent.json", "eval.json", "eval.csv", "results.json", "COMPLETE"):
        assert (run_dir / name).exists(), name
    results = json.loads((run_dir / "results.json").read_text())
    assert results["training"]["timesteps"] >= 2000 and results["training"]["num_env_runners"] == 2
    assert results["training"]["num_envs_per_env_runner"] == 2  # --n-envs 4 split over the runners
    # Trained behind the observation filter, loaded with its statistics.
    assert load_rllib_agent(run_dir).normalizer is not None
    agents = [r["agent"] for r in results["evaluation"]["results"]]
    assert agents == ["rllib ppo (learned)", "handbook"]
    assert load_rllib_agent(run_dir).predict(np.zeros((2, 11), np.float32))[0].shape == (2, 3)
