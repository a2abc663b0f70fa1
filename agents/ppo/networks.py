"""The actor-critic: a policy MLP ending in one block of logits per action dimension, a value MLP.

Flax's ``linen`` modules, shaped as Stable-Baselines3's ``MlpPolicy`` (separate policy and value
networks, orthogonal initialisation: gain sqrt(2) in the hidden layers, 0.01 on the logits, 1 on
the value), so that a trained policy converts to an SB3 ``model.zip`` layer for layer
(:mod:`agents.ppo.sb3_format`).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["ACTIVATIONS", "ActorCritic", "log_prob_entropy"]

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
