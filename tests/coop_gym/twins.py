"""An env that saw bad input must go on exactly like a twin that never did: the helpers that check it.

Shared by ``test_bad_input.py`` (the single env) and ``test_vector_bad_input.py`` (the vector
env), with the Markdown report both print when run as ``python -m tests.coop_gym.test_...``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from coop_gym.envs.sit_to_stand import SitToStandEnv

ENV_ID = "CoopGym/SitToStand-v0"


def assert_info_equal(a: dict[str, Any], b: dict[str, Any]) -> None:
    """Two infos hold the same keys and values (nested dicts compared key by key)."""
    assert a.keys() == b.keys()
    for key in a:
        if isinstance(a[key], dict):
            assert_info_equal(a[key], b[key])
        else:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def valid_actions(action_type: str, n: int, seed: int = 7) -> list[Any]:
    """A fixed sequence of valid actions (with a few lifts) of ``action_type``."""
    rng = np.random.default_rng(seed)
    out: list[Any] = []
    for _ in range(n):
        a = [int(rng.integers(3)), int(rng.integers(3)), int(rng.random() < 0.05)]
        if action_type == "discrete":
            out.append(int(np.ravel_multi_index(a, (3, 3, 2))))
        elif action_type == "continuous":
            out.append(np.array([a[0] - 1.0, a[1] * 0.9 - 0.9, 2.0 * a[2] - 1.0], dtype=np.float32))
        else:
            out.append(np.array(a))
    return out


def assert_same_future(env: gym.Env[Any, Any], twin: gym.Env[Any, Any], actions: list[Any]) -> None:
    """Step both with ``actions`` (resetting both when an episode ends): identical results."""
    for t, action in enumerate(actions):
        got, want = env.step(action), twin.step(action)
        np.testing.assert_array_equal(got[0], want[0], err_msg=f"obs at step {t}")
        assert got[1:4] == want[1:4], f"reward/terminated/truncated at step {t}"
        assert_info_equal(got[4], want[4])
        if got[2] or got[3]:
            got_reset, want_reset = env.reset(), twin.reset()
            np.testing.assert_array_equal(got_reset[0], want_reset[0])
            assert_info_equal(got_reset[1], want_reset[1])


def started_pair(seed: int = 3, steps: int = 4, **kwargs: Any) -> tuple[SitToStandEnv, SitToStandEnv]:
    """Two identical envs, reset with ``seed`` and stepped ``steps`` times."""
    pair = (SitToStandEnv(**kwargs), SitToStandEnv(**kwargs))
    action_type = kwargs.get("action_type", "multidiscrete")
    for env in pair:
        env.reset(seed=seed)
        for action in valid_actions(action_type, steps, seed=1):
            if env.step(action)[2]:
                env.reset()
    return pair


def vector_actions(n_envs: int, count: int, seed: int = 3, lift_probability: float = 0.05) -> list[np.ndarray]:
    """A fixed sequence of valid multidiscrete actions for ``n_envs`` envs (each lifts with ``lift_probability``)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        a = rng.integers(0, [3, 3, 2], size=(n_envs, 3))
        a[:, 2] = rng.random(n_envs) < lift_probability
        out.append(a)
    return out


def assert_same_vector_future(env: Any, twin: Any, actions: list[np.ndarray]) -> None:
    """Step both vector envs with ``actions``: identical results, env by env (they autoreset)."""
    for t, a in enumerate(actions):
        got, want = env.step(a), twin.step(a)
        for k in range(4):
            np.testing.assert_array_equal(got[k], want[k], err_msg=f"step {t}, item {k}")
        assert_info_equal(got[4], want[4])


def message(call: Callable[[], Any]) -> str:
    """What ``call`` raises, as ``Type: message`` (the bad-input reports' last column)."""
    try:
        call()
    except Exception as exc:  # the table reports whatever is raised
        return f"{type(exc).__name__}: {exc}"
    return "(accepted)"


def print_report(rows: list[tuple[str, str, str]]) -> None:
    """Print ``(where, bad input, raised)`` rows as a Markdown table."""
    print("| where | bad input | raised |\n|---|---|---|")
    for where, what, raised in rows:
        print(f"| {where} | {what} | {raised.replace('|', '/')} |")
