"""Property-based robustness of the env over the whole parameter space the dataclasses allow.

Strategies are built from each field's validated range (``RANGES`` below: the model
dataclasses' own ``RANGES``, and the bounds of ``coop_gym.envs.config``'s ``__post_init__``);
the first tests check that the table covers every field and that the validation enforces it.

Properties, for arbitrary parameters, action types, observation modes, seeds and action
sequences: no NaN or inf in observations, rewards or infos; observations inside the
observation space; the in-env filter covariance ``env.unwrapped.core.P`` symmetric PSD.

Each ``@given`` test counts its examples; run ``pytest -s`` to see the counts printed
(or ``--hypothesis-show-statistics``).
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coop_gym.envs.config import ACTION_TYPES, OBSERVATION_MODES, LiftCriteria, RewardWeights
from coop_gym.envs.sit_to_stand import SitToStandEnv
from coop_gym.model.dynamics import DELAY_LINE_LENGTH
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
from coop_gym.model.personas import Persona, sample_person
from estimator.judgment import ThresholdJudgment

EXAMPLES: Counter[str] = Counter()
"""Examples run per property (printed at the end of the module)."""

# field -> (low, high), inclusive: the validated range of each numeric field (the model's
# dataclasses declare theirs in RANGES, which their __post_init__ enforces).
RANGES: dict[type, dict[str, tuple[float, float]]] = {
    **{cls: cls.RANGES for cls in (Biomechanics, Intention, Cooperativeness, Sensors, Cues, Timing)},
    LiftCriteria: {"success_lean_m": (0.0, 1.0), "upright_m": (-1.0, 1.0)},
    RewardWeights: dict.fromkeys(("success", "unsafe", "premature", "time_per_s", "force_per_n_s"), (0.0, 1e6)),
}
# Non-range fields (bools, ints, enumerations) are drawn separately below.
OTHER_FIELDS = {
    Intention: {"saturate"},
    Cooperativeness: {"baseline"},
    Timing: {"substeps"},
}
# Values that satisfy the cross-field constraints whichever single field is at a bound.
PERMISSIVE = {
    Cooperativeness: {
        "touch_threshold_n": 0.0,
        "firm_push_threshold_n": 1000.0,
        "initial_p_uncooperative": 0.0,
        "initial_p_cooperative": 0.0,
    },
    LiftCriteria: {"success_lean_m": 1.0, "upright_m": -1.0},
    Cues: {"soft_push_n": 0.0, "firm_push_n": 200.0},
}


def _range_cases() -> list[tuple[type, str, float, float]]:
    return [(cls, name, lo, hi) for cls, fields in RANGES.items() for name, (lo, hi) in fields.items()]


def test_range_table_covers_every_field() -> None:
    for cls, fields in RANGES.items():
        names = {f.name for f in dataclasses.fields(cls)}
        assert set(fields) | OTHER_FIELDS.get(cls, set()) == names, cls.__name__


@pytest.mark.parametrize(
    ("cls", "name", "low", "high"), _range_cases(), ids=[f"{c.__name__}.{n}" for c, n, _, _ in _range_cases()]
)
def test_range_table_matches_validation(cls: type, name: str, low: float, high: float) -> None:
    """Bounds accepted; just outside, NaN and inf rejected with a message naming the field."""
    base = dict(PERMISSIVE.get(cls, {}))
    if cls is LiftCriteria and name == "upright_m":
        base["success_lean_m"] = high  # upright_m's upper bound is success_lean_m
    for ok in (low, high):
        cls(**{**base, name: ok})
    span = high - low
    for bad in (low - 1e-6 * max(1.0, span), high + 1e-6 * max(1.0, span), math.nan, math.inf, "1"):
        with pytest.raises(ValueError, match=rf"{cls.__name__}\.{name}"):
            cls(**{**base, name: bad})


# --------------------------------------------------------------------------- strategies


def _number(low: float, high: float) -> st.SearchStrategy[float]:
    # Bounds are drawn often: that is where numerics break.
    return st.one_of(st.sampled_from([low, high]), st.floats(low, high, allow_nan=False, allow_infinity=False))


@st.composite
def dataclass_values(draw: st.DrawFn, cls: type, shrink: float = 1.0) -> dict[str, Any]:
    """Every range field of ``cls``; ``shrink`` > 1 keeps multiplicative variation inside the range."""
    out: dict[str, Any] = {}
    for name, (low, high) in RANGES[cls].items():
        lo, hi = low, high
        if shrink > 1.0 and name in VARIED.get(cls, ()):
            # At most down to the range's geometric middle, so the interval never empties.
            s = min(shrink, math.sqrt(high / low)) if low > 0 else shrink
            lo, hi = low * s, high / s
        out[name] = draw(_number(lo, hi))
    return out


# Fields multiplied by exp(N(0, sigma)) per episode (coop_gym.model.personas.VARIED_PARAMETERS).
VARIED: dict[type, tuple[str, ...]] = {
    Biomechanics: ("damping_rate_per_s", "voluntary_gain_per_s2", "push_compliance_m_per_s2_n"),
    Intention: ("push_gain_m_per_s_n", "verbal_gain_m_per_s"),
    Cooperativeness: ("persuadability", "startle_sensitivity"),
}
# Variation may carry a varied field past its validated range (test_sample_person_near_a_bound_does_not_raise);
# re-validating such a person, as test_sampled_person_is_valid_and_finite does, would then raise. So for
# that test varied fields are drawn exp(VARIATION_SIGMAS * sigma) inside their bounds (a draw beyond
# that has p ~ 3e-7); the env is exercised over the whole range.
VARIATION_SIGMAS = 5.0


@st.composite
def persons(draw: st.DrawFn, timing: Timing, keep_varied_in_range: bool = False) -> Persona:
    """A persona with every parameter drawn from its validated range (and the cross-field rules)."""
    variation = draw(st.one_of(st.just(0.0), _number(0.0, 1.0)))
    shrink = math.exp(VARIATION_SIGMAS * variation) if keep_varied_in_range else 1.0
    bio = Biomechanics(**draw(dataclass_values(Biomechanics, shrink)))
    iv = draw(dataclass_values(Intention, shrink))
    # The delay line holds DELAY_LINE_LENGTH - 1 steps of dt.
    iv["reaction_delay_s"] = min(iv["reaction_delay_s"], (DELAY_LINE_LENGTH - 1) * timing.dt_s)
    intent = Intention(**iv, saturate=draw(st.booleans()))
    cv = draw(dataclass_values(Cooperativeness, shrink))
    cv["touch_threshold_n"], cv["firm_push_threshold_n"] = sorted(
        (cv["touch_threshold_n"], cv["firm_push_threshold_n"])
    )
    total = cv["initial_p_uncooperative"] + cv["initial_p_cooperative"]
    if total > 1.0:
        cv["initial_p_uncooperative"] /= total
        cv["initial_p_cooperative"] = max(0.0, 1.0 - cv["initial_p_uncooperative"])
    coop = Cooperativeness(**cv, baseline=draw(st.sampled_from([-1, 0, 1])))
    sensors = Sensors(**draw(dataclass_values(Sensors)))
    return Persona(
        "drawn", "a person drawn from the whole parameter space", PersonParams(bio, intent, coop, sensors), variation
    )


@st.composite
def timings(draw: st.DrawFn) -> Timing:
    return Timing(**draw(dataclass_values(Timing)), substeps=draw(st.integers(1, 100)))


@st.composite
def env_configs(draw: st.DrawFn) -> dict[str, Any]:
    """Keyword arguments of SitToStandEnv drawn over the whole validated space."""
    timing = draw(timings())
    lift = draw(dataclass_values(LiftCriteria))
    lift["upright_m"] = min(lift["upright_m"], lift["success_lean_m"])
    cues = draw(dataclass_values(Cues))
    cues["soft_push_n"] = min(cues["soft_push_n"], cues["firm_push_n"])
    return {
        "personas": [draw(persons(timing))],
        "timing": timing,
        "cues": Cues(**cues),
        "realism": Realism(**{f.name: draw(st.booleans()) for f in dataclasses.fields(Realism)}),
        "lift": LiftCriteria(**lift),
        "reward": RewardWeights(**draw(dataclass_values(RewardWeights))),
        "judgment": ThresholdJudgment(draw(_number(0.0, 30.0)), draw(_number(1e-6, 10.0))),
        "observation_mode": draw(st.sampled_from(OBSERVATION_MODES)),
        "action_type": draw(st.sampled_from(ACTION_TYPES)),
    }


def actions_for(action_type: str) -> st.SearchStrategy[Any]:
    """Arbitrary valid actions; lifting is rare so that episodes run long."""
    lift = st.sampled_from([0] * 15 + [1])
    if action_type == "multidiscrete":
        return st.tuples(st.integers(0, 2), st.integers(0, 2), lift).map(list)
    if action_type == "discrete":
        return st.tuples(st.integers(0, 2), st.integers(0, 2), lift).map(
            lambda a: int(np.ravel_multi_index(a, (3, 3, 2)))
        )
    unit = st.floats(-1.0, 1.0, allow_nan=False, width=32)
    return st.tuples(unit, unit, st.sampled_from([-1.0] * 15 + [1.0])).map(lambda a: np.array(a, dtype=np.float32))


# --------------------------------------------------------------------------- checks


def assert_finite_info(info: dict[str, Any], where: str) -> None:
    for key, value in info.items():
        if isinstance(value, dict):
            assert_finite_info(value, f"{where}.{key}")
        elif isinstance(value, (int, float, np.ndarray, np.number)) and not isinstance(value, bool):
            assert np.all(np.isfinite(value)), f"{where}: info[{key!r}] = {value!r}"


def assert_symmetric_psd(P: np.ndarray, where: str) -> None:
    assert np.all(np.isfinite(P)), f"{where}: non-finite covariance {P}"
    scale = max(1.0, float(np.max(np.abs(P))))
    np.testing.assert_allclose(P, np.swapaxes(P, -1, -2), rtol=0, atol=1e-12 * scale, err_msg=where)
    eig = np.linalg.eigvalsh(0.5 * (P + np.swapaxes(P, -1, -2)))
    assert np.all(eig >= -1e-10 * scale), f"{where}: covariance not PSD, eigenvalues {eig}"


def check_step(env: SitToStandEnv, obs: np.ndarray, reward: Any, info: dict[str, Any], where: str) -> None:
    assert obs.dtype == np.float32, where
    assert np.all(np.isfinite(obs)), f"{where}: obs {obs}"
    assert env.observation_space.contains(obs), f"{where}: obs {obs} outside {env.observation_space}"
    assert isinstance(reward, float) and math.isfinite(reward), f"{where}: reward {reward!r}"
    assert_finite_info(info, where)
    assert_symmetric_psd(env.core.P[0], where)


def rollout_checked(env: SitToStandEnv, seed: int, actions: list[Any]) -> None:
    obs, info = env.reset(seed=seed)
    check_step(env, obs, 0.0, info, "reset")
    for t, action in enumerate(actions):
        obs, reward, terminated, truncated, info = env.step(action)
        assert isinstance(terminated, bool) and isinstance(truncated, bool)
        check_step(env, obs, reward, info, f"step {t} action {action!r}")
        if terminated or truncated:  # the raw env refuses to step past either
            obs, info = env.reset()
            check_step(env, obs, 0.0, info, f"reset after step {t}")


# --------------------------------------------------------------------------- properties

COMMON = settings(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def _random_parameters_and_actions(config: dict[str, Any], seed: int, data: st.DataObject) -> None:
    env = SitToStandEnv(**config)
    actions = data.draw(st.lists(actions_for(config["action_type"]), min_size=1, max_size=80), label="actions")
    rollout_checked(env, seed, actions)


@settings(COMMON, max_examples=150)
@given(config=env_configs(), seed=st.integers(0, 2**32 - 1), data=st.data())
def test_env_finite_and_in_space_over_parameter_space(config: dict[str, Any], seed: int, data: st.DataObject) -> None:
    EXAMPLES["env_finite_and_in_space_over_parameter_space"] += 1
    _random_parameters_and_actions(config, seed, data)


@pytest.mark.slow
@settings(COMMON, max_examples=3000)
@given(config=env_configs(), seed=st.integers(0, 2**32 - 1), data=st.data())
def test_env_finite_and_in_space_over_parameter_space_long(
    config: dict[str, Any], seed: int, data: st.DataObject
) -> None:
    EXAMPLES["env_finite_and_in_space_over_parameter_space_long"] += 1
    _random_parameters_and_actions(config, seed, data)


def _held_cue_episode(config: dict[str, Any], seed: int, push: int, verbal: int, max_steps: int) -> None:
    config = {**config, "action_type": "multidiscrete"}
    env = SitToStandEnv(**config)
    rollout_checked(env, seed, [[push, verbal, 0]] * min(env.timing.max_episode_steps, max_steps))


HELD_CUE = {
    "config": env_configs(),
    "seed": st.integers(0, 2**32 - 1),
    "push": st.integers(0, 2),
    "verbal": st.integers(0, 2),
}


@settings(COMMON, max_examples=25)
@given(**HELD_CUE)
def test_env_finite_under_a_held_cue_for_a_whole_episode(
    config: dict[str, Any], seed: int, push: int, verbal: int
) -> None:
    """One cue (or none) held for a whole episode (up to 1000 steps): slow instabilities have time to grow."""
    EXAMPLES["env_finite_under_a_held_cue_for_a_whole_episode"] += 1
    _held_cue_episode(config, seed, push, verbal, 1000)


@pytest.mark.slow
@settings(COMMON, max_examples=300)
@given(**HELD_CUE)
def test_env_finite_under_a_held_cue_for_a_whole_episode_long(
    config: dict[str, Any], seed: int, push: int, verbal: int
) -> None:
    EXAMPLES["env_finite_under_a_held_cue_for_a_whole_episode_long"] += 1
    _held_cue_episode(config, seed, push, verbal, 10000)


def _default_env_episodes(seed: int, data: st.DataObject) -> None:
    action_type = data.draw(st.sampled_from(ACTION_TYPES), label="action_type")
    env = SitToStandEnv(action_type=action_type, personas="all")
    actions = data.draw(st.lists(actions_for(action_type), min_size=300, max_size=300), label="actions")
    rollout_checked(env, seed, actions)


@settings(COMMON, max_examples=15)
@given(seed=st.integers(0, 2**32 - 1), data=st.data())
def test_default_env_finite_over_arbitrary_action_sequences(seed: int, data: st.DataObject) -> None:
    """The registered defaults, full 300-step episodes of arbitrary actions (lifts included)."""
    EXAMPLES["default_env_finite_over_arbitrary_action_sequences"] += 1
    _default_env_episodes(seed, data)


@pytest.mark.slow
@settings(COMMON, max_examples=300)
@given(seed=st.integers(0, 2**32 - 1), data=st.data())
def test_default_env_finite_over_arbitrary_action_sequences_long(seed: int, data: st.DataObject) -> None:
    EXAMPLES["default_env_finite_over_arbitrary_action_sequences_long"] += 1
    _default_env_episodes(seed, data)


@settings(COMMON, max_examples=100)
@given(
    persona=timings().flatmap(lambda timing: persons(timing, keep_varied_in_range=True)),
    seed=st.integers(0, 2**32 - 1),
    realism=st.booleans(),
)
def test_sampled_person_is_valid_and_finite(persona: Persona, seed: int, realism: bool) -> None:
    """Every drawn person is a valid PersonParams (re-validated) and packs to finite numbers."""
    EXAMPLES["sampled_person_is_valid_and_finite"] += 1
    person = sample_person(persona, np.random.default_rng(seed), vary=True)
    if realism:
        person = person.with_realism(Realism.off())
    for level in dataclasses.fields(person):
        value = getattr(person, level.name)
        assert dataclasses.replace(value) == value  # re-runs __post_init__


def test_person_variation_near_a_bound_keeps_reset_working() -> None:
    """A persona at a range bound, varied per episode: every reset works and stays finite."""
    params = PersonParams(biomechanics=Biomechanics(damping_rate_per_s=100.0, voluntary_gain_per_s2=1000.0))
    env = SitToStandEnv(personas=[Persona("edge", "stiffest allowed", params, 1.0)])
    for seed in range(20):  # about half of the draws vary damping above 100
        obs, info = env.reset(seed=seed)
        check_step(env, obs, 0.0, info, f"reset seed {seed}")
        for _ in range(20):
            obs, reward, _, _, info = env.step([2, 2, 0])
            check_step(env, obs, reward, info, f"seed {seed}")


def test_sample_person_near_a_bound_does_not_raise() -> None:
    persona = Persona("edge", "damping at its upper bound", PersonParams(Biomechanics(damping_rate_per_s=100.0)), 0.15)
    dampings = [
        sample_person(persona, np.random.default_rng(seed)).biomechanics.damping_rate_per_s for seed in range(20)
    ]
    assert max(dampings) > 100.0 > min(dampings)  # varied around the bound, beyond it on some seeds
    assert all(np.isfinite(dampings))


def teardown_module() -> None:
    for name, count in sorted(EXAMPLES.items()):
        print(f"hypothesis examples run: {name}: {count}")
