"""Bad input to the vector env: a clear error, and no env of the batch changed.

The vector env's twin of ``test_bad_input.py``: for each bad action, reset option or call
order, the exception and its message, then every env goes on exactly like a twin batch
that never saw the bad input.

``python -m tests.coop_gym.test_vector_bad_input`` prints every case with the message it
produces (a Markdown table).
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from tests.coop_gym.twins import ENV_ID, assert_same_vector_future, message, print_report, vector_actions


def _vector_env(n: int = 3, **kwargs: Any) -> Any:
    return gym.make_vec(ENV_ID, num_envs=n, **kwargs)


def _started_vector_pair() -> tuple[Any, Any]:
    """Two identical vector envs of 3, reset with seed 9 and stepped 5 times."""
    pair = _vector_env(), _vector_env()
    for e in pair:
        e.reset(seed=9)
        for a in vector_actions(3, 5):
            e.step(a)
    return pair


BAD_VECTOR_ACTIONS: list[tuple[str, Any, str]] = [
    ("one env's action", np.array([1, 2, 0]), r"action has shape \(3,\).*\(3, 3\) for 3 envs"),
    ("too many envs", np.zeros((4, 3), dtype=int), r"action has shape \(4, 3\).*\(3, 3\) for 3 envs"),
    ("NaN in one env", np.array([[0, 0, 0], [math.nan, 0, 0], [0, 0, 0]]), r"action contains NaN or inf"),
    ("out of range in one env", np.array([[0, 0, 0], [0, 3, 0], [0, 0, 0]]), r"multidiscrete action must be"),
    ("strings", np.array([["1", "2", "0"]] * 3), r"action must be numeric"),
    ("None", None, r"action must be numeric"),
    ("bools", np.ones((3, 3), dtype=bool), r"multidiscrete action must be numbers, not bools"),
    ("a bool cue in one env", [[0, 0, 0], [True, 2, False], [0, 0, 0]], r"multidiscrete action must be numbers, not"),
]


@pytest.mark.parametrize(
    ("action_type", "action"),
    [
        ("multidiscrete", [[0, 0, 0], [1, np.True_, 0]]),
        ("discrete", [3, True]),
        ("continuous", [[0.0, 0.0, 0.0], [0.5, False, -1.0]]),
    ],
)
def test_vector_env_refuses_a_bool_cue_on_every_action_type(action_type: str, action: Any) -> None:
    envs = _vector_env(2, action_type=action_type)
    envs.reset(seed=0)
    with pytest.raises(ValueError, match=rf"{action_type} action must be numbers, not bools"):
        envs.step(action)


@pytest.mark.parametrize(
    ("action", "match"), [c[1:] for c in BAD_VECTOR_ACTIONS], ids=[c[0] for c in BAD_VECTOR_ACTIONS]
)
def test_vector_env_bad_action_changes_no_env(action: Any, match: str) -> None:
    env, twin = _started_vector_pair()
    with pytest.raises(ValueError, match=match):
        env.step(action)
    assert_same_vector_future(env, twin, vector_actions(3, 320))  # crosses the time limit


BAD_VECTOR_RESETS: list[tuple[str, dict[str, Any], type[Exception], str]] = [
    ("options a str", {"options": "x"}, ValueError, r"reset options must be a dict, got str"),
    ("reset_mask a list", {"options": {"reset_mask": [True, False, True]}}, TypeError, r"must be a numpy array"),
    ("reset_mask shape", {"options": {"reset_mask": np.ones(2, dtype=bool)}}, ValueError, r"must have shape \(3,\)"),
    ("reset_mask empty", {"options": {"reset_mask": np.zeros(3, dtype=bool)}}, ValueError, r"at least one env"),
    ("unknown option", {"options": {"bogus": 1}}, ValueError, r"unknown reset option\(s\) \['bogus'\]"),
    ("bad initial_xi", {"options": {"initial_xi": 5}}, ValueError, r"initial_xi must be -1, 0 or 1"),
    ("seed list length", {"seed": [1, 2]}, ValueError, r"a list of seeds must have num_envs=3 entries"),
    ("negative seed", {"seed": -1}, ValueError, r"seed must be a non-negative int"),
    ("str seed", {"seed": "a"}, ValueError, r"seed must be None, an int or a list"),
]


@pytest.mark.parametrize(
    ("kwargs", "exc", "match"), [c[1:] for c in BAD_VECTOR_RESETS], ids=[c[0] for c in BAD_VECTOR_RESETS]
)
def test_vector_env_bad_reset_changes_no_env(kwargs: dict[str, Any], exc: type[Exception], match: str) -> None:
    env, twin = _started_vector_pair()
    with pytest.raises(exc, match=match):
        env.reset(**kwargs)
    assert_same_vector_future(env, twin, vector_actions(3, 100))


def test_vector_env_bad_construction_and_order() -> None:
    with pytest.raises(ValueError, match=r"num_envs must be a positive int, got 0"):
        _vector_env(0)
    with pytest.raises(ValueError, match=r"autoreset_mode must be an AutoresetMode or one of"):
        _vector_env(2, autoreset_mode="bogus")
    with pytest.raises(ValueError, match=r"unknown persona 'nobody'"):
        _vector_env(2, personas="nobody")
    with pytest.raises(ValueError, match=r"max_episode_steps must be a positive int or None, got 0"):
        _vector_env(2, max_episode_steps=0)
    env = _vector_env()
    with pytest.raises(RuntimeError, match=r"step\(\) called before reset\(\)"):
        env.step(np.zeros((3, 3), dtype=int))
    twin = _vector_env()
    for e in (env, twin):
        e.reset(seed=1)
    assert_same_vector_future(env, twin, vector_actions(3, 50))


def main() -> None:
    """Print every case and the message it produces, as a Markdown table."""
    rows: list[tuple[str, str, str]] = []
    for name, action, _ in BAD_VECTOR_ACTIONS:

        def vstep(a: Any = action) -> Any:
            env = gym.make_vec(ENV_ID, num_envs=3)
            env.reset(seed=0)
            return env.step(a)

        rows.append(("vector step (3 envs)", f"{name}: `{action!r}`".replace("\n", " "), message(vstep)))
    for name, kwargs, _, _ in BAD_VECTOR_RESETS:
        rows.append(
            ("vector reset", f"{name}: `{kwargs!r}`", message(lambda k=kwargs: gym.make_vec(ENV_ID, 3).reset(**k)))
        )
    rows.append(("vector order", "step before reset", message(lambda: gym.make_vec(ENV_ID, 3).step(None))))
    print_report(rows)


if __name__ == "__main__":
    main()
