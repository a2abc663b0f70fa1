"""The declared gymnasium range is the tested one: both checkers pass at its lowest and highest version.

The default install takes the newest gymnasium (1.4.0 here), so the ``highest`` test runs
in every default run; the ``lowest`` one runs in a venv pinned to the lower bound, which the
README's test command builds after the default suite (``scripts/test_other_installs.sh``)::

    python -m venv .venv-gymlow && . .venv-gymlow/bin/activate
    pip install "torch==2.13.0" "gymnasium==1.1.1" -e ".[train,test]"
    python -m pytest tests/coop_gym/test_gymnasium_range.py

Each is skipped (saying why) under any other version. Gymnasium 1.0 lacks
``gymnasium.vector.AutoresetMode``; ray[rllib] 2.60 pins 1.2.2, inside the range.
"""

from __future__ import annotations

import warnings
from importlib.metadata import requires
from typing import Any

import gymnasium as gym
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from packaging.requirements import Requirement
from packaging.specifiers import SpecifierSet

import coop_gym

LOWEST_SUPPORTED = "1.1.1"
HIGHEST_TESTED = "1.4.0"


def _declared_range() -> SpecifierSet:
    """The gymnasium requirement of the installed coop_gym (pyproject's ``dependencies``)."""
    for text in requires("coop_gym") or []:
        requirement = Requirement(text)
        if requirement.name == "gymnasium" and requirement.marker is None:
            return requirement.specifier
    raise AssertionError("coop_gym declares no gymnasium requirement")


def test_declared_range_starts_at_the_tested_lower_bound_and_holds_the_installed_version():
    declared = _declared_range()
    assert {(s.operator, s.version) for s in declared} == {(">=", LOWEST_SUPPORTED), ("<", "2")}
    assert declared.contains(gym.__version__)
    assert declared.contains(HIGHEST_TESTED)


def _check_every_id() -> None:
    env_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    for env_id in sorted(coop_gym.ENV_IDS):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            # Gymnasium's own nudge to the level's newer version (Hard...-v2): the one warning allowed.
            warnings.filterwarnings("ignore", r".*SitToStandHard\w*-v1 is out of date", DeprecationWarning)
            env: Any = gym.make(env_id)
            gym_check_env(env.unwrapped)
            env_checker.check_env(env.unwrapped, warn=True)
            env.close()
        vec = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point")
        obs, _ = vec.reset(seed=0)
        assert obs.shape[0] == 3
        vec.step(vec.action_space.sample())
        vec.close()


@pytest.mark.skipif(gym.__version__ != LOWEST_SUPPORTED, reason=f"runs under gymnasium=={LOWEST_SUPPORTED} only")
def test_checkers_pass_on_the_lowest_supported_gymnasium():
    _check_every_id()


@pytest.mark.skipif(gym.__version__ != HIGHEST_TESTED, reason=f"runs under gymnasium=={HIGHEST_TESTED} only")
def test_checkers_pass_on_the_highest_tested_gymnasium():
    _check_every_id()
