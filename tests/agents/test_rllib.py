"""Ray RLlib: the predict adapter, the loader, evaluation CLI dispatch, and train.py --framework rllib.

Skipped without the ``[rllib]`` extra. The end-to-end run starts a local Ray instance with
two env runners; actor start-up alone took ~3 min on the loaded 2-core development
machine, so it is marked ``slow`` (``python -m pytest -m slow tests/agents/test_rllib.py``).
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

from ray.rllib.core import DEFAULT_MODULE_ID

import coop_gym  # noqa: F401
from agents.evaluate import evaluate
from agents.rllib import (
    CHECKPOINT_DIR,
    RLlibAgent,
    _module_path,
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


@pytest.mark.slow
def test_train_py_framework_rllib_with_two_env_runners(tmp_path):
    argv = [
        sys.executable,
        str(ROOT / "train.py"),
        "--framework",
        "rllib",
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
    agents = [r["agent"] for r in results["evaluation"]["results"]]
    assert agents == ["rllib ppo (learned)", "handbook"]
    assert load_rllib_agent(run_dir).predict(np.zeros((2, 11), np.float32))[0].shape == (2, 3)
