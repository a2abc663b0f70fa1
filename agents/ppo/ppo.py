r"""PPO on a Gymnasium vector env, read top to bottom: settings, rollout, advantages, update, loop.

The algorithm of CleanRL's ``ppo.py`` and PureJaxRL's, with SB3's conventions where they differ
(the value target is not clipped, the value loss has no 1/2, advantages are normalised per
minibatch with the unbiased std, a time-limit end adds ``gamma * V(final observation)`` to its
reward)::

    ratio   = exp(log pi(a|s) - log pi_old(a|s))
    L       = -mean(min(A ratio, A clip(ratio, 1 - eps, 1 + eps)))
              - ent_coef mean(H(pi(.|s))) + vf_coef mean((R - V(s))^2)
    theta  <- Adam(clip_by_global_norm(grad L, max_grad_norm), lr, eps=1e-5)

for ``n_epochs`` passes over random minibatches of ``batch_size``. The networks are flax's
(:mod:`agents.ppo.networks`), the optimiser optax's; an update is one jitted ``lax.scan`` over
its epochs and minibatches. The rollout's policy runs in NumPy on the same weights, because on a
few dozen envs a NumPy forward pass costs less than a call into XLA -- and XLA's single thread is
then free for the update: with ``policy_lag=1`` each update runs there while the next rollout
plays the weights of the update before it (PPO's ratio is to the policy that played).

A seed trains the same weights in any process and at any thread count: the envs are seeded
``seed .. seed + n_envs - 1``, the network's initial weights by ``jax.random`` from ``seed``, the
actions and the minibatches by two NumPy streams spawned from ``seed``, and XLA runs on one
thread (:func:`jax_modules`).

Example:
    >>> import coop_gym
    >>> learner = PPO("CoopGym/SitToStandHard-v2", PPOConfig(n_envs=4, n_steps=32, batch_size=64), seed=0)
    >>> learner.learn(256).num_timesteps
    256
"""

from __future__ import annotations

import dataclasses
import functools
import os
import pickle
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode

from agents.ppo.normalizer import ObsNormalizer
from agents.ppo.numpy_policy import NumpyPolicy
from coop_gym.envs.kernels.report import REPORT

__all__ = ["PPO", "NumpyPolicy", "ObsNormalizer", "PPOConfig", "Rollout", "compile_update", "jax_modules", "ppo_loss"]


def jax_modules() -> tuple[Any, Any, Any]:
    """``(jax, jax.numpy, optax)`` with XLA held to one thread (set before JAX's first use)."""
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_cpu_multi_thread_eigen" not in flags:
        os.environ["XLA_FLAGS"] = f"{flags} --xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1".strip()
    import jax
    import jax.numpy as jnp
    import optax

    return jax, jnp, optax


# --- 1. settings ---------------------------------------------------------------------


@dataclass(frozen=True)
class PPOConfig:
    """PPO's settings; the defaults are ``train.py``'s on the hard level (:mod:`agents.hyperparams`)."""

    n_envs: int = 16
    n_steps: int = 256
    """Steps per env per rollout: an update reads ``n_envs * n_steps`` samples."""
    batch_size: int = 512
    n_epochs: int = 10
    learning_rate: float = 3e-4
    anneal_lr: bool = True
    """The learning rate falls linearly to 0 over the run."""
    gamma: float = 0.995
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.02
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    hidden: tuple[int, ...] = (64, 64)
    activation: str = "tanh"
    normalize_obs: bool = True
    """Observations scaled by their running mean and std (SB3's ``VecNormalize``: clipped to +-10)."""
    policy_lag: int = 1
    ALGO: ClassVar[str] = "ppo"
    """The :mod:`agents.hyperparams` algorithm whose settings :meth:`from_training` reads."""
    POLICY_KWARGS: ClassVar[dict[str, str]] = {"net_arch": "hidden"}
    """The field of each ``policy_kwargs`` setting :meth:`from_training` takes."""

    def __post_init__(self) -> None:
        """Refuse settings the loop cannot run."""
        for name in ("n_envs", "n_steps", "batch_size", "n_epochs"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{type(self).__name__}.{name} must be a positive integer, got {value!r}")
        if not self.hidden or not all(isinstance(w, int) and not isinstance(w, bool) and w > 0 for w in self.hidden):
            raise ValueError(f"{type(self).__name__}.hidden must be positive layer widths, got {self.hidden!r}")
        samples = self.n_envs * self.n_steps
        if samples % self.batch_size:
            raise ValueError(
                f"{type(self).__name__}: n_envs * n_steps ({samples}) must be a multiple of "
                f"batch_size ({self.batch_size})"
            )
        if self.policy_lag not in (0, 1):
            raise ValueError(f"{type(self).__name__}.policy_lag must be 0 or 1, got {self.policy_lag!r}")
        if self.activation not in ("tanh", "relu"):
            raise ValueError(f"{type(self).__name__}.activation must be 'tanh' or 'relu', got {self.activation!r}")

    def replace(self, **changes: Any) -> Any:
        """A copy with ``changes``."""
        return dataclasses.replace(self, **changes)

    @classmethod
    def from_training(cls, config: Any) -> Any:
        """The settings of a :class:`agents.hyperparams.TrainingConfig` of :attr:`ALGO` (``"lin_X"``: X, annealed).

        A rollout smaller than a minibatch is one minibatch, as in SB3.

        Raises:
            ValueError: a setting this learner does not have.
        """
        kwargs = dict(config.algo_kwargs)
        rate = kwargs.pop("learning_rate", cls.learning_rate)
        anneal = isinstance(rate, str) and rate.startswith("lin_")
        policy_kwargs = dict(config.policy_kwargs or {})
        network = {field: policy_kwargs.pop(key) for key, field in cls.POLICY_KWARGS.items() if key in policy_kwargs}
        network["hidden"] = tuple(network.get("hidden", cls.hidden))
        fields = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(kwargs) - fields) + sorted(policy_kwargs)
        if config.algo != cls.ALGO or unknown:
            raise ValueError(f"{cls.__name__}.from_training: {config.algo!r} settings {unknown} are not this learner's")
        n_steps = int(kwargs.pop("n_steps", cls.n_steps))
        batch_size = min(int(kwargs.pop("batch_size", cls.batch_size)), config.n_envs * n_steps)  # one at least
        return cls(
            n_envs=config.n_envs,
            n_steps=n_steps,
            batch_size=batch_size,
            learning_rate=float(rate[4:] if anneal else rate),
            anneal_lr=anneal,
            normalize_obs=bool(config.normalize),
            **network,
            **kwargs,
        )


# --- 2. the rollout --------------------------------------------------------------------


class Rollout(NamedTuple):
    """``n_steps`` steps of every env: arrays of shape (n_steps, n_envs, ...)."""

    obs: np.ndarray
    actions: np.ndarray
    log_probs: np.ndarray
    values: np.ndarray
    rewards: np.ndarray
    starts: np.ndarray
    """1 where the step began an episode."""
    last_values: np.ndarray
    """V of the observations after the last step, (n_envs,)."""
    last_starts: np.ndarray
    """1 where an episode begins after the last step, (n_envs,)."""
    lstm_states: tuple[np.ndarray, ...] = ()
    """A recurrent policy's LSTM states when the rollout began, each (n_envs, hidden); none for the MLP."""


# --- 3. the advantages ------------------------------------------------------------------


def advantages(rollout: Rollout, gamma: float, gae_lambda: float) -> tuple[np.ndarray, np.ndarray]:
    """``(advantages, returns)`` by generalised advantage estimation, both (n_steps, n_envs)."""
    next_values = np.concatenate([rollout.values[1:], rollout.last_values[None]])
    next_live = 1.0 - np.concatenate([rollout.starts[1:], rollout.last_starts[None]])
    adv = np.zeros_like(rollout.rewards)
    last = np.zeros_like(rollout.rewards[0])
    for t in reversed(range(rollout.rewards.shape[0])):
        delta = rollout.rewards[t] + gamma * next_values[t] * next_live[t] - rollout.values[t]
        last = delta + gamma * gae_lambda * next_live[t] * last
        adv[t] = last
    return adv, adv + rollout.values


# --- 4. the update ------------------------------------------------------------------------


@functools.cache
def make_update(network: Any, config: PPOConfig, nvec: tuple[int, ...], samples: int) -> tuple[Any, Any]:
    """``(optimiser, update)``: ``update(params, opt_state, orders, batch, lr, clip) -> (params, opt_state, stats)``.

    ``batch``: ``(obs, actions, old_log_probs, advantages, returns)``, one row per sample;
    ``orders``: one permutation of the samples per epoch, (n_epochs, samples), cut into the
    epoch's minibatches in order; NumPy draws them, outside the compiled update. Built once per process
    for each set of arguments: the learners of one configuration (seeds, a resumed run) share it.
    """
    from agents.ppo.networks import log_prob_entropy

    def loss(params: Any, batch: tuple[Any, ...], clip: Any) -> tuple[Any, dict[str, Any]]:
        obs, actions, old_log_prob, adv, returns = batch
        logits, values = network.apply(params, obs)
        log_prob, entropy = log_prob_entropy(logits, actions, nvec)
        return ppo_loss(config, log_prob, entropy, values, (old_log_prob, adv, returns), clip)

    shape = (samples // config.batch_size, config.batch_size)
    return compile_update(config, loss, lambda batch, index: [c[index] for c in batch], shape)


def ppo_loss(
    config: PPOConfig, log_prob: Any, entropy: Any, values: Any, targets: tuple[Any, Any, Any], clip: Any
) -> tuple[Any, dict[str, Any]]:
    """PPO's loss (the module docstring's) of a minibatch; ``targets``: ``(old log-probs, advantages, returns)``."""
    _, jnp, _ = jax_modules()
    old_log_prob, adv, returns = targets
    if config.batch_size > 1:  # as SB3: a minibatch of one is left as it is
        adv = (adv - adv.mean()) / (adv.std(ddof=1) + 1e-8)
    log_ratio = log_prob - old_log_prob
    ratio = jnp.exp(log_ratio)
    policy_loss = -jnp.minimum(adv * ratio, adv * jnp.clip(ratio, 1 - clip, 1 + clip)).mean()
    value_loss = ((returns - values) ** 2).mean()
    total = policy_loss - config.ent_coef * entropy.mean() + config.vf_coef * value_loss
    return total, {
        "policy_gradient_loss": policy_loss,
        "value_loss": value_loss,
        "entropy_loss": -entropy.mean(),
        "approx_kl": ((ratio - 1) - log_ratio).mean(),
        "clip_fraction": (jnp.abs(ratio - 1) > clip).mean(),
    }


def compile_update(config: PPOConfig, loss: Any, select: Any, shape: tuple[int, int]) -> tuple[Any, Any]:
    """``(optimiser, update)`` of ``loss(params, minibatch, clip)``, one jitted call for all epochs and minibatches.

    ``select(batch, index)`` is the minibatch of ``index``, a row of an epoch's order cut to ``shape``
    (minibatches, units per minibatch). SB3's optimiser: Adam (eps 1e-5) after clipping by global norm.
    """
    jax, jnp, optax = jax_modules()
    optimizer = optax.inject_hyperparams(
        lambda learning_rate: optax.chain(
            optax.clip_by_global_norm(config.max_grad_norm), optax.adam(learning_rate, eps=1e-5)
        )
    )(learning_rate=config.learning_rate)

    @jax.jit
    def update(params: Any, opt_state: Any, orders: Any, batch: Any, lr: Any, clip: Any) -> Any:
        opt_state.hyperparams["learning_rate"] = lr

        def minibatch(carry: Any, index: Any) -> Any:
            params, opt_state = carry
            (_, stats), grads = jax.value_and_grad(loss, has_aux=True)(params, select(batch, index), clip)
            updates, opt_state = optimizer.update(grads, opt_state, params)
            return (optax.apply_updates(params, updates), opt_state), stats

        def epoch(carry: Any, order: Any) -> Any:
            return jax.lax.scan(minibatch, carry, order.reshape(shape))

        (params, opt_state), stats = jax.lax.scan(epoch, (params, opt_state), orders)
        return params, opt_state, jax.tree_util.tree_map(jnp.mean, stats)

    return optimizer, update


# --- 5. the loop ---------------------------------------------------------------------------


def make_vector_env(env_id: str, n_envs: int, env_kwargs: dict[str, Any] | None = None) -> gym.vector.VectorEnv:
    """``n_envs`` envs of ``env_id`` as one vector env that resets a finished env on the same step.

    A ``CoopGym/`` id gets coop_gym's batched env; any other, Gymnasium's ``SyncVectorEnv``.
    """
    same_step: dict[str, Any] = {"autoreset_mode": AutoresetMode.SAME_STEP}
    if env_id.startswith("CoopGym/"):
        return gym.make_vec(env_id, n_envs, "vector_entry_point", **{**same_step, **(env_kwargs or {})})
    return gym.make_vec(env_id, n_envs, "sync", vector_kwargs=same_step, **(env_kwargs or {}))


class PPO:
    """The learner: ``PPO(env_id, config, seed).learn(total_timesteps)``; :attr:`params` are the weights.

    ``on_rollout`` (given to :meth:`learn`) is called after each rollout with the learner; it
    returns False to stop. The episodes finished meanwhile: :meth:`take_episodes`.
    """

    def __init__(
        self, env_id: str, config: PPOConfig | None = None, seed: int = 0, env_kwargs: dict[str, Any] | None = None
    ) -> None:
        """Build the envs (seeded ``seed .. seed + n_envs - 1``), the network and the optimiser."""
        jax, _, _ = jax_modules()
        self.env_id, self.config, self.seed = env_id, config or PPOConfig(), int(seed)
        self.env_kwargs = dict(env_kwargs or {})
        cfg = self.config
        self.env = make_vector_env(env_id, cfg.n_envs, self.env_kwargs)
        space = self.env.single_action_space
        if isinstance(space, spaces.Discrete):
            self.nvec: tuple[int, ...] = (int(space.n),)
        elif isinstance(space, spaces.MultiDiscrete):
            self.nvec = tuple(int(n) for n in space.nvec)
        else:
            raise ValueError(f"PPO needs a Discrete or MultiDiscrete action space, got {space}")
        obs_shape = tuple(self.env.single_observation_space.shape or ())
        self.network = self._make_network()
        self.params = self.network.init(jax.random.PRNGKey(self.seed % 2**31), *self._example_inputs(obs_shape))
        self.optimizer, self._update = self._make_update()
        self.opt_state = self.optimizer.init(self.params)
        # Two streams from the seed: the actions' and the minibatches'.
        streams = np.random.PCG64(self.seed).spawn(2)
        self.rng, self.minibatch_rng = np.random.Generator(streams[0]), np.random.Generator(streams[1])
        self.normalizer = ObsNormalizer(obs_shape) if cfg.normalize_obs else None
        self.num_timesteps, self.stats = 0, dict[str, float]()
        self.learning_rate = cfg.learning_rate
        """The learning rate of the last update."""
        self._finished: list[tuple[np.ndarray, ...]] = []
        self._act_with(self.params)
        self._pending: Any = None
        self._started = time.time()
        self._discrete = isinstance(space, spaces.Discrete)
        self._env_step = self._step_rows if hasattr(self.env, "step_rows") else self._step_infos
        raw, _ = self.env.reset(seed=[self.seed + i for i in range(cfg.n_envs)])  # type: ignore[arg-type]
        self._obs = self._observe(raw)
        self._starts = np.ones(cfg.n_envs, dtype=np.float32)
        self._returns, self._lengths = np.zeros(cfg.n_envs), np.zeros(cfg.n_envs, dtype=np.int64)

    def _make_network(self) -> Any:
        from agents.ppo.networks import ActorCritic

        return ActorCritic(self.nvec, self.config.hidden, self.config.activation)

    def _example_inputs(self, obs_shape: tuple[int, ...]) -> tuple[np.ndarray, ...]:
        """What the network's initialisation is called with."""
        return (np.zeros((1, *obs_shape), np.float32),)

    def _make_update(self) -> tuple[Any, Any]:
        return make_update(self.network, self.config, self.nvec, self.config.n_envs * self.config.n_steps)

    def _policy(self, params: Any) -> Any:
        """The rollout's NumPy policy over ``params``."""
        return NumpyPolicy(params, self.nvec, self.config.activation)

    def _observe(self, raw: np.ndarray) -> np.ndarray:
        """The policy's input: ``raw`` scaled by the statistics (which take it in first)."""
        if self.normalizer is None:
            return np.asarray(raw, dtype=np.float32)
        self.normalizer.update(raw)
        return self.normalizer(raw)

    def _step_rows(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Any]:
        """One step of coop_gym's vector env, no info dicts built: ``(obs, rewards, terminated, truncated, final)``.

        ``final``: None, or ``(done, final observations, outcome codes)`` where episodes ended.
        """
        obs, rewards, terminated, truncated, final = self.env.step_rows(actions)  # type: ignore[attr-defined]
        if final is not None:
            final = (final[0], final[1], final[2][:, REPORT.outcome])
        return obs, rewards, terminated, truncated, final

    def _step_infos(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Any]:
        """:meth:`_step_rows` on any vector env that resets on the same step, from its infos."""
        obs, rewards, terminated, truncated, infos = self.env.step(actions)
        done = np.logical_or(terminated, truncated)
        if not done.any():
            return obs, rewards, terminated, truncated, None
        final_obs = np.stack([infos["final_obs"][i] if d else obs[i] for i, d in enumerate(done)])
        outcomes = infos["final_info"].get("outcome_code", np.zeros(len(done), np.int64))
        return obs, rewards, terminated, truncated, (done, final_obs, outcomes)

    def _record(self, final: Any) -> None:
        """Keep the episodes that just ended (:meth:`take_episodes`)."""
        done, _, outcomes = final
        now = np.full(int(done.sum()), time.time() - self._started)
        self._finished.append((self._returns[done], self._lengths[done], now, outcomes[done].astype(np.int64)))
        self._returns[done], self._lengths[done] = 0.0, 0

    def take_episodes(self) -> dict[str, np.ndarray]:
        """The episodes finished since the last call: ``{"r", "l", "t", "outcome"}`` arrays, in the order they ended.

        ``r`` return, ``l`` length, ``t`` seconds since the learner was built (SB3's monitor
        columns), ``outcome`` the code of :class:`coop_gym.envs.config.Outcome` (0 where the env
        gives none).
        """
        chunks, self._finished = self._finished, []
        columns = list(zip(*chunks, strict=False)) or [
            [np.zeros(0)],
            [np.zeros(0, np.int64)],
            [np.zeros(0)],
            [np.zeros(0, np.int64)],
        ]
        return {name: np.concatenate(column) for name, column in zip(("r", "l", "t", "outcome"), columns, strict=True)}

    def rollout(self) -> Rollout:
        """``n_steps`` steps of every env with the acting weights."""
        cfg, step, memory = self.config, self._env_step, self._memory()
        shape = (cfg.n_steps, cfg.n_envs)
        obs = np.zeros((*shape, *self._obs.shape[1:]), np.float32)
        actions = np.zeros((*shape, len(self.nvec)), np.int64)
        log_probs, values, rewards, starts = (np.zeros(shape, np.float32) for _ in range(4))
        for t in range(cfg.n_steps):
            obs[t], starts[t] = self._obs, self._starts
            actions[t], log_probs[t], values[t] = self._act(self._obs, self._starts)
            raw, reward, terminated, truncated, final = step(actions[t, :, 0] if self._discrete else actions[t])
            self._obs = self._observe(raw)
            self._returns += reward
            self._lengths += 1
            rewards[t] = reward
            if final is not None:
                cut = truncated & ~terminated
                if cut.any():  # a time-limit end: bootstrap from the final observation
                    final_obs = self.normalizer(final[1][cut]) if self.normalizer else final[1][cut]
                    rewards[t, cut] += cfg.gamma * self._final_values(final_obs, cut)
                self._record(final)
            self._starts = final[0].astype(np.float32) if final is not None else np.zeros(cfg.n_envs, np.float32)
        self.num_timesteps += cfg.n_steps * cfg.n_envs
        last_values = self._last_values().astype(np.float32)
        return Rollout(obs, actions, log_probs, values, rewards, starts, last_values, self._starts.copy(), memory)

    # The MLP policy's step and values; a recurrent learner carries its LSTM states through them.

    def _act(self, obs: np.ndarray, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(actions, log pi(a|s), V(s))`` of a step (``starts``: 1 where ``obs`` begins an episode)."""
        return self._acting.act(obs, self.rng)  # type: ignore[no-any-return]

    def _final_values(self, final_obs: np.ndarray, cut: np.ndarray) -> np.ndarray:
        """V of the final observations of the envs ``cut`` (a mask), which just hit their time limit."""
        return self._acting.value(final_obs)  # type: ignore[no-any-return]

    def _last_values(self) -> np.ndarray:
        """V of the observations after the rollout."""
        return self._acting.value(self._obs)  # type: ignore[no-any-return]

    def _memory(self) -> tuple[np.ndarray, ...]:
        """What the policy carries between steps, as the rollout begins (none for the MLP)."""
        return ()

    def update(self, rollout: Rollout, progress_remaining: float) -> None:
        """Start one PPO update on ``rollout``; with ``policy_lag=0`` wait for it and act with its weights."""
        cfg = self.config
        batch, units = self._batch(rollout)
        lr = cfg.learning_rate * (progress_remaining if cfg.anneal_lr else 1.0)
        self.learning_rate = lr
        orders = np.stack([self.minibatch_rng.permutation(units) for _ in range(cfg.n_epochs)]).astype(np.int32)
        self._land()
        self._pending = self._update(self.params, self.opt_state, orders, batch, lr, cfg.clip_range)
        if cfg.policy_lag == 0:
            self._land()

    def _batch(self, rollout: Rollout) -> tuple[list[Any], int]:
        """``(what the update reads, how many units its minibatches are drawn from)``: one row per sample."""
        adv, returns = advantages(rollout, self.config.gamma, self.config.gae_lambda)
        flat = lambda x: x.reshape(-1, *x.shape[2:])  # noqa: E731
        batch = [flat(rollout.obs), flat(rollout.actions), flat(rollout.log_probs), flat(adv), flat(returns)]
        return batch, len(batch[0])

    def set_params(self, params: Any) -> None:
        """Take ``params`` (the network's tree) as the weights, and act with them."""
        jax, _, _ = jax_modules()
        self._land()
        self.params = jax.tree_util.tree_map(jax.numpy.asarray, params)
        self._act_with(self.params)

    @property
    def acting_params(self) -> Any:
        """The weights the next rollout plays (with ``policy_lag=1``, those before the update in flight)."""
        return self._acting_params

    def _act_with(self, params: Any) -> None:
        """The rollout plays ``params`` from now on."""
        self._acting_params = params
        self._acting = self._policy(params)

    def wait_for_update(self) -> None:
        """Wait until the update in flight (``policy_lag``) has finished, without landing it: nothing changes.

        For a clock that should count the update's time where it ran.
        """
        if self._pending is not None:
            jax, _, _ = jax_modules()
            jax.block_until_ready(self._pending)

    def _land(self) -> None:
        """Wait for the update in flight; its weights become the learner's and the rollout's."""
        if self._pending is None:
            return
        self.params, self.opt_state, stats = self._pending
        self._pending = None
        self.stats = {name: float(value) for name, value in stats.items()}
        self._act_with(self.params)

    def learn(self, total_timesteps: int, on_rollout: Callable[[PPO], bool] | None = None) -> PPO:
        """Train in whole rollouts until :attr:`num_timesteps` reaches ``total_timesteps``, the run's length.

        The learning rate falls over the run's length, so a learner restored at step ``k``
        (:meth:`state` / :meth:`restore`) continues exactly as the unbroken run. The last update
        lands before this returns.
        """
        while self.num_timesteps < total_timesteps:
            rollout = self.rollout()
            self.update(rollout, 1.0 - self.num_timesteps / total_timesteps)
            if on_rollout is not None and not on_rollout(self):
                break
        self._land()
        return self

    # --- 6. checkpoints ----------------------------------------------------------------------

    def state(self) -> dict[str, Any]:
        """Everything the run needs to continue exactly, as NumPy and plain Python (picklable).

        An update still in flight (``policy_lag``) is waited for and kept as such: the restored
        learner lands it where the unbroken run would have.
        """
        jax, _, _ = jax_modules()
        as_numpy = functools.partial(jax.tree_util.tree_map, np.asarray)
        pending = None
        if self._pending is not None:
            params, opt_state, stats = self._pending
            pending = (as_numpy(params), jax.tree_util.tree_leaves(as_numpy(opt_state)), as_numpy(stats))
        norm = self.normalizer
        return {
            "num_timesteps": self.num_timesteps,
            "params": as_numpy(self.params),
            "opt_state": jax.tree_util.tree_leaves(as_numpy(self.opt_state)),
            "pending": pending,
            "acting_params": as_numpy(self._acting_params),
            "stats": dict(self.stats),
            "rng": [self.rng.bit_generator.state, self.minibatch_rng.bit_generator.state],
            "normalizer": None if norm is None else {"count": norm.count, "sum": norm.sum, "sum_sq": norm.sum_sq},
            "env": pickle.dumps(self.env),
            "episode": {"obs": self._obs, "starts": self._starts, "returns": self._returns, "lengths": self._lengths},
            "elapsed_s": time.time() - self._started,
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`state` (taken from a learner of the same id, settings and seed)."""
        jax, jnp, _ = jax_modules()
        treedef = jax.tree_util.tree_structure(self.opt_state)

        def opt_state(leaves: list[np.ndarray]) -> Any:
            return jax.tree_util.tree_unflatten(treedef, [jnp.asarray(leaf) for leaf in leaves])

        self.num_timesteps = int(state["num_timesteps"])
        self.params = jax.tree_util.tree_map(jnp.asarray, state["params"])
        self.opt_state = opt_state(state["opt_state"])
        self._pending = None
        if state["pending"] is not None:
            params, leaves, stats = state["pending"]
            self._pending = (jax.tree_util.tree_map(jnp.asarray, params), opt_state(leaves), stats)
        self._act_with(jax.tree_util.tree_map(jnp.asarray, state["acting_params"]))
        self.stats = dict(state["stats"])
        self.rng.bit_generator.state, self.minibatch_rng.bit_generator.state = state["rng"]
        if self.normalizer is not None and state["normalizer"] is not None:
            saved = state["normalizer"]
            self.normalizer.count = saved["count"]
            self.normalizer.sum, self.normalizer.sum_sq = saved["sum"].copy(), saved["sum_sq"].copy()
            self.normalizer.update(np.zeros((0, *self.normalizer.sum.shape)))  # the mean and variance of the sums
        self.env.close()
        self.env = pickle.loads(state["env"])
        self._env_step = self._step_rows if hasattr(self.env, "step_rows") else self._step_infos
        episode = state["episode"]
        self._obs, self._starts = episode["obs"].copy(), episode["starts"].copy()
        self._returns, self._lengths = episode["returns"].copy(), episode["lengths"].copy()
        self._started = time.time() - float(state["elapsed_s"])
        self._finished = []
