"""Building what SB3 trains: the training ``VecEnv`` and the algorithm with the project's defaults.

* :func:`make_train_env` -- ``n_envs`` envs seeded ``seed, seed + 1, ...`` through the
  batched env's SB3 adapter (:mod:`agents.rl.sb3_vec`) or SB3's ``DummyVecEnv`` of single envs
  (the same episodes), with episode statistics (``VecMonitor``) and optional observation
  normalisation (``VecNormalize``).
* :func:`make_model` -- PPO, RecurrentPPO or DQN with the hyperparameters of
  :mod:`agents.hyperparams` (RL Zoo's ``lin_<value>`` schedules become :class:`LinearDecay`).
* :func:`sb3_settings` -- the same settings for an SB3 user's own script: the constructor's
  keyword arguments as a dict, and the env wrappers they were tuned with, named.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
from stable_baselines3 import DQN, PPO
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecFrameStack, VecMonitor, VecNormalize

import coop_gym  # noqa: F401 -- registers the env ids
from agents.hyperparams import ALGORITHMS, TrainingConfig, hyperparams_for
from agents.rl.sb3_vec import make_sb3_vec_env
from coop_gym.cli import SEED_LIMIT
from estimator.validate import check_integer

__all__ = [
    "VEC_NORMALIZE_KWARGS",
    "LinearDecay",
    "SB3Settings",
    "algorithm_class",
    "find_frame_stack",
    "find_vec_normalize",
    "make_model",
    "make_train_env",
    "observation_features",
    "sb3_settings",
]

VEC_NORMALIZE_KWARGS: dict[str, Any] = {"norm_obs": True, "norm_reward": False}
"""``VecNormalize``'s keyword arguments wherever a setting says ``normalize``: observations by a
running mean and std, rewards left alone (they are already O(1))."""


def algorithm_class(algo: str) -> type[BaseAlgorithm]:
    """The SB3 class of an algorithm name (:data:`agents.hyperparams.ALGORITHMS`): what trains and loads it.

    A model of the JAX learner (``framework="jax"``, :mod:`agents.ppo`) is saved as SB3's PPO or
    sb3-contrib's RecurrentPPO, so this class loads it too.
    """
    if algo == "ppo":
        return PPO
    if algo == "dqn":
        return DQN
    if algo == "recurrent_ppo":
        from sb3_contrib import RecurrentPPO

        return RecurrentPPO  # type: ignore[no-any-return]
    raise ValueError(f"unknown algorithm {algo!r}; known: {', '.join(ALGORITHMS)}")


def make_train_env(
    env_id: str,
    n_envs: int,
    seed: int,
    *,
    personas: str = "train",
    normalize: bool = False,
    monitor_file: str | Path | None = None,
    monitor_append: bool = False,
    env_kwargs: dict[str, Any] | None = None,
    backend: str = "auto",
) -> VecEnv:
    """The training ``VecEnv``: ``n_envs`` envs seeded ``seed, seed + 1, ...``.

    Args:
        env_id: Registered env id.
        n_envs: Parallel envs.
        seed: Seed of env 0.
        personas: Persona set (``"train"`` by default; never train on ``"test"``).
        normalize: Wrap in ``VecNormalize`` (observations only).
        monitor_file: Write SB3's ``monitor.csv`` episode log here (for learning curves).
        monitor_append: Append to an existing ``monitor_file`` (a resumed run) instead of replacing it.
        env_kwargs: Extra env kwargs.
        backend: ``"batched"`` or ``"auto"`` (the native vector env through
            :mod:`agents.rl.sb3_vec`), ``"dummy"`` (SB3 ``DummyVecEnv`` of single envs).

    Returns:
        The ``VecEnv`` (``VecMonitor``-wrapped; ``VecNormalize`` outermost if asked).
    """
    check_integer("n_envs", n_envs, 1, SEED_LIMIT)  # envs are seeded seed .. seed + n_envs - 1
    if backend not in ("auto", "batched", "dummy"):
        raise ValueError(f"backend must be 'auto', 'batched' or 'dummy', got {backend!r}")
    kwargs = {"personas": personas, **(env_kwargs or {})}
    venv: VecEnv
    if backend == "dummy":
        venv = DummyVecEnv([_env_factory(env_id, kwargs) for _ in range(n_envs)])
        venv.seed(seed)
    else:
        # Training reads only finished episodes' infos (outcome, terminal observation, truncation).
        venv = make_sb3_vec_env(env_id, n_envs, seed, kwargs, step_infos="finished")
    filename = None
    if monitor_file is not None:
        Path(monitor_file).parent.mkdir(parents=True, exist_ok=True)
        filename = str(monitor_file)
    append = monitor_append and filename is not None and Path(str(filename)).exists()
    venv = VecMonitor(venv, filename=None if append else filename, info_keywords=("outcome",))
    if append:
        from stable_baselines3.common.monitor import ResultsWriter

        # VecMonitor always starts a new file; a resumed run keeps its episodes and adds rows.
        venv.results_writer = ResultsWriter(str(filename), extra_keys=("outcome",), override_existing=False)
    if normalize:
        venv = VecNormalize(venv, **VEC_NORMALIZE_KWARGS)
    return venv


def _env_factory(env_id: str, kwargs: dict[str, Any]) -> Callable[[], gym.Env[Any, Any]]:
    return lambda: gym.make(env_id, **kwargs)


class LinearDecay:
    """A value falling linearly from ``initial`` to 0 over training (RL Zoo's ``lin_<value>``).

    A class rather than a lambda so saved models pickle and load cleanly.
    """

    def __init__(self, initial: float) -> None:
        """Start at ``initial``."""
        self.initial = float(initial)

    def __call__(self, progress_remaining: float) -> float:
        """SB3 passes the fraction of training left (1 -> 0)."""
        return progress_remaining * self.initial

    def __repr__(self) -> str:
        """As RL Zoo writes it."""
        return f"lin_{self.initial:g}"


def _schedules(kwargs: dict[str, Any]) -> dict[str, Any]:
    """Turn RL Zoo schedule strings (``"lin_3e-4"``) into :class:`LinearDecay` objects."""
    out = dict(kwargs)
    for key in ("learning_rate", "clip_range", "clip_range_vf"):
        value = out.get(key)
        if isinstance(value, str):
            kind, _, number = value.partition("_")
            if kind != "lin":
                raise ValueError(f"{key}={value!r}: only linear schedules 'lin_<value>' are supported")
            out[key] = LinearDecay(float(number))
    return out


def make_model(
    config: TrainingConfig,
    env: VecEnv,
    seed: int,
    *,
    tensorboard_log: str | Path | None = None,
    verbose: int = 0,
    overrides: dict[str, Any] | None = None,
) -> BaseAlgorithm:
    """Build ``config.algo`` (SB3's class) on ``env`` with its settings plus ``overrides``.

    Raises:
        ValueError: a ``framework="jax"`` setting (its learner is :func:`agents.rl.ppo_run.make_learner`).
    """
    if config.framework != "sb3":
        raise ValueError(
            f"make_model builds SB3's classes; framework {config.framework!r} trains agents.ppo's learner "
            "(agents.rl.ppo_run.make_learner)"
        )
    cls = algorithm_class(config.algo)
    kwargs = _schedules(config.model_kwargs() | dict(overrides or {}))
    return cls(
        config.policy,
        env,
        seed=seed,
        verbose=verbose,
        device="cpu",
        tensorboard_log=str(tensorboard_log) if tensorboard_log is not None else None,
        **kwargs,
    )


@dataclass(frozen=True)
class SB3Settings:
    """The package's tuned settings for one env id, in the form an SB3 script takes them.

    Example:
        >>> from stable_baselines3 import PPO
        >>> settings = sb3_settings("CoopGym/SitToStandHard-v2")
        >>> settings.wrappers
        ('VecMonitor', 'VecNormalize')
        >>> env = settings.make_env(seed=0)  # n_envs envs on the training persona set, normalised
        >>> model = PPO(settings.policy, env, seed=0, **settings.hyperparams)
        >>> model.n_steps, model.n_envs
        (512, 8)
        >>> env.close()

    Attributes:
        env_id: Registered env id.
        algo: ``"ppo"``, ``"recurrent_ppo"`` or ``"dqn"`` (its class: :func:`algorithm_class`).
        policy: SB3 policy name.
        n_envs: Parallel training envs the settings were tuned with (``n_steps`` is per env).
        total_timesteps: Training budget [env steps].
        env_kwargs: ``gym.make`` keyword arguments of the training envs: the persona set.
        vec_normalize: ``VecNormalize`` keyword arguments (:data:`VEC_NORMALIZE_KWARGS`), or None
            where the settings train without it. The statistics are part of the trained agent:
            save them beside the model (or use :func:`agents.rl.save_agent`).
        hyperparams: The algorithm constructor's keyword arguments, ``policy_kwargs`` included
            and ``lin_<value>`` schedules as :class:`LinearDecay` callables.
    """

    env_id: str
    algo: str
    policy: str
    n_envs: int
    total_timesteps: int
    env_kwargs: dict[str, Any]
    vec_normalize: dict[str, Any] | None
    hyperparams: dict[str, Any]

    @property
    def wrappers(self) -> tuple[str, ...]:
        """The ``VecEnv`` wrappers of :meth:`make_env`, innermost first."""
        return ("VecMonitor", "VecNormalize") if self.vec_normalize is not None else ("VecMonitor",)

    def make_env(self, seed: int = 0) -> VecEnv:
        """The training ``VecEnv`` of these settings (:func:`make_train_env`): seeded envs, wrapped as named.

        SB3's own ``VecNormalize(make_vec_env(env_id, n_envs, seed, env_kwargs=env_kwargs),
        **vec_normalize)`` plays the same people, one single env at a time.
        """
        return make_train_env(
            self.env_id,
            self.n_envs,
            seed,
            personas=self.env_kwargs["personas"],
            normalize=self.vec_normalize is not None,
            env_kwargs={k: v for k, v in self.env_kwargs.items() if k != "personas"},
        )


def sb3_settings(env_id: str, algo: str = "ppo") -> SB3Settings:
    """The settings ``train.py --framework sb3`` trains ``algo`` with on ``env_id`` (:func:`hyperparams_for`).

    Raises:
        ValueError: unknown algorithm.
    """
    config = hyperparams_for(algo, env_id)
    return SB3Settings(
        env_id=env_id,
        algo=config.algo,
        policy=config.policy,
        n_envs=config.n_envs,
        total_timesteps=config.total_timesteps,
        env_kwargs={"personas": config.personas},
        vec_normalize=dict(VEC_NORMALIZE_KWARGS) if config.normalize else None,
        hyperparams=_schedules(config.model_kwargs()),
    )


def find_vec_normalize(env: VecEnv | None) -> VecNormalize | None:
    """The ``VecNormalize`` layer of a wrapped ``VecEnv`` (None if there is none)."""
    while env is not None:
        if isinstance(env, VecNormalize):
            return env
        env = getattr(env, "venv", None)
    return None


def find_frame_stack(env: VecEnv | None) -> int:
    """The frames a wrapped ``VecEnv`` stacks into one observation (its ``VecFrameStack``'s ``n_stack``; 1 if none)."""
    while env is not None:
        if isinstance(env, VecFrameStack):
            return int(env.stacked_obs.n_stack)
        env = getattr(env, "venv", None)
    return 1


def observation_features(env_id: str, env: VecEnv | None = None, env_kwargs: dict[str, Any] | None = None) -> list[str]:
    """The observation feature names of ``env`` (a training ``VecEnv``) or of a fresh ``env_id`` env.

    ``env_kwargs`` are passed to the fresh env (e.g. ``estimator="switching"`` adds its estimate).
    """
    from agents.base import features_of

    if env is not None:
        try:
            return [str(f) for f in env.get_attr("features", indices=[0])[0]]
        except (AttributeError, IndexError):
            pass
    single = gym.make(env_id, **(env_kwargs or {}))
    try:
        return list(features_of(single))
    finally:
        single.close()
