"""The PPO learner: :class:`PPO` and its settings :class:`PPOConfig` (:mod:`agents.ppo.ppo`, read top to bottom)."""

from agents.ppo.ppo import PPO, PPOConfig, Rollout

__all__ = ["PPO", "PPOConfig", "Rollout"]
