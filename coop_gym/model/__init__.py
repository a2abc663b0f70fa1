"""The pure human model: parameters, personas and the three levels (paper §III)."""

from coop_gym.model.dynamics import Trajectory, pack_person, simulate
from coop_gym.model.params import (
    Biomechanics,
    Cooperativeness,
    Cues,
    Intention,
    PersonParams,
    Realism,
    Sensors,
    Timing,
)
from coop_gym.model.personas import (
    PERSONAS,
    TEST_PERSONAS,
    TRAIN_PERSONAS,
    Persona,
    get_persona,
    resolve_personas,
    sample_person,
)
from estimator.compiled.cache import guard_kernel_cache

__all__ = [
    "PERSONAS",
    "TEST_PERSONAS",
    "TRAIN_PERSONAS",
    "Biomechanics",
    "Cooperativeness",
    "Cues",
    "Intention",
    "PersonParams",
    "Persona",
    "Realism",
    "Sensors",
    "Timing",
    "Trajectory",
    "get_persona",
    "pack_person",
    "resolve_personas",
    "sample_person",
    "simulate",
]

# dynamics' kernels inline each other and read params' constants: key their cache by both.
guard_kernel_cache("coop_gym.model.dynamics")
