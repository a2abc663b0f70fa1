r"""Recurrent PPO: :class:`agents.ppo.PPO` with an LSTM before the policy's MLP and one before the value's.

The networks are sb3-contrib's ``MlpLstmPolicy`` (:class:`agents.ppo.networks.LstmActorCritic`),
the loss, optimiser, loop and checkpoints PPO's. The rollout steps both LSTMs in NumPy, their
state zeroed where an episode starts; a time-limit end adds ``gamma * V(final observation)`` to
its reward, V taken one value-LSTM step on from that env's state after the step (not zeroed), as
sb3-contrib's rollout does. An update cuts the rollout into minibatches of whole env rollouts
(``batch_size / n_steps`` envs each; CleanRL's ``ppo_atari_lstm`` scheme), each run through the
LSTMs from the states the rollout began with, zeroed where an episode starts inside it. A trained
learner saves as sb3-contrib's ``RecurrentPPO`` (:func:`agents.ppo.sb3_format.to_sb3`), which loads,
plays and is scored without JAX.

What ``train.py --algo recurrent_ppo --framework jax`` trains (:func:`agents.rl.ppo_run.make_learner`),
and ``bench/learners.py``'s ``jax-lstm-*`` rows.

Example:
    >>> import coop_gym
    >>> config = RecurrentPPOConfig(n_envs=4, n_steps=32, batch_size=64)
    >>> RecurrentPPO("CoopGym/SitToStandHard-v2", config, seed=0).learn(256).num_timesteps
    256
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from agents.ppo.numpy_policy import NumpyPolicy
from agents.ppo.ppo import PPO, PPOConfig, Rollout, advantages, compile_update, ppo_loss

__all__ = ["RecurrentPPO", "RecurrentPPOConfig"]


# --- 1. settings ---------------------------------------------------------------------


@dataclass(frozen=True)
class RecurrentPPOConfig(PPOConfig):
    """Recurrent PPO's settings: PPO's, an LSTM of ``lstm_hidden_size`` before MLPs of ``hidden``.

    The defaults are ``train.py``'s on the hard level (:mod:`agents.hyperparams`); ``batch_size``
    is a multiple of ``n_steps`` (a minibatch is whole env rollouts).
    """

    hidden: tuple[int, ...] = (64,)
    """The MLP after each LSTM (sb3-contrib's ``net_arch``)."""
    lstm_hidden_size: int = 64
    policy_lag: int = 0
    ALGO: ClassVar[str] = "recurrent_ppo"
    POLICY_KWARGS: ClassVar[dict[str, str]] = {"net_arch": "hidden", "lstm_hidden_size": "lstm_hidden_size"}

    def __post_init__(self) -> None:
        """Refuse settings the loop cannot run."""
        super().__post_init__()
        size = self.lstm_hidden_size
        if isinstance(size, bool) or not isinstance(size, int) or size < 1:
            raise ValueError(f"RecurrentPPOConfig.lstm_hidden_size must be a positive integer, got {size!r}")
        if self.batch_size % self.n_steps:
            raise ValueError(
                f"RecurrentPPOConfig: batch_size ({self.batch_size}) must be a multiple of n_steps "
                f"({self.n_steps}): a minibatch is whole env rollouts"
            )


# --- 2. the rollout --------------------------------------------------------------------


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-x))  # type: ignore[no-any-return]


class NumpyLstmPolicy(NumpyPolicy):
    """:class:`~agents.ppo.numpy_policy.NumpyPolicy` after the two LSTMs (:func:`agents.ppo.networks.lstm_cell`).

    A state is ``(h_pi, c_pi, h_vf, c_vf)``, each (n, lstm_hidden_size).
    """

    def __init__(self, params: Any, nvec: tuple[int, ...], activation: str) -> None:
        """Each LSTM's ``(W_ih^T, W_hh^T, b_ih + b_hh)``, the MLPs as :class:`NumpyPolicy`'s."""
        super().__init__(params, nvec, activation)

        def lstm(weights: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            w_ih, w_hh = (np.asarray(weights[w], np.float32).T.copy() for w in ("weight_ih", "weight_hh"))
            return w_ih, w_hh, np.asarray(weights["bias_ih"], np.float32) + np.asarray(weights["bias_hh"], np.float32)

        self.lstm_pi, self.lstm_vf = (lstm(params["params"][name]) for name in ("lstm_pi", "lstm_vf"))

    @staticmethod
    def _cell(weights: tuple[np.ndarray, ...], x: np.ndarray, h: np.ndarray, c: np.ndarray) -> tuple[Any, Any]:
        w_ih, w_hh, bias = weights
        i, f, g, o = np.split(x @ w_ih + h @ w_hh + bias, 4, axis=1)
        c = _sigmoid(f) * c + _sigmoid(i) * np.tanh(g)
        return _sigmoid(o) * np.tanh(c), c

    def step(
        self, obs: np.ndarray, starts: np.ndarray, state: tuple[np.ndarray, ...]
    ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, ...]]:
        """``(logits, V(s), state after)``: one step of both LSTMs from ``state``, zeroed where ``starts``."""
        keep = (1.0 - starts)[:, None].astype(np.float32)
        h_pi, c_pi = self._cell(self.lstm_pi, obs, state[0] * keep, state[1] * keep)
        h_vf, c_vf = self._cell(self.lstm_vf, obs, state[2] * keep, state[3] * keep)
        return self._mlp(self.pi, h_pi), self._mlp(self.vf, h_vf)[:, 0], (h_pi, c_pi, h_vf, c_vf)

    def value_after(self, obs: np.ndarray, h_vf: np.ndarray, c_vf: np.ndarray) -> np.ndarray:
        """V of ``obs`` one value-LSTM step on from ``(h_vf, c_vf)``, as given (nothing zeroed)."""
        h, _ = self._cell(self.lstm_vf, obs, h_vf, c_vf)
        return self._mlp(self.vf, h)[:, 0]  # type: ignore[no-any-return]


# --- 3. the advantages: PPO's (agents.ppo.ppo.advantages) -----------------------------
# --- 4. the update ------------------------------------------------------------------------


@functools.cache
def make_update(network: Any, config: RecurrentPPOConfig, nvec: tuple[int, ...]) -> tuple[Any, Any]:
    """``(optimiser, update)``: ``update(params, opt_state, orders, batch, lr, clip) -> (params, opt_state, stats)``.

    ``batch``: ``(obs, actions, old_log_probs, advantages, returns, starts)``, each (n_steps, n_envs,
    ...), then the four (n_envs, lstm_hidden_size) LSTM states the rollout began with; ``orders``:
    one permutation of the envs per epoch, (n_epochs, n_envs), cut into minibatches of
    ``batch_size / n_steps`` envs in order. The loss is PPO's over a minibatch's samples.
    """
    from agents.ppo.networks import log_prob_entropy

    def loss(params: Any, batch: tuple[Any, ...], clip: Any) -> tuple[Any, dict[str, Any]]:
        obs, actions, old_log_prob, adv, returns, starts, *state = batch
        logits, values, _ = network.apply(params, obs, starts, tuple(state))
        rows = lambda x: x.reshape(-1, *x.shape[2:])  # noqa: E731  # time-major, as the network's outputs
        log_prob, entropy = log_prob_entropy(logits, rows(actions), nvec)
        return ppo_loss(config, log_prob, entropy, values, (rows(old_log_prob), rows(adv), rows(returns)), clip)

    def select(batch: list[Any], envs: Any) -> list[Any]:
        return [column[:, envs] for column in batch[:6]] + [state[envs] for state in batch[6:]]

    per_minibatch = config.batch_size // config.n_steps
    return compile_update(config, loss, select, (config.n_envs // per_minibatch, per_minibatch))


# --- 5. the loop ---------------------------------------------------------------------------


class RecurrentPPO(PPO):
    """The learner: ``RecurrentPPO(env_id, config, seed).learn(total_timesteps)``, as :class:`agents.ppo.PPO`.

    What differs from PPO is the network, the rollout's step and values (the LSTM states carried
    through them, :attr:`lstm_state`) and what the update reads.
    """

    config: RecurrentPPOConfig

    def __init__(
        self,
        env_id: str,
        config: RecurrentPPOConfig | None = None,
        seed: int = 0,
        env_kwargs: dict[str, Any] | None = None,
    ) -> None:
        """PPO's envs, network and optimiser; the LSTM states zero."""
        config = config or RecurrentPPOConfig()
        if not isinstance(config, RecurrentPPOConfig):
            raise ValueError(f"RecurrentPPO needs a RecurrentPPOConfig, got {type(config).__name__}")
        super().__init__(env_id, config, seed, env_kwargs)
        zeros = np.zeros((config.n_envs, config.lstm_hidden_size), np.float32)
        self.lstm_state: tuple[np.ndarray, ...] = (zeros, zeros, zeros, zeros)
        """``(h_pi, c_pi, h_vf, c_vf)`` after each env's last step, each (n_envs, lstm_hidden_size)."""

    def _make_network(self) -> Any:
        from agents.ppo.networks import LstmActorCritic

        cfg = self.config
        return LstmActorCritic(self.nvec, cfg.hidden, cfg.lstm_hidden_size, cfg.activation)

    def _example_inputs(self, obs_shape: tuple[int, ...]) -> tuple[Any, ...]:
        state = tuple(np.zeros((1, self.config.lstm_hidden_size), np.float32) for _ in range(4))
        return np.zeros((1, 1, *obs_shape), np.float32), np.zeros((1, 1), np.float32), state

    def _make_update(self) -> tuple[Any, Any]:
        return make_update(self.network, self.config, self.nvec)

    def _policy(self, params: Any) -> NumpyLstmPolicy:
        return NumpyLstmPolicy(params, self.nvec, self.config.activation)

    # The rollout (PPO.rollout) through these: the states zeroed where an episode starts (step t
    # reads the starts of its own observation), carried on to the next rollout.

    def _act(self, obs: np.ndarray, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        logits, values, self.lstm_state = self._acting.step(obs, starts, self.lstm_state)
        actions, log_probs = self._acting.sample(logits, self.rng)
        return actions, log_probs, values.astype(np.float32)

    def _final_values(self, final_obs: np.ndarray, cut: np.ndarray) -> np.ndarray:
        # As sb3-contrib: from the value LSTM's state after the step that ended the episode, not zeroed.
        return self._acting.value_after(final_obs, self.lstm_state[2][cut], self.lstm_state[3][cut])  # type: ignore[no-any-return]

    def _last_values(self) -> np.ndarray:
        keep = (1.0 - self._starts)[:, None].astype(np.float32)
        return self._acting.value_after(self._obs, self.lstm_state[2] * keep, self.lstm_state[3] * keep)  # type: ignore[no-any-return]

    def _memory(self) -> tuple[np.ndarray, ...]:
        return tuple(state.copy() for state in self.lstm_state)

    def _batch(self, rollout: Rollout) -> tuple[list[Any], int]:
        """The (n_steps, n_envs) columns and the states the rollout began with; minibatches are drawn from the envs."""
        adv, returns = advantages(rollout, self.config.gamma, self.config.gae_lambda)
        columns = [rollout.obs, rollout.actions, rollout.log_probs, adv, returns, rollout.starts]
        return [*columns, *rollout.lstm_states], self.config.n_envs

    # --- 6. checkpoints: PPO's, and the LSTM states ------------------------------------------

    def state(self) -> dict[str, Any]:
        """PPO's :meth:`~agents.ppo.PPO.state` and :attr:`lstm_state`."""
        return {**super().state(), "lstm_state": [state.copy() for state in self.lstm_state]}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`state` (taken from a learner of the same id, settings and seed)."""
        super().restore(state)
        self.lstm_state = tuple(np.array(s, np.float32) for s in state["lstm_state"])
