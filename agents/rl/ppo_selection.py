"""The :mod:`agents.ppo` learner with the SB3-side tools: its policy kept by :class:`SelectionCallback`.

:func:`learn_selected` trains a :class:`~agents.ppo.PPO` and, at the rollout starts the selection
asks for, scores the policy the next rollout plays (as SB3's PPO: :func:`agents.ppo.sb3_format.to_sb3`),
exactly as :class:`~agents.rl.callbacks.SelectionCallback` does for an SB3 model; the best-scoring
policy is the SB3 model returned, which :func:`agents.rl.save_agent` saves like any other.
"""

from __future__ import annotations

from typing import Any

from stable_baselines3 import PPO as SB3PPO

from agents.ppo import PPO
from agents.ppo.sb3_format import to_sb3
from agents.rl.callbacks import SelectionCallback

__all__ = ["learn_selected"]


def learn_selected(
    learner: PPO, total_timesteps: int, selection: SelectionCallback | None
) -> tuple[SB3PPO, dict[str, Any] | None]:
    """``(model, selected)``: train to ``total_timesteps``; the kept policy as SB3's PPO and the selection's record.

    Without ``selection`` the final policy is kept and the record is None.
    """

    def score(trained: PPO) -> bool:
        if selection is not None and selection.due(trained.num_timesteps):
            selection.model = to_sb3(trained, trained.acting_params)  # the policy the next rollout plays
            selection.num_timesteps = trained.num_timesteps
            selection.on_rollout_start()
        return True

    learner.learn(total_timesteps, score)
    model = to_sb3(learner)
    if selection is None:
        return model, None
    return model, selection.finish(model)
