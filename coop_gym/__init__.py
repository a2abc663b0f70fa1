"""coop_gym: Gymnasium environments for guiding an older adult through sit-to-stand.

``import coop_gym`` registers the ids in :data:`coop_gym.registration.ENV_IDS`, e.g.
``gymnasium.make("CoopGym/SitToStand-v0")``; ``gymnasium.make("coop_gym:CoopGym/SitToStand-v0")``
works without the import.
"""

import importlib
from typing import Any

from coop_gym.registration import ENV_IDS, register_envs

# Imported on first use (PEP 562), so ``import coop_gym`` registers the ids without building the
# envs, and the lowest layer ``coop_gym.compiled`` can be imported by ``estimator`` without a cycle.
_LAZY = {
    **dict.fromkeys(
        ["FEATURES", "REWARD_TERMS", "LiftCriteria", "Outcome", "RewardWeights", "SitToStandEnv"], "coop_gym.envs"
    ),
    **dict.fromkeys(
        [
            "PERSONAS",
            "TEST_PERSONAS",
            "TRAIN_PERSONAS",
            "Biomechanics",
            "Cooperativeness",
            "Cues",
            "Intention",
            "Persona",
            "PersonParams",
            "Realism",
            "Sensors",
            "Timing",
        ],
        "coop_gym.model",
    ),
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'coop_gym' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__version__ = "0.1.0"

register_envs()

__all__ = ["ENV_IDS", "__version__", "register_envs", *_LAZY]
