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
minibatches of ``batch_size``.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Sequence
from typing import Any

__all__ = ["build"]

_XLA_ONE_THREAD = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"


def _jax() -> tuple[Any, Any, Any]:
    """``(jax, jax.numpy, optax)``, XLA held to one thread before its first use."""
    os.environ.setdefault("XLA_FLAGS", _XLA_ONE_THREAD)
    import jax
    import jax.numpy as jnp
    import optax

    return jax, jnp, optax


def build(
    *,
    nvec: Sequence[int],
    relu: bool,
    samples: int,
    batch_size: int,
    n_epochs: int,
    max_grad_norm: float,
    ent_coef: float,
    vf_coef: float,
    normalize_advantage: bool,
) -> dict[str, Any]:
    """The jitted functions for a policy over ``len(nvec)`` categorical action dimensions.

    Returns:
        ``{"update", "init", "unflatten_opt", "nvec", "relu"}``: ``update(params, opt_state, key,
        obs, actions, old_log_probs, advantages, returns, learning_rate, clip_range) -> (params,
        opt_state, key, stats)``;
        ``init(params)`` the optimiser state; ``unflatten_opt(params, leaves)`` it from saved leaves.
    """
    jax, jnp, optax = _jax()
    activation = jax.nn.relu if relu else jnp.tanh
    splits = [int(n) for n in nvec]
    bounds = [sum(splits[:i]) for i in range(len(splits) + 1)]

    def mlp(layers: list[tuple[Any, Any]], x: Any) -> Any:
        for weight, bias in layers[:-1]:
            x = activation(x @ weight + bias)
        weight, bias = layers[-1]
        return x @ weight + bias

    def log_softmaxes(params: Any, obs: Any) -> list[Any]:
        logits = mlp(params["pi"], obs)
        return [jax.nn.log_softmax(logits[:, lo:hi]) for lo, hi in itertools.pairwise(bounds)]

    def value(params: Any, obs: Any) -> Any:
        return mlp(params["vf"], obs)[:, 0]

    def loss(params: Any, batch: tuple[Any, ...], clip_range: Any) -> tuple[Any, dict[str, Any]]:
        obs, actions, old_log_prob, advantages, returns = batch
        heads = log_softmaxes(params, obs)
        log_prob = sum(jnp.take_along_axis(h, actions[:, i : i + 1], 1)[:, 0] for i, h in enumerate(heads))
        entropy = sum(-(jnp.exp(h) * h).sum(axis=1) for h in heads)
        if normalize_advantage:
            advantages = (advantages - advantages.mean()) / (advantages.std(ddof=1) + 1e-8)
        log_ratio = log_prob - old_log_prob
        ratio = jnp.exp(log_ratio)
        policy_loss = -jnp.minimum(
            advantages * ratio, advantages * jnp.clip(ratio, 1 - clip_range, 1 + clip_range)
        ).mean()
        value_loss = ((returns - value(params, obs)) ** 2).mean()
        entropy_loss = -entropy.mean()
        total = policy_loss + ent_coef * entropy_loss + vf_coef * value_loss
        stats = {
            "policy_gradient_loss": policy_loss,
            "value_loss": value_loss,
            "entropy_loss": entropy_loss,
            "approx_kl": ((ratio - 1) - log_ratio).mean(),
            "clip_fraction": (jnp.abs(ratio - 1) > clip_range).mean(),
            "loss": total,
        }
        return total, stats

    optimizer = optax.inject_hyperparams(
        lambda learning_rate: optax.chain(optax.clip_by_global_norm(max_grad_norm), optax.adam(learning_rate, eps=1e-5))
    )(learning_rate=3e-4)
    minibatches = samples // batch_size

    def update(params: Any, opt_state: Any, key: Any, *rollout_and_rates: Any) -> tuple[Any, Any, Any, Any]:
        *rollout, learning_rate, clip_range = rollout_and_rates
        opt_state.hyperparams["learning_rate"] = learning_rate
        grad = jax.value_and_grad(loss, has_aux=True)

        def minibatch(carry: Any, index: Any) -> Any:
            params, opt_state = carry
            batch = tuple(column[index] for column in rollout)
            (_, stats), grads = grad(params, batch, clip_range)
            updates, opt_state = optimizer.update(grads, opt_state, params)
            return (optax.apply_updates(params, updates), opt_state), stats

        def epoch(carry: Any, epoch_key: Any) -> Any:
            order = jax.random.permutation(epoch_key, samples).reshape(minibatches, batch_size)
            return jax.lax.scan(minibatch, carry, order)

        key, sub = jax.random.split(key)
        (params, opt_state), stats = jax.lax.scan(epoch, (params, opt_state), jax.random.split(sub, n_epochs))
        return params, opt_state, key, {name: values.mean() for name, values in stats.items()}

    def unflatten_opt(params: Any, leaves: list[Any]) -> Any:
        treedef = jax.tree_util.tree_structure(optimizer.init(params))
        return jax.tree_util.tree_unflatten(treedef, [jnp.asarray(leaf) for leaf in leaves])

    return {
        "update": jax.jit(update),
        "init": optimizer.init,
        "unflatten_opt": unflatten_opt,
        "nvec": splits,
        "relu": relu,
    }
