"""agents.rl.ensemble: saved caregivers as one, the greedy action of their mean action probabilities."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("jax")
pytest.importorskip("stable_baselines3")

import coop_gym  # noqa: F401
from agents.ppo import PPO, PPOConfig

HARD = "CoopGym/SitToStandHard-v2"
TINY = PPOConfig(n_envs=4, n_steps=64, batch_size=128, n_epochs=2)


def _saved(tmp_path: Path, seed: int, env_id: str = HARD) -> Path:
    from agents.ppo.sb3_format import to_sb3
    from agents.rl import save_agent

    learner = PPO(env_id, TINY, seed=seed).learn(512)
    return save_agent(to_sb3(learner), tmp_path / f"seed_{seed}", algo="ppo", env_id=env_id)


@pytest.fixture(scope="module")
def saved(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    folder = tmp_path_factory.mktemp("ensemble")
    return [_saved(folder, seed) for seed in (0, 1, 2)]


def _member_probabilities(agent: Any, obs: np.ndarray) -> list[np.ndarray]:
    import torch

    with torch.no_grad():
        distribution = agent.model.policy.get_distribution(torch.from_numpy(agent.normalize(obs)))
        return [d.probs.double().numpy() for d in distribution.distribution]


def test_the_ensemble_acts_on_its_members_mean_probabilities(saved: list[Path]) -> None:
    from agents.rl import load_agent
    from agents.rl.ensemble import load_ensemble

    ensemble = load_ensemble(saved)
    members = [load_agent(path) for path in saved]
    obs = np.random.default_rng(3).normal(size=(64, 11)).astype(np.float32) * 0.3 + 0.2
    per_member = [_member_probabilities(m, obs) for m in members]
    mean = [np.mean([p[head] for p in per_member], axis=0) for head in range(3)]
    for ours, theirs in zip(ensemble.probabilities(obs), mean, strict=True):
        np.testing.assert_allclose(ours, theirs, atol=1e-6)
    actions, _ = ensemble.predict(obs)
    np.testing.assert_array_equal(actions, np.stack([m.argmax(axis=1) for m in mean], axis=1))
    assert ensemble.predict(obs[0])[0].shape == (3,)  # one observation, one action
    # Two copies of one model act as that model.
    twice, alone = load_ensemble([saved[0], saved[0]]), members[0]
    np.testing.assert_array_equal(twice.predict(obs)[0], alone.predict(obs)[0])


def test_the_ensemble_is_scored_as_any_agent(saved: list[Path]) -> None:
    from agents.evaluate import evaluate
    from agents.rl.ensemble import load_ensemble

    result = evaluate(load_ensemble(saved, name="three"), HARD, "test", 8, 0)
    assert result.episodes == 8 and 0.0 <= result.success_rate <= 1.0


def test_an_ensemble_refuses_what_it_cannot_be(saved: list[Path], tmp_path: Path) -> None:
    from agents.rl.ensemble import load_ensemble

    with pytest.raises(ValueError, match="at least 2 members"):
        load_ensemble(saved[:1])
    other = _saved(tmp_path, 0, "CoopGym/SitToStand-v0")
    with pytest.raises(ValueError, match=r"member 1 .* env_id"):
        load_ensemble([saved[0], other])
    with pytest.raises(ValueError, match="greedy only"):
        load_ensemble(saved[:2]).predict(np.zeros((1, 11), np.float32), deterministic=False)


def test_the_evaluate_command_scores_an_ensemble_and_names_a_missing_member(saved: list[Path]) -> None:
    import json
    import subprocess
    import sys

    members = "+".join(str(path) for path in saved)
    command = [sys.executable, "-m", "agents.evaluate", "--model", f"ensemble:{members}", "--compare", "blind"]
    done = subprocess.run([*command, "--episodes", "4", "--json"], capture_output=True, text=True, check=True)
    rows = json.loads(done.stdout)
    assert f"ensemble:{members}" in json.dumps(rows) and "blind" in json.dumps(rows)
    missing = subprocess.run(
        [sys.executable, "-m", "agents.evaluate", "--model", f"ensemble:{saved[0]}+nowhere/model.zip"],
        capture_output=True,
        text=True,
    )
    assert missing.returncode == 2 and "no saved model at 'nowhere/model.zip'" in missing.stderr
