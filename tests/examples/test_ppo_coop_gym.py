"""examples/ppo_coop_gym.py: episode statistics under NEXT_STEP autoreset, and a few hundred training steps."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "ppo_coop_gym.py"


def _example():
    spec = importlib.util.spec_from_file_location("ppo_coop_gym", EXAMPLE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while the file runs
    spec.loader.exec_module(module)
    return module


def test_recorded_episode_statistics_match_the_rewards_and_outcomes_the_env_returned():
    example = _example()
    args = example.Args(num_envs=4)
    envs = example.make_envs(args)
    envs.reset(seed=3)
    rng = np.random.default_rng(0)
    running = np.zeros(4)
    lengths = np.zeros(4, dtype=int)
    autoreset = np.zeros(4, dtype=bool)
    expected, reported = [], []
    for _ in range(400):
        actions = envs.action_space.sample()
        actions[:, 2] = rng.random(4) < 0.05  # lift rarely, so episodes vary in length
        _, reward, term, trunc, infos = envs.step(actions)
        # NEXT_STEP: the step after an episode ends is a reset (reward 0), not part of any episode.
        running[autoreset] = 0.0
        lengths[autoreset] = 0
        running[~autoreset] += reward[~autoreset]
        lengths[~autoreset] += 1
        autoreset = np.logical_or(term, trunc)
        for i in np.flatnonzero(autoreset):
            expected.append((running[i], lengths[i], str(infos["outcome"][i])))
        reported += example.finished_episodes(infos)
    envs.close()
    assert len(reported) == len(expected) > 10
    for (r, length, outcome), (r_exp, length_exp, outcome_exp) in zip(reported, expected, strict=True):
        assert r == pytest.approx(r_exp) and length == length_exp and outcome == outcome_exp
        assert outcome in ("success", "unsafe", "premature", "timeout")


def test_example_defaults_are_train_py_settings_on_the_default_hard_level():
    from agents.hyperparams import hyperparams_for
    from coop_gym.registration import HARD_ENV_ID

    args, config = _example().Args(), hyperparams_for("ppo")
    assert args.env_id == config.env_id == HARD_ENV_ID
    assert (args.personas, args.total_timesteps, args.num_envs) == (
        config.personas,
        config.total_timesteps,
        config.n_envs,
    )
    kwargs = config.algo_kwargs
    assert (args.num_steps, args.update_epochs, args.num_steps * args.num_envs // args.num_minibatches) == (
        kwargs["n_steps"], kwargs["n_epochs"], kwargs["batch_size"]
    )  # fmt: skip
    assert (args.gamma, args.gae_lambda, args.ent_coef, args.clip_coef) == (
        kwargs["gamma"], kwargs["gae_lambda"], kwargs["ent_coef"], kwargs["clip_range"]
    )  # fmt: skip
    assert args.anneal_lr and float(kwargs["learning_rate"].removeprefix("lin_")) == args.learning_rate


def test_example_trains_a_few_hundred_steps(tmp_path):
    argv = ["--total-timesteps", "512", "--num-envs", "4", "--num-steps", "64", "--update-epochs", "2"]
    out = subprocess.run(
        [sys.executable, str(EXAMPLE), *argv], capture_output=True, text=True, timeout=600, cwd=tmp_path, check=False
    )
    assert out.returncode == 0, out.stderr[-3000:]
    assert "iteration 2/2" in out.stdout and "episodic_return=" in out.stdout
    assert any((tmp_path / "runs").iterdir())  # TensorBoard events
