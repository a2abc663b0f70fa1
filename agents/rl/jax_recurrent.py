r"""Recurrent PPO (an LSTM policy) with its update compiled by JAX: sb3-contrib's RecurrentPPO, faster.

:class:`JaxRecurrentPPO` is sb3-contrib's :class:`~sb3_contrib.RecurrentPPO` with the rollout
and the update replaced, as :class:`agents.rl.jax_ppo.JaxPPO` is SB3's PPO: the networks are
sb3-contrib's ``MlpLstmPolicy`` (an LSTM for the policy and one for the value, each followed by
its MLP), the loss and optimiser SB3's PPO's. The rollout steps both LSTMs in NumPy, their
state zeroed where an episode starts, and bootstraps a time-limit end from the value LSTM's
state, as sb3-contrib's rollout does. The update (:func:`agents.rl.jax_update.build` with
``lstm=True``) cuts the rollout into minibatches of whole env rollouts (``batch_size /
n_steps`` envs each; CleanRL's ``ppo_atari_lstm`` scheme), each run through the LSTMs from
the states they had when the rollout began -- sb3-contrib instead cuts padded sequences at
episode starts, so the two make different minibatches of the same rollout. A saved
``JaxRecurrentPPO`` is a RecurrentPPO ``model.zip``: it loads, plays and is scored without JAX.

Only ``MlpLstmPolicy`` with one LSTM layer each for the policy and the value
(``enable_critic_lstm=True``, ``shared_lstm=False``, the default); ``batch_size`` a multiple
of ``n_steps`` that divides ``n_envs * n_steps`` (or at least ``n_envs * n_steps``: then the
whole rollout is one minibatch, as in SB3).

Example:
    >>> from agents.rl import make_train_env
    >>> env = make_train_env("CoopGym/SitToStandRaw-v0", n_envs=4, seed=0)
    >>> model = JaxRecurrentPPO("MlpLstmPolicy", env, n_steps=16, batch_size=32, seed=0, device="cpu")
    >>> model = model.learn(128)
    >>> model.num_timesteps
    128
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from sb3_contrib import RecurrentPPO
from stable_baselines3.common.torch_layers import FlattenExtractor

from agents.rl.jax_ppo import JaxTraining, _RolloutPolicy
from agents.rl.jax_update import _jax

__all__ = ["JaxRecurrentPPO"]

_LSTMS = ("lstm_pi", "lstm_vf")
_LSTM_WEIGHTS = ("weight_ih", "weight_hh", "bias_ih", "bias_hh")
"""A torch ``nn.LSTM``'s parameters of its one layer (``<name>_l0``), in the order JAX holds them."""


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-x))


class _LstmRolloutPolicy(_RolloutPolicy):
    """The recurrent policy's step in NumPy: each LSTM, then its MLP (formulas: :mod:`agents.rl.jax_update`)."""

    def __init__(self, params: dict[str, Any], nvec: list[int], relu: bool) -> None:
        super().__init__(params, nvec, relu)
        # (W_ih^T, W_hh^T, b_ih + b_hh) of each LSTM
        self.lstm = {
            name: (
                np.asarray(params[name][0], dtype=np.float32).T.copy(),
                np.asarray(params[name][1], dtype=np.float32).T.copy(),
                np.asarray(params[name][2], dtype=np.float32) + np.asarray(params[name][3], dtype=np.float32),
            )
            for name in _LSTMS
        }

    def _step(self, name: str, obs: np.ndarray, h: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        w_ih, w_hh, bias = self.lstm[name]
        i, f, g, o = np.split(obs @ w_ih + h @ w_hh + bias, 4, axis=1)
        c = _sigmoid(f) * c + _sigmoid(i) * np.tanh(g)
        return _sigmoid(o) * np.tanh(c), c

    def act_recurrent(
        self, obs: np.ndarray, starts: np.ndarray, state: tuple[np.ndarray, ...], rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[np.ndarray, ...]]:
        """``(actions, values, log_probs, state)``: one step of both LSTMs from ``state`` (zeroed where ``starts``)."""
        keep = (1.0 - starts)[:, None].astype(np.float32)
        h_pi, c_pi = self._step("lstm_pi", obs, state[0] * keep, state[1] * keep)
        h_vf, c_vf = self._step("lstm_vf", obs, state[2] * keep, state[3] * keep)
        actions, log_prob = self.sample(self._mlp(self.pi, h_pi), rng)
        return actions, self._mlp(self.vf, h_vf)[:, 0], log_prob, (h_pi, c_pi, h_vf, c_vf)

    def value_recurrent(self, obs: np.ndarray, starts: np.ndarray, h_vf: np.ndarray, c_vf: np.ndarray) -> np.ndarray:
        """The value of ``obs`` after the value LSTM's state ``(h_vf, c_vf)`` (zeroed where ``starts``)."""
        keep = (1.0 - starts)[:, None].astype(np.float32)
        h, _ = self._step("lstm_vf", obs, h_vf * keep, c_vf * keep)
        return self._mlp(self.vf, h)[:, 0]


class JaxRecurrentPPO(JaxTraining, RecurrentPPO):
    """sb3-contrib's RecurrentPPO, its update compiled by JAX and its rollout in NumPy (see the module docstring)."""

    _lag_supported = False

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "_lstm_state", "_rollout_start"]

    def _lstm_modules(self) -> dict[str, torch.nn.LSTM]:
        return {"lstm_pi": self.policy.lstm_actor, "lstm_vf": self.policy.lstm_critic}

    def _params_from_torch(self) -> dict[str, Any]:
        """:class:`JaxTraining`'s MLP weights, and each LSTM's ``(W_ih, W_hh, b_ih, b_hh)`` as torch holds them."""
        _, jnp, _ = _jax()
        params: dict[str, Any] = super()._params_from_torch()
        for name, lstm in self._lstm_modules().items():
            params[name] = tuple(jnp.asarray(getattr(lstm, f"{w}_l0").detach().numpy()) for w in _LSTM_WEIGHTS)
        return params

    def _params_to_torch(self, params: dict[str, Any]) -> None:
        super()._params_to_torch(params)
        with torch.no_grad():
            for name, lstm in self._lstm_modules().items():
                for w, value in zip(_LSTM_WEIGHTS, params[name], strict=True):
                    getattr(lstm, f"{w}_l0").copy_(torch.from_numpy(np.array(value)))

    def _check_supported(self) -> None:
        super()._check_supported()
        policy = self.policy
        if policy.lstm_critic is None or policy.shared_lstm or policy.lstm_actor.num_layers != 1:
            raise ValueError("JaxRecurrentPPO needs one LSTM layer each for the policy and the value (the default)")
        if not isinstance(policy.features_extractor, FlattenExtractor):
            raise ValueError("JaxRecurrentPPO needs the default FlattenExtractor")
        batch = min(self.batch_size, self.n_envs * self.n_steps)  # a smaller rollout is one minibatch, as in SB3
        if batch % self.n_steps or (self.n_envs * self.n_steps) % batch:
            raise ValueError(
                f"JaxRecurrentPPO: batch_size ({self.batch_size}) must be a multiple of n_steps ({self.n_steps}) "
                f"dividing n_envs * n_steps ({self.n_envs * self.n_steps}): minibatches are whole env rollouts"
            )

    def _build_options(self) -> dict[str, Any]:
        return {"lstm": True, "n_steps": self.n_steps}

    def _rollout_policy(self, params: dict[str, Any]) -> _LstmRolloutPolicy:
        compiled = self._compiled()
        return _LstmRolloutPolicy(params, compiled["nvec"], compiled["relu"])

    def _update_inputs(self) -> tuple[np.ndarray, ...]:
        """The (T, N, ...) rollout, its episode starts, and the LSTM states the rollout began with."""
        buffer = self.rollout_buffer
        return (
            buffer.observations,
            buffer.actions.astype(np.int32),
            buffer.log_probs,
            buffer.advantages,
            buffer.returns,
            buffer.episode_starts.astype(np.float32),
            *self._rollout_start,
        )

    def _jax_state(self) -> tuple[Any, Any, Any]:
        """:class:`JaxTraining`'s state, and the LSTM states the envs are in (zeros, or saved with the model)."""
        found = super()._jax_state()
        saved = getattr(self, "jax_saved_state", None) or {}
        hidden = self.policy.lstm_actor.hidden_size
        states = saved.get("lstm_state")
        if states is None or states[0].shape != (self.n_envs, hidden):
            states = [np.zeros((self.n_envs, hidden), dtype=np.float32) for _ in range(4)]
        self._lstm_state = tuple(np.asarray(s, dtype=np.float32) for s in states)
        return found

    def _rollout_begins(self) -> None:
        self._rollout_start = self._lstm_state

    def _act(self, obs: np.ndarray, buffer: Any, step: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Both LSTMs' step from the envs' states (kept in ``buffer`` before the step, as sb3-contrib keeps them)."""
        hidden = (buffer.hidden_states_pi, buffer.cell_states_pi, buffer.hidden_states_vf, buffer.cell_states_vf)
        for column, value in zip(hidden, self._lstm_state, strict=True):
            column[step, 0] = value
        starts = np.asarray(self._last_episode_starts, dtype=np.float32)
        actions, values, log_probs, self._lstm_state = self._policy.act_recurrent(
            obs, starts, self._lstm_state, self._rng
        )
        return actions, values, log_probs

    def _final_values(self, final: np.ndarray, envs: list[int]) -> np.ndarray:
        """As sb3-contrib: the final observation's value after the value LSTM's state (not reset)."""
        h_vf, c_vf = self._lstm_state[2][envs], self._lstm_state[3][envs]
        return self._policy.value_recurrent(final, np.zeros(len(envs), dtype=np.float32), h_vf, c_vf)  # type: ignore[no-any-return]

    def _next_values(self, obs: np.ndarray, dones: np.ndarray) -> np.ndarray:
        starts = dones.astype(np.float32)
        return self._policy.value_recurrent(obs, starts, self._lstm_state[2], self._lstm_state[3])  # type: ignore[no-any-return]

    def _rollout_ends(self) -> None:
        self.jax_saved_state = {**self.jax_saved_state, "lstm_state": [np.array(s) for s in self._lstm_state]}
