"""Checkpoints: training stopped at a rollout boundary and resumed ends with the weights of an unbroken run."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from agents.hyperparams import ALGORITHMS, hyperparams_for
from agents.rl import (
    CHECKPOINTS_DIR,
    CheckpointCallback,
    TrainingInterrupted,
    latest_checkpoint,
    make_model,
    make_train_env,
    restore_checkpoint,
)

torch.set_num_threads(1)

TOTAL_STEPS = 384
_TINY = {
    "ppo": {"n_steps": 32, "batch_size": 32, "n_epochs": 2},
    "recurrent_ppo": {"n_steps": 32, "batch_size": 32, "n_epochs": 1},
    "dqn": {
        "learning_starts": 16,
        "buffer_size": 1000,
        "batch_size": 16,
        "train_freq": 4,
        "target_update_interval": 50,
    },
}


def _train(algo: str, folder: Path, stop_at: int | None = None):
    """Train TOTAL_STEPS; with ``stop_at``, stop at the first boundary past it, restore from disk and finish."""
    config = hyperparams_for(algo)
    monitor = folder / "monitor.csv"
    env = make_train_env(config.env_id, 2, 0, normalize=config.normalize, monitor_file=monitor)
    model = make_model(config, env, 0, overrides=_TINY[algo])
    stop = lambda: stop_at is not None and model.num_timesteps >= stop_at  # noqa: E731
    checkpoints = CheckpointCallback(folder, 128, algo=algo, env_id=config.env_id, stop_requested=stop)
    try:
        model.learn(TOTAL_STEPS, callback=checkpoints)
    except TrainingInterrupted as exc:
        assert exc.checkpoint == latest_checkpoint(folder)
        env.close()
        # A new process would build the env from scratch: do the same.
        fresh = make_train_env(config.env_id, 2, 0, monitor_file=monitor, monitor_append=True)
        model, _ = restore_checkpoint(latest_checkpoint(folder), fresh)
        assert model.num_timesteps < TOTAL_STEPS
        model.learn(TOTAL_STEPS - model.num_timesteps, reset_num_timesteps=False)
    return model


def _episodes(monitor: Path) -> list[tuple[str, str]]:
    rows = monitor.read_text().splitlines()[2:]  # the JSON header and the column names
    return [(r.split(",")[0], r.split(",")[1]) for r in rows]  # return, length (not the wall time)


# PPO (the default algorithm) runs by default; the others are the same check, marked slow.
@pytest.mark.parametrize("algo", [a if a == "ppo" else pytest.param(a, marks=pytest.mark.slow) for a in ALGORITHMS])
def test_resumed_training_reaches_the_same_weights(algo, tmp_path):
    straight, resumed = tmp_path / "straight", tmp_path / "resumed"
    straight.mkdir(), resumed.mkdir()
    a = _train(algo, straight)
    b = _train(algo, resumed, stop_at=200)
    assert a.num_timesteps == b.num_timesteps == TOTAL_STEPS
    weights_a, weights_b = a.policy.state_dict(), b.policy.state_dict()
    assert all(torch.equal(weights_a[k], weights_b[k]) for k in weights_a)
    assert _episodes(straight / "monitor.csv") == _episodes(resumed / "monitor.csv")  # no episode lost or doubled
    assert len(list((resumed / CHECKPOINTS_DIR).iterdir())) <= 2  # only the newest are kept
