"""RL Baselines3 Zoo end to end: train with the shipped YAML on a tiny budget, then ``rl_zoo3.enjoy`` it.

Skipped when rl_zoo3 is not installed (``pip install -e ".[zoo]"``; the ``[test]`` extra
includes it). The commands are docs/integrations.md's, with a tiny ``-n``.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

# Looked up, not imported: importing rl_zoo3 patches gymnasium's TimeLimit (rl_zoo3.gym_patches)
# for the whole test process, which changes the infos other tests compare.
if importlib.util.find_spec("rl_zoo3") is None:
    pytest.skip("rl_zoo3 is not installed (pip install -e '.[zoo]')", allow_module_level=True)

ROOT = Path(__file__).resolve().parents[2]
ZOO = ["--algo", "ppo", "--env", "CoopGym/SitToStand-v0", "--gym-packages", "coop_gym", "--num-threads", "1"]


def _run(module: str, *argv: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", module, *argv], capture_output=True, text=True, timeout=600, cwd=cwd, check=False
    )


def test_zoo_trained_model_plays_with_enjoy_and_loads_in_agents(tmp_path):
    conf = str(ROOT / "agents" / "zoo" / "ppo.yml")
    # One PPO rollout of the shipped config (8 envs x 512 steps); no periodic evaluation.
    train = _run("rl_zoo3.train", *ZOO, "-conf", conf, "-n", "4096", "-f", "logs", "--eval-freq", "-1", cwd=tmp_path)
    assert train.returncode == 0, train.stderr[-3000:]
    model = tmp_path / "logs" / "ppo" / "CoopGym-SitToStand-v0_1" / "CoopGym-SitToStand-v0.zip"
    assert model.exists()

    enjoy = _run("rl_zoo3.enjoy", *ZOO, "-f", "logs", "--exp-id", "1", "-n", "300", "--no-render", cwd=tmp_path)
    assert enjoy.returncode == 0, enjoy.stderr[-3000:]
    assert "Mean reward" in enjoy.stdout  # at least one episode finished and was reported

    # The same file is scored by the common evaluation path (RL Zoo's vecnormalize.pkl is found).
    # In a subprocess: unpickling RL Zoo's schedules imports rl_zoo3, whose patches must stay out of this process.
    score = _run("agents.evaluate", "--model", str(model), "--personas", "test", "--episodes", "8", "--json", cwd=ROOT)
    assert score.returncode == 0, score.stderr[-3000:]
    assert '"episodes": 8' in score.stdout


def test_zoo_takes_the_package_module_for_a_hard_id_from_any_folder(tmp_path):
    # -conf names a module (agents.zoo.ppo), not a file: no checkout path in the command.
    argv = ["--algo", "ppo", "--env", "CoopGym/SitToStandHardDiscreteUnit-v2", "--gym-packages", "coop_gym"]
    argv += ["-conf", "agents.zoo.ppo", "--num-threads", "1", "-n", "4096", "-f", "logs", "--eval-freq", "-1"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}  # this checkout's agents, wherever coop_gym is installed
    train = subprocess.run(
        [sys.executable, "-m", "rl_zoo3.train", *argv], capture_output=True, text=True, timeout=600, cwd=tmp_path,
        env=env, check=False,
    )  # fmt: skip
    assert train.returncode == 0, train.stderr[-3000:]
    assert "'ent_coef', 0.02" in train.stdout and "'personas': 'train_wide'" in train.stdout  # the hard settings
    run = tmp_path / "logs" / "ppo" / "CoopGym-SitToStandHardDiscreteUnit-v2_1"
    assert (run / "CoopGym-SitToStandHardDiscreteUnit-v2.zip").exists()
