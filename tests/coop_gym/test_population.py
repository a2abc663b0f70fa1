"""The validation people: a documented population, drawn seeded, played wherever personas are."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import pytest

import coop_gym  # noqa: F401 -- registers the ids
from coop_gym.model.difficulty import DIFFICULTIES, Difficulty
from coop_gym.model.personas import (
    LEVEL_KNOBS,
    PERSONAS,
    POPULATION,
    TEST_PERSONAS,
    TRAIN_PERSONAS,
    VALIDATION_PEOPLE,
    VALIDATION_POPULATION_SEED,
    ParameterRange,
    Persona,
    resolve_personas,
    training_population,
    validation_people,
)

HARD_V2 = DIFFICULTIES["hard-v2"]


def test_the_validation_set_is_the_seeded_draw_of_named_people_apart_from_every_persona() -> None:
    people = resolve_personas("validation")
    assert people == validation_people() == validation_people(VALIDATION_PEOPLE, VALIDATION_POPULATION_SEED)
    assert len(people) == VALIDATION_PEOPLE == len({p.name for p in people})
    assert not {p.name for p in people} & set(PERSONAS)
    assert all(p.variation_relative_std == 0.0 for p in people)  # the population is the variation
    # No validation person is a training or test persona, with or without its level knobs.
    named = {PERSONAS[n].params for n in (*TRAIN_PERSONAS, *TEST_PERSONAS)}
    assert not {p.params for p in people} & named
    # Another seed draws other people; the draw does not depend on how many are drawn.
    assert validation_people(4, seed=1) != validation_people(4)
    assert [p.params for p in validation_people(4)] == [p.params for p in people[:4]]


def test_the_training_population_is_other_people_of_the_same_population() -> None:
    from agents.hyperparams import hyperparams_for

    trained = resolve_personas("train_population")
    assert trained == training_population() and len(trained) == 512
    assert all(p.name.startswith("population_") for p in trained)
    assert not {p.params for p in trained} & {p.params for p in validation_people()}
    # A training distribution the trainer accepts (it holds no held-out persona).
    assert hyperparams_for("ppo").replace(personas="train_population").personas == "train_population"


def test_every_drawn_parameter_lies_in_its_documented_range() -> None:
    for person in validation_people(200, seed=3):
        for level, ranges in POPULATION.items():
            values = dict(person.level_factors) if level == "level" else vars(getattr(person.params, level))
            for name, allowed in ranges.items():
                assert allowed.low <= values[name] <= allowed.high, (person.name, level, name)
        coop = person.params.cooperativeness
        assert coop.initial_p_uncooperative + coop.initial_p_cooperative <= 1.0
        assert coop.baseline in {PERSONAS[n].params.cooperativeness.baseline for n in TRAIN_PERSONAS}
        # Attention is not varied: only a test persona (forgetful) departs from typical there.
        typical = PERSONAS["typical"].params.cooperativeness
        for name in ("explanation_memory_s", "drift_rate_per_s", "idle_after_s"):
            assert getattr(coop, name) == getattr(typical, name)


def test_the_ranges_come_from_the_defaults_and_the_training_personas() -> None:
    typical = PERSONAS["typical"].params
    compliance = POPULATION["biomechanics"]["push_compliance_m_per_s2_n"]
    assert (compliance.low, compliance.high) == pytest.approx(
        (typical.biomechanics.push_compliance_m_per_s2_n / 4, typical.biomechanics.push_compliance_m_per_s2_n * 4)
    )
    startle = POPULATION["cooperativeness"]["startle_sensitivity"]
    assert (startle.low, startle.high) == (0.5, 3.0)  # stoic .. anxious
    assert all(r.source for ranges in POPULATION.values() for r in ranges.values())
    assert set(POPULATION["level"]) == set(LEVEL_KNOBS)
    assert set(LEVEL_KNOBS) <= {f.name for f in dataclasses.fields(Difficulty)}


def test_a_persons_level_factors_scale_the_levels_knobs_for_them_alone() -> None:
    person = validation_people(1)[0]
    factors = dict(person.level_factors)
    [at_level] = HARD_V2.personas_at([person])
    coop = at_level.params.cooperativeness
    assert coop.lapse_rate_per_s == pytest.approx(HARD_V2.lapse_rate_per_s * factors["lapse_rate_per_s"])
    assert coop.refusal_rate_per_s == pytest.approx(HARD_V2.refusal_rate_per_s * factors["refusal_rate_per_s"])
    assert coop.guided_push_rate_per_s == pytest.approx(
        person.params.cooperativeness.guided_push_rate_per_s * HARD_V2.guided_push_scale * factors["guided_push_scale"]
    )
    # A persona without factors meets the level as it is.
    [typical] = HARD_V2.personas_at([PERSONAS["typical"]])
    assert typical.params == HARD_V2.apply(PERSONAS["typical"].params)


def test_envs_and_the_evaluation_play_the_validation_people() -> None:
    from agents.evaluate import evaluate

    env = gym.make("CoopGym/SitToStandHard-v2", personas="validation")
    _, info = env.reset(seed=0)
    assert info["persona"].startswith("validation_")
    env.close()
    result = evaluate("prober", "CoopGym/SitToStandHard-v2", "validation", episodes=8, seed=0, n_envs=8)
    assert result.personas == tuple(p.name for p in validation_people())


@pytest.mark.parametrize(
    ("build", "match"),
    [
        (lambda: validation_people(0), r"validation_people: n must be an int >= 1, got 0"),
        (lambda: validation_people(True), r"n must be an int >= 1, got True"),
        (lambda: validation_people(4, seed=-1), r"seed must be an int >= 0, got -1"),
        (lambda: resolve_personas("validaton"), r"unknown persona 'validaton'; known: typical.*a set: .*validation"),
        (
            lambda: Persona("p", "", PERSONAS["typical"].params, level_factors=(("lapse", 2.0),)),
            r"Persona.level_factors: \('lapse', 2.0\) must be a knob of",
        ),
        (
            lambda: Persona("p", "", PERSONAS["typical"].params, level_factors=(("lapse_rate_per_s", -1.0),)),
            r"finite float factor >= 0",
        ),
        (lambda: ParameterRange(0.0, 1.0, True, "s"), r"log=True needs low > 0"),
        (lambda: ParameterRange(2.0, 1.0, False, "s"), r"finite low <= high"),
    ],
)
def test_bad_input_is_named(build, match) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ValueError, match=match):
        build()
