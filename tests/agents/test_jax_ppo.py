"""JaxPPO: SB3's PPO with a compiled rollout policy and update -- the same networks, loss and outputs as SB3's."""

from __future__ import annotations

import copy
import hashlib
import subprocess
import sys
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
from agents.rl.jax_ppo import JaxPPO

torch.set_num_threads(1)

ENV_ID = "CoopGym/SitToStandHard-v2"
_TINY = {"n_steps": 32, "batch_size": 64, "n_epochs": 2}


def _model(seed: int = 0, n_envs: int = 4, folder: Path | None = None, lag: int = 0) -> JaxPPO:
    config = hyperparams_for("ppo", ENV_ID, "jax")
    env = make_train_env(
        ENV_ID, n_envs, seed, personas=config.personas, normalize=True, monitor_file=folder and folder / "monitor.csv"
    )
    model = make_model(config, env, seed, overrides={**_TINY, "policy_lag": lag})
    assert isinstance(model, JaxPPO)
    return model


def _weights(model: JaxPPO) -> bytes:
    return b"".join(t.numpy().tobytes() for t in model.policy.state_dict().values())


def test_the_rollout_policy_is_the_torch_policy():
    """Actions sampled by the rollout's NumPy policy get the torch policy's log-probabilities and values."""
    model = _model()
    model.learn(640)  # weights moved away from their initial values; the rate decayed part of the way
    obs = np.asarray(model._last_obs, dtype=np.float32)
    actions, values, log_probs = model._policy.act(obs, np.random.default_rng(0))
    with torch.no_grad():
        t_values, t_log_probs, _ = model.policy.evaluate_actions(
            torch.from_numpy(obs), torch.from_numpy(np.asarray(actions).astype(np.int64))
        )
    np.testing.assert_allclose(values, t_values.numpy().ravel(), rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(log_probs, t_log_probs.numpy(), rtol=1e-4, atol=1e-5)
    # Sampling follows the probabilities: 20000 draws of one row against its softmax.
    row = np.repeat(obs[:1], 20000, axis=0)
    draws, _, _ = model._policy.act(row, np.random.default_rng(1))
    with torch.no_grad():
        dist = model.policy.get_distribution(torch.from_numpy(obs[:1]))
    for head, categorical in enumerate(dist.distribution):
        expected = categorical.probs.numpy()[0]
        observed = np.bincount(draws[:, head], minlength=expected.size) / len(draws)
        np.testing.assert_allclose(observed, expected, atol=0.015)
    # The update ran at the schedule's learning rate (SB3's lin_ schedule, injected into Adam).
    assert float(model._opt_state.hyperparams["learning_rate"]) == pytest.approx(
        model.lr_schedule(model._current_progress_remaining)
    )
    # Greedy play is the torch policy's (the saved model needs no JAX).
    greedy, _ = model.predict(obs, deterministic=True)
    assert greedy.shape == (obs.shape[0], 3)


def _head_by_head(logits, nvec, rng):
    """The rollout's sampling written one head at a time (the form the all-heads sampler must equal)."""
    bounds = np.cumsum([0, *nvec])
    actions = np.empty((logits.shape[0], len(nvec)), dtype=np.int32)
    log_prob = np.zeros(logits.shape[0], dtype=np.float32)
    uniform = rng.random((logits.shape[0], len(nvec)), dtype=np.float32)
    for head in range(len(nvec)):
        block = logits[:, bounds[head] : bounds[head + 1]]
        shifted = block - block.max(axis=1, keepdims=True)
        log_p = shifted - np.log(np.exp(shifted).sum(axis=1, keepdims=True))
        cdf = np.cumsum(np.exp(log_p), axis=1)
        choice = np.minimum((uniform[:, head : head + 1] > cdf).sum(axis=1), block.shape[1] - 1)
        actions[:, head] = choice
        log_prob += log_p[np.arange(logits.shape[0]), choice]
    return actions, log_prob


@pytest.mark.parametrize("nvec", [[3, 3, 2], [18], [2, 5, 3, 4], [40], [2, 9]])
def test_all_heads_sample_as_each_head_alone_bit_for_bit(nvec):
    from agents.rl.jax_ppo import _RolloutPolicy

    policy = _RolloutPolicy({"pi": [], "vf": []}, nvec, relu=False)
    for trial in range(120):
        rows, scale = [1, 16, 64, 256][trial % 4], [0.1, 1.0, 5.0, 30.0][trial % 4]
        logits = np.random.default_rng(trial).normal(0, scale, (rows, sum(nvec))).astype(np.float32)
        if trial % 3 == 0:
            logits[:, 1] = logits[:, 0]  # an exact tie
        actions, log_prob = policy.sample(logits, np.random.default_rng(trial))
        expected_actions, expected_log_prob = _head_by_head(logits, nvec, np.random.default_rng(trial))
        assert actions.dtype == expected_actions.dtype and log_prob.dtype == expected_log_prob.dtype
        np.testing.assert_array_equal(actions, expected_actions)
        np.testing.assert_array_equal(log_prob.view(np.int32), expected_log_prob.view(np.int32))
    with pytest.raises(ValueError, match="float32"):
        policy.sample(np.zeros((2, sum(nvec))), np.random.default_rng(0))


def test_a_saved_model_loads_plays_and_continues(tmp_path):
    model = _model()
    model.learn(256)
    path = save_agent(model, tmp_path / "run", algo="ppo", env_id=ENV_ID)
    agent = load_agent(path)  # what evaluation loads
    from agents.evaluate import evaluate

    result = evaluate(agent, ENV_ID, "test", 4, 0)
    assert result.summary()["episodes"] == 4
    loaded, info = load_model(path)
    assert isinstance(loaded, JaxPPO) and info["framework"] == "jax"
    np.testing.assert_array_equal(loaded.jax_saved_state["key"], model.jax_saved_state["key"])
    assert _weights(loaded) == _weights(model)


@pytest.mark.parametrize("lag", [0, 1])
def test_checkpoint_and_resume_give_the_unbroken_run(tmp_path, lag):
    """Stopped at a rollout boundary, restored onto fresh envs, finished: the weights of the run that never stopped.

    With ``policy_lag=1`` the checkpoint is taken while an update runs ahead of the rollout.
    """
    total = 768

    def run(folder: Path, stop_at: int | None) -> bytes:
        model = _model(folder=folder, lag=lag)
        stop = lambda: stop_at is not None and model.num_timesteps >= stop_at  # noqa: E731
        callback = CheckpointCallback(folder, 256, algo="ppo", env_id=ENV_ID, stop_requested=stop)
        try:
            model.learn(total, callback=callback)
        except TrainingInterrupted:
            config = hyperparams_for("ppo", ENV_ID, "jax")
            fresh = make_train_env(
                ENV_ID, 4, 0, personas=config.personas, monitor_file=folder / "monitor.csv", monitor_append=True
            )
            model, _ = restore_checkpoint(latest_checkpoint(folder), fresh)
            assert isinstance(model, JaxPPO) and model.num_timesteps < total and model.policy_lag == lag
            model.learn(total - model.num_timesteps, reset_num_timesteps=False)
        return _weights(model)

    assert run(tmp_path / "stopped", stop_at=300) == run(tmp_path / "unbroken", stop_at=None)


def test_the_rollout_through_the_fused_step_trains_the_weights_of_the_wrappers_step(monkeypatch):
    """``collect_rollouts`` steps ``make_train_env``'s stack by ``fused_step``: the same run as ``env.step``."""
    import agents.rl.jax_ppo as jax_ppo

    fused = _model()
    assert jax_ppo.fused_step(fused.get_env()) is not None
    fused.learn(1024)
    monkeypatch.setattr(jax_ppo, "fused_step", lambda env: None)
    wrapped = _model()
    wrapped.learn(1024)
    assert _weights(fused) == _weights(wrapped)
    a, b = fused.get_env(), wrapped.get_env()
    assert np.array_equal(a.obs_rms.var, b.obs_rms.var) and np.array_equal(a.ret_rms.var, b.ret_rms.var)
    assert [e["r"] for e in fused.ep_info_buffer] == [e["r"] for e in wrapped.ep_info_buffer]


def test_waiting_for_a_lagged_update_changes_no_number():
    """``wait_for_update`` at every rollout's end (what a clock that counts training time does): the same run."""
    from stable_baselines3.common.callbacks import BaseCallback

    class Wait(BaseCallback):
        def _on_step(self) -> bool:
            return True

        def _on_rollout_end(self) -> None:
            self.model.wait_for_update()
            assert self.model._pending is None

    waited, free = _model(lag=1), _model(lag=1)
    waited.learn(768, callback=Wait())
    free.learn(768)
    assert _weights(waited) == _weights(free)
    _model().wait_for_update()  # without lag: nothing to wait for


def test_a_lagged_rollout_is_played_by_the_weights_before_the_last_update():
    """``policy_lag=1``: the second rollout is played by the initial weights (the first update runs beside it).

    With 0 it is played by the first update's weights.
    """
    for lag in (0, 1):
        model = _model(lag=lag)
        initial = copy.deepcopy(model.policy)
        model.learn(2 * 4 * 32)  # two rollouts of 4 envs x 32 steps, two updates
        buffer = model.rollout_buffer  # the second rollout
        obs = torch.from_numpy(buffer.observations.reshape(-1, buffer.observations.shape[-1]))
        actions = torch.from_numpy(buffer.actions.reshape(-1, 3).astype(np.int64))
        with torch.no_grad():
            _, log_probs, _ = initial.evaluate_actions(obs, actions)
        by_initial = np.allclose(buffer.log_probs.ravel(), log_probs.numpy(), rtol=1e-4, atol=1e-5)
        assert by_initial == bool(lag), lag
        # Both updates have landed in the weights a user gets: the rollout policy is the torch policy.
        rollout_obs = np.asarray(model._last_obs, dtype=np.float32)
        picked, _, rollout_log_probs = model._policy.act(rollout_obs, np.random.default_rng(0))
        with torch.no_grad():
            _, torch_log_probs, _ = model.policy.evaluate_actions(
                torch.from_numpy(rollout_obs), torch.from_numpy(picked.astype(np.int64))
            )
        np.testing.assert_allclose(rollout_log_probs, torch_log_probs.numpy(), rtol=1e-4, atol=1e-5)
        assert model._n_updates == 2 * _TINY["n_epochs"]


_SAME_SEED = """
import hashlib, sys, torch
torch.set_num_threads(int(sys.argv[1]))
sys.path.insert(0, "tests/agents")
from test_jax_ppo import _model, _weights
model = _model(lag=int(sys.argv[2]))
model.learn(512)
print(hashlib.sha256(_weights(model)).hexdigest())
"""


@pytest.mark.parametrize("lag", [0, 1])
def test_a_seed_trains_the_same_weights_in_fresh_processes_whatever_the_torch_threads(lag):
    """Unlike SB3's PPO, whose weights depend on torch's thread count (tests/agents/test_rl.py).

    With ``policy_lag=1`` the update runs on its own thread beside the rollout: the weights do not depend on timing.
    """
    root = Path(__file__).resolve().parents[2]
    digests = {
        subprocess.run(
            [sys.executable, "-c", _SAME_SEED, threads, str(lag)], cwd=root, capture_output=True, text=True, check=True
        ).stdout.strip()
        for threads in ("1", "1", "2")
    }
    assert len(digests) == 1 and len(next(iter(digests))) == 64, digests
    another_seed = _model(seed=1, lag=lag)
    another_seed.learn(512)
    assert hashlib.sha256(_weights(another_seed)).hexdigest() not in digests


def test_what_it_cannot_train_is_named():
    with pytest.raises(ValueError, match="'jax' for ppo, recurrent_ppo"):
        hyperparams_for("dqn", None, "jax")
    config = hyperparams_for("ppo", ENV_ID, "jax")
    env = make_train_env(ENV_ID, 4, 0)
    with pytest.raises(ValueError, match="multiple of batch_size"):
        make_model(config, env, 0, overrides={"n_steps": 24, "batch_size": 64}).learn(96)
    # A rollout smaller than one minibatch is one minibatch, as in SB3.
    assert make_model(config, env, 0, overrides={"n_steps": 10, "batch_size": 64}).learn(40).num_timesteps == 40
    with pytest.raises(ValueError, match="target_kl"):
        make_model(config, env, 0, overrides={**_TINY, "target_kl": 0.01}).learn(64)
    for lag in (2, -1, True, 0.5):
        with pytest.raises(ValueError, match="policy_lag must be 0 or 1"):
            make_model(config, env, 0, overrides={**_TINY, "policy_lag": lag})


def test_one_update_is_sb3s_update():
    """On the same rollout and weights, a compiled update moves the weights as SB3's ``PPO.train`` does.

    Three epochs of one minibatch (the whole rollout), so the minibatch order cannot differ; after the
    first Adam step (about the gradient's sign) the steps depend on the gradients' sizes too.
    """
    from stable_baselines3 import PPO

    steps, envs = 16, 4
    overrides = {"n_steps": steps, "batch_size": steps * envs, "n_epochs": 3}
    config = hyperparams_for("ppo", ENV_ID, "jax")
    config = config.replace(algo_kwargs={k: v for k, v in config.algo_kwargs.items() if k != "policy_lag"})
    ours = make_model(config, make_train_env(ENV_ID, envs, 0, normalize=True), 0, overrides=overrides)
    sb3 = make_model(
        config.replace(framework="sb3"), make_train_env(ENV_ID, envs, 0, normalize=True), 0, overrides=overrides
    )
    assert type(sb3) is PPO and _weights(ours) == _weights(sb3)  # the same initial weights
    ours.learn(steps * envs)  # one rollout and one update, from which the rollout is reused
    sb3.policy.load_state_dict(_initial_state(config, envs, overrides))
    ours.policy.load_state_dict(_initial_state(config, envs, overrides))
    ours.jax_saved_state = None  # a fresh optimiser, as SB3's
    ours._keep_state(*ours._jax_state())
    for name in (
        "observations",
        "actions",
        "rewards",
        "returns",
        "episode_starts",
        "values",
        "log_probs",
        "advantages",
    ):
        setattr(sb3.rollout_buffer, name, getattr(ours.rollout_buffer, name).copy())
    sb3.rollout_buffer.pos, sb3.rollout_buffer.full, sb3.rollout_buffer.generator_ready = steps, True, False
    sb3._current_progress_remaining = ours._current_progress_remaining = 1.0
    from stable_baselines3.common.logger import configure

    sb3.set_logger(configure(None, []))
    sb3.train()
    ours.train()
    for (name, a), b in zip(sb3.policy.state_dict().items(), ours.policy.state_dict().values(), strict=True):
        np.testing.assert_allclose(b.numpy(), a.numpy(), rtol=1e-4, atol=2e-6, err_msg=name)
    assert not np.allclose(
        _initial_state(config, envs, overrides)["action_net.weight"], sb3.policy.action_net.weight.detach()
    )


def _initial_state(config, envs: int, overrides: dict) -> dict:
    """The torch weights a seed-0 model starts from."""
    model = make_model(
        config.replace(framework="sb3"), make_train_env(ENV_ID, envs, 0, normalize=True), 0, overrides=overrides
    )
    return {k: v.clone() for k, v in model.policy.state_dict().items()}


def test_the_epochs_orders_are_permutations_drawn_from_the_key():
    """Each epoch's minibatch order is a permutation; the same key draws the same orders and the next key."""
    import jax

    from agents.rl.jax_update import epoch_orders

    key = np.asarray(jax.random.PRNGKey(7))
    next_key, orders = epoch_orders(key, 4096, 10)
    assert orders.shape == (10, 4096) and orders.dtype == np.int32
    assert all(np.array_equal(np.sort(order), np.arange(4096)) for order in orders)
    assert len({order.tobytes() for order in orders}) == 10
    again_key, again = epoch_orders(key, 4096, 10)
    np.testing.assert_array_equal(again, orders)
    np.testing.assert_array_equal(again_key, next_key)
    assert next_key.dtype == np.uint32 and next_key.shape == (2,) and not np.array_equal(next_key, key)
    assert not np.array_equal(epoch_orders(next_key, 4096, 10)[1], orders)
    assert epoch_orders(key, 1, 3)[1].tolist() == [[0], [0], [0]]


def test_a_callers_xla_flags_keep_xla_on_one_thread():
    """The caller's ``XLA_FLAGS`` (say, a pinned instruction set) are kept and the one-thread flags added."""
    from agents.rl.jax_update import xla_flags

    one_thread = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
    assert xla_flags("") == one_thread
    assert xla_flags("--xla_cpu_max_isa=AVX2") == "--xla_cpu_max_isa=AVX2 " + one_thread
    assert xla_flags(one_thread) == one_thread  # the flags of a second build are not added twice
    mine = "--xla_cpu_multi_thread_eigen=true"
    assert xla_flags(mine) == mine + " intra_op_parallelism_threads=1"


def test_train_py_runs_the_lagged_learner_on_the_hard_level_only():
    assert hyperparams_for("ppo", ENV_ID, "jax").algo_kwargs["policy_lag"] == 1
    assert "policy_lag" not in hyperparams_for("ppo", "CoopGym/SitToStand-v0", "jax").algo_kwargs
    assert "policy_lag" not in hyperparams_for("recurrent_ppo", ENV_ID, "jax").algo_kwargs  # it has none
    assert "policy_lag" not in hyperparams_for("ppo", ENV_ID, "sb3").algo_kwargs
