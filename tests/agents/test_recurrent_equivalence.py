"""agents.ppo.RecurrentPPO against JaxRecurrentPPO, the learner it replaces: the same settings, rollouts and updates.

Both learners are built as ``train.py --algo recurrent_ppo --framework jax`` builds them (the old
one through :func:`agents.rl.make_model` on SB3's env stack inside ``VecNormalize``), on the hard
level's settings with small sizes. The new learner starts from the old one's initial weights,
plays the actions the old one drew (their samplers draw differently from their streams) and
takes the old one's minibatch orders; everything else -- the normalised observations, episode
starts, LSTM states, rewards with their time-limit bootstraps, values, log-probabilities, last
values, advantages, returns, the observation statistics and the weights after each update -- is
its own, and must be the old one's.

The old learner's semantics this holds the new one to: the LSTM state of step ``t`` is zeroed
where ``obs[t]`` begins an episode (``episode_starts[t]``, SB3's buffer convention: the start
stored with the step is the one before it); envs reset on the same step (the observation after
an end is the next episode's first); a time-limit end bootstraps from ``V`` one value-LSTM step
on from the state after the ending step, that state not zeroed; the last values zero the state
where an episode begins after the last step.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecNormalize

pytest.importorskip("jax")

import coop_gym  # noqa: F401
from agents.hyperparams import HYPERPARAMS, hyperparams_for
from agents.ppo.ppo import advantages
from agents.ppo.recurrent import RecurrentPPO, RecurrentPPOConfig
from agents.ppo.sb3_format import sb3_state_dict
from agents.rl import find_vec_normalize, make_model, make_train_env
from agents.rl.jax_recurrent import JaxRecurrentPPO
from agents.rl.jax_update import epoch_orders
from agents.rl.ppo_run import make_learner

torch.set_num_threads(1)

HARD = "CoopGym/SitToStandHard-v2"
SEED, N_ENVS, ROLLOUTS = 3, 4, 3
SMALL = {"n_steps": 32, "batch_size": 64}
"""Two minibatches of two whole env rollouts each, the hard level's 10 epochs."""
SHORT = {"timing": {"episode_s": 0.3}}
"""Three-step episodes: the untrained policy's episodes end unsafe in a step or two, so time-limit ends are rare."""


def _config() -> object:
    config = hyperparams_for("recurrent_ppo", HARD, "jax")
    return config.replace(n_envs=N_ENVS, algo_kwargs={**config.algo_kwargs, **SMALL})


def _old_model(config: object, env_kwargs: dict) -> JaxRecurrentPPO:
    """The old learner as ``train.py`` builds it (agents/trainer/run.py, ``_model_to_train``)."""
    env = make_train_env(HARD, config.n_envs, SEED, personas=config.personas, env_kwargs=env_kwargs)
    model = make_model(config, VecNormalize(env, norm_obs=True, norm_reward=False), SEED)
    assert type(model) is JaxRecurrentPPO
    return model


class _Recorder(BaseCallback):
    """What the old learner's rollouts held when each ended, and the weights each rollout played."""

    def __init__(self) -> None:
        super().__init__()
        self.rollouts: list[dict[str, object]] = []
        self.played: list[dict[str, object]] = []

    def _on_rollout_start(self) -> None:
        self.played.append(self.model._params)

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        model, buffer = self.model, self.model.rollout_buffer
        stats = find_vec_normalize(model.get_env()).obs_rms
        self.rollouts.append(
            {
                "obs": buffer.observations.copy(),
                "actions": buffer.actions.astype(np.int64),
                "starts": buffer.episode_starts.copy(),
                "rewards": buffer.rewards.copy(),
                "values": buffer.values.copy(),
                "log_probs": buffer.log_probs.copy(),
                "last_values": np.array(self.locals["last_values"]),
                "last_starts": np.asarray(self.locals["dones"], np.float32),
                "advantages": buffer.advantages.copy(),
                "returns": buffer.returns.copy(),
                "lstm_start": [s.copy() for s in model._rollout_start],
                "lstm_end": [s.copy() for s in model._lstm_state],
                "orders": epoch_orders(model._key, model.n_envs, model.n_epochs)[1],
                "obs_stats": (stats.mean.copy(), stats.var.copy(), stats.count),
            }
        )


def _flax(old_params: dict) -> dict:
    """The old learner's JAX weights as the new network's tree."""

    def mlp(layers: list) -> dict:
        return {f"Dense_{i}": {"kernel": np.asarray(w), "bias": np.asarray(b)} for i, (w, b) in enumerate(layers)}

    names = ("weight_ih", "weight_hh", "bias_ih", "bias_hh")
    tree = {net: mlp(old_params[net]) for net in ("pi", "vf")}
    for net in ("lstm_pi", "lstm_vf"):
        tree[net] = {name: np.asarray(value) for name, value in zip(names, old_params[net], strict=True)}
    return {"params": tree}


class _Orders:
    """A stand-in for the new learner's minibatch stream: the old learner's permutations, in turn."""

    def __init__(self, orders: list[np.ndarray]) -> None:
        self.rows = iter(np.concatenate(orders))

    def permutation(self, n: int) -> np.ndarray:
        row = next(self.rows)
        assert len(row) == n
        return row


def _replay(learner: RecurrentPPO, actions: np.ndarray) -> None:
    """The next rollout plays ``actions`` (n_steps, n_envs, dims), its log-probabilities the learner's own."""
    steps, sample = iter(actions), learner._acting.sample
    learner._acting.sample = lambda logits, rng: sample(logits, rng, next(steps))


def _close(ours: object, theirs: object, what: str) -> None:
    np.testing.assert_allclose(np.asarray(ours), np.asarray(theirs), rtol=1e-5, atol=1e-5, err_msg=what)


def _weights_close(params: object, old_params: dict, what: str) -> None:
    ours, theirs = sb3_state_dict(params), sb3_state_dict(_flax(old_params))
    for name, value in theirs.items():
        _close(ours[name].numpy(), value.numpy(), f"{what}: {name}")


@pytest.mark.parametrize("env_kwargs", [{}, SHORT], ids=["hard", "short-episodes"])
def test_rollouts_and_updates_are_jax_recurrent_ppos(env_kwargs: dict) -> None:
    config = _config()
    old, recorder = _old_model(config, env_kwargs), _Recorder()
    samples = N_ENVS * SMALL["n_steps"]
    old.learn(ROLLOUTS * samples, callback=recorder)
    new = make_learner(config, HARD, SEED, env_kwargs)
    assert isinstance(new, RecurrentPPO)
    new.set_params(_flax(recorder.played[0]))
    new.minibatch_rng = _Orders([r["orders"] for r in recorder.rollouts])  # type: ignore[assignment]
    timeouts = 0
    for k, theirs in enumerate(recorder.rollouts[:2]):  # the second from carried states and statistics
        _replay(new, theirs["actions"])
        rollout = new.rollout()
        assert rollout.starts[1:].sum() > 0  # episodes ended inside the rollout
        for name in ("obs", "starts", "rewards", "values", "log_probs", "last_values", "last_starts"):
            _close(getattr(rollout, name), theirs[name], f"rollout {k}: {name}")
        for name, ours_state, their_state in zip(("h_pi", "c_pi", "h_vf", "c_vf"), rollout.lstm_states,
                                                 theirs["lstm_start"], strict=True):  # fmt: skip
            _close(ours_state, their_state, f"rollout {k}: {name} as the rollout began")
        for ours_state, their_state in zip(new.lstm_state, theirs["lstm_end"], strict=True):
            _close(ours_state, their_state, f"rollout {k}: the LSTM states after it")
        adv, returns = advantages(rollout, new.config.gamma, new.config.gae_lambda)
        _close(adv, theirs["advantages"], f"rollout {k}: advantages")
        _close(returns, theirs["returns"], f"rollout {k}: returns")
        mean, var, count = theirs["obs_stats"]
        _close(new.normalizer.mean, mean, "observation mean")
        _close(new.normalizer.var, var, "observation variance")
        assert new.normalizer.count == pytest.approx(count)
        progress = 1.0 - new.num_timesteps / (ROLLOUTS * samples)
        new.update(rollout, progress)
        assert new.learning_rate == pytest.approx(old.lr_schedule(progress))
        _weights_close(new.params, recorder.played[k + 1], f"the weights after update {k}")
        timeouts += int(np.sum(new.take_episodes()["outcome"] == 4))
    if env_kwargs:
        assert timeouts > 0  # time-limit ends were bootstrapped


def test_train_py_gives_both_learners_the_same_settings() -> None:
    """What ``train.py --algo recurrent_ppo --framework jax`` passes: the new learner's config and the old model's."""
    training = hyperparams_for("recurrent_ppo", HARD, "jax")
    old = _old_model(training, {})
    new = make_learner(training, HARD, SEED)
    cfg = new.config
    assert isinstance(cfg, RecurrentPPOConfig)
    assert (cfg.n_envs, cfg.n_steps, cfg.n_epochs) == (old.n_envs, old.n_steps, old.n_epochs)
    assert cfg.batch_size == min(old.batch_size, old.n_envs * old.n_steps)
    assert (cfg.gamma, cfg.gae_lambda, cfg.ent_coef, cfg.vf_coef) == (old.gamma, old.gae_lambda, old.ent_coef,
                                                                        old.vf_coef)  # fmt: skip
    assert (cfg.max_grad_norm, cfg.clip_range) == (old.max_grad_norm, old.clip_range(1.0))
    assert old.normalize_advantage and old.target_kl is None and old.clip_range_vf is None
    for progress in (1.0, 0.5, 0.1):
        assert cfg.learning_rate * (progress if cfg.anneal_lr else 1.0) == pytest.approx(old.lr_schedule(progress))
    assert cfg.policy_lag == old.policy_lag == 0
    assert cfg.lstm_hidden_size == old.policy.lstm_actor.hidden_size == old.policy.lstm_critic.hidden_size
    assert old.policy.activation_fn is torch.nn.Tanh and cfg.activation == "tanh"
    ours = {name: tuple(value.shape) for name, value in sb3_state_dict(new.params).items()}
    assert ours == {name: tuple(value.shape) for name, value in old.policy.state_dict().items()}
    stats = find_vec_normalize(old.get_env())
    assert new.normalizer is not None and stats is not None and stats.norm_obs and not stats.norm_reward
    assert (new.normalizer.clip, new.normalizer.epsilon) == (stats.clip_obs, stats.epsilon)
    assert new.env_kwargs["personas"] == training.personas == "train_wide"
    # The table's settings themselves (train.py's sizing aside) convert to the same.
    table = RecurrentPPOConfig.from_training(HYPERPARAMS["recurrent_ppo"][HARD])
    sizing = {"n_envs": cfg.n_envs, "n_steps": cfg.n_steps, "batch_size": cfg.batch_size}
    assert table.replace(**sizing) == cfg
