"""Scripted caregivers: random, lift-at-once, push-then-lift, the handbook caregiver, the oracle, the prober.

Every agent is a :class:`agents.caregivers.scripted_base.ScriptedAgent`: SB3's ``predict`` over a batch,
features found by name, per-env phase memory (:class:`agents.caregivers.scripted_base.PhaseState`).
The belief caregiver, which reads the switching particle filter, is :mod:`agents.caregivers.belief`.

Example:
    >>> import gymnasium as gym
    >>> import coop_gym
    >>> env = gym.make("CoopGym/SitToStand-v0")
    >>> agent = HandbookCaregiver.for_env(env)
    >>> obs, _ = env.reset(seed=0)
    >>> action, state = agent.predict(obs)
    >>> action.tolist()  # first step: explain ("lean forward"), no push, no lift
    [0, 2, 0]
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from agents.base import (
    LIFT,
    PUSH_FIRM,
    PUSH_NONE,
    PUSH_SOFT,
    VERBAL_FORWARD,
    VERBAL_NONE,
    WAIT,
    require_features,
)
from agents.caregivers.belief import BeliefCaregiver
from agents.caregivers.blind import TUNED_BLIND, BlindAgent, BlindSettings, CuePhase
from agents.caregivers.scripted_base import EPS_S as _EPS_S
from agents.caregivers.scripted_base import PhaseState, ScriptedAgent
from coop_gym.envs.config import LiftCriteria
from coop_gym.model.difficulty import Difficulty
from estimator.judgment import ThresholdJudgment
from estimator.validate import check_number

__all__ = [
    "SCRIPTED_AGENTS",
    "TUNED_BLIND",
    "TUNED_PROBER",
    "BlindAgent",
    "BlindSettings",
    "CuePhase",
    "HandbookCaregiver",
    "HandbookSettings",
    "LiftAtOnceAgent",
    "OracleAgent",
    "OracleSettings",
    "PhaseState",
    "ProbingCaregiver",
    "ProbingSettings",
    "PushThenLiftAgent",
    "PushThenLiftSettings",
    "RandomAgent",
    "ScriptedAgent",
    "make_scripted",
]

_DEFAULT_LEAN_M = LiftCriteria().success_lean_m
_JUDGMENT_DELAY_S = ThresholdJudgment().delay_s


class RandomAgent(ScriptedAgent):
    """Uniformly random cues and lift decision every step (seeded; ignores ``deterministic``).

    Lifting with probability 1/2 each step, it usually lifts within the first steps: the
    floor every other agent must clear.
    """

    name = "random"

    def _decide(
        self, obs: NDArray[np.float64], memory: PhaseState, now: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
        n = obs.shape[0]
        draws = self.rng.integers(0, (3, 3, 2), size=(n, 3))
        return draws[:, 0], draws[:, 1], draws[:, 2]


class LiftAtOnceAgent(ScriptedAgent):
    """Lifts on the very first step, without any cue: what a robot unaware of the mind does."""

    name = "lift_at_once"

    def _decide(
        self, obs: NDArray[np.float64], memory: PhaseState, now: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
        n = obs.shape[0]
        return np.full(n, PUSH_NONE), np.full(n, VERBAL_NONE), np.full(n, LIFT)


@dataclass(frozen=True)
class PushThenLiftSettings:
    """Settings of :class:`PushThenLiftAgent`.

    Attributes:
        lean_m: Lift once the shoulder is estimated at least this far forward [m].
        escalate_after_s: Push gently this long, then firmly until leaning [s].
    """

    lean_m: float = _DEFAULT_LEAN_M
    escalate_after_s: float = 2.0

    def __post_init__(self) -> None:
        """Validate ranges."""
        check_number("PushThenLiftSettings.lean_m", self.lean_m, 0.0, 1.0)
        check_number("PushThenLiftSettings.escalate_after_s", self.escalate_after_s, 0.0, 3600.0)


class PushThenLiftAgent(ScriptedAgent):
    """Pushes until the person leans, then lifts -- ignoring the mental state (paper §I/§II).

    A gentle push first, then a firm one if the person has not leant after
    ``escalate_after_s``. No explanation is given and cooperativeness is never checked,
    so a frail person, whom a firm push moves a long way whatever they think, is lifted
    while resisting: the paper's failure scenario. Reads the filter's ``x_hat_m`` when
    the observation has it, else the measured shoulder position.
    """

    name = "push_then_lift"
    settings_class = PushThenLiftSettings

    def __init__(
        self,
        features: Sequence[str] | None = None,
        action_type: str = "multidiscrete",
        seed: int | None = None,
        settings: PushThenLiftSettings | None = None,
    ) -> None:
        """See :class:`ScriptedAgent`; it reads ``x_hat_m`` where the observation has it."""
        super().__init__(features, action_type, seed, settings)
        self.lean_feature = "x_hat_m" if "x_hat_m" in self.features else "measured_position_m"
        self.columns |= require_features(self.features, (self.lean_feature,), type(self).__name__)

    def _decide(
        self, obs: NDArray[np.float64], memory: PhaseState, now: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
        n = obs.shape[0]
        leaning = self._column(obs, self.lean_feature) >= self.settings.lean_m
        pushed_long = now - memory.phase_start_s >= self.settings.escalate_after_s - _EPS_S
        push = np.where(pushed_long, PUSH_FIRM, PUSH_SOFT)
        return np.where(leaning, PUSH_NONE, push), np.full(n, VERBAL_NONE), np.where(leaning, LIFT, WAIT)


@dataclass(frozen=True)
class HandbookSettings:
    """Settings of :class:`HandbookCaregiver` (defaults follow the paper's §II and §IV).

    Attributes:
        lean_m: Lift only once the filter's shoulder estimate is at least this far forward
            [m]: the centre of mass over the feet (``LiftCriteria.success_lean_m``) plus a
            small margin for estimation error.
        pause_s: Silence before each gentle push [s], so the push is a fresh cue onset and
            earns its own judgment (the judgment samples ``xi_hat`` a fixed delay after a
            cue's *onset*).
        judge_after_s: Push this long before reading the judgment [s] (the paper's 0.75 s
            sampling delay).
        pushes_per_explanation: Unresponsive push-and-judge rounds before explaining again
            (the explanation must still be fresh when the push comes).
        lean_patience_s: After a cooperative judgment, keep pushing gently and encouraging
            this long for the lean [s]; then re-check cooperativeness with a fresh push.
    """

    lean_m: float = _DEFAULT_LEAN_M + 0.01
    pause_s: float = 0.1
    judge_after_s: float = _JUDGMENT_DELAY_S
    pushes_per_explanation: int = 2
    lean_patience_s: float = 4.0

    def __post_init__(self) -> None:
        """Validate ranges."""
        check_number("HandbookSettings.lean_m", self.lean_m, 0.0, 1.0)
        check_number("HandbookSettings.pause_s", self.pause_s, 0.0, 60.0)
        check_number("HandbookSettings.judge_after_s", self.judge_after_s, 0.0, 60.0)
        check_number("HandbookSettings.lean_patience_s", self.lean_patience_s, 0.0, 3600.0)
        if isinstance(self.pushes_per_explanation, bool) or not isinstance(self.pushes_per_explanation, int):
            raise ValueError(
                f"HandbookSettings.pushes_per_explanation must be an int, got {self.pushes_per_explanation!r}"
            )
        if self.pushes_per_explanation < 1:
            raise ValueError(f"HandbookSettings.pushes_per_explanation must be >= 1, got {self.pushes_per_explanation}")


class HandbookCaregiver(ScriptedAgent):
    """The caregiving handbook of paper §II, run on the paper's thresholded judgment (§IV).

    1. **Explain** -- say "lean forward" (one utterance) before touching the person.
    2. **Pause** briefly, then **push gently** on the upper back: a fresh cue onset, so
       the filter's judgment is made for this push 0.75 s later.
    3. **Judge**: cooperative -> keep the gentle push and encourage ("lean forward")
       until the shoulder estimate shows the lean, then **lift**; unresponsive -> push
       again (after a pause), re-explaining every ``pushes_per_explanation`` rounds;
       uncooperative -> **re-explain** before touching again. A lean that does not come
       within ``lean_patience_s`` is re-judged with a fresh push.

    It lifts only while its latest judgment is cooperative *and* the estimated lean
    reaches ``lean_m``; otherwise it keeps guiding to the end and gives up by waiting,
    never by lifting unsafely. It never uses a firm push (startles) or "lean back"
    (confuses).
    """

    name = "handbook"
    needs = ("elapsed_s", "verbal_cue", "x_hat_m", "judgment")
    settings_class = HandbookSettings
    EXPLAIN, PAUSE, PUSH, LEAN = 0, 1, 2, 3

    def _decide(
        self, obs: NDArray[np.float64], memory: PhaseState, now: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
        s = self.settings
        silent = self._column(obs, "verbal_cue") == 0.0
        judgment = self._column(obs, "judgment")
        leaning = self._column(obs, "x_hat_m") >= s.lean_m
        age = now - memory.phase_start_s
        phase = memory.phase.copy()  # transitions are decided on the phase at the start of the step

        # Explain: the utterance has been spoken (flag) and has finished playing.
        done_explaining = (phase == self.EXPLAIN) & memory.flag & silent
        memory.enter(done_explaining, self.PAUSE, now)
        memory.count[done_explaining] = 0
        # Pause: a real silence (no push, nothing playing) so the next push is a new onset.
        done_pausing = (phase == self.PAUSE) & (age >= s.pause_s - _EPS_S) & silent
        memory.enter(done_pausing, self.PUSH, now)
        # Push: the judgment for this push's onset is in.
        judged = (phase == self.PUSH) & (age >= s.judge_after_s - _EPS_S)
        cooperative = judged & (judgment > 0.5)
        uncooperative = judged & (judgment < -0.5)
        unresponsive = judged & ~cooperative & ~uncooperative
        memory.count[unresponsive] += 1
        again = unresponsive & (memory.count < s.pushes_per_explanation)
        memory.enter(cooperative, self.LEAN, now)
        memory.enter(again, self.PAUSE, now)
        memory.enter(uncooperative | (unresponsive & ~again), self.EXPLAIN, now)
        # Lean: the lean did not come; re-judge with a fresh push.
        impatient = (phase == self.LEAN) & (age >= s.lean_patience_s - _EPS_S) & ~leaning
        memory.enter(impatient, self.PAUSE, now)

        phase = memory.phase
        lift = (phase == self.LEAN) & leaning & (judgment > 0.5)
        speak = (phase == self.EXPLAIN) & ~memory.flag & silent
        memory.flag |= speak
        encourage = (phase == self.LEAN) & silent & ~lift
        push = np.where(((phase == self.PUSH) | (phase == self.LEAN)) & ~lift, PUSH_SOFT, PUSH_NONE)
        verbal = np.where(speak | encourage, VERBAL_FORWARD, VERBAL_NONE)
        return push, verbal, np.where(lift, LIFT, WAIT)


@dataclass(frozen=True)
class OracleSettings:
    """Settings of :class:`OracleAgent`.

    Attributes:
        lean_m: Lift once cooperative and the shoulder estimate is at least this far
            forward [m] (``LiftCriteria.success_lean_m`` plus a margin for estimation error).
    """

    lean_m: float = _DEFAULT_LEAN_M + 0.01

    def __post_init__(self) -> None:
        """Validate ranges."""
        check_number("OracleSettings.lean_m", self.lean_m, 0.0, 1.0)


class OracleAgent(ScriptedAgent):
    """Sees the true ``xi`` (the oracle observation's ``true_xi``): an upper bound.

    Lifts exactly when the person is cooperative and leaning enough; otherwise explains
    ("lean forward", repeated whenever silent, so the explanation is always fresh) and
    pushes gently -- the combination that turns people cooperative fastest without
    startling them.
    """

    name = "oracle"
    needs = ("elapsed_s", "verbal_cue", "x_hat_m", "true_xi")

    settings_class = OracleSettings
    default_observation = "oracle"

    def _decide(
        self, obs: NDArray[np.float64], memory: PhaseState, now: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
        cooperative = self._column(obs, "true_xi") > 0.5
        lift = cooperative & (self._column(obs, "x_hat_m") >= self.settings.lean_m)
        silent = self._column(obs, "verbal_cue") == 0.0
        push = np.where(lift, PUSH_NONE, PUSH_SOFT)
        verbal = np.where(silent & ~lift, VERBAL_FORWARD, VERBAL_NONE)
        return push, verbal, np.where(lift, LIFT, WAIT)


# --- the probing caregiver: reads the mind from the answer to a cue ---


@dataclass(frozen=True)
class ProbingSettings:
    """Settings of :class:`ProbingCaregiver` (see the module docstring for the cycle).

    The defaults are the hard level's (:data:`TUNED_PROBER`), as :class:`BlindAgent`'s are.

    Attributes:
        burst_s: Length of a recruiting burst (soft push + "lean forward") [s].
        push_below_m: Push only while the shoulder estimate is behind this [m].
        settle_s: Silence between the burst and the probe [s].
        window_s: How long a probe's answer is watched for [s].
        answer_m: Forward displacement since the probe began that counts as an answer [m].
        lean_m: Lift only with the shoulder estimate at least this far forward [m].
    """

    burst_s: float = 1.0
    push_below_m: float = 0.32
    settle_s: float = 0.1
    window_s: float = 1.2
    answer_m: float = 0.03
    lean_m: float = 0.16

    def __post_init__(self) -> None:
        """Validate ranges."""
        for name in ("burst_s", "settle_s", "window_s"):
            check_number(f"ProbingSettings.{name}", getattr(self, name), 0.0, 60.0)
        for name in ("push_below_m", "answer_m", "lean_m"):
            check_number(f"ProbingSettings.{name}", getattr(self, name), 0.0, 1.0)


# Winners of `python -m agents.tune.baselines prober --level LEVEL` (its 36 settings, 300 episodes each
# of the training personas from seed 1,000,000); the command prints every setting's success, and docs/HARD_LEVEL.md
# ("The prober") keeps the final table. Rerun after a model change.
TUNED_PROBER: dict[str, ProbingSettings] = {
    # A tie on these levels: the first in grid order.
    "v0": ProbingSettings(push_below_m=0.25, answer_m=0.012),
    "easy": ProbingSettings(push_below_m=0.25, answer_m=0.012),
    "medium": ProbingSettings(push_below_m=0.25),
    "hard": ProbingSettings(),
    "hard-v2": ProbingSettings(),
}
"""The probing caregiver's settings chosen on each level's training personas (``v0``: the ``-v0`` ids)."""


class ProbingCaregiver(ScriptedAgent):
    """Recruit, settle, probe with words alone, lift on a forward answer (module docstring)."""

    name = "prober"
    needs = ("elapsed_s", "x_hat_m")
    settings_class = ProbingSettings
    tuned = TUNED_PROBER
    RECRUIT, SETTLE, PROBE = 0, 1, 2

    def _decide(
        self, obs: NDArray[np.float64], memory: PhaseState, now: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
        s = self.settings
        x = self._column(obs, "x_hat_m")
        age = now - memory.phase_start_s
        phase = memory.phase.copy()  # transitions are decided on the phase at the start of the step
        # Probe: the answer is in (lift), or the window passed without one (recruit again).
        answered = (phase == self.PROBE) & (x - memory.anchor >= s.answer_m) & (x >= s.lean_m)
        memory.enter((phase == self.PROBE) & ~answered & (age >= s.window_s - _EPS_S), self.RECRUIT, now)
        # Settle -> probe: remember where the shoulder was when the question was asked.
        asking = (phase == self.SETTLE) & (age >= s.settle_s - _EPS_S)
        memory.enter(asking, self.PROBE, now)
        memory.anchor[asking] = x[asking]
        # Recruit -> settle after one burst.
        memory.enter((phase == self.RECRUIT) & (age >= s.burst_s - _EPS_S), self.SETTLE, now)

        recruiting = memory.phase == self.RECRUIT
        push = np.where(recruiting & (x < s.push_below_m), PUSH_SOFT, PUSH_NONE)
        verbal = np.where(recruiting | asking, VERBAL_FORWARD, VERBAL_NONE)
        return push, verbal, np.where(answered, LIFT, WAIT)


SCRIPTED_AGENTS: dict[str, type[ScriptedAgent]] = {
    cls.name: cls
    for cls in (
        RandomAgent,
        LiftAtOnceAgent,
        PushThenLiftAgent,
        HandbookCaregiver,
        OracleAgent,
        BlindAgent,
        ProbingCaregiver,
        BeliefCaregiver,
    )
}
"""Scripted agents by name."""


def make_scripted(
    name: str,
    features: Sequence[str] | None = None,
    action_type: str = "multidiscrete",
    seed: int | None = None,
    level: str | Difficulty | None = None,
) -> ScriptedAgent:
    """Build a scripted agent by name (see :data:`SCRIPTED_AGENTS`).

    ``level`` (a difficulty or its name, or None for the ``-v0`` ids) picks the blind, probing
    and belief caregivers' settings chosen for that level (:data:`TUNED_BLIND`,
    :data:`TUNED_PROBER`, :data:`agents.caregivers.belief.TUNED_BELIEF`); the other agents do not depend
    on it. A level of your own has no chosen settings: build ``BlindAgent(settings=...)``,
    ``ProbingCaregiver(settings=...)`` or ``BeliefCaregiver(settings=...)``.
    """
    if name not in SCRIPTED_AGENTS:
        raise ValueError(f"unknown scripted agent {name!r}; known: {', '.join(SCRIPTED_AGENTS)}")
    cls = SCRIPTED_AGENTS[name]
    settings = None if cls.tuned is None else cls.chosen_settings(level)
    return cls(features, action_type, seed, settings=settings)
