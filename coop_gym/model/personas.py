"""Named personas: parameter sets for different older adults, and a train/test split.

Each episode draws one persona from the env's set and then a person around it
(multiplicative log-normal variation of every gain and trait), so a policy meets a
population, not one parameter vector. The split keeps some personas out of training
so generalisation can be measured.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from coop_gym.model.params import PersonParams

__all__ = [
    "PERSONAS",
    "TEST_PERSONAS",
    "TRAIN_PERSONAS",
    "VARIED_PARAMETERS",
    "WIDE_VARIATION_STD",
    "Persona",
    "get_persona",
    "resolve_personas",
    "sample_person",
]


@dataclass(frozen=True)
class Persona:
    """A named kind of person.

    Attributes:
        name: Identifier used in env ids and kwargs.
        description: One line for humans.
        params: The persona's typical parameters.
        variation_relative_std: Std of the log of each varied parameter (0.2 ~ +/-20 %).
    """

    name: str
    description: str
    params: PersonParams
    # Calibrated with coop_gym/experiment/calibrate.py (people differ by about +/-20 %).
    variation_relative_std: float = 0.2

    def __post_init__(self) -> None:
        """Validate the name, the parameters and the variation level."""
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"Persona.name must be a non-empty str, got {self.name!r}")
        if not isinstance(self.params, PersonParams):
            raise ValueError(f"Persona.params must be a PersonParams, got {type(self.params).__name__}")
        if not 0.0 <= self.variation_relative_std <= 1.0:
            raise ValueError(f"Persona.variation_relative_std must be in [0, 1], got {self.variation_relative_std!r}")


_TYPICAL = PersonParams()


def _typical_but(**levels: dict[str, Any]) -> PersonParams:
    """The typical person with some fields of some levels changed, e.g. ``_typical_but(intention={"min_m": -0.02})``."""
    changed = {level: dataclasses.replace(getattr(_TYPICAL, level), **fields) for level, fields in levels.items()}
    return dataclasses.replace(_TYPICAL, **changed)


PERSONAS: dict[str, Persona] = {
    p.name: p
    for p in (
        Persona("typical", "An average older adult: hesitant at first, follows a good explanation.", _TYPICAL),
        Persona(
            "frail",
            "Weak and compliant: a push moves them a lot whatever they think (the paper's first failure scenario).",
            _typical_but(
                biomechanics={
                    "voluntary_gain_per_s2": 4.0,
                    "damping_rate_per_s": 4.0,
                    "push_compliance_m_per_s2_n": 0.045,
                    "stiffness_factor_uncooperative": 0.9,
                    "stiffness_factor_unresponsive": 1.0,
                },
                # Too infirm to lean back far against a push.
                intention={"min_m": -0.02},
                cooperativeness={"initial_p_uncooperative": 0.35, "initial_p_cooperative": 0.1},
            ),
        ),
        Persona(
            "anxious",
            "Starts uncooperative and startles easily; needs patient explaining.",
            _typical_but(
                cooperativeness={
                    "startle_sensitivity": 3.0,
                    "persuadability": 0.7,
                    "baseline": -1,
                    "initial_p_uncooperative": 0.8,
                    "initial_p_cooperative": 0.0,
                },
            ),
        ),
        Persona(
            "hard_of_hearing",
            "Words barely get through: weak response to verbal cues, explanations prepare little.",
            _typical_but(intention={"verbal_gain_m_per_s": 0.03}, cooperativeness={"hearing": 0.3}),
        ),
        Persona(
            "cooperative",
            "Willing and engaged: often cooperative from the start, easily persuaded.",
            _typical_but(
                cooperativeness={
                    "persuadability": 1.5,
                    "baseline": 1,
                    "initial_p_uncooperative": 0.05,
                    "initial_p_cooperative": 0.6,
                },
            ),
        ),
        Persona(
            "stoic",
            "Stiff and slow to move, steady in mood: small, late responses to every cue.",
            _typical_but(
                biomechanics={"damping_rate_per_s": 8.0, "push_compliance_m_per_s2_n": 0.008},
                intention={"reaction_delay_s": 0.5, "push_gain_m_per_s_n": 0.004},
                cooperativeness={"startle_sensitivity": 0.5},
            ),
        ),
        Persona(
            "forgetful",
            "Mild cognitive impairment: explanations fade fast and attention drifts away when idle.",
            _typical_but(
                cooperativeness={"explanation_memory_s": 2.5, "drift_rate_per_s": 0.3, "idle_after_s": 1.5},
            ),
        ),
    )
}

TRAIN_PERSONAS: tuple[str, ...] = ("typical", "anxious", "hard_of_hearing", "cooperative", "stoic")
"""Personas an agent may train on."""

TEST_PERSONAS: tuple[str, ...] = ("frail", "forgetful")
"""Held-out personas for measuring generalisation."""

WIDE_VARIATION_STD = 0.5
"""``variation_relative_std`` of the ``"train_wide"`` set: one sd of a varied gain is x1.65 or
x0.61 around each training persona instead of about +/-20 % (domain randomisation). A policy trained on the
narrow spread learns the training personas' exact push compliance; on the hard level one
of three PPO seeds then read a held-out frail person's pushed lean as cooperation
(docs/agents.md, "Why the wider spread")."""

_SETS: dict[str, tuple[str, ...]] = {
    "train": TRAIN_PERSONAS,
    "test": TEST_PERSONAS,
    "all": tuple(PERSONAS),
}

# Sets of personas changed from their named originals (the same names, so infos and
# per-persona tables still say who was played).
_WIDE_SETS: dict[str, tuple[str, ...]] = {"train_wide": TRAIN_PERSONAS}


def get_persona(name: str) -> Persona:
    """Look up a persona by name; an unknown name raises ``ValueError`` listing the known ones."""
    try:
        return PERSONAS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown persona {name!r}; known: {', '.join(PERSONAS)}") from None


def resolve_personas(spec: str | Persona | Sequence[str | Persona]) -> tuple[Persona, ...]:
    """Turn a set name, a persona name, a Persona or a sequence of them into personas.

    The sets: ``"train"``, ``"test"`` (held out), ``"all"``, and ``"train_wide"`` -- the
    training personas with :data:`WIDE_VARIATION_STD` person-to-person variation.
    """
    if isinstance(spec, Persona):
        return (spec,)
    if isinstance(spec, str):
        if spec in _SETS:
            return tuple(PERSONAS[n] for n in _SETS[spec])
        if spec in _WIDE_SETS:
            return tuple(
                dataclasses.replace(PERSONAS[n], variation_relative_std=WIDE_VARIATION_STD) for n in _WIDE_SETS[spec]
            )
        return (get_persona(spec),)
    if isinstance(spec, Sequence) and len(spec) > 0:
        out: list[Persona] = []
        for item in spec:
            out.extend(resolve_personas(item) if isinstance(item, (str, Persona)) else _bad_persona(item))
        return tuple(out)
    return _bad_persona(spec)


def _bad_persona(spec: object) -> tuple[Persona, ...]:
    raise ValueError(
        "personas must be 'train', 'train_wide', 'test', 'all', a persona name or a non-empty list of them, "
        f"got {spec!r}"
    )


# Gains and traits that vary from person to person (log-normally, so they keep their sign).
# The env core applies the same variation in compiled code from this table.
VARIED_PARAMETERS: dict[str, tuple[str, ...]] = {
    "biomechanics": ("damping_rate_per_s", "voluntary_gain_per_s2", "push_compliance_m_per_s2_n"),
    "intention": ("push_gain_m_per_s_n", "verbal_gain_m_per_s"),
    "cooperativeness": ("persuadability", "startle_sensitivity"),
}


def sample_person(persona: Persona, rng: np.random.Generator, vary: bool = True) -> PersonParams:
    """Draw one person around ``persona`` using ``rng`` only.

    The same number of random draws is made whether or not ``vary`` is set, so turning
    variation off does not shift the rest of an episode's random stream.
    """
    n_varied = sum(len(v) for v in VARIED_PARAMETERS.values())
    factors = np.exp(rng.standard_normal(n_varied) * persona.variation_relative_std)
    if not vary:
        return persona.params
    levels: dict[str, object] = {}
    k = 0
    for level, names in VARIED_PARAMETERS.items():
        base = getattr(persona.params, level)
        # The field ranges check what a user hands in; a person drawn around a persona at
        # the edge of a range may lie just beyond it (a positive gain times a log-normal
        # factor stays positive and finite). So the varied copy is not re-validated -- the
        # env core's compiled reset does the same -- rather than raising on some seeds.
        varied = copy.copy(base)
        for name in names:
            object.__setattr__(varied, name, float(getattr(base, name) * factors[k]))
            k += 1
        levels[level] = varied
    # Hearing is a bounded 0..1 fraction, so it stays at the persona's value.
    return dataclasses.replace(persona.params, **levels)  # type: ignore[arg-type]
