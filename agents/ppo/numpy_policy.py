"""The rollout's policy: the actor-critic's forward pass in NumPy over flax's weights, and its sampling.

On a few dozen envs a NumPy forward pass costs less than a call into XLA (:mod:`agents.ppo.ppo`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["NumpyPolicy", "head_columns"]


def head_columns(nvec: tuple[int, ...] | list[int]) -> tuple[np.ndarray, np.ndarray]:
    """``(columns, last)``: each action dimension's logit columns as a row of a (dims, widest) table.

    Rows are padded with column ``sum(nvec)``, read as a -inf logit (probability exactly 0);
    ``last[d]`` is dimension ``d``'s highest action.
    """
    n_logits, widest, bounds = int(sum(nvec)), max(nvec), np.cumsum([0, *nvec])
    columns = np.full((len(nvec), widest), n_logits)
    for head, n in enumerate(nvec):
        columns[head, :n] = np.arange(bounds[head], bounds[head] + n)
    return columns, np.asarray(nvec) - 1


class NumpyPolicy:
    """The actor-critic's forward pass in NumPy over flax's weights, and its sampling.

    The logits are laid out as a (dims, widest) table, padded with -inf, so that every action
    dimension is sampled at once.
    """

    def __init__(self, params: Any, nvec: tuple[int, ...], activation: str) -> None:
        """Weights as NumPy (``params``: ``{"params": {"pi": {...}, "vf": {...}}}`` of :class:`ActorCritic`)."""

        def layers(net: dict[str, Any]) -> list[tuple[np.ndarray, np.ndarray]]:
            names = sorted(net, key=lambda name: int(name.split("_")[1]))
            return [(np.asarray(net[n]["kernel"]), np.asarray(net[n]["bias"])) for n in names]

        self.pi, self.vf = layers(params["params"]["pi"]), layers(params["params"]["vf"])
        self.act_fn = np.tanh if activation == "tanh" else (lambda x: np.maximum(x, 0.0))
        self.columns, self.last = head_columns(nvec)
        self.offsets = np.arange(len(nvec)) * max(nvec)  # of each dimension's row in the flattened table

    def _mlp(self, layers: list[tuple[np.ndarray, np.ndarray]], x: np.ndarray) -> np.ndarray:
        for weight, bias in layers[:-1]:
            x = self.act_fn(x @ weight + bias)
        weight, bias = layers[-1]
        return x @ weight + bias

    def value(self, obs: np.ndarray) -> np.ndarray:
        """V(s) of each row."""
        return self._mlp(self.vf, obs)[:, 0]

    def act(self, obs: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(actions (n, dims), log pi(a|s), V(s))``: each dimension drawn by its inverse CDF."""
        actions, log_prob = self.sample(self._mlp(self.pi, obs), rng)
        return actions, log_prob, self.value(obs).astype(np.float32)

    def sample(
        self, logits: np.ndarray, rng: np.random.Generator, actions: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(actions (n, dims), log pi(a|s))`` drawn from ``logits`` (n, sum(nvec)), a dimension at once.

        ``actions``: take these instead of drawing (a replay of another learner's rollout), ``rng`` unused.
        """
        n = len(logits)
        padded = np.concatenate([logits, np.full((n, 1), -np.inf, np.float32)], axis=1)[:, self.columns]
        weights = np.exp(padded - padded.max(axis=2, keepdims=True))  # unnormalised probabilities
        cdf = np.cumsum(weights, axis=2)
        total = cdf[:, :, -1]
        if actions is None:
            draws = rng.random((n, len(self.last), 1)) * total[:, :, None]
            actions = np.minimum((draws >= cdf).sum(axis=2), self.last)
        chosen = weights.reshape(n, -1)[np.arange(n)[:, None], self.offsets + actions]
        return actions, np.log(chosen / total).sum(axis=1).astype(np.float32)
