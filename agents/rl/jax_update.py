r"""The compiled part of :class:`agents.rl.jax_ppo.JaxPPO`: one PPO update.

The networks are SB3's ``MlpPolicy``: a policy MLP ending in the action logits (one block of
logits per action dimension) and a separate value MLP, each ``x @ W + b`` per layer with
the activation between layers. The update is SB3's ``PPO.train`` written as formulas::

    ratio      = exp(log pi(a|s) - log pi_old(a|s))
    A          = (A - mean A) / (std A + 1e-8)                 per minibatch
    L_clip     = -mean(min(A * ratio, A * clip(ratio, 1 - eps, 1 + eps)))
    L_value    = mean((R - V(s))^2)
    L          = L_clip - ent_coef * mean(H(pi(.|s))) + vf_coef * L_value
    theta     <- Adam(clip_by_global_norm(grad L, max_grad_norm), lr, eps=1e-5)

for ``n_epochs`` passes, each over a fresh random permutation of the rollout cut into
minibatches of ``batch_size``. NumPy draws the permutations from the update's key
(:func:`epoch_orders`) before the compiled epochs run.

With ``lstm=True`` (:class:`agents.rl.jax_recurrent.JaxRecurrentPPO`) the networks are
sb3-contrib's ``MlpLstmPolicy``: an LSTM for the policy and another for the value, each
followed by its MLP. A torch ``nn.LSTM`` step, gates in torch's order ``i, f, g, o``::

    (i, f, g, o) = x W_ih^T + b_ih + h W_hh^T + b_hh
    c'           = sigmoid(f) c + sigmoid(i) tanh(g)
    h'           = sigmoid(o) tanh(c')

with ``(h, c)`` zeroed where an episode starts. A minibatch is whole env rollouts
(``batch_size / n_steps`` envs of ``n_steps`` steps), run through the LSTMs from the states
they had when the rollout began; the loss is the one above over its samples.
"""

from __future__ import annotations

import functools
import itertools
import os
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["build", "epoch_orders", "xla_flags"]

_XLA_ONE_THREAD = ("--xla_cpu_multi_thread_eigen=false", "intra_op_parallelism_threads=1")


def xla_flags(given: str) -> str:
    """``XLA_FLAGS`` with the one-thread flags added to ``given``, except those ``given`` sets itself."""
    names = {flag.split("=")[0].lstrip("-") for flag in given.split()}
    added = [flag for flag in _XLA_ONE_THREAD if flag.split("=")[0].lstrip("-") not in names]
    return " ".join([*given.split(), *added])


def _jax() -> tuple[Any, Any, Any]:
    """``(jax, jax.numpy, optax)``, XLA held to one thread before its first use (:func:`xla_flags`)."""
    os.environ["XLA_FLAGS"] = xla_flags(os.environ.get("XLA_FLAGS", ""))
    import jax
    import jax.numpy as jnp
    import optax

    return jax, jnp, optax


def _dense(jax: Any) -> Any:
    """``dense(x, w, b) = x @ w + b``, its weight gradient ``x^T g`` computed as a plain matrix product.

    Autodiff writes ``x^T g`` as one product contracting both operands' first axis, which XLA's
    CPU backend hands to a slower kernel than ``a @ b``; ``x^T`` made an array of its own behind an
    optimization barrier (so XLA cannot fold it back) turns it into ``a @ b``. The sums run in
    another order than autodiff's, so the gradient can differ from it in the last bits.
    """

    @jax.custom_vjp
    def dense(x: Any, w: Any, b: Any) -> Any:
        return x @ w + b

    def forward(x: Any, w: Any, b: Any) -> tuple[Any, tuple[Any, Any]]:
        return x @ w + b, (x, w)

    def backward(residuals: tuple[Any, Any], g: Any) -> tuple[Any, Any, Any]:
        x, w = residuals
        return g @ w.T, jax.lax.optimization_barrier(x.T) @ g, g.sum(axis=0)

    dense.defvjp(forward, backward)
    return dense


class _Loss:
    """PPO's loss (the formulas above) over SB3's networks: ``loss(params, batch, clip_range) -> (L, stats)``."""

    def __init__(
        self, nvec: Sequence[int], relu: bool, ent_coef: float, vf_coef: float, normalize_advantage: bool, lstm: bool
    ) -> None:
        self.jax, self.jnp, _ = _jax()
        self.activation = self.jax.nn.relu if relu else self.jnp.tanh
        self.dense = _dense(self.jax)
        splits = [int(n) for n in nvec]
        self.bounds = [sum(splits[:i]) for i in range(len(splits) + 1)]
        self.ent_coef, self.vf_coef = ent_coef, vf_coef
        self.normalize_advantage, self.lstm = normalize_advantage, lstm

    def mlp(self, layers: list[tuple[Any, Any]], x: Any) -> Any:
        for weight, bias in layers[:-1]:
            x = self.activation(self.dense(x, weight, bias))
        weight, bias = layers[-1]
        return self.dense(x, weight, bias)

    def log_softmaxes(self, logits: Any) -> list[Any]:
        return [self.jax.nn.log_softmax(logits[:, lo:hi]) for lo, hi in itertools.pairwise(self.bounds)]

    def forward(self, params: Any, batch: tuple[Any, ...]) -> tuple[Any, Any, tuple[Any, ...]]:
        """``(logits, values, (actions, old_log_prob, advantages, returns))`` of a minibatch, one row per sample."""
        if not self.lstm:
            obs, *rest = batch
            return self.mlp(params["pi"], obs), self.mlp(params["vf"], obs)[:, 0], tuple(rest)
        obs, actions, old_log_prob, advantages, returns, starts, *state = batch
        latent_pi, latent_vf = self.sequences((params["lstm_pi"], params["lstm_vf"]), obs, starts, state)
        flat = (actions, old_log_prob, advantages, returns)
        rows = latent_pi.shape[0] * latent_pi.shape[1]
        flat = tuple(column.reshape(rows, *column.shape[2:]) for column in flat)
        values = self.mlp(params["vf"], latent_vf.reshape(rows, -1))[:, 0]
        return self.mlp(params["pi"], latent_pi.reshape(rows, -1)), values, flat

    def cell(self, weights: Any, x: Any, h: Any, c: Any) -> tuple[Any, Any]:
        """One LSTM step (torch's gate order)."""
        jax, jnp = self.jax, self.jnp
        w_ih, w_hh, b_ih, b_hh = weights
        i, f, g, o = jnp.split(x @ w_ih.T + b_ih + h @ w_hh.T + b_hh, 4, axis=1)
        c = jax.nn.sigmoid(f) * c + jax.nn.sigmoid(i) * jnp.tanh(g)
        return jax.nn.sigmoid(o) * jnp.tanh(c), c

    def sequences(self, weights: tuple[Any, Any], obs: Any, starts: Any, state: list[Any]) -> tuple[Any, Any]:
        """Both LSTMs' outputs (T, E, hidden) over (T, E, features) from ``state``, zeroed where an episode starts."""

        def step(carry: Any, inputs: Any) -> Any:
            x, start = inputs
            keep = (1.0 - start)[:, None]
            h_pi, c_pi = self.cell(weights[0], x, carry[0] * keep, carry[1] * keep)
            h_vf, c_vf = self.cell(weights[1], x, carry[2] * keep, carry[3] * keep)
            return (h_pi, c_pi, h_vf, c_vf), (h_pi, h_vf)

        return self.jax.lax.scan(step, tuple(state), (obs, starts))[1]

    def __call__(self, params: Any, batch: tuple[Any, ...], clip_range: Any) -> tuple[Any, dict[str, Any]]:
        jnp = self.jnp
        logits, values, (actions, old_log_prob, advantages, returns) = self.forward(params, batch)
        heads = self.log_softmaxes(logits)
        log_prob = sum(jnp.take_along_axis(h, actions[:, i : i + 1], 1)[:, 0] for i, h in enumerate(heads))
        entropy = sum(-(jnp.exp(h) * h).sum(axis=1) for h in heads)
        if self.normalize_advantage:
            advantages = (advantages - advantages.mean()) / (advantages.std(ddof=1) + 1e-8)
        log_ratio = log_prob - old_log_prob
        ratio = jnp.exp(log_ratio)
        policy_loss = -jnp.minimum(
            advantages * ratio, advantages * jnp.clip(ratio, 1 - clip_range, 1 + clip_range)
        ).mean()
        value_loss = ((returns - values) ** 2).mean()
        entropy_loss = -entropy.mean()
        total = policy_loss + self.ent_coef * entropy_loss + self.vf_coef * value_loss
        stats = {
            "policy_gradient_loss": policy_loss,
            "value_loss": value_loss,
            "entropy_loss": entropy_loss,
            "approx_kl": ((ratio - 1) - log_ratio).mean(),
            "clip_fraction": (jnp.abs(ratio - 1) > clip_range).mean(),
            "loss": total,
        }
        return total, stats


def _optimizer(max_grad_norm: float) -> Any:
    """SB3's optimiser: Adam (eps 1e-5) after clipping by global norm; the learning rate set per update."""
    _, _, optax = _jax()
    return optax.inject_hyperparams(
        lambda learning_rate: optax.chain(optax.clip_by_global_norm(max_grad_norm), optax.adam(learning_rate, eps=1e-5))
    )(learning_rate=3e-4)


def epoch_orders(key: Any, n: int, n_epochs: int) -> tuple[np.ndarray, np.ndarray]:
    """``(next key, orders)``: ``n_epochs`` random permutations of ``n`` items and the next update's key.

    ``key`` is two uint32 words (a fresh run's is ``jax.random.PRNGKey(seed)``); they seed NumPy's
    PCG64, which draws the permutations, ``(n_epochs, n)`` int32, then the next key's two words.
    """
    words = [int(word) for word in np.asarray(key, dtype=np.uint32).ravel()]
    rng = np.random.Generator(np.random.PCG64(words))
    orders = np.stack([rng.permutation(n).astype(np.int32) for _ in range(n_epochs)])
    return rng.integers(0, 2**32, size=2, dtype=np.uint32), orders


def _unflatten_opt(optimizer: Any, params: Any, leaves: list[Any]) -> Any:
    """``optimizer``'s state over ``params`` from its saved leaves."""
    jax, jnp, _ = _jax()
    treedef = jax.tree_util.tree_structure(optimizer.init(params))
    return jax.tree_util.tree_unflatten(treedef, [jnp.asarray(leaf) for leaf in leaves])


def _epochs(loss: _Loss, optimizer: Any, lstm: bool, shape: tuple[int, int]) -> Any:
    """``epochs(params, opt_state, orders, *rollout, learning_rate, clip_range) -> (params, opt_state, stats)``.

    Every epoch (a row of ``orders``, cut into ``shape`` = (minibatches, units per minibatch)) and
    minibatch of one update, as one function for ``jax.jit``.
    """
    jax, _, optax = _jax()
    minibatches, per_minibatch = shape

    def epochs(params: Any, opt_state: Any, orders: Any, *rollout_and_rates: Any) -> tuple[Any, Any, Any]:
        *rollout, learning_rate, clip_range = rollout_and_rates
        opt_state.hyperparams["learning_rate"] = learning_rate
        grad = jax.value_and_grad(loss, has_aux=True)

        def minibatch(carry: Any, index: Any) -> Any:
            params, opt_state = carry
            if lstm:  # six (T, N, ...) columns, then the four (N, hidden) starting states
                batch = tuple(column[:, index] for column in rollout[:6]) + tuple(s[index] for s in rollout[6:])
            else:
                batch = tuple(column[index] for column in rollout)
            (_, stats), grads = grad(params, batch, clip_range)
            updates, opt_state = optimizer.update(grads, opt_state, params)
            return (optax.apply_updates(params, updates), opt_state), stats

        def epoch(carry: Any, order: Any) -> Any:
            return jax.lax.scan(minibatch, carry, order.reshape(minibatches, per_minibatch))

        (params, opt_state), stats = jax.lax.scan(epoch, (params, opt_state), orders)
        return params, opt_state, {name: values.mean() for name, values in stats.items()}

    return epochs


@functools.cache
def build(
    *,
    nvec: tuple[int, ...],
    relu: bool,
    samples: int,
    batch_size: int,
    n_epochs: int,
    max_grad_norm: float,
    ent_coef: float,
    vf_coef: float,
    normalize_advantage: bool,
    lstm: bool = False,
    n_steps: int = 0,
) -> dict[str, Any]:
    """The update and what goes with it for a policy over ``len(nvec)`` categorical action dimensions.

    Built once per process for each set of arguments: models of one configuration (seeds of a
    sweep, a resumed run) share the compiled functions, which hold no model's state.

    ``update`` draws the epochs' permutations from ``key`` (:func:`epoch_orders`) and runs every epoch
    and minibatch in one jitted call, which it does not wait for.

    Returns:
        ``{"update", "init", "unflatten_opt", "nvec", "relu"}``: ``update(params, opt_state, key, obs,
        actions, old_log_probs, advantages, returns, learning_rate, clip_range) -> (params, opt_state, key,
        stats)``; with ``lstm=True`` the rollout columns are ``(n_steps, n_envs, ...)`` and ``episode_starts``
        and the four ``(n_envs, hidden)`` LSTM states the rollout began with (policy ``h, c``, value ``h, c``)
        follow ``returns``; ``init(params)`` the optimiser state; ``unflatten_opt(params, leaves)`` it from
        saved leaves.
    """
    jax, _, _ = _jax()
    loss = _Loss(nvec, relu, ent_coef, vf_coef, normalize_advantage, lstm)
    optimizer = _optimizer(max_grad_norm)
    minibatches = samples // batch_size  # each of samples, or with an LSTM of whole env rollouts:
    units, per_minibatch = (samples, batch_size) if not lstm else (samples // n_steps, batch_size // n_steps)
    compiled = jax.jit(_epochs(loss, optimizer, lstm, (minibatches, per_minibatch)))

    def update(params: Any, opt_state: Any, key: Any, *rollout_and_rates: Any) -> tuple[Any, Any, Any, Any]:
        key, orders = epoch_orders(key, units, n_epochs)
        params, opt_state, stats = compiled(params, opt_state, orders, *rollout_and_rates)
        return params, opt_state, key, stats

    return {
        "update": update,
        "init": optimizer.init,
        "unflatten_opt": functools.partial(_unflatten_opt, optimizer),
        "nvec": [int(n) for n in nvec],
        "relu": relu,
    }
