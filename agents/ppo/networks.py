"""The actor-critics: a policy MLP ending in one block of logits per action dimension, a value MLP.

Flax's ``linen`` modules, shaped as Stable-Baselines3's ``MlpPolicy`` (separate policy and value
networks, orthogonal initialisation: gain sqrt(2) in the hidden layers, 0.01 on the logits, 1 on
the value), so that a trained policy converts to an SB3 ``model.zip`` layer for layer
(:mod:`agents.ppo.sb3_format`). :class:`LstmActorCritic` puts an LSTM before each MLP, as
sb3-contrib's ``MlpLstmPolicy`` (``enable_critic_lstm=True``, ``shared_lstm=False``).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["ACTIVATIONS", "ActorCritic", "LstmActorCritic", "log_prob_entropy", "lstm_cell"]

ACTIVATIONS = {"tanh": nn.tanh, "relu": nn.relu}
"""The hidden layers' activation, by the name a config gives."""


@jax.custom_vjp
def _matmul(x: Any, w: Any) -> Any:
    return x @ w


def _matmul_forward(x: Any, w: Any) -> tuple[Any, tuple[Any, Any]]:
    return x @ w, (x, w)


def _matmul_backward(residuals: tuple[Any, Any], g: Any) -> tuple[Any, Any]:
    # Autodiff writes the weight gradient x^T g as one product contracting both operands' first
    # axis, which XLA's CPU backend runs on a slower kernel than a @ b; x^T as an array of its
    # own (behind a barrier, so that XLA does not fold it back) makes it a @ b.
    x, w = residuals
    return g @ w.T, jax.lax.optimization_barrier(x.T) @ g


_matmul.defvjp(_matmul_forward, _matmul_backward)


def _dot(x: Any, w: Any, dimension_numbers: Any, precision: Any = None, preferred_element_type: Any = None) -> Any:
    """``nn.Dense``'s product ``x @ w``, with the gradient of :func:`_matmul`."""
    return _matmul(x, w)


class _MLP(nn.Module):
    hidden: Sequence[int]
    out: int
    out_gain: float
    activation: str

    @nn.compact
    def __call__(self, x: Any) -> Any:
        act = ACTIVATIONS[self.activation]
        for width in self.hidden:
            x = act(nn.Dense(width, kernel_init=nn.initializers.orthogonal(np.sqrt(2)), dot_general=_dot)(x))
        return nn.Dense(self.out, kernel_init=nn.initializers.orthogonal(self.out_gain), dot_general=_dot)(x)


class ActorCritic(nn.Module):
    """``(logits, value)`` of a batch of observations: ``logits`` (batch, sum(nvec)), ``value`` (batch,)."""

    nvec: Sequence[int]
    """Choices per action dimension (a ``Discrete(n)`` space is ``(n,)``)."""
    hidden: Sequence[int] = (64, 64)
    activation: str = "tanh"

    def setup(self) -> None:
        """The two networks."""
        self.pi = _MLP(self.hidden, int(sum(self.nvec)), 0.01, self.activation)
        self.vf = _MLP(self.hidden, 1, 1.0, self.activation)

    def __call__(self, obs: Any) -> tuple[Any, Any]:
        """Logits and value."""
        return self.pi(obs), self.vf(obs)[:, 0]


def lstm_cell(weights: tuple[Any, Any, Any, Any], x: Any, h: Any, c: Any) -> tuple[Any, Any]:
    """One step of torch's ``nn.LSTM`` (its gate order ``i, f, g, o``): ``(h', c')``.

    ``weights`` are torch's ``(W_ih, W_hh, b_ih, b_hh)`` as it holds them, (4 hidden, inputs) and so on::

        (i, f, g, o) = x W_ih^T + b_ih + h W_hh^T + b_hh
        c'           = sigmoid(f) c + sigmoid(i) tanh(g)
        h'           = sigmoid(o) tanh(c')
    """
    w_ih, w_hh, b_ih, b_hh = weights
    i, f, g, o = jnp.split(x @ w_ih.T + b_ih + h @ w_hh.T + b_hh, 4, axis=-1)
    c = nn.sigmoid(f) * c + nn.sigmoid(i) * jnp.tanh(g)
    return nn.sigmoid(o) * jnp.tanh(c), c


class _LSTM(nn.Module):
    """torch's one-layer ``nn.LSTM`` over a (time, batch, features) sequence, its state zeroed where ``starts``.

    Initialised as torch initialises it (sb3-contrib leaves its LSTMs so): every weight and bias
    uniform in +-1/sqrt(size).
    """

    size: int

    @nn.compact
    def __call__(self, x: Any, starts: Any, h: Any, c: Any) -> tuple[Any, tuple[Any, Any]]:
        bound = 1.0 / np.sqrt(self.size)

        def uniform(key: Any, shape: tuple[int, ...], dtype: Any = jnp.float32) -> Any:
            return jax.random.uniform(key, shape, dtype, -bound, bound)

        gates, features = 4 * self.size, x.shape[-1]
        weights = (
            self.param("weight_ih", uniform, (gates, features)),
            self.param("weight_hh", uniform, (gates, self.size)),
            self.param("bias_ih", uniform, (gates,)),
            self.param("bias_hh", uniform, (gates,)),
        )

        def step(carry: tuple[Any, Any], inputs: tuple[Any, Any]) -> tuple[tuple[Any, Any], Any]:
            x_t, start = inputs
            keep = (1.0 - start)[:, None]
            h, c = lstm_cell(weights, x_t, carry[0] * keep, carry[1] * keep)
            return (h, c), h

        state, out = jax.lax.scan(step, (h, c), (x, starts))
        return out, state


class LstmActorCritic(nn.Module):
    """sb3-contrib's ``MlpLstmPolicy``: an LSTM for the policy and one for the value, each before its MLP.

    ``(logits, values, state)`` of ``obs`` (time, envs, features) from ``state`` (the policy LSTM's
    ``h, c``, the value LSTM's ``h, c``, each (envs, lstm_hidden_size)), zeroed where ``starts``
    (time, envs) is 1: ``logits`` (time * envs, sum(nvec)) and ``values`` (time * envs,) time-major,
    ``state`` the one after the last step.
    """

    nvec: Sequence[int]
    hidden: Sequence[int] = (64,)
    lstm_hidden_size: int = 64
    activation: str = "tanh"

    def setup(self) -> None:
        """The two LSTMs and the two networks after them."""
        self.lstm_pi, self.lstm_vf = _LSTM(self.lstm_hidden_size), _LSTM(self.lstm_hidden_size)
        self.pi = _MLP(self.hidden, int(sum(self.nvec)), 0.01, self.activation)
        self.vf = _MLP(self.hidden, 1, 1.0, self.activation)

    def __call__(self, obs: Any, starts: Any, state: tuple[Any, ...]) -> tuple[Any, Any, tuple[Any, ...]]:
        """Logits, values and the state after the sequence."""
        latent_pi, (h_pi, c_pi) = self.lstm_pi(obs, starts, state[0], state[1])
        latent_vf, (h_vf, c_vf) = self.lstm_vf(obs, starts, state[2], state[3])
        rows = obs.shape[0] * obs.shape[1]
        logits = self.pi(latent_pi.reshape(rows, -1))
        return logits, self.vf(latent_vf.reshape(rows, -1))[:, 0], (h_pi, c_pi, h_vf, c_vf)


def log_softmaxes(logits: Any, nvec: Sequence[int]) -> list[Any]:
    """Each action dimension's log-probabilities, from its block of ``logits``."""
    bounds = np.cumsum([0, *nvec])
    return [nn.log_softmax(logits[:, lo:hi]) for lo, hi in itertools.pairwise(bounds)]


def log_prob_entropy(logits: Any, actions: Any, nvec: Sequence[int]) -> tuple[Any, Any]:
    """``(log pi(a|s), H(pi(.|s)))`` summed over the action dimensions; ``actions`` (batch, dims) int."""
    heads = log_softmaxes(logits, nvec)
    log_prob = sum(jnp.take_along_axis(h, actions[:, i : i + 1], 1)[:, 0] for i, h in enumerate(heads))
    entropy = sum(-(jnp.exp(h) * h).sum(axis=1) for h in heads)
    return log_prob, entropy
