"""coop_gym: Gymnasium environments for guiding an older adult through sit-to-stand.

``import coop_gym`` registers the ids in :data:`coop_gym.registration.ENV_IDS`, e.g.
``gymnasium.make("CoopGym/SitToStand-v0")``; ``gymnasium.make("coop_gym:CoopGym/SitToStand-v0")``
works without the import.
"""

from coop_gym.envs import FEATURES, REWARD_TERMS, LiftCriteria, Outcome, RewardWeights, SitToStandEnv
from coop_gym.model import (
    PERSONAS,
    TEST_PERSONAS,
    TRAIN_PERSONAS,
    Biomechanics,
    Cooperativeness,
    Cues,
    Intention,
    Persona,
    PersonParams,
    Realism,
    Sensors,
    Timing,
)
from coop_gym.registration import ENV_IDS, register_envs

__version__ = "0.1.0"

register_envs()

__all__ = [
    "ENV_IDS",
    "FEATURES",
    "PERSONAS",
    "REWARD_TERMS",
    "TEST_PERSONAS",
    "TRAIN_PERSONAS",
    "Biomechanics",
    "Cooperativeness",
    "Cues",
    "Intention",
    "LiftCriteria",
    "Outcome",
    "PersonParams",
    "Persona",
    "Realism",
    "RewardWeights",
    "Sensors",
    "SitToStandEnv",
    "Timing",
    "__version__",
    "register_envs",
]
