"""Bad input everywhere a user can hand something in: a clear error, and nothing broken.

For each bad constructor argument, action, reset option or call order: the exception type,
a message naming the problem, and -- for an env already running -- that the env then goes
on exactly like a twin that never saw the bad input (same observations, rewards, infos).

``python -m tests.coop_gym.test_bad_input`` prints every case with the message it produces
(a Markdown table); the vector env's cases are in ``test_vector_bad_input.py``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import coop_gym
from coop_gym.envs.sit_to_stand import SitToStandEnv
from coop_gym.model.params import PersonParams, Timing
from coop_gym.model.personas import Persona
from tests.coop_gym.twins import ENV_ID, assert_same_future, message, print_report, started_pair, valid_actions

# --------------------------------------------------------------------------- constructor

edge_persona = Persona("slow", "a long reaction delay", PersonParams())
BAD_KWARGS: list[tuple[str, Callable[[], dict[str, Any]], type[Exception], str]] = [
    ("unknown persona", lambda: {"personas": "nobody"}, ValueError, r"unknown persona 'nobody'; known: typical"),
    ("empty persona list", lambda: {"personas": []}, ValueError, r"personas must be .* got \[\]"),
    ("persona not a name", lambda: {"personas": 42}, ValueError, r"personas must be .* got 42"),
    ("None in persona list", lambda: {"personas": ["typical", None]}, ValueError, r"personas must be .* got None"),
    ("bad observation_mode", lambda: {"observation_mode": "pixels"}, ValueError, r"observation_mode must be one of"),
    ("observation_mode None", lambda: {"observation_mode": None}, ValueError, r"observation_mode must be one of"),
    ("bad action_type", lambda: {"action_type": "box"}, ValueError, r"action_type must be one of .* got 'box'"),
    ("bad estimator", lambda: {"estimator": "particle"}, ValueError, r"estimator must be one of .* got 'particle'"),
    ("bad render_mode", lambda: {"render_mode": "ascii"}, ValueError, r"render_mode must be None or one of"),
    ("unknown realism key", lambda: {"realism": {"telepathy": True}}, ValueError, r"unknown Realism field.*telepathy"),
    ("realism not bool", lambda: {"realism": {"sensor_noise": "yes"}}, ValueError, r"Realism\.sensor_noise must be"),
    ("realism a string", lambda: {"realism": "off"}, ValueError, r"realism must be a Realism, a dict"),
    ("timing dt 0", lambda: {"timing": {"dt_s": 0.0}}, ValueError, r"Timing\.dt_s must be in"),
    ("timing dt NaN", lambda: {"timing": {"dt_s": math.nan}}, ValueError, r"Timing\.dt_s must be in"),
    ("timing substeps float", lambda: {"timing": {"substeps": 2.5}}, ValueError, r"Timing\.substeps must be an int"),
    ("timing episode < 0", lambda: {"timing": {"episode_s": -1.0}}, ValueError, r"Timing\.episode_s must be in"),
    ("unknown timing key", lambda: {"timing": {"dt": 0.02}}, ValueError, r"unknown Timing field.*'dt'"),
    (
        "dt too fine for reaction delay",
        lambda: {"timing": {"dt_s": 0.001}},
        ValueError,
        r"Intention\.reaction_delay_s=0\.3 is 300 steps",
    ),
    ("cues negative push", lambda: {"cues": {"soft_push_n": -5.0}}, ValueError, r"Cues\.soft_push_n must be in"),
    ("cues inf push", lambda: {"cues": {"firm_push_n": math.inf}}, ValueError, r"Cues\.firm_push_n must be in"),
    ("reward NaN", lambda: {"reward": {"success": math.nan}}, ValueError, r"RewardWeights\.success must be a finite"),
    ("reward negative", lambda: {"reward": {"unsafe": -2.0}}, ValueError, r"RewardWeights\.unsafe must be in"),
    ("reward wrong dataclass", lambda: {"reward": Timing()}, ValueError, r"reward must be a RewardWeights.*got Timing"),
    ("lift upright > success", lambda: {"lift": {"upright_m": 0.5}}, ValueError, r"LiftCriteria\.upright_m must be in"),
    ("lift not a number", lambda: {"lift": {"success_lean_m": "far"}}, ValueError, r"LiftCriteria\.success_lean_m"),
    ("judgment threshold 0", lambda: {"judgment": {"threshold": 0}}, ValueError, r"ThresholdJudgment\.threshold"),
    ("judgment delay < 0", lambda: {"judgment": {"delay_s": -1.0}}, ValueError, r"ThresholdJudgment\.delay_s"),
    ("unknown judgment key", lambda: {"judgment": {"window": 1}}, ValueError, r"unknown ThresholdJudgment field"),
    ("estimator_options str", lambda: {"estimator_options": "fast"}, ValueError, r"estimator_options must be a dict"),
    (
        "estimator_options for kalman",
        lambda: {"estimator_options": {"probability_floor": 0.1}},
        ValueError,
        r"estimator='kalman' takes none",
    ),
    (
        "unknown multiple-model option",
        lambda: {"estimator": "multiple_model", "estimator_options": {"bogus": 1}},
        ValueError,
        r"estimator_options for 'multiple_model'.*bogus",
    ),
    (
        "bad multiple-model option value",
        lambda: {"estimator": "imm", "estimator_options": {"probability_floor": 0.5}},
        ValueError,
        r"probability_floor must be in \[0, 1/3\)",
    ),
    ("unknown kwarg", lambda: {"bogus": 1}, TypeError, r"unexpected keyword argument 'bogus'"),
    # Issue #13: NumPy scalars count as numbers (tests/coop_gym/test_numpy_values.py), NumPy bools
    # and arrays do not; a soft push stronger than the firm one.
    ("timing dt np.bool_", lambda: {"timing": {"dt_s": np.True_}}, ValueError, r"Timing\.dt_s must be a number"),
    ("timing dt array", lambda: {"timing": {"dt_s": np.array([0.02])}}, ValueError, r"Timing\.dt_s must be a number"),
    ("timing substeps bool", lambda: {"timing": {"substeps": True}}, ValueError, r"Timing\.substeps must be an int"),
    (
        "timing substeps np.bool_",
        lambda: {"timing": {"substeps": np.True_}},
        ValueError,
        r"Timing\.substeps must be an int in \[1, 100\], got np\.True_",
    ),
    (
        "timing substeps np.float64",
        lambda: {"timing": {"substeps": np.float64(5.0)}},
        ValueError,
        r"Timing\.substeps must be an int",
    ),
    (
        "timing substeps np.int64 0",
        lambda: {"timing": {"substeps": np.int64(0)}},
        ValueError,
        r"Timing\.substeps must be an int in \[1, 100\], got np\.int64\(0\)",
    ),
    (
        "cues soft push > firm push",
        lambda: {"cues": {"soft_push_n": 30.0, "firm_push_n": 10.0}},
        ValueError,
        r"Cues\.soft_push_n \(30\.0 N\) must be <= firm_push_n \(10\.0 N\)",
    ),
    (
        "cues soft push > default firm push",
        lambda: {"cues": {"soft_push_n": np.float32(40.0)}},
        ValueError,
        r"Cues\.soft_push_n \(40\.0 N\) must be <= firm_push_n \(30\.0 N\)",
    ),
    ("realism np.str_", lambda: {"realism": {"sensor_noise": np.str_("yes")}}, ValueError, r"Realism\.sensor_noise"),
]


@pytest.mark.filterwarnings("ignore:.*render_mode.*:UserWarning")  # gym.make's own warning, before ours
@pytest.mark.parametrize(("kwargs", "exc", "match"), [c[1:] for c in BAD_KWARGS], ids=[c[0] for c in BAD_KWARGS])
def test_bad_constructor_argument(kwargs: Callable[[], dict[str, Any]], exc: type[Exception], match: str) -> None:
    with pytest.raises(exc, match=match):
        SitToStandEnv(**kwargs())
    with pytest.raises(exc, match=match):  # gym.make passes the kwargs through unchanged
        gym.make(ENV_ID, **kwargs())


BAD_PERSONAS: list[tuple[str, Callable[[], Any], str]] = [
    ("variation > 1", lambda: Persona("x", "y", PersonParams(), 2.0), r"Persona\.variation_relative_std"),
    ("variation NaN", lambda: Persona("x", "y", PersonParams(), math.nan), r"Persona\.variation_relative_std"),
    ("params a dict", lambda: Persona("x", "y", {"biomechanics": {}}), r"Persona\.params must be a PersonParams"),
    ("name not a str", lambda: Persona(3, "y", PersonParams()), r"Persona\.name must be a non-empty str"),
]


@pytest.mark.parametrize(("make", "match"), [c[1:] for c in BAD_PERSONAS], ids=[c[0] for c in BAD_PERSONAS])
def test_bad_persona(make: Callable[[], Any], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        make()


def test_persona_delay_is_checked_against_dt_at_construction_not_at_reset() -> None:
    from coop_gym.model.params import Intention

    slow = Persona("slow", "longest delay", PersonParams(intention=Intention(reaction_delay_s=1.2)))
    SitToStandEnv(personas=[slow])  # 60 steps of 20 ms fit the delay line
    with pytest.raises(ValueError, match=r"reaction_delay_s=1\.2 is 67 steps"):
        SitToStandEnv(personas=[slow], timing={"dt_s": 0.018})
    # A persona without delay is fine at any dt (the core used to pack a default person).
    instant = Persona("instant", "no delay", PersonParams(intention=Intention(reaction_delay_s=0.0)))
    env = SitToStandEnv(personas=[instant], timing={"dt_s": 1e-4, "substeps": 100})
    env.reset(seed=0)
    assert np.all(np.isfinite(env.step([1, 2, 0])[0]))


def test_a_failed_construction_leaves_the_registry_working() -> None:
    with pytest.raises(ValueError):
        gym.make(ENV_ID, personas="nobody")
    env, twin = gym.make(ENV_ID), SitToStandEnv()
    for e in (env, twin):
        e.reset(seed=11)
    assert_same_future(env, twin, valid_actions("multidiscrete", 50))


# --------------------------------------------------------------------------- actions

BAD_ACTIONS: list[tuple[str, str, Any, str]] = [
    ("multidiscrete", "too short", [1, 2], r"action has shape \(1, 2\); the multidiscrete action space needs \(3,\)"),
    ("multidiscrete", "too long", [1, 2, 0, 0], r"action has shape \(1, 4\).* needs \(3,\)"),
    ("multidiscrete", "batched", [[1, 2, 0]], r"action has shape \(1, 1, 3\).* needs \(3,\)"),
    ("multidiscrete", "ragged", [1, [2], 0], r"action could not be read as an array"),
    ("multidiscrete", "push 3", [3, 0, 0], r"multidiscrete action must be \[push 0\.\.2, verbal 0\.\.2, lift 0\.\.1\]"),
    ("multidiscrete", "negative", [-1, 0, 0], r"multidiscrete action must be \[push 0\.\.2"),
    ("multidiscrete", "lift 2", np.array([0, 0, 2]), r"multidiscrete action must be \[push 0\.\.2"),
    ("multidiscrete", "non-integer", [1.5, 0, 0], r"multidiscrete action must be integers"),
    ("multidiscrete", "NaN", [math.nan, 0, 0], r"action contains NaN or inf"),
    ("multidiscrete", "inf", np.array([0.0, math.inf, 0.0]), r"action contains NaN or inf"),
    ("multidiscrete", "huge", [1e300, 0, 0], r"multidiscrete action must be \[push 0\.\.2"),
    ("multidiscrete", "beyond int64", [10**30, 0, 0], r"action must be numeric, got dtype object"),
    ("multidiscrete", "string", "abc", r"action must be numeric, got dtype <U3"),
    ("multidiscrete", "strings", ["1", "2", "0"], r"action must be numeric, got dtype <U1"),
    ("multidiscrete", "None", None, r"action must be numeric, got dtype object"),
    ("multidiscrete", "dict", {"push": 1}, r"action must be numeric, got dtype object"),
    ("multidiscrete", "complex", np.array([1, 2, 0], dtype=complex), r"action must be numeric, got dtype complex128"),
    ("discrete", "18", 18, r"discrete action must be in \[0, 17\]"),
    ("discrete", "negative", -1, r"discrete action must be in \[0, 17\]"),
    ("discrete", "non-integer", 2.5, r"discrete action must be integers"),
    ("discrete", "NaN", math.nan, r"action contains NaN or inf"),
    ("discrete", "inf", -math.inf, r"action contains NaN or inf"),
    ("discrete", "a list", [3], r"action has shape \(1, 1\); the discrete action space needs \(\)"),
    ("discrete", "a triple", [1, 2, 0], r"action has shape \(1, 3\); the discrete action space needs \(\)"),
    ("discrete", "string", "3", r"action must be numeric"),
    ("discrete", "None", None, r"action must be numeric, got dtype object"),
    ("discrete", "True", True, r"discrete action must be numbers, not bools, got \[True\]"),
    ("discrete", "numpy False", np.bool_(False), r"discrete action must be numbers, not bools"),
    ("multidiscrete", "bools", np.array([True, False, True]), r"multidiscrete action must be numbers, not bools"),
    # Issue #21: a bool among numbers (np.asarray makes [True, 2, False] an int array) on every action type.
    ("multidiscrete", "a bool cue", [True, 2, False], r"multidiscrete action must be numbers, not bools"),
    ("multidiscrete", "a numpy bool cue", (1, np.True_, 0), r"multidiscrete action must be numbers, not bools"),
    ("discrete", "a bool in a list", [True], r"discrete action must be numbers, not bools"),
    ("continuous", "a bool cue", [True, 0.5, -1.0], r"continuous action must be numbers, not bools"),
    ("continuous", "bools", np.array([True, False, True]), r"continuous action must be numbers, not bools"),
    ("continuous", "above 1", np.array([0.0, 0.0, 1.5], dtype=np.float32), r"continuous action must lie in \[-1, 1\]"),
    ("continuous", "below -1", [-2.0, 0.0, 0.0], r"continuous action must lie in \[-1, 1\]"),
    ("continuous", "NaN", np.array([math.nan, 0, 0], dtype=np.float32), r"action contains NaN or inf"),
    ("continuous", "inf", [0.0, math.inf, 0.0], r"action contains NaN or inf"),
    ("continuous", "too short", [0.0, 0.0], r"action has shape \(1, 2\); the continuous action space needs \(3,\)"),
    ("continuous", "scalar", 0.5, r"action has shape \(1,\); the continuous action space needs \(3,\)"),
    ("continuous", "string", "0.5", r"action must be numeric"),
    ("continuous", "None", None, r"action must be numeric, got dtype object"),
]


@pytest.mark.parametrize(
    ("action_type", "action", "match"),
    [(c[0], c[2], c[3]) for c in BAD_ACTIONS],
    ids=[f"{c[0]}-{c[1]}" for c in BAD_ACTIONS],
)
def test_bad_action_raises_and_changes_nothing(action_type: str, action: Any, match: str) -> None:
    env, twin = started_pair(action_type=action_type)
    with pytest.raises(ValueError, match=match):
        env.step(action)
    assert_same_future(env, twin, valid_actions(action_type, 40))


@pytest.mark.parametrize("action", [[math.nan, 0, 0], [3, 0, 0], "abc"], ids=["NaN", "out of range", "string"])
def test_bad_action_through_gym_make_does_not_count_as_a_step(action: Any) -> None:
    """Through the registered wrappers: same error, and TimeLimit truncates at the same step."""
    env, twin = gym.make(ENV_ID), gym.make(ENV_ID)
    for e in (env, twin):
        e.reset(seed=5)
        e.step([0, 0, 0])
    with pytest.raises(ValueError):
        env.step(action)
    assert_same_future(env, twin, [np.array([1, 2, 0])] * 305)


def test_several_bad_actions_in_a_row_change_nothing() -> None:
    env, twin = started_pair()
    for action in (b[2] for b in BAD_ACTIONS if b[0] == "multidiscrete"):
        with pytest.raises(ValueError):
            env.step(action)
    assert_same_future(env, twin, valid_actions("multidiscrete", 100))


# --------------------------------------------------------------------------- reset

BAD_RESETS: list[tuple[str, dict[str, Any], type[Exception], str]] = [
    ("unknown option", {"options": {"bogus": 1}}, ValueError, r"unknown reset option\(s\) \['bogus'\]"),
    ("unknown persona", {"options": {"persona": "nobody"}}, ValueError, r"persona='nobody' is not one of this env's"),
    (
        "held-out persona",
        {"options": {"persona": "frail"}},
        ValueError,
        r"persona='frail' is not one of this env's \['typical'",
    ),
    ("persona not a name", {"options": {"persona": 3}}, ValueError, r"persona=3 is not one of this env's"),
    ("persona a list", {"options": {"persona": ["typical"]}}, ValueError, r"persona=\['typical'\] is not one of"),
    ("initial_xi 2", {"options": {"initial_xi": 2}}, ValueError, r"initial_xi must be -1, 0 or 1, got 2"),
    ("initial_xi 0.5", {"options": {"initial_xi": 0.5}}, ValueError, r"initial_xi must be -1, 0 or 1, got 0\.5"),
    ("initial_xi str", {"options": {"initial_xi": "1"}}, ValueError, r"initial_xi must be -1, 0 or 1, got '1'"),
    ("initial_xi bool", {"options": {"initial_xi": True}}, ValueError, r"initial_xi must be -1, 0 or 1, got True"),
    ("initial_xi NaN", {"options": {"initial_xi": math.nan}}, ValueError, r"initial_xi must be -1, 0 or 1, got nan"),
    ("options a str", {"options": "typical"}, ValueError, r"reset options must be a dict, got str"),
    ("options a list", {"options": [("persona", "typical")]}, ValueError, r"reset options must be a dict, got list"),
    ("negative seed", {"seed": -1}, gym.error.Error, r"Seed must be greater or equal to zero"),
    ("str seed", {"seed": "abc"}, gym.error.Error, r"Seed must be a python integer"),
    ("float seed", {"seed": 1.5}, gym.error.Error, r"Seed must be a python integer"),
    # Issue #13: a NumPy array or bool as initial_xi is refused by name (parse_reset_options' check_choice).
    (
        "initial_xi array",
        {"options": {"initial_xi": np.array([1])}},
        ValueError,
        r"initial_xi must be -1, 0 or 1, got array",
    ),
    (
        "initial_xi np.bool_",
        {"options": {"initial_xi": np.True_}},
        ValueError,
        r"initial_xi must be -1, 0 or 1, got np\.True_",
    ),
]


@pytest.mark.parametrize(("kwargs", "exc", "match"), [c[1:] for c in BAD_RESETS], ids=[c[0] for c in BAD_RESETS])
def test_bad_reset_mid_episode_raises_and_changes_nothing(kwargs: dict[str, Any], exc: type, match: str) -> None:
    env, twin = started_pair()
    with pytest.raises(exc, match=match):
        env.reset(**kwargs)
    # The episode in progress goes on untouched, and so do later resets.
    assert_same_future(env, twin, valid_actions("multidiscrete", 60))


@pytest.mark.parametrize(("kwargs", "exc", "match"), [c[1:] for c in BAD_RESETS], ids=[c[0] for c in BAD_RESETS])
def test_bad_first_reset_leaves_a_fresh_env(kwargs: dict[str, Any], exc: type, match: str) -> None:
    env, twin = SitToStandEnv(), SitToStandEnv()
    with pytest.raises(exc, match=match):
        env.reset(**kwargs)
    with pytest.raises(RuntimeError, match=r"called before reset\(\)"):
        env.step([0, 0, 0])
    for e in (env, twin):
        e.reset(seed=21)
    assert_same_future(env, twin, valid_actions("multidiscrete", 40))


def test_valid_reset_options_are_honoured() -> None:
    env = SitToStandEnv(personas="all")
    for persona in coop_gym.PERSONAS:
        for xi in (-1, 0, 1):
            _, info = env.reset(seed=0, options={"persona": persona, "initial_xi": xi})
            assert (info["persona"], info["true_xi"]) == (persona, xi)


# --------------------------------------------------------------------------- call order


def test_step_before_reset() -> None:
    env = SitToStandEnv()
    with pytest.raises(RuntimeError, match=r"step\(\) called before reset\(\) or after the episode ended"):
        env.step([0, 0, 0])
    wrapped = gym.make(ENV_ID)
    with pytest.raises(gym.error.ResetNeeded, match=r"Cannot call env\.step\(\) before calling env\.reset\(\)"):
        wrapped.step([0, 0, 0])
    twin = SitToStandEnv()
    for e in (env, twin):
        e.reset(seed=2)
    assert_same_future(env, twin, valid_actions("multidiscrete", 30))


def _lifted(make: Callable[..., gym.Env[Any, Any]]) -> tuple[gym.Env[Any, Any], gym.Env[Any, Any]]:
    """Two envs whose episode a lift has just ended."""
    pair = make(), make()
    for e in pair:
        e.reset(seed=4)
        assert e.step([0, 0, 1])[2]  # lift: terminated
    return pair


def _timed_out(make: Callable[..., gym.Env[Any, Any]]) -> tuple[gym.Env[Any, Any], gym.Env[Any, Any]]:
    """Two envs whose episode clock has just truncated their episode (the raw env refuses steps as after a lift)."""
    pair = make(timing={"episode_s": 0.5}), make(timing={"episode_s": 0.5})
    for e in pair:
        e.reset(seed=6)
        ends = [e.step([1, 2, 0])[2:4] for _ in range(5)]
        assert ends == [(False, False)] * 4 + [(False, True)]  # 5 steps of 0.1 s: truncated, not terminated
    return pair


@pytest.mark.parametrize(
    ("ended", "make", "retry"),
    [
        (_lifted, SitToStandEnv, [0, 0, 0]),
        (_lifted, lambda **kwargs: gym.make(ENV_ID, **kwargs), [0, 0, 0]),
        (_timed_out, SitToStandEnv, [0, 0, 1]),
    ],
    ids=["terminated-raw", "terminated-gym.make", "truncated-raw"],
)
def test_step_after_the_episode_ended(
    ended: Callable[..., tuple[gym.Env[Any, Any], gym.Env[Any, Any]]],
    make: Callable[..., gym.Env[Any, Any]],
    retry: list[int],
) -> None:
    env, twin = ended(make)
    with pytest.raises(RuntimeError, match=r"after the episode ended; call reset\(\)"):
        env.step([0, 0, 0])
    with pytest.raises(RuntimeError):  # still refused, however often
        env.step(retry)
    for e in (env, twin):
        e.reset()
    assert_same_future(env, twin, valid_actions("multidiscrete", 30))


def test_close_twice_and_step_after_close_reset() -> None:
    env = SitToStandEnv(render_mode="rgb_array")
    env.reset(seed=0)
    env.render()
    env.close()
    env.close()
    env.reset(seed=0)  # a closed env can still be reset and stepped (it only lost its window)
    assert env.step([1, 2, 0])[0].shape == env.observation_space.shape


# --------------------------------------------------------------------------- report


def main() -> None:
    """Print every case and the message it produces, as a Markdown table."""
    rows: list[tuple[str, str, str]] = []
    for name, kwargs, _, _ in BAD_KWARGS:
        rows.append(("SitToStandEnv(...)", f"{name}: `{kwargs()!r}`", message(lambda k=kwargs: SitToStandEnv(**k()))))
    for name, make, _ in BAD_PERSONAS:
        rows.append(("Persona(...)", name, message(make)))
    for action_type, name, action, _ in BAD_ACTIONS:

        def step(a: Any = action, t: str = action_type) -> Any:
            env = SitToStandEnv(action_type=t)
            env.reset(seed=0)
            return env.step(a)

        rows.append((f"step ({action_type})", f"{name}: `{action!r}`", message(step)))
    for name, kwargs, _, _ in BAD_RESETS:
        rows.append(("reset(...)", f"{name}: `{kwargs!r}`", message(lambda k=kwargs: SitToStandEnv().reset(**k))))
    rows.append(("order", "step before reset", message(lambda: SitToStandEnv().step([0, 0, 0]))))

    def after_lift() -> Any:
        env = SitToStandEnv()
        env.reset(seed=0)
        env.step([0, 0, 1])
        return env.step([0, 0, 0])

    rows.append(("order", "step after termination", message(after_lift)))
    print_report(rows)


if __name__ == "__main__":
    main()
