"""Named personas: parameter sets for different older adults, and a train/test split.

Each episode draws one persona from the env's set and then a person around it
(multiplicative log-normal variation of every gain and trait), so a policy meets a
population, not one parameter vector. The split keeps some personas out of training
so generalisation can be measured.

**The validation people**: persons drawn from a documented population that no training episode
shows. People, not episodes, are the unit of generalisation (SPEC, "People, not episodes"). Training
plays the training personas (:data:`TRAIN_PERSONAS`, each with its
person-to-person spread); the test people (``frail``, ``forgetful``) are touched only to
report. Every choice -- which checkpoint, which seed, which setting -- is made on the
*validation people*: :data:`VALIDATION_PEOPLE` persons, each drawn once from
:data:`POPULATION` with the seed :data:`VALIDATION_POPULATION_SEED`, and played as
``personas="validation"`` (each episode one of them, uniformly, with no further variation:
the population is the variation).

The population's ranges come from the model's defaults (SPEC and paper §III: the ``typical``
person), the spread of the *training* personas around them, the calibration
(:mod:`coop_gym.experiment.calibrate`) and the difficulty levels
(:mod:`coop_gym.model.difficulty`) -- never from a test persona:

* **gains** (eq. 1 ``lambda1, k1, k2``; eq. 6 ``k3, k4``): log-uniform over the typical value
  times ``[1/4, 4]``; a factor of 4 is the widest a training persona departs from typical on any
  one gain (``hard_of_hearing``'s verbal gain is a quarter of typical);
* **stiffening** (``stiffness_factor_*``): uniform from the calibrated value to 1, the paper's
  model without it;
* **traits** (``persuadability``, ``startle_sensitivity``, ``hearing``, ``baseline``, the start
  of ``xi``): over the span of the training personas (``anxious`` .. ``cooperative``,
  ``stoic`` .. ``anxious``, ``hard_of_hearing`` .. ``typical``);
* **the level's lapse and recruitment knobs** (:data:`LEVEL_KNOBS`):
  each level's value times a factor log-uniform over ``[1/2, 2]``, the step between the
  ``medium`` and ``hard`` levels (on a ``-v0`` id, which has no level, they do nothing);
* attention (``explanation_memory_s``, ``drift_rate_per_s``, ``idle_after_s``) and everything
  else stay typical: no training persona departs from typical there.

A validation person may resemble a test person on some parameters -- reading people unlike the
training ones is what validation is for -- but none is one, and the ranges were set without
them. :func:`validation_people` draws another population (more people, another seed).
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from coop_gym.model.params import PersonParams

__all__ = [
    "LEVEL_KNOBS",
    "PERSONAS",
    "POPULATION",
    "TEST_PERSONAS",
    "TRAINING_POPULATION_SEED",
    "TRAIN_PERSONAS",
    "VALIDATION_PEOPLE",
    "VALIDATION_POPULATION_SEED",
    "VARIED_PARAMETERS",
    "WIDE_VARIATION_STD",
    "ParameterRange",
    "Persona",
    "get_persona",
    "resolve_personas",
    "sample_person",
    "training_population",
    "validation_people",
]


@dataclass(frozen=True)
class Persona:
    """A named kind of person.

    Attributes:
        name: Identifier used in env ids and kwargs.
        description: One line for humans.
        params: The persona's typical parameters.
        variation_relative_std: Std of the log of each varied parameter (0.2 ~ +/-20 %).
        level_factors: ``(knob, factor)`` pairs: at a difficulty level this person's
            :data:`LEVEL_KNOBS` are the level's values times these factors (the validation
            people, :func:`validation_people`); empty, the level's values as they are.
    """

    name: str
    description: str
    params: PersonParams
    # Calibrated with coop_gym/experiment/calibrate.py (people differ by about +/-20 %).
    variation_relative_std: float = 0.2
    level_factors: tuple[tuple[str, float], ...] = ()

    def __post_init__(self) -> None:
        """Validate the name, the parameters, the variation level and the level factors."""
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"Persona.name must be a non-empty str, got {self.name!r}")
        if not isinstance(self.params, PersonParams):
            raise ValueError(f"Persona.params must be a PersonParams, got {type(self.params).__name__}")
        if not 0.0 <= self.variation_relative_std <= 1.0:
            raise ValueError(f"Persona.variation_relative_std must be in [0, 1], got {self.variation_relative_std!r}")
        for knob, factor in self.level_factors:
            if knob not in LEVEL_KNOBS or not (isinstance(factor, float) and 0.0 <= factor < float("inf")):
                raise ValueError(
                    f"Persona.level_factors: ({knob!r}, {factor!r}) must be a knob of {list(LEVEL_KNOBS)} "
                    "and a finite float factor >= 0"
                )


LEVEL_KNOBS: tuple[str, ...] = (
    "lapse_rate_per_s",
    "pushed_lapse_rate_per_s",
    "refusal_rate_per_s",
    "guided_push_scale",
    "words_alone_scale",
)
"""The difficulty level's knobs (:class:`~coop_gym.model.difficulty.Difficulty` fields) a person's
``level_factors`` may scale: how readily willingness lapses, and how readily it is won."""


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

    The sets: ``"train"``, ``"test"`` (held out), ``"all"``, ``"train_wide"`` -- the
    training personas with :data:`WIDE_VARIATION_STD` person-to-person variation -- and
    ``"validation"``, the validation people (:func:`validation_people`), and ``"train_population"``,
    other people of their population to train on (:func:`training_population`).
    """
    if isinstance(spec, Persona):
        return (spec,)
    if isinstance(spec, str):
        if spec in _SETS:
            return tuple(PERSONAS[n] for n in _SETS[spec])
        if spec in _DRAWN_SETS:
            return _DRAWN_SETS[spec]()
        if spec in _WIDE_SETS:
            return tuple(
                dataclasses.replace(PERSONAS[n], variation_relative_std=WIDE_VARIATION_STD) for n in _WIDE_SETS[spec]
            )
        if spec not in PERSONAS:
            sets = ", ".join([*_SETS, *_WIDE_SETS, *_DRAWN_SETS])
            raise ValueError(f"unknown persona {spec!r}; known: {', '.join(PERSONAS)}; or a set: {sets}")
        return (PERSONAS[spec],)
    if isinstance(spec, Sequence) and len(spec) > 0:
        out: list[Persona] = []
        for item in spec:
            out.extend(resolve_personas(item) if isinstance(item, (str, Persona)) else _bad_persona(item))
        return tuple(out)
    return _bad_persona(spec)


def _bad_persona(spec: object) -> tuple[Persona, ...]:
    raise ValueError(
        "personas must be 'train', 'train_wide', 'train_population', 'validation', 'test', 'all', a persona name "
        f"or a non-empty list of them, got {spec!r}"
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


# --- the validation people ------------------------------------------------------

VALIDATION_PEOPLE = 64
"""Persons in the ``"validation"`` set: enough that no one person decides a score of 1000 episodes."""

VALIDATION_POPULATION_SEED = 58
"""Seed of the ``"validation"`` draw. Any fixed seed serves; it is fixed so every run is judged on the same people."""


@dataclass(frozen=True)
class ParameterRange:
    """The range one person parameter is drawn from.

    Attributes:
        low: Smallest value (a factor for the level knobs).
        high: Largest value.
        log: Draw ``log(value)`` uniformly (gains and rates, which keep their sign); else the value.
        source: Where the range comes from.
    """

    low: float
    high: float
    log: bool
    source: str

    def __post_init__(self) -> None:
        """A range is finite, ordered, and positive where it is drawn on a log scale."""
        if not (math.isfinite(self.low) and math.isfinite(self.high) and self.low <= self.high):
            raise ValueError(f"ParameterRange needs finite low <= high, got [{self.low}, {self.high}]")
        if self.log and self.low <= 0:
            raise ValueError(f"ParameterRange with log=True needs low > 0, got {self.low}")

    def draw(self, rng: np.random.Generator) -> float:
        """One value, from ``rng`` only."""
        if self.log:
            return float(np.exp(rng.uniform(np.log(self.low), np.log(self.high))))
        return float(rng.uniform(self.low, self.high))


_GAIN_FACTOR = 4.0
_GAIN_SOURCE = (
    "typical x [1/4, 4]: hard_of_hearing's verbal gain is typical/4, the widest departure of a training persona"
)
_CALIBRATED = "from the calibrated value (coop_gym/experiment/calibrate.py) to 1, the paper's model"


def _gain(level: str, name: str) -> ParameterRange:
    typical = getattr(getattr(_TYPICAL, level), name)
    return ParameterRange(typical / _GAIN_FACTOR, typical * _GAIN_FACTOR, True, _GAIN_SOURCE)


def _training_span(level: str, name: str, log: bool) -> ParameterRange:
    values = [getattr(getattr(PERSONAS[p].params, level), name) for p in TRAIN_PERSONAS]
    return ParameterRange(min(values), max(values), log, "the span of the training personas")


POPULATION: dict[str, dict[str, ParameterRange]] = {
    "biomechanics": {
        "damping_rate_per_s": _gain("biomechanics", "damping_rate_per_s"),
        "voluntary_gain_per_s2": _gain("biomechanics", "voluntary_gain_per_s2"),
        "push_compliance_m_per_s2_n": _gain("biomechanics", "push_compliance_m_per_s2_n"),
        "stiffness_factor_uncooperative": ParameterRange(
            _TYPICAL.biomechanics.stiffness_factor_uncooperative, 1.0, False, _CALIBRATED
        ),
        "stiffness_factor_unresponsive": ParameterRange(
            _TYPICAL.biomechanics.stiffness_factor_unresponsive, 1.0, False, _CALIBRATED
        ),
    },
    "intention": {
        "push_gain_m_per_s_n": _gain("intention", "push_gain_m_per_s_n"),
        "verbal_gain_m_per_s": _gain("intention", "verbal_gain_m_per_s"),
    },
    "cooperativeness": {
        "persuadability": _training_span("cooperativeness", "persuadability", True),
        "startle_sensitivity": _training_span("cooperativeness", "startle_sensitivity", True),
        "hearing": _training_span("cooperativeness", "hearing", False),
        "initial_p_uncooperative": _training_span("cooperativeness", "initial_p_uncooperative", False),
        # A fraction of what is left after initial_p_uncooperative (the two sum to at most 1),
        # up to the training personas' largest.
        "initial_p_cooperative": _training_span("cooperativeness", "initial_p_cooperative", False),
    },
    "level": {
        knob: ParameterRange(0.5, 2.0, True, "the level's value x [1/2, 2]: medium is hard x 1/2 on each")
        for knob in LEVEL_KNOBS
    },
}
"""Each person parameter the population varies, by model level (``"level"``: factors on the
difficulty level's knobs), with its range and the range's source. ``baseline`` is drawn
uniformly from the training personas' baselines."""

_BASELINES = tuple(sorted({PERSONAS[p].params.cooperativeness.baseline for p in TRAIN_PERSONAS}))


def _person(rng: np.random.Generator) -> tuple[PersonParams, tuple[tuple[str, float], ...]]:
    """One person of :data:`POPULATION` and its level factors, drawn in a fixed order from ``rng``."""
    drawn = {level: {name: r.draw(rng) for name, r in ranges.items()} for level, ranges in POPULATION.items()}
    coop = drawn["cooperativeness"]
    coop["initial_p_cooperative"] = min(coop["initial_p_cooperative"], 1.0 - coop["initial_p_uncooperative"])
    coop["baseline"] = int(_BASELINES[int(rng.integers(len(_BASELINES)))])
    levels = {
        level: dataclasses.replace(getattr(_TYPICAL, level), **fields)
        for level, fields in drawn.items()
        if level != "level"
    }
    return dataclasses.replace(_TYPICAL, **levels), tuple(drawn["level"].items())


@functools.lru_cache(maxsize=8)  # immutable people, resolved by every env and evaluation of the set
def validation_people(
    n: int = VALIDATION_PEOPLE, seed: int = VALIDATION_POPULATION_SEED, prefix: str = "validation"
) -> tuple[Persona, ...]:
    """``n`` persons drawn from :data:`POPULATION` with ``seed``: the same people for the same arguments.

    Each is a :class:`Persona` named ``{prefix}_KK`` with no person-to-person variation of its
    own. ``personas="validation"`` is ``validation_people()``, ``"train_population"`` is
    :func:`training_population`; any env, :func:`agents.evaluate.evaluate` and ``--personas``
    take the tuple too.

    Raises:
        ValueError: ``n`` is not a positive int, or ``seed`` not a non-negative int.
    """
    _check_int("n", n, 1)
    _check_int("seed", seed, 0)
    rng = np.random.default_rng(seed)
    width = len(str(n - 1))
    people = []
    for k in range(n):
        params, factors = _person(rng)
        people.append(
            Persona(
                f"{prefix}_{k:0{width}d}",
                f"Person {k} drawn from the population (seed {seed}).",
                params,
                variation_relative_std=0.0,
                level_factors=factors,
            )
        )
    return tuple(people)


TRAINING_POPULATION_SEED = 1958
"""Seed of the ``"train_population"`` draw: other people than the validation people's seed draws."""


def training_population() -> tuple[Persona, ...]:
    """``"train_population"``: 512 persons of :data:`POPULATION` (seed :data:`TRAINING_POPULATION_SEED`) to train on.

    Training across bodies (domain randomisation over the person parameters): the same
    population as the validation people, other persons, so validation still meets people no
    training episode shows; the test people stay outside both.
    """
    return validation_people(512, TRAINING_POPULATION_SEED, "population")


def _check_int(name: str, value: object, low: int) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise ValueError(f"validation_people: {name} must be an int >= {low}, got {value!r}")


_DRAWN_SETS: dict[str, Callable[[], tuple[Persona, ...]]] = {
    "validation": validation_people,
    "train_population": training_population,
}
"""Set names that resolve to drawn people."""
