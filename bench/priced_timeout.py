"""A measurement aid, not an env version: hard-v2 with a timeout priced as a failed assistance.

On every coop_gym id a timeout costs only the time that passed (30 s x 0.01 = 0.3), less than a
premature lift (0.5), so a learner that has not yet found the person's mind can settle on never
lifting. Importing this module registers :data:`PRICED_ENV_ID`: ``CoopGym/SitToStandHardDiscreteUnit-v2``
(the id CleanRL's ``ppo.py`` takes) whose reward also subtracts :data:`TIMEOUT_PENALTY` when an
episode ends in a timeout. Dynamics, observations and outcomes are the id's own, so a policy
trained on it is scored on the id itself. ``bench/learners.py``'s ``cleanrl-ppo-priced`` row trains
CleanRL's script on it (``--env-id priced_timeout:PricedTimeout/SitToStandHardDiscreteUnit-v2``).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

import coop_gym  # noqa: F401 -- registers BASE_ENV_ID

BASE_ENV_ID = "CoopGym/SitToStandHardDiscreteUnit-v2"
PRICED_ENV_ID = "PricedTimeout/SitToStandHardDiscreteUnit-v2"
TIMEOUT_PENALTY = 1.0
"""Subtracted from the last reward of an episode that ends in a timeout: a failed assistance."""


class PricedTimeout(gym.Wrapper[Any, Any, Any, Any]):
    """Subtracts ``penalty`` from the reward of the step whose outcome is ``timeout``."""

    def __init__(self, env: gym.Env[Any, Any], penalty: float = TIMEOUT_PENALTY) -> None:
        super().__init__(env)
        self.penalty = float(penalty)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        if info.get("outcome") == "timeout":
            reward = float(reward) - self.penalty
        return observation, float(reward), terminated, truncated, info


def make_priced(**kwargs: Any) -> gym.Env[Any, Any]:
    """``BASE_ENV_ID`` made as registered (its time limit included), wrapped in :class:`PricedTimeout`."""
    return PricedTimeout(gym.make(BASE_ENV_ID, **kwargs))


if PRICED_ENV_ID not in gym.registry:
    gym.register(PRICED_ENV_ID, entry_point=make_priced)
