"""Numbers the README, the docs pages and the docstrings quote from the parameter dataclasses match the code.

Each case: a file, a regular expression whose groups are the quoted numbers, and the
values the dataclasses give. A prose number that drifts from its field fails here.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import pytest

import coop_gym
from coop_gym.envs.config import LiftCriteria, RewardWeights
from coop_gym.model.params import Cues, Intention, Timing
from coop_gym.model.personas import PERSONAS
from estimator.judgment import ThresholdJudgment

ROOT = Path(__file__).resolve().parents[1]
README = "README.md"
ENVIRONMENTS = "docs/environments.md"
AGENTS_PAGE = "docs/agents.md"
ESTIMATORS_PAGE = "docs/estimators.md"
BENCHMARKS = "docs/BENCHMARKS.md"
ENV = "coop_gym/envs/sit_to_stand.py"
JUDGMENT = "estimator/judgment.py"


def _variation_percent() -> tuple[float, ...]:
    stds = {p.variation_relative_std for p in PERSONAS.values()}
    assert len(stds) == 1, f"personas differ in variation ({stds}): the prose quotes one number"
    return (100 * stds.pop(),)


def _wide_variation() -> tuple[float, ...]:
    from coop_gym.model.personas import WIDE_VARIATION_STD

    return (WIDE_VARIATION_STD, _variation_percent()[0] / 100)


def _reward_weights() -> tuple[float, ...]:
    w = RewardWeights()
    return (w.success, w.unsafe, w.premature, w.time_per_s, w.force_per_n_s)


def _max_episode_steps() -> tuple[float, ...]:
    # The ids register no TimeLimit; each env reports its own length in its spec.
    steps = {gym.make(env_id).spec.max_episode_steps for env_id in coop_gym.ENV_IDS}
    assert len(steps) == 1
    return (float(steps.pop()),)


# The environment at a glance: the README's table, and the same table on the docs page.
ENV_TABLE_CASES: list[tuple[str, str, Callable[[], tuple[float, ...]]]] = [
    ("pushes", r"soft (\d+) N, firm (\d+) N", lambda: (Cues().soft_push_n, Cues().firm_push_n)),
    ("rate", r"(\d+) Hz simulation and filter", lambda: (1.0 / Timing().dt_s,)),
    ("action", r"agent acts every ([\d.]+) s", lambda: (Timing().action_period_s,)),
    ("episode", r"truncated at (\d+) s \((\d+) steps\)", lambda: (Timing().episode_s, *_max_episode_steps())),
    ("variation", r"~(\d+) % per-episode variation", _variation_percent),
    ("success", r"shoulder ≥ ([\d.]+) m forward", lambda: (LiftCriteria().success_lean_m,)),
    ("upright", r"upright \(< ([\d.]+) m\)", lambda: (LiftCriteria().upright_m,)),
    (
        "reward",
        r"\+(\d+) success, \u2212(\d+) unsafe, \u2212([\d.]+) premature, \u2212([\d.]+) per s, \u2212([\d.]+) per N·s",
        _reward_weights,
    ),
]

CASES: list[tuple[str, str, str, Callable[[], tuple[float, ...]]]] = [
    *[
        (f"{prefix}-{name}", path, pattern, expected)
        for name, pattern, expected in ENV_TABLE_CASES
        for prefix, path in (("readme", README), ("docs-environments", ENVIRONMENTS))
    ],
    ("docs-wide-variation", AGENTS_PAGE, r"has\nstd ([\d.]+) around its persona instead of ([\d.]+)", _wide_variation),
    (
        "docs-judgment-delay",
        ESTIMATORS_PAGE,
        r"filter ([\d.]+) s after the first cue",
        lambda: (ThresholdJudgment().delay_s,),
    ),
    ("readme-judgment-band", README, r"its ±([\d.]+) band", lambda: (ThresholdJudgment().threshold,)),
    (
        "docs-judgment-band",
        ESTIMATORS_PAGE,
        r"thresholds the `xi` estimate at ±([\d.]+)",
        lambda: (ThresholdJudgment().threshold,),
    ),
    ("docs-reaction-delay", BENCHMARKS, r"\(([\d.]+) s reaction delay\)", lambda: (Intention().reaction_delay_s,)),
    (
        "env-rate",
        ENV,
        r"run at\s+(\d+) Hz; the agent acts every ([\d.]+) s",
        lambda: (1.0 / Timing().dt_s, Timing().action_period_s),
    ),
    (
        "env-pushes",
        ENV,
        r"soft push \((\d+) N\), 2 firm push \((\d+) N\)",
        lambda: (Cues().soft_push_n, Cues().firm_push_n),
    ),
    ("env-continuous", ENV, r"\(a0 \+ 1\) / 2 \* (\d+) N", lambda: (Cues().firm_push_n,)),
    ("env-utterance", ENV, r"\((\d+) s long\)", lambda: (Cues().verbal_duration_s,)),
    ("env-success", ENV, r"shoulder at least ([\d.]+) m forward", lambda: (LiftCriteria().success_lean_m,)),
    ("env-upright", ENV, r"still upright \(< ([\d.]+) m\)", lambda: (LiftCriteria().upright_m,)),
    (
        "env-reward",
        ENV,
        r"``success``\s+\+(\d+) .*?``unsafe`` -(\d+) .*?``premature`` -([\d.]+)\s+.*?``time`` -([\d.]+) per second; "
        r"``force`` -([\d.]+) per newton-second",
        _reward_weights,
    ),
    (
        "env-episode",
        ENV,
        r"(\d+) s \((\d+) steps\) by the ``TimeLimit``",
        lambda: (Timing().episode_s, *_max_episode_steps()),
    ),
    ("env-variation", ENV, r"about (\d+) % variation", _variation_percent),
    (
        "judgment-paper",
        JUDGMENT,
        r"delay of ([\d.]+) s and ``t = ([\d.]+)``",
        lambda: (ThresholdJudgment().delay_s, ThresholdJudgment().threshold),
    ),
]


@pytest.mark.parametrize(
    ("path", "pattern", "expected"),
    [pytest.param(path, pattern, expected, id=name) for name, path, pattern, expected in CASES],
)
def test_quoted_number_matches_the_code(path: str, pattern: str, expected: Callable[[], tuple[float, ...]]) -> None:
    text = (ROOT / path).read_text(encoding="utf-8")
    match = re.search(pattern, text, flags=re.DOTALL)
    assert match is not None, f"{path}: no text matches {pattern!r} (reworded? update the case)"
    quoted = tuple(float(g) for g in match.groups())
    assert quoted == pytest.approx(expected()), f"{path} says {match.group(0)!r}; the code says {expected()}"
