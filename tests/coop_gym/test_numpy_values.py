"""NumPy scalars are numbers wherever Python numbers are (issue #13); NumPy bools and arrays are not.

A NumPy scalar handed to a parameter dataclass is stored as the Python number of the same
value, so nothing downstream computes in float32 or sees an ``np.int64`` where it expects an
``int``.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from coop_gym.envs.sit_to_stand import SitToStandEnv
from coop_gym.model.dynamics import simulate
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

LEVELS = (Biomechanics, Intention, Cooperativeness, Sensors, Cues, Timing)


def _numeric_fields(cls: type) -> list[tuple[str, Any]]:
    defaults = cls()
    return [
        (f.name, getattr(defaults, f.name))
        for f in dataclasses.fields(cls)
        if isinstance(getattr(defaults, f.name), (int, float)) and not isinstance(getattr(defaults, f.name), bool)
    ]


@pytest.mark.parametrize("cls", LEVELS, ids=lambda c: c.__name__)
@pytest.mark.parametrize("numpy_type", [np.float64, np.float32, np.int64, np.int32, np.uint8])
def test_every_numeric_field_takes_a_numpy_scalar_and_stores_a_python_number(cls: type, numpy_type: type) -> None:
    for name, default in _numeric_fields(cls):
        given = numpy_type(default)
        if float(given) != default or (isinstance(default, int) and not np.issubdtype(numpy_type, np.integer)):
            continue  # not the same value in this type (0.012 as an int), or a float for an int field
        obj = cls(**{name: given})
        stored = getattr(obj, name)
        assert type(stored) in (int, float), (name, type(stored))
        assert stored == given.item()


def test_timing_from_float32_and_int64() -> None:
    timing = Timing(dt_s=np.float32(0.02), substeps=np.int64(5))
    assert type(timing.dt_s) is float and timing.dt_s == float(np.float32(0.02))
    assert type(timing.substeps) is int and timing.substeps == 5
    assert timing.max_episode_steps == Timing(dt_s=float(np.float32(0.02))).max_episode_steps


def test_realism_switches_take_numpy_bools() -> None:
    realism = Realism(sensor_noise=np.False_, process_noise=np.True_)
    assert realism.sensor_noise is False and realism.process_noise is True
    assert Intention(saturate=np.False_).saturate is False


def test_an_env_built_from_numpy_values_is_the_env_built_from_python_ones() -> None:
    numpy_env = SitToStandEnv(
        timing={"dt_s": np.float64(0.02), "substeps": np.int64(5), "episode_s": np.float32(30.0)},
        cues={"soft_push_n": np.int64(10), "firm_push_n": np.float64(30.0)},
    )
    python_env = SitToStandEnv()
    for env in (numpy_env, python_env):
        env.reset(seed=4)
    for action in ([1, 2, 0], [2, 0, 0], [0, 1, 0], [0, 0, 1]):
        got, want = numpy_env.step(action), python_env.step(action)
        np.testing.assert_array_equal(got[0], want[0])
        assert got[1:4] == want[1:4]


def test_simulate_takes_a_numpy_initial_xi_and_names_a_bad_one() -> None:
    person = PersonParams()
    rng = np.random.default_rng(0)
    python = simulate(person, np.full(20, 10.0), np.ones(20), np.random.default_rng(1), initial_xi=1, hold_xi=True)
    from_numpy = simulate(
        person, np.full(20, 10.0), np.ones(20), np.random.default_rng(1), initial_xi=np.int64(1), hold_xi=True
    )
    np.testing.assert_array_equal(from_numpy.true_state, python.true_state)
    for bad, shown in ((np.array([1]), r"array\(\[1\]\)"), (np.True_, r"np\.True_"), (True, "True"), ("1", "'1'")):
        with pytest.raises(ValueError, match=rf"initial_xi must be -1, 0 or 1, got {shown}"):
            simulate(person, np.zeros(5), np.zeros(5), rng, initial_xi=bad)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (
            {"soft_push_n": 30.0, "firm_push_n": 10.0},
            r"Cues\.soft_push_n \(30\.0 N\) must be <= firm_push_n \(10\.0 N\)",
        ),
        ({"soft_push_n": np.float64(30.5)}, r"soft_push_n \(30\.5 N\) must be <= firm_push_n \(30\.0 N\)"),
    ],
)
def test_a_soft_push_stronger_than_the_firm_one_is_refused_naming_both(kwargs: dict[str, Any], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        Cues(**kwargs)
    assert Cues(soft_push_n=20.0, firm_push_n=20.0).soft_push_n == 20.0  # equal is allowed


@pytest.mark.parametrize(
    ("cls", "kwargs", "match"),
    [
        (Timing, {"dt_s": np.True_}, r"Timing\.dt_s must be a number, got np\.True_"),
        (Timing, {"dt_s": np.array([0.02])}, r"Timing\.dt_s must be a number, got array\(\[0\.02\]\)"),
        (Timing, {"dt_s": np.float32("nan")}, r"Timing\.dt_s must be in \[0\.0001, 0\.1\], got np\.float32\(nan\)"),
        (Timing, {"substeps": np.float64(5.0)}, r"Timing\.substeps must be an int in \[1, 100\], got np\.float64"),
        (Timing, {"substeps": np.array(5)}, r"Timing\.substeps must be an int in \[1, 100\], got array\(5\)"),
        (Biomechanics, {"damping_rate_per_s": np.complex128(6.0)}, r"Biomechanics\.damping_rate_per_s must be a num"),
        (Cooperativeness, {"baseline": np.array([1])}, r"Cooperativeness\.baseline must be -1, 0 or 1, got array"),
        (Cooperativeness, {"baseline": np.True_}, r"Cooperativeness\.baseline must be -1, 0 or 1, got np\.True_"),
        (Realism, {"sensor_noise": np.int64(1)}, r"Realism\.sensor_noise must be a bool, got np\.int64\(1\)"),
        (Intention, {"saturate": 1}, r"Intention\.saturate must be a bool, got 1"),
    ],
    ids=lambda v: v.__name__ if isinstance(v, type) else None,
)
def test_numpy_bools_and_arrays_are_not_numbers(cls: type, kwargs: dict[str, Any], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        cls(**kwargs)


def test_lift_criteria_and_reward_weights_take_numpy_scalars() -> None:
    from coop_gym.envs.config import LiftCriteria, RewardWeights

    assert LiftCriteria(success_lean_m=np.float32(0.15)).success_lean_m == float(np.float32(0.15))
    assert RewardWeights(success=np.float64(1.0)).success == 1.0
