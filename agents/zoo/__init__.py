r"""RL Baselines3 Zoo's hyperparameters for the coop_gym ids, as a module RL Zoo's ``-conf`` imports.

    python -m rl_zoo3.train --algo ppo --env CoopGym/SitToStandHard-v2 --gym-packages coop_gym \\
        -conf agents.zoo.ppo --num-threads 1 -f logs/

RL Zoo's ``-conf`` takes a YAML file or the name of a module holding a dict ``hyperparams``
keyed by env id (``rl_zoo3.exp_manager.ExpManager.read_hyperparameters``); a module name works
from any folder once coop_gym is installed. :mod:`agents.zoo.ppo`, :mod:`agents.zoo.ppo_lstm` and
:mod:`agents.zoo.dqn` hold :func:`zoo_hyperparams` of their algorithm: the ids of
:data:`agents.hyperparams.HYPERPARAMS` (the same entries as the generated
``agents/zoo/*.yml``) and, for PPO, every hard id a policy is trained on (the held-out ids score,
they are not trained on), each with the hard level's settings (:func:`hyperparams_for`).
"""

from __future__ import annotations

from typing import Any

from agents.hyperparams import HYPERPARAMS, ZOO_ALGO_NAMES, TrainingConfig, hyperparams_for
from coop_gym.registration import ENV_IDS

__all__ = ["HARD_TRAINING_IDS", "zoo_entry", "zoo_hyperparams"]

HARD_TRAINING_IDS: tuple[str, ...] = tuple(
    env_id
    for env_id, kwargs in ENV_IDS.items()
    if str(kwargs.get("difficulty", "")).startswith("hard") and kwargs.get("personas") != "test"
)
"""The hard ids a policy is trained on (``-v1`` and ``-v2``, every observation, action and scale)."""


def zoo_entry(config: TrainingConfig) -> dict[str, Any]:
    """One env's entry in RL Zoo's hyperparameter dict: the keys of a YAML entry, as Python values."""
    entry: dict[str, Any] = {
        "n_envs": config.n_envs,
        "n_timesteps": config.total_timesteps,
        "policy": config.policy,
        "env_kwargs": {"personas": config.personas},
        **config.algo_kwargs,
    }
    if config.normalize:
        entry["normalize"] = {"norm_obs": True, "norm_reward": False}
    if config.policy_kwargs:
        entry["policy_kwargs"] = dict(config.policy_kwargs)
    return entry


def zoo_hyperparams(algo: str) -> dict[str, dict[str, Any]]:
    """RL Zoo's ``hyperparams`` dict of ``algo`` (a name of :data:`ZOO_ALGO_NAMES`' keys), keyed by env id.

    Example:
        >>> hyperparams = zoo_hyperparams("ppo")
        >>> hyperparams["CoopGym/SitToStandHardDiscreteUnit-v2"]["ent_coef"]
        0.02
    """
    if algo not in ZOO_ALGO_NAMES:
        raise ValueError(f"unknown algorithm {algo!r}; known: {', '.join(ZOO_ALGO_NAMES)}")
    env_ids = [*HYPERPARAMS[algo], *(HARD_TRAINING_IDS if algo == "ppo" else ())]
    return {env_id: zoo_entry(hyperparams_for(algo, env_id)) for env_id in dict.fromkeys(env_ids)}
