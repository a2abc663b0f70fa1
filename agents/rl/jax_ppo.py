r"""PPO with its update compiled by JAX and its rollout policy in NumPy: SB3's PPO, faster.

:class:`JaxPPO` is Stable-Baselines3's :class:`~stable_baselines3.PPO` with ``collect_rollouts``
(the policy in NumPy, into SB3's rollout buffer and its GAE) and ``train`` (every epoch and
minibatch of an update in one jitted ``lax.scan``, SB3's loss and Adam: :mod:`agents.rl.jax_update`)
replaced; the rest -- constructor, hyperparameters, the torch policy's initial weights,
callbacks, ``VecNormalize``, ``save``/``load`` -- is SB3's. A saved ``JaxPPO`` is a PPO
``model.zip`` that loads and plays without JAX; a checkpoint (optimiser moments and random
streams included) continues exactly.

Only ``MlpPolicy`` on a ``Discrete`` or ``MultiDiscrete`` action space; ``n_envs * n_steps`` a
multiple of ``batch_size`` (or at most one minibatch). With ``policy_lag=1`` each update runs on
its own thread while the next rollout plays with the weights it started from
(:meth:`JaxTraining.train`). XLA runs on one thread and the initial weights are drawn on one
torch thread, so a seed trains the same weights whatever the thread and core counts.

Example:
    >>> from agents.rl import make_train_env
    >>> env = make_train_env("CoopGym/SitToStand-v0", n_envs=4, seed=0)
    >>> model = JaxPPO("MlpPolicy", env, n_steps=16, batch_size=32, seed=0, device="cpu")
    >>> model = model.learn(128)
    >>> model.num_timesteps
    128
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from numba import njit
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.utils import explained_variance
from stable_baselines3.common.vec_env import VecEnv

from agents.ppo.numpy_policy import head_columns
from agents.rl.jax_update import _jax, build
from agents.rl.normalize import numpy_sum
from agents.rl.sb3_vec import fused_step
from estimator.compiled import guard_kernel_cache

__all__ = ["JaxPPO", "JaxTraining", "jax_available"]


def jax_available() -> bool:
    """Whether JAX and optax can be imported (the ``train`` extra installs them)."""
    import importlib.util

    return importlib.util.find_spec("jax") is not None and importlib.util.find_spec("optax") is not None


class _RolloutPolicy:
    """The policy's forward pass in NumPy, for the rollout.

    On a few hundred envs the arithmetic costs less than a call into compiled code. Each
    action dimension is sampled by its inverse CDF: NumPy's ``exp`` and ``log``, the maxima, sums and
    comparisons between them compiled in NumPy's order (:func:`_shifted_blocks`, :func:`_block_sums`,
    :func:`_pick`).
    """

    def __init__(self, params: dict[str, list[tuple[Any, Any]]], nvec: list[int], relu: bool) -> None:
        self.pi = [(np.asarray(w, dtype=np.float32), np.asarray(b, dtype=np.float32)) for w, b in params["pi"]]
        self.vf = [(np.asarray(w, dtype=np.float32), np.asarray(b, dtype=np.float32)) for w, b in params["vf"]]
        self.activation = (lambda x: np.maximum(x, 0.0)) if relu else np.tanh
        # All heads at once (_shifted_blocks reads the padding column as a -inf logit).
        self.columns, self.last = head_columns(nvec)

    def _mlp(self, layers: list[tuple[np.ndarray, np.ndarray]], x: np.ndarray) -> np.ndarray:
        for weight, bias in layers[:-1]:
            x = self.activation(x @ weight + bias)
        weight, bias = layers[-1]
        return x @ weight + bias

    def value(self, obs: np.ndarray) -> np.ndarray:
        return self._mlp(self.vf, obs)[:, 0]

    def act(self, obs: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(actions (n, heads), values, log_probs)`` for a batch of normalised observations."""
        actions, log_prob = self.sample(self._mlp(self.pi, obs), rng)
        return actions, self.value(obs), log_prob

    def sample(self, logits: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """``(actions (n, heads), log_probs)`` drawn from the action logits, each head by its inverse CDF.

        Per head, with one uniform ``u`` per head and row::

            log_p  = logits - max(logits) - log(sum(exp(logits - max(logits))))
            action = min(#{j : u > cumsum(exp(log_p))_j}, n_head - 1)

        and ``log_prob`` the sum of the heads' ``log_p[action]``, added head by head. The
        block of all heads is C-contiguous, so each head's sums run as they would on that
        head alone (tests/agents/test_jax_ppo.py holds it to the head-by-head form).
        """
        n, heads = logits.shape[0], len(self.last)
        uniform = rng.random((n, heads), dtype=np.float32)
        if logits.dtype != np.float32:
            raise ValueError(f"the rollout policy's logits must be float32, got {logits.dtype}")
        # exp and log stay NumPy's: numba's round some values to other last bits.
        shifted = _shifted_blocks(np.ascontiguousarray(logits), self.columns)
        log_p = shifted - np.log(_block_sums(np.exp(shifted)))
        return _pick(np.exp(log_p), log_p, uniform, self.last)


@njit(cache=True, error_model="numpy")
def _shifted_blocks(logits: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """``block - block.max(axis=2)``: each head's logits in row ``head`` of a ``(n, heads, widest)`` block.

    ``columns[head]`` are the head's logit columns; column ``logits.shape[1]`` is the padding, -inf.
    """
    n, total = logits.shape
    heads, widest = columns.shape
    shifted = np.empty((n, heads, widest), dtype=np.float32)
    for row in range(n):
        for head in range(heads):
            top = np.float32(-np.inf)
            for k in range(widest):
                column = columns[head, k]
                value = logits[row, column] if column < total else np.float32(-np.inf)
                shifted[row, head, k] = value
                if value > top:
                    top = value
            for k in range(widest):
                shifted[row, head, k] = shifted[row, head, k] - top
    return shifted


@njit(cache=True, error_model="numpy")
def _block_sums(values: np.ndarray) -> np.ndarray:
    """``values.sum(axis=2, keepdims=True)`` of a contiguous float32 block, in NumPy's order (:func:`numpy_sum`).

    NumPy splits a block of over :data:`~agents.rl.normalize.PAIRWISE_BLOCK` values in two first, so an action dimension
    that wide sums to the last bits of another order.
    """
    n, heads, _ = values.shape
    sums = np.empty((n, heads, 1), dtype=np.float32)
    for row in range(n):
        for head in range(heads):
            sums[row, head, 0] = numpy_sum(values[row, head], np.float32(0.0))
    return sums


@njit(cache=True, error_model="numpy")
def _pick(
    probabilities: np.ndarray, log_p: np.ndarray, uniform: np.ndarray, last: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each head's action by its inverse CDF (the cumulative sum one by one) and the sum of their log-probabilities."""
    n, heads, widest = probabilities.shape
    choice = np.empty((n, heads), dtype=np.int32)
    log_prob = np.zeros(n, dtype=np.float32)
    for row in range(n):
        for head in range(heads):
            cdf = np.float32(0.0)
            above = 0
            for k in range(widest):
                cdf = probabilities[row, head, k] if k == 0 else cdf + probabilities[row, head, k]
                if uniform[row, head] > cdf:
                    above += 1
            choice[row, head] = min(above, last[head])
            log_prob[row] += log_p[row, head, choice[row, head]]
    return choice, log_prob


class JaxTraining:
    """What :class:`JaxPPO` and :class:`agents.rl.jax_recurrent.JaxRecurrentPPO` share over their SB3 class.

    The weights move between the torch policy and JAX, the compiled update
    (:func:`agents.rl.jax_update.build`), the optimiser state and random streams that ``save``
    keeps, the rollout (``collect_rollouts``) and ``train``, all for SB3's MLP policy. A recurrent
    subclass replaces its rollout policy (:meth:`_rollout_policy`), the policy's step and values
    (:meth:`_act`, :meth:`_final_values`, :meth:`_next_values`, :meth:`_rollout_begins`,
    :meth:`_rollout_ends`) and what the update reads (:meth:`_update_inputs`).
    """

    framework = "jax"
    """What ``agent.json`` records (:func:`agents.rl.bundle.load_model` loads this class again)."""

    # Given by the SB3 class the mixin sits on.
    policy: Any
    action_space: spaces.Space[Any]
    n_envs: int
    n_steps: int
    batch_size: Any
    n_epochs: int
    max_grad_norm: float
    ent_coef: float
    vf_coef: float
    normalize_advantage: bool
    use_sde: bool
    target_kl: float | None
    clip_range_vf: Any
    seed: int | None
    logger: Any
    lr_schedule: Any
    clip_range: Any
    rollout_buffer: Any
    _current_progress_remaining: float
    _n_updates: int
    gamma: float
    num_timesteps: int
    _last_obs: Any
    _last_episode_starts: Any
    _update_info_buffer: Any

    _jax: dict[str, Any] | None = None
    _pending: Any = None

    policy_lag: int = 0
    """0: each rollout runs the weights of the update before it (PPO). 1: each rollout runs the
    weights of the update before last, while the last update runs on another core (set with the
    constructor's ``policy_lag``; see :meth:`train`)."""

    def __init__(self, *args: Any, policy_lag: int = 0, **kwargs: Any) -> None:
        """The SB3 class's constructor, plus ``policy_lag`` (0 or 1; see :attr:`policy_lag`)."""
        if policy_lag not in (0, 1) or isinstance(policy_lag, bool):
            raise ValueError(f"policy_lag must be 0 or 1, got {policy_lag!r}")
        self.policy_lag = policy_lag
        super().__init__(*args, **kwargs)

    def _excluded_save_params(self) -> list[str]:
        """The compiled functions and the working state are rebuilt on use, never saved (``jax_saved_state`` is)."""
        return [
            *super()._excluded_save_params(),  # type: ignore[misc]
            "_jax",
            "_params",
            "_opt_state",
            "_key",
            "_policy",
            "_rng",
            "_pending",
        ]

    def _setup_model(self) -> None:
        """SB3's set-up, with the initial weights drawn on one torch thread.

        Torch's orthogonal initialisation (a QR decomposition) rounds differently on another
        thread count; training itself never runs torch, so with this the weights a seed trains
        do not depend on ``torch.set_num_threads`` at all.
        """
        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            super()._setup_model()  # type: ignore[misc]
        finally:
            torch.set_num_threads(threads)

    # --- the networks, as JAX sees them --------------------------------------------

    def _torch_layers(self) -> tuple[list[torch.nn.Linear], list[torch.nn.Linear]]:
        """The policy's and the value function's ``Linear`` layers, input to output."""
        extractor = self.policy.mlp_extractor  # type: ignore[union-attr]
        pi = [m for m in extractor.policy_net if isinstance(m, torch.nn.Linear)] + [self.policy.action_net]
        vf = [m for m in extractor.value_net if isinstance(m, torch.nn.Linear)] + [self.policy.value_net]
        return pi, vf  # type: ignore[return-value]

    def _params_from_torch(self) -> dict[str, list[tuple[Any, Any]]]:
        """The torch policy's weights as JAX arrays: ``{"pi": [(W, b), ...], "vf": [...]}`` (``x @ W + b``)."""
        _, jnp, _ = _jax()
        pi, vf = self._torch_layers()

        def layers(mods: list[torch.nn.Linear]) -> list[tuple[Any, Any]]:
            return [(jnp.asarray(m.weight.detach().numpy().T), jnp.asarray(m.bias.detach().numpy())) for m in mods]

        return {"pi": layers(pi), "vf": layers(vf)}

    def _params_to_torch(self, params: dict[str, list[tuple[Any, Any]]]) -> None:
        """Copy JAX weights into the torch policy (what ``predict`` and ``save`` use)."""
        pi, vf = self._torch_layers()
        with torch.no_grad():
            for mods, layers in ((pi, params["pi"]), (vf, params["vf"])):
                for module, (weight, bias) in zip(mods, layers, strict=True):
                    module.weight.copy_(torch.from_numpy(np.array(weight).T))
                    module.bias.copy_(torch.from_numpy(np.array(bias)))

    def _check_supported(self) -> None:
        if not isinstance(self.action_space, (spaces.Discrete, spaces.MultiDiscrete)):
            raise ValueError(
                f"{type(self).__name__} needs a Discrete or MultiDiscrete action space, got {self.action_space}"
            )
        activation = self.policy.activation_fn  # type: ignore[union-attr]
        if activation not in (torch.nn.Tanh, torch.nn.ReLU):
            raise ValueError(f"{type(self).__name__} needs a Tanh or ReLU activation, got {activation.__name__}")
        if self.policy_lag and not self._lag_supported:
            raise ValueError(f"{type(self).__name__} does not support policy_lag")
        if self.use_sde or self.target_kl is not None or self.clip_range_vf is not None:
            raise ValueError(f"{type(self).__name__} supports neither use_sde, target_kl nor clip_range_vf")
        samples = self.n_envs * self.n_steps
        if samples > self.batch_size and samples % self.batch_size:
            raise ValueError(
                f"{type(self).__name__}: n_envs * n_steps ({samples}) must be a multiple of "
                f"batch_size ({self.batch_size})"
            )

    _lag_supported = True

    def _build_options(self) -> dict[str, Any]:
        """Options of :func:`agents.rl.jax_update.build` beyond PPO's own (none for the MLP)."""
        return {}

    def _rollout_policy(self, params: dict[str, Any]) -> Any:
        """The rollout's NumPy policy over ``params``."""
        compiled = self._compiled()
        return _RolloutPolicy(params, compiled["nvec"], compiled["relu"])

    def _update_inputs(self) -> tuple[np.ndarray, ...]:
        """The rollout columns the compiled update reads: one row per sample."""
        buffer = self.rollout_buffer
        return (
            buffer.observations.reshape(-1, *buffer.observations.shape[2:]),
            buffer.actions.reshape(-1, buffer.actions.shape[-1]).astype(np.int32),
            buffer.log_probs.reshape(-1),
            buffer.advantages.reshape(-1),
            buffer.returns.reshape(-1),
        )

    def _compiled(self) -> dict[str, Any]:
        """The compiled update and what goes with it (:func:`agents.rl.jax_update.build`), built on first use."""
        if self._jax is None:
            self._check_supported()
            nvec = (
                (int(self.action_space.n),)
                if isinstance(self.action_space, spaces.Discrete)
                else tuple(int(n) for n in self.action_space.nvec)  # type: ignore[attr-defined]
            )
            relu = self.policy.activation_fn is torch.nn.ReLU  # type: ignore[union-attr]
            self._jax = build(
                nvec=nvec,
                relu=relu,
                samples=self.n_envs * self.n_steps,
                # A rollout smaller than a minibatch is one minibatch, as in SB3.
                batch_size=min(self.batch_size, self.n_envs * self.n_steps),
                n_epochs=self.n_epochs,
                max_grad_norm=self.max_grad_norm,
                ent_coef=self.ent_coef,
                vf_coef=self.vf_coef,
                normalize_advantage=self.normalize_advantage,
                **self._build_options(),
            )
        return self._jax

    def _jax_state(self) -> tuple[Any, Any, Any]:
        """``(params, optimiser state, key)``: the torch weights, and the saved moments and keys if any.

        A checkpoint taken while an update ran ahead of the rollout (``policy_lag``) holds that
        update's weights under ``"params"``; the torch weights are then the rollout's.
        """
        jax, jnp, _ = _jax()
        compiled = self._compiled()
        params = self._params_from_torch()
        saved = getattr(self, "jax_saved_state", None)
        if saved is not None and "params" in saved:
            treedef = jax.tree_util.tree_structure(params)
            params = jax.tree_util.tree_unflatten(treedef, [jnp.asarray(leaf) for leaf in saved["params"]])
        seed = int(self.seed or 0) % (2**31)
        self._rng = np.random.Generator(np.random.PCG64(seed))
        if saved is None or "opt" not in saved:  # fresh: no optimiser state saved
            opt_state = compiled["init"](params)
            key = jax.random.PRNGKey(seed)
        else:
            opt_state = compiled["unflatten_opt"](params, saved["opt"])
            key = jax.numpy.asarray(saved["key"])
            self._rng.bit_generator.state = saved["rollout_rng"]
        return params, opt_state, key

    def _keep_state(self, params: Any, opt_state: Any, key: Any, *, rollout: bool = True) -> None:
        """Hold the state for the next call and for ``save`` (as NumPy: a zip loads without JAX).

        ``rollout``: the rollout policy (and the torch weights) take ``params`` too; if not, the
        state saves ``params`` apart from the torch weights (see :meth:`_jax_state`).
        """
        jax, _, _ = _jax()
        self._params, self._opt_state, self._key = params, opt_state, key
        saved = {k: v for k, v in (getattr(self, "jax_saved_state", None) or {}).items() if k != "params"}
        if rollout:
            self._policy = self._rollout_policy(params)
        else:
            saved["params"] = [np.asarray(leaf) for leaf in jax.tree_util.tree_leaves(params)]
        self.jax_saved_state = {
            **saved,
            "opt": [np.asarray(leaf) for leaf in jax.tree_util.tree_leaves(opt_state)],
            "key": np.asarray(key),
            "rollout_rng": self._rng.bit_generator.state,
        }

    def _setup_learn(self, *args: Any, **kwargs: Any) -> Any:
        """SB3's set-up, then the JAX state from the torch weights (a load or ``set_parameters`` included)."""
        result = super()._setup_learn(*args, **kwargs)  # type: ignore[misc]
        self._pending = None
        saved = getattr(self, "jax_saved_state", None) or {}
        self._keep_state(*self._jax_state(), rollout="params" not in saved)
        if "params" in saved:  # a checkpoint of a lagged run: the rollout runs the torch weights
            self._policy = self._rollout_policy(self._params_from_torch())
        return result

    def learn(self, *args: Any, **kwargs: Any) -> Any:
        """SB3's ``learn``; with ``policy_lag``, the update still running lands in the weights at the end."""
        result = super().learn(*args, **kwargs)  # type: ignore[misc]
        if self.policy_lag:
            self._land()
            self._adopt_newest()
        return result

    def save(self, *args: Any, **kwargs: Any) -> None:
        """SB3's ``save``; an update still running (``policy_lag``) is waited for and kept beside the rollout's."""
        if self._land():
            self._keep_state(self._params, self._opt_state, self._key, rollout=False)
        super().save(*args, **kwargs)  # type: ignore[misc]

    # --- SB3's two methods, replaced -------------------------------------------------

    def collect_rollouts(
        self,
        env: VecEnv,
        callback: BaseCallback,
        rollout_buffer: Any,
        n_rollout_steps: int,
    ) -> bool:
        """SB3's rollout (callbacks, episode infos, timeout bootstrap, its buffer and GAE), the policy in NumPy.

        ``make_train_env``'s stack steps through :func:`agents.rl.sb3_vec.fused_step`.

        The policy's step is the subclass's :meth:`_act`; :meth:`_final_values` values the final
        observation of a time-limit end, :meth:`_next_values` the observations after the rollout.
        """
        assert self._last_obs is not None, "No previous observation was provided"
        buffer = rollout_buffer
        buffer.reset()
        callback.on_rollout_start()
        self._rollout_begins()
        env_step = fused_step(env) or env.step  # train.py's stack in one function, the same numbers
        for step in range(n_rollout_steps):
            obs = np.asarray(self._last_obs, dtype=np.float32)
            actions, values, log_probs = self._act(obs, buffer, step)
            env_actions = actions[:, 0] if isinstance(self.action_space, spaces.Discrete) else actions
            new_obs, rewards, dones, infos = env_step(env_actions)
            self.num_timesteps += env.num_envs
            callback.update_locals(locals())
            if not callback.on_step():
                return False
            self._update_info_buffer(infos, dones)
            rewards = np.asarray(rewards, dtype=np.float32).copy()
            # As SB3: a time-limit end adds gamma * V(final observation) to its reward.
            cut = [
                i
                for i in np.flatnonzero(dones).tolist()
                if infos[i].get("terminal_observation") is not None and infos[i].get("TimeLimit.truncated", False)
            ]
            if cut:
                final = np.stack([infos[i]["terminal_observation"] for i in cut]).astype(np.float32)
                rewards[cut] += self.gamma * self._final_values(final, cut)
            buffer.observations[step], buffer.actions[step], buffer.rewards[step] = obs, actions, rewards
            buffer.episode_starts[step] = self._last_episode_starts
            buffer.values[step], buffer.log_probs[step] = values, log_probs
            self._last_obs = new_obs
            self._last_episode_starts = dones
        buffer.pos, buffer.full = n_rollout_steps, True
        last_values = self._next_values(np.asarray(new_obs, dtype=np.float32), np.asarray(dones))
        self._rollout_ends()
        buffer.compute_returns_and_advantage(last_values=torch.from_numpy(last_values), dones=dones)
        callback.update_locals(locals())
        callback.on_rollout_end()
        return True

    # The MLP policy's step and values; a recurrent subclass carries its LSTM state through them.

    def _act(self, obs: np.ndarray, buffer: Any, step: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(actions, values, log_probs)`` of the rollout's ``step`` (``buffer``: what it fills)."""
        return self._policy.act(obs, self._rng)  # type: ignore[no-any-return]

    def _final_values(self, final: np.ndarray, envs: list[int]) -> np.ndarray:
        """The values of the final observations of envs ``envs``, which just hit their time limit."""
        return self._policy.value(final)  # type: ignore[no-any-return]

    def _next_values(self, obs: np.ndarray, dones: np.ndarray) -> np.ndarray:
        """The values of the observations after the rollout (``dones``: each begins an episode)."""
        return self._policy.value(obs)  # type: ignore[no-any-return]

    def _rollout_begins(self) -> None:
        """Called before a rollout's first step."""

    def _rollout_ends(self) -> None:
        """Called after a rollout's last step."""

    def train(self) -> None:
        """One PPO update: every epoch and minibatch in one compiled call, then the torch weights.

        With ``policy_lag=1`` the update is started and not waited for: the next rollout runs
        the weights this update starts from while it runs (JAX dispatches it to its own thread),
        and it lands at the start of the next ``train``. Each update then starts from the
        weights of the one before, on a rollout played by the weights before those; PPO's
        ratio is taken to the policy that played. The values do not depend on timing: a seed
        trains the same weights, and a checkpoint (taken by ``save``, which waits for the
        update) continues exactly.
        """
        compiled = self._compiled()
        self._update_learning_rate(self.policy.optimizer)  # type: ignore[attr-defined]
        learning_rate = float(self.lr_schedule(self._current_progress_remaining))
        clip_range = float(self.clip_range(self._current_progress_remaining))
        buffer = self.rollout_buffer
        inputs = self._update_inputs()
        if self.policy_lag:
            self._land()
            self._adopt_newest()
            # The next rollout refills the buffer while the update reads its own copy.
            inputs = tuple(np.array(column) for column in inputs)
        result = compiled["update"](self._params, self._opt_state, self._key, *inputs, learning_rate, clip_range)
        self._n_updates += self.n_epochs
        explained = explained_variance(buffer.values.ravel(), buffer.returns.ravel())
        self.logger.record("train/explained_variance", float(explained))
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/clip_range", clip_range)
        if self.policy_lag:
            self._pending = result
        else:
            self._land(result)
            self._adopt_newest()

    def wait_for_update(self) -> None:
        """Wait until an update running ahead of the rollout (``policy_lag``) has finished; the numbers do not change.

        For a clock that should count the update's time where it ran, not where it was next needed.
        """
        self._land()

    def _adopt_newest(self) -> None:
        """The last landed update's weights become the torch weights and the rollout policy."""
        self._params_to_torch(self._params)
        self._keep_state(self._params, self._opt_state, self._key)

    def _land(self, result: Any = None) -> bool:
        """Wait for an update (``result``, or the one running ahead of the rollout) and hold its state.

        The torch weights and the rollout policy are left as they are. False if there was none.
        """
        if result is None:
            result, self._pending = self._pending, None
            if result is None:
                return False
        self._params, self._opt_state, self._key, stats = result
        stats = {name: float(value) for name, value in stats.items()}
        for name in ("entropy_loss", "policy_gradient_loss", "value_loss", "approx_kl", "clip_fraction", "loss"):
            self.logger.record(f"train/{name}", stats[name])
        return True


class JaxPPO(JaxTraining, PPO):
    """SB3's PPO with the update compiled by JAX and the rollout policy in NumPy (see the module docstring)."""


guard_kernel_cache(__name__)
