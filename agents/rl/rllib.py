"""Ray RLlib PPO (new API stack) on the coop_gym envs: the way to scale training out.

* :func:`ppo_config` -- an RLlib ``PPOConfig`` mirroring the SB3 PPO defaults of
  :mod:`agents.hyperparams` (batch, minibatch, epochs, gamma, lambda, clip, entropy, net,
  the learning rate decaying linearly to 0, observations normalised by running mean/std,
  no KL penalty). Each env runner steps ``num_envs_per_env_runner`` envs through coop_gym's
  own batched vector env (``gymnasium.make_vec(..., vectorization_mode="vector_entry_point")``).
  RLlib's sampler has a fixed cost per vector step (connectors, the module's forward pass,
  the action distribution) far above the env's own cost per env step, so
  :data:`DEFAULT_NUM_ENVS` envs share that fixed part, not SB3's 8.
  The env is named ``coop_gym:<id>``, so every Ray worker imports coop_gym (and so
  registers the ids) before it makes the env: bare ids fail in fresh workers.
* :func:`train` -- ``algo.train()`` until the env-step budget is spent, then a checkpoint.
* :class:`RLlibAgent` / :func:`load_rllib_agent` -- the trained RLModule behind SB3's
  ``predict(obs, state, episode_start, deterministic) -> (actions, state)``, behind the
  observation normaliser it trained with (:class:`agents.rl.normalize.ObsNormalizer`, shared
  with the SB3 agents), so :func:`agents.evaluate.evaluate` scores it on the same seeded
  episodes as every agent.

What ``python train.py --framework rllib`` does with them is :mod:`agents.trainer.rllib_run`.

Ray starts a local instance by default (``num_env_runners + 1`` CPUs); ``address``
(``"ray://head:10001"`` or ``"auto"``) joins an existing cluster instead, whose nodes
must have coop_gym installed. torch and ray are imported only in this module.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from numpy.typing import NDArray
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.connectors.env_to_module import MeanStdFilter
from ray.rllib.core import (
    COMPONENT_ENV_RUNNER,
    COMPONENT_ENV_TO_MODULE_CONNECTOR,
    COMPONENT_LEARNER,
    COMPONENT_LEARNER_GROUP,
    COMPONENT_RL_MODULE,
    DEFAULT_MODULE_ID,
    Columns,
)
from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
from ray.rllib.core.rl_module.rl_module import RLModule
from ray.rllib.utils.filter import RunningStat
from ray.rllib.utils.metrics import ENV_RUNNER_RESULTS, EPISODE_RETURN_MEAN, NUM_ENV_STEPS_SAMPLED_LIFETIME
from ray.rllib.utils.numpy import SMALL_NUMBER

import coop_gym
from agents.hyperparams import hyperparams_for
from agents.rl.normalize import ObsNormalizer
from agents.run_folder import AGENT_FILE, RLLIB_CHECKPOINT_DIR, RLLIB_FRAMEWORK, is_rllib_run

__all__ = [
    "CHECKPOINT_DIR",
    "DEFAULT_NUM_ENVS",
    "FRAMEWORK",
    "RLlibAgent",
    "envs_per_runner",
    "filter_normalizer",
    "is_rllib_run",
    "load_rllib_agent",
    "ppo_config",
    "train",
]

FRAMEWORK = RLLIB_FRAMEWORK
CHECKPOINT_DIR = RLLIB_CHECKPOINT_DIR
DEFAULT_NUM_ENVS = 64
"""Envs sampled in all (split over the env runners) when ``--n-envs`` is not given.

Sampling throughput rises with the envs per runner while they share the sampler's fixed
cost per vector step, then falls once one iteration's fragments grow too short; 64 was the
best count measured. Measure it on a machine with ``python train.py --framework rllib
--n-envs N --timesteps 40000`` (every iteration prints its env steps/s). With the
4096-step batch, 64 envs sample 64-step fragments (SB3: 8 x 512); GAE bootstraps the cut
episodes from the value function.
"""
OBS_CLIP = 10.0
"""Normalised observations are clipped to +-this (SB3 ``VecNormalize``'s ``clip_obs``)."""


def envs_per_runner(n_envs: int | None, num_env_runners: int) -> int:
    """Envs in each env runner: ``n_envs`` (default :data:`DEFAULT_NUM_ENVS`) split over the runners.

    ``num_env_runners=0`` samples in the driver, which then steps all of them.
    """
    total = DEFAULT_NUM_ENVS if n_envs is None else n_envs
    return max(1, total // max(1, num_env_runners))


def _module_prefixed(env_id: str) -> str:
    """``coop_gym:<id>``: gymnasium imports coop_gym (registering the ids) in each worker first."""
    return env_id if ":" in env_id else f"coop_gym:{env_id}"


def _sb3_ppo_training(sb3: Any, timesteps: int | None) -> dict[str, Any]:
    """``PPOConfig.training`` arguments equal to SB3 PPO's hyperparameters (``sb3``: its TrainingConfig)."""
    kw = dict(sb3.algo_kwargs)
    learning_rate = str(kw["learning_rate"])
    lr_start = float(learning_rate.removeprefix("lin_"))
    # SB3's "lin_3e-4" decays to 0 over the budget; RLlib's piecewise-linear schedule counts
    # sampled env steps, so it needs the budget (without one the rate stays at its start).
    lr: float | list[list[float]] = lr_start
    if learning_rate.startswith("lin_") and timesteps is not None:
        if timesteps < 1:
            raise ValueError(f"timesteps must be a positive int, got {timesteps!r}")
        lr = [[0, lr_start], [int(timesteps), 0.0]]
    return {
        # One SB3 rollout (n_envs x n_steps) is one RLlib train batch.
        "train_batch_size_per_learner": int(kw["n_steps"]) * sb3.n_envs,
        "minibatch_size": int(kw["batch_size"]),
        "num_epochs": int(kw["n_epochs"]),
        "lr": lr,
        "gamma": float(kw["gamma"]),
        "lambda_": float(kw["gae_lambda"]),
        "clip_param": float(kw["clip_range"]),
        "entropy_coeff": float(kw["ent_coef"]),
        "vf_loss_coeff": float(kw["vf_coef"]),
        "grad_clip": float(kw["max_grad_norm"]),
        "grad_clip_by": "global_norm",
        # SB3 does not clip the value loss; RLlib's default clip (10) would bind on returns of -2..1 rarely.
        "vf_clip_param": float("inf"),
        # SB3's PPO has only the clipped objective; RLlib adds a KL penalty (0.2) by default.
        "use_kl_loss": False,
    }


def ppo_config(
    env_id: str,
    *,
    seed: int = 0,
    num_env_runners: int = 2,
    num_envs_per_env_runner: int = 4,
    personas: str = "train",
    env_kwargs: dict[str, Any] | None = None,
    timesteps: int | None = None,
) -> PPOConfig:
    """RLlib PPO on the new API stack, with the SB3 PPO defaults of :mod:`agents.hyperparams`.

    Args:
        env_id: Registered coop_gym id (bare or ``coop_gym:``-prefixed).
        seed: Seed of the env runners and the network initialisation.
        num_env_runners: Remote sampling actors (0: sample in the driver).
        num_envs_per_env_runner: Envs batched inside each runner (one vector env).
        personas: Persona set trained on (never ``"test"``).
        env_kwargs: Extra env kwargs.
        timesteps: Training budget [env steps]: the learning rate decays linearly from its
            start value to 0 over it, as SB3's ``"lin_3e-4"``; None keeps it constant.

    Returns:
        The config (``.build_algo()`` makes the algorithm).
    """
    if env_id.removeprefix("coop_gym:") not in coop_gym.ENV_IDS:
        raise ValueError(f"env_id must be a coop_gym id ({', '.join(coop_gym.ENV_IDS)}), got {env_id!r}")
    sb3 = hyperparams_for("ppo")
    return (
        PPOConfig()
        .environment(_module_prefixed(env_id), env_config={"personas": personas, **(env_kwargs or {})})
        .env_runners(
            num_env_runners=num_env_runners,
            num_envs_per_env_runner=num_envs_per_env_runner,
            gym_env_vectorize_mode=gym.VectorizeMode.VECTOR_ENTRY_POINT,
            num_cpus_per_env_runner=1,
            # RLlib's default 60 s sampling timeout drops whole batches when the machine is busy
            # (iterations of 0 env steps, forever); wait for the samples instead.
            sample_timeout_s=None,
            # SB3's VecNormalize (normalize=True in agents.hyperparams): running mean/std of
            # the observations, clipped to +-10; the runners' statistics are merged after every
            # iteration and saved in the checkpoint, where RLlibAgent reads them.
            env_to_module_connector=(
                (lambda env, spaces, device: MeanStdFilter(clip_by_value=OBS_CLIP)) if sb3.normalize else None
            ),
        )
        .learners(num_learners=0)  # the learner runs in the driver process, on CPU
        .training(**_sb3_ppo_training(sb3, timesteps))
        .rl_module(
            model_config=DefaultModelConfig(
                fcnet_hiddens=list(sb3.policy_kwargs.get("net_arch", [64, 64])),
                fcnet_activation="tanh",  # SB3's MlpPolicy activation
                vf_share_layers=False,
            )
        )
        .debugging(seed=seed, log_level="ERROR")
    )


def _env_steps(result: dict[str, Any]) -> int:
    return int(result.get(ENV_RUNNER_RESULTS, {}).get(NUM_ENV_STEPS_SAMPLED_LIFETIME, 0))


def train(config: PPOConfig, timesteps: int, checkpoint_dir: str | Path, *, verbose: bool = True) -> dict[str, Any]:
    """Build the algorithm, train until ``timesteps`` env steps are sampled, save a checkpoint.

    Ray must already be initialised (``ray.init``); the algorithm is stopped on return.

    Returns:
        ``timesteps`` (sampled), ``iterations``, ``wall_time_s``, ``steps_per_s`` and the
        per-iteration ``history`` (env steps, mean training return).
    """
    algo = config.build_algo()
    history: list[dict[str, Any]] = []
    started = time.perf_counter()
    steps = 0
    try:
        while steps < timesteps:
            result = algo.train()
            if _env_steps(result) <= steps:
                raise RuntimeError(f"RLlib iteration {len(history) + 1} sampled no env steps (env runners failing?)")
            steps = _env_steps(result)
            episode_return = result.get(ENV_RUNNER_RESULTS, {}).get(EPISODE_RETURN_MEAN)
            history.append({"timesteps": steps, "episode_return_mean": episode_return})
            if verbose:
                shown = "n/a" if episode_return is None else f"{episode_return:+.3f}"
                rate = steps / (time.perf_counter() - started)
                print(f"iteration {len(history)}: {steps} env steps, mean return {shown}, {rate:.0f} steps/s")
        wall = time.perf_counter() - started
        algo.save_to_path(str(Path(checkpoint_dir).resolve()))
    finally:
        algo.stop()
    return {
        "timesteps": steps,
        "iterations": len(history),
        "wall_time_s": wall,
        "steps_per_s": steps / wall if wall > 0 else None,
        "history": history,
    }


def filter_normalizer(state: dict[Any, Any]) -> ObsNormalizer:
    """The normaliser of ``MeanStdFilter.get_state()`` of a single-agent pipeline, frozen (no update).

    The same arithmetic as ``ray.rllib.utils.filter.MeanStdFilter`` with ``update=False``:
    ``clip((obs - mean) / (std + SMALL_NUMBER), +-clip)``.
    """
    (agent_state,) = state.values()
    (stats,) = agent_state["running_stats"]
    running = RunningStat.from_state(stats)
    return ObsNormalizer.from_mean_std(running.mean, running.std, agent_state["clip_by_value"], SMALL_NUMBER)


class RLlibAgent:
    """A trained RLlib RLModule behind SB3's ``predict`` protocol (no Ray instance needed).

    Args:
        module: The torch RLModule (PPO's default MLP).
        env_id: Env id it was trained on (None if unknown).
        normalizer: The observation filter it was trained behind (None: raw observations).
    """

    def __init__(self, module: RLModule, env_id: str | None = None, normalizer: ObsNormalizer | None = None) -> None:
        """Wrap the module; actions are drawn from its inference distribution."""
        self.module = module
        self.env_id = env_id
        self.normalizer = normalizer
        self.name = "rllib_ppo"
        self.observation_space = module.observation_space
        self.action_space = module.action_space
        self._dist_cls = module.get_inference_action_dist_cls()

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[NDArray[Any], Any]:
        """Actions for a batch (or a single) observation; the MLP keeps no state, so ``state`` stays None."""
        obs = np.asarray(observation, dtype=np.float32)
        single = obs.ndim == 1
        batch = obs[None] if single else obs
        if self.normalizer is not None:
            batch = self.normalizer(batch)
        with torch.no_grad():
            out = self.module.forward_inference({Columns.OBS: torch.from_numpy(batch)})
            dist = self._dist_cls.from_logits(out[Columns.ACTION_DIST_INPUTS])
            if deterministic:
                dist = dist.to_deterministic()
            actions = dist.sample().cpu().numpy()
        if isinstance(self.action_space, gym.spaces.Box):
            actions = np.clip(actions, self.action_space.low, self.action_space.high).astype(np.float32)
        else:
            actions = actions.astype(np.int64)
        return (actions[0] if single else actions), None


def _module_path(checkpoint: Path) -> Path:
    """The RLModule inside an algorithm checkpoint (``learner_group/learner/rl_module/default_policy``)."""
    return checkpoint / COMPONENT_LEARNER_GROUP / COMPONENT_LEARNER / COMPONENT_RL_MODULE / DEFAULT_MODULE_ID


def _filter_path(checkpoint: Path) -> Path:
    """The MeanStdFilter inside an algorithm checkpoint (``env_runner/env_to_module_connector/MeanStdFilter``)."""
    return checkpoint / COMPONENT_ENV_RUNNER / COMPONENT_ENV_TO_MODULE_CONNECTOR / MeanStdFilter.__name__


def load_rllib_agent(path: str | Path) -> RLlibAgent:
    """Load the agent of an RLlib run folder, its ``checkpoint/``, or any RLlib algorithm checkpoint."""
    path = Path(path)
    folder = path.parent if path.name == CHECKPOINT_DIR else path
    info_file = folder / AGENT_FILE
    info = json.loads(info_file.read_text()) if info_file.exists() else {}
    checkpoint = folder / info["checkpoint"] if info.get("checkpoint") else path
    module_path = _module_path(checkpoint)
    if not module_path.exists():
        raise FileNotFoundError(f"no RLlib RLModule checkpoint at {module_path}")
    module = RLModule.from_checkpoint(str(module_path.resolve()))
    # A checkpoint trained behind the filter has its statistics; one without it saw raw observations.
    filter_path = _filter_path(checkpoint)
    normalizer = None
    if filter_path.exists():
        # from_checkpoint cannot rebuild the filter (its spaces are not saved): restore into one of
        # the module's shape (given after construction: the constructor cannot take it, RLlib 2.60).
        trained_filter = MeanStdFilter()
        trained_filter.input_observation_space = module.observation_space
        trained_filter.restore_from_path(str(filter_path.resolve()))
        normalizer = filter_normalizer(trained_filter.get_state())
    return RLlibAgent(module, info.get("env_id"), normalizer)
