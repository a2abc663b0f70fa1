"""JaxRecurrentPPO: sb3-contrib's RecurrentPPO with a NumPy rollout and a compiled update -- the same LSTMs and loss."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import torch

from agents.hyperparams import hyperparams_for
from agents.rl import (
    CheckpointCallback,
    TrainingInterrupted,
    latest_checkpoint,
    load_agent,
    load_model,
    make_model,
    make_train_env,
    restore_checkpoint,
    save_agent,
)
from agents.rl.jax_recurrent import JaxRecurrentPPO

torch.set_num_threads(1)

ENV_ID = "CoopGym/SitToStandHard-v2"
RAW = {"observation_mode": "raw"}
_TINY = {"n_steps": 32, "batch_size": 64, "n_epochs": 2}


def _model(seed: int = 0, n_envs: int = 4, folder: Path | None = None, overrides: dict | None = None):
    config = hyperparams_for("recurrent_ppo", ENV_ID, "jax")
    env = make_train_env(
        ENV_ID,
        n_envs,
        seed,
        personas=config.personas,
        normalize=True,
        env_kwargs=RAW,
        monitor_file=folder and folder / "monitor.csv",
    )
    model = make_model(config, env, seed, overrides=overrides or _TINY)
    assert isinstance(model, JaxRecurrentPPO)
    return model


def _weights(model) -> bytes:
    return b"".join(t.numpy().tobytes() for t in model.policy.state_dict().values())


def _as_sequences(column: np.ndarray) -> torch.Tensor:
    """(T, N, ...) time-major -> (N * T, ...) env-major: sb3-contrib's sequences, one per env."""
    return torch.from_numpy(np.ascontiguousarray(column.swapaxes(0, 1).reshape(-1, *column.shape[2:])))


def test_the_rollout_is_the_torch_policys():
    """Over a rollout with episode ends, the NumPy LSTMs' log-probabilities and values are the torch policy's."""
    model = _model(overrides={"n_steps": 400, "batch_size": 1600, "n_epochs": 1})
    model.learn(1600)  # a second rollout, from the LSTM states the first one ended in
    model.learn(1600, reset_num_timesteps=False)
    buffer = model.rollout_buffer
    assert buffer.episode_starts[1:].sum() > 0  # episodes ended inside the rollout: the resets are exercised
    states = [torch.from_numpy(s[None].copy()) for s in model._rollout_start]
    assert float(states[0].abs().sum()) > 0  # it did not start from zeros
    from sb3_contrib.common.recurrent.type_aliases import RNNStates

    with torch.no_grad():
        values, log_prob, _ = model.policy.evaluate_actions(
            _as_sequences(buffer.observations),
            _as_sequences(buffer.actions.astype(np.int64)),
            RNNStates((states[0], states[1]), (states[2], states[3])),
            _as_sequences(buffer.episode_starts),
        )
    np.testing.assert_allclose(_as_sequences(buffer.values).numpy(), values.numpy().ravel(), rtol=1e-4, atol=2e-5)
    np.testing.assert_allclose(_as_sequences(buffer.log_probs).numpy(), log_prob.numpy(), rtol=1e-4, atol=2e-5)


def test_one_update_is_sb3_contribs_update():
    """On the same rollout and weights, the compiled update moves the weights as sb3-contrib's ``train`` does.

    One minibatch (the whole rollout) and three epochs: sb3-contrib's padded sequences and the
    compiled whole-env sequences then hold the same samples, so the loss is the same.
    """
    from sb3_contrib import RecurrentPPO
    from stable_baselines3.common.logger import configure

    steps, envs = 48, 4
    overrides = {"n_steps": steps, "batch_size": steps * envs, "n_epochs": 3}
    ours = _model(overrides=overrides)
    config = hyperparams_for("recurrent_ppo", ENV_ID, "jax").replace(framework="sb3")
    theirs = make_model(config, make_train_env(ENV_ID, envs, 0, normalize=True, env_kwargs=RAW), 0, overrides=overrides)
    assert type(theirs) is RecurrentPPO
    initial = {k: v.clone() for k, v in ours.policy.state_dict().items()}
    ours.learn(2 * steps * envs)  # two rollouts: the second starts from non-zero LSTM states
    assert ours.rollout_buffer.episode_starts[1:].sum() > 0
    for model in (ours, theirs):
        model.policy.load_state_dict(initial)
    ours.jax_saved_state = {k: v for k, v in ours.jax_saved_state.items() if k == "lstm_state"}  # a fresh optimiser
    ours._keep_state(*ours._jax_state())
    theirs.rollout_buffer = copy.deepcopy(ours.rollout_buffer)  # sb3-contrib flattens the arrays it reads
    theirs._current_progress_remaining = ours._current_progress_remaining = 1.0
    theirs.set_logger(configure(None, []))
    theirs.train()
    trained = {k: v.clone() for k, v in theirs.policy.state_dict().items()}
    ours.train()
    for (name, a), b in zip(trained.items(), ours.policy.state_dict().values(), strict=True):
        np.testing.assert_allclose(b.numpy(), a.numpy(), rtol=1e-4, atol=3e-6, err_msg=name)
    assert not np.allclose(initial["lstm_actor.weight_hh_l0"], trained["lstm_actor.weight_hh_l0"])


def test_a_saved_model_loads_plays_and_is_scored(tmp_path):
    model = _model()
    model.learn(256)
    path = save_agent(model, tmp_path / "run", algo="recurrent_ppo", env_id=ENV_ID)
    loaded, info = load_model(path)
    assert isinstance(loaded, JaxRecurrentPPO) and info["framework"] == "jax"
    assert _weights(loaded) == _weights(model)
    from agents.evaluate import evaluate

    result = evaluate(load_agent(path), ENV_ID, "test", 4, 0, env_kwargs=RAW)
    assert result.summary()["episodes"] == 4


def test_checkpoint_and_resume_give_the_unbroken_run(tmp_path):
    """Stopped at a rollout boundary, restored onto fresh envs, finished: the unbroken run's weights."""
    total = 384

    def run(folder: Path, stop_at: int | None) -> bytes:
        model = _model(folder=folder)
        stop = lambda: stop_at is not None and model.num_timesteps >= stop_at  # noqa: E731
        callback = CheckpointCallback(folder, 128, algo="recurrent_ppo", env_id=ENV_ID, stop_requested=stop)
        try:
            model.learn(total, callback=callback)
        except TrainingInterrupted:
            config = hyperparams_for("recurrent_ppo", ENV_ID, "jax")
            fresh = make_train_env(
                ENV_ID,
                4,
                0,
                personas=config.personas,
                env_kwargs=RAW,
                monitor_file=folder / "monitor.csv",
                monitor_append=True,
            )
            model, _ = restore_checkpoint(latest_checkpoint(folder), fresh)
            assert isinstance(model, JaxRecurrentPPO) and model.num_timesteps < total
            model.learn(total - model.num_timesteps, reset_num_timesteps=False)
        return _weights(model)

    assert run(tmp_path / "stopped", stop_at=150) == run(tmp_path / "unbroken", stop_at=None)


def test_what_it_cannot_train_is_named():
    with pytest.raises(ValueError, match="whole env rollouts"):
        _model(overrides={"n_steps": 32, "batch_size": 16}).learn(128)
    with pytest.raises(ValueError, match="JaxRecurrentPPO does not support policy_lag"):
        _model(overrides={"policy_lag": 1}).learn(128)
    # A rollout smaller than one minibatch is one minibatch, as in SB3.
    assert _model(overrides={"n_steps": 32, "batch_size": 512}).learn(128).num_timesteps == 128
    config = hyperparams_for("recurrent_ppo", ENV_ID, "jax")
    env = make_train_env(ENV_ID, 4, 0, env_kwargs=RAW)
    with pytest.raises(ValueError, match="one LSTM layer"):
        shared = {"shared_lstm": True, "enable_critic_lstm": False}
        make_model(config, env, 0, overrides={**_TINY, "policy_kwargs": shared}).learn(128)
