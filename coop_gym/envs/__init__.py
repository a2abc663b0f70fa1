"""Gymnasium environments: the single env and the natively batched vector env."""

from coop_gym.envs.config import LiftCriteria, Outcome, RewardWeights
from coop_gym.envs.core import FEATURES, REWARD_TERMS, SitToStandCore
from coop_gym.envs.sit_to_stand import SitToStandEnv

__all__ = ["FEATURES", "REWARD_TERMS", "LiftCriteria", "Outcome", "RewardWeights", "SitToStandCore", "SitToStandEnv"]
