"""Registered env ids: one per observation mode, action type, estimator and persona set."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from coop_gym.model.params import Timing

__all__ = ["ENV_IDS", "HARD_ENV_ID", "LEVEL_ENV_IDS", "register_envs", "unit_twin"]

MAX_EPISODE_STEPS = Timing().max_episode_steps
"""30 s at one action per 0.1 s: the episode length of every registered id on its default timing.

The ids register no ``TimeLimit``: each env ends its episodes at their own length
(``timing.max_episode_steps``, truncated with outcome ``"timeout"``), so a custom ``timing`` gives the
length it asks for. A
``TimeLimit`` of 300 steps would cut a 60 s episode in half. ``env.spec.max_episode_steps`` still
reports the length of the env's own timing (``SitToStandEnv.spec``), for clients that read it.
``gym.make(id, max_episode_steps=n)`` adds a ``TimeLimit`` of ``n`` steps as usual.
"""

# id -> keywords of the env (coop_gym.envs.contract.EnvArguments: the single and the vector env take them)
ENV_IDS: dict[str, dict[str, Any]] = {
    "CoopGym/SitToStand-v0": {},
    "CoopGym/SitToStandRaw-v0": {"observation_mode": "raw"},
    "CoopGym/SitToStandOracle-v0": {"observation_mode": "oracle"},
    "CoopGym/SitToStandDiscrete-v0": {"action_type": "discrete"},
    "CoopGym/SitToStandContinuous-v0": {"action_type": "continuous"},
    "CoopGym/SitToStandMM-v0": {"estimator": "multiple_model"},
    "CoopGym/SitToStandIMM-v0": {"estimator": "imm"},
    "CoopGym/SitToStandHeldOut-v0": {"personas": "test"},
    # v1: difficulty levels (coop_gym.model.difficulty) and the safety-priced reward.
    "CoopGym/SitToStandEasy-v1": {"difficulty": "easy"},
    "CoopGym/SitToStandMedium-v1": {"difficulty": "medium"},
    "CoopGym/SitToStandHard-v1": {"difficulty": "hard"},
    "CoopGym/SitToStandHardRaw-v1": {"difficulty": "hard", "observation_mode": "raw"},
    "CoopGym/SitToStandHardOracle-v1": {"difficulty": "hard", "observation_mode": "oracle"},
    "CoopGym/SitToStandHardDiscrete-v1": {"difficulty": "hard", "action_type": "discrete"},
    "CoopGym/SitToStandHardIMM-v1": {"difficulty": "hard", "estimator": "imm"},
    "CoopGym/SitToStandHardHeldOut-v1": {"difficulty": "hard", "personas": "test"},
    # v2: the hard-v2 level, two of hard's knobs changed (coop_gym.model.difficulty);
    # the variants that clients naming an env by id alone need (CleanRL's --env-id, RL Zoo, RLlib)
    # are ids, the others take it as difficulty="hard-v2".
    "CoopGym/SitToStandHard-v2": {"difficulty": "hard-v2"},
    "CoopGym/SitToStandHardDiscrete-v2": {"difficulty": "hard-v2", "action_type": "discrete"},
    "CoopGym/SitToStandHardHeldOut-v2": {"difficulty": "hard-v2", "personas": "test"},
    # Unit: the same tasks with every observation feature scaled to about [-1, 1]
    # (contract.FEATURE_SCALES), learnable with a library's default settings; the physical
    # values are in info["unscaled_obs"]. New names, not a -v2 of the same ones: Gymnasium's
    # make() warns that an id is "out of date" once a higher version of its name exists.
    "CoopGym/SitToStandUnit-v0": {"observation_scale": "unit"},
    "CoopGym/SitToStandDiscreteUnit-v0": {"observation_scale": "unit", "action_type": "discrete"},
    "CoopGym/SitToStandEasyUnit-v1": {"difficulty": "easy", "observation_scale": "unit"},
    "CoopGym/SitToStandMediumUnit-v1": {"difficulty": "medium", "observation_scale": "unit"},
    "CoopGym/SitToStandHardUnit-v1": {"difficulty": "hard", "observation_scale": "unit"},
    "CoopGym/SitToStandHardDiscreteUnit-v1": {
        "difficulty": "hard",
        "action_type": "discrete",
        "observation_scale": "unit",
    },
    "CoopGym/SitToStandHardHeldOutUnit-v1": {"difficulty": "hard", "personas": "test", "observation_scale": "unit"},
    "CoopGym/SitToStandHardUnit-v2": {"difficulty": "hard-v2", "observation_scale": "unit"},
    "CoopGym/SitToStandHardDiscreteUnit-v2": {
        "difficulty": "hard-v2",
        "action_type": "discrete",
        "observation_scale": "unit",
    },
    "CoopGym/SitToStandHardHeldOutUnit-v2": {
        "difficulty": "hard-v2",
        "personas": "test",
        "observation_scale": "unit",
    },
}

LEVEL_ENV_IDS: dict[str, str] = {
    "v0": "CoopGym/SitToStand-v0",
    **{kwargs["difficulty"]: env_id for env_id, kwargs in ENV_IDS.items() if kwargs.keys() == {"difficulty"}},
}
"""The id of each level (``v0``: the paper's model; then each difficulty by name), from :data:`ENV_IDS`."""

HARD_ENV_ID = LEVEL_ENV_IDS["hard-v2"]
"""The hard level's newest id: what ``train.py``, ``agents.tools.play``, ``agents.caregivers.reading`` and
``agents.tune.belief`` play by default."""


def unit_twin(env_id: str | None) -> str | None:
    """The id of the same task with physical observation features, for a unit-scaled id (None otherwise).

    Example:
        >>> unit_twin("CoopGym/SitToStandHardDiscreteUnit-v2")
        'CoopGym/SitToStandHardDiscrete-v2'
        >>> unit_twin("CoopGym/SitToStandHard-v2") is None
        True
    """
    kwargs = ENV_IDS.get(env_id or "", {})
    if kwargs.get("observation_scale") != "unit":
        return None
    physical = {k: v for k, v in kwargs.items() if k != "observation_scale"}
    return next((other for other, other_kwargs in ENV_IDS.items() if other_kwargs == physical), None)


def register_envs() -> None:
    """Register every id once (idempotent: re-importing registers nothing twice)."""
    for env_id, kwargs in ENV_IDS.items():
        if env_id in gym.registry:
            continue
        gym.register(
            id=env_id,
            entry_point="coop_gym.envs.sit_to_stand:SitToStandEnv",
            vector_entry_point="coop_gym.envs.vector:SitToStandVectorEnv",
            max_episode_steps=None,  # no TimeLimit: the env truncates at its length (see MAX_EPISODE_STEPS)
            kwargs=dict(kwargs),
        )
