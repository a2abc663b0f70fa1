"""Scripted baselines: random, lift-at-once, push-then-lift, the handbook caregiver, the oracle.

Every agent is a :class:`agents.scripted_base.ScriptedAgent`: SB3's ``predict`` over a batch,
features found by name, per-env phase memory (:class:`agents.scripted_base.PhaseState`).
The belief caregiver, which reads the switching particle filter, is :mod:`agents.belief`.

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
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.base import (
    LIFT,
    PUSH_FIRM,
    PUSH_NONE,
    PUSH_SOFT,
    VERBAL_BACK,
    VERBAL_FORWARD,
    VERBAL_NONE,
    WAIT,
    require_features,
)
from agents.belief import BeliefCaregiver
from agents.scripted_base import EPS_S as _EPS_S
from agents.scripted_base import PhaseState, ScriptedAgent
from compiled.checks import check_flag, check_number
from coop_gym.envs.config import LiftCriteria
from coop_gym.envs.contract import observation_features
from estimator.judgment import ThresholdJudgment

__all__ = [
    "SCRIPTED_AGENTS",
    "TUNED_BLIND",
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

    def __init__(
        self,
        features: Sequence[str] | None = None,
        action_type: str = "multidiscrete",
        seed: int | None = None,
        settings: PushThenLiftSettings | None = None,
    ) -> None:
        """See :class:`ScriptedAgent`; ``settings`` default to :class:`PushThenLiftSettings`."""
        super().__init__(features, action_type, seed)
        self.settings = settings or PushThenLiftSettings()
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
    EXPLAIN, PAUSE, PUSH, LEAN = 0, 1, 2, 3

    def __init__(
        self,
        features: Sequence[str] | None = None,
        action_type: str = "multidiscrete",
        seed: int | None = None,
        settings: HandbookSettings | None = None,
    ) -> None:
        """See :class:`ScriptedAgent`; ``settings`` default to :class:`HandbookSettings`."""
        super().__init__(features, action_type, seed)
        self.settings = settings or HandbookSettings()

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

    def __init__(
        self,
        features: Sequence[str] | None = None,
        action_type: str = "multidiscrete",
        seed: int | None = None,
        settings: OracleSettings | None = None,
    ) -> None:
        """See :class:`ScriptedAgent`; the default features are the oracle observation's."""
        super().__init__(
            features if features is not None else observation_features("oracle", "kalman"), action_type, seed
        )
        self.settings = settings or OracleSettings()

    def _decide(
        self, obs: NDArray[np.float64], memory: PhaseState, now: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
        cooperative = self._column(obs, "true_xi") > 0.5
        lift = cooperative & (self._column(obs, "x_hat_m") >= self.settings.lean_m)
        silent = self._column(obs, "verbal_cue") == 0.0
        push = np.where(lift, PUSH_NONE, PUSH_SOFT)
        verbal = np.where(silent & ~lift, VERBAL_FORWARD, VERBAL_NONE)
        return push, verbal, np.where(lift, LIFT, WAIT)


# --- mental-state-blind baselines (tuned and searched in agents/tune_baselines.py) ---

_PUSHES = {"none": PUSH_NONE, "soft": PUSH_SOFT, "firm": PUSH_FIRM}
_VERBALS = {"none": VERBAL_NONE, "forward": VERBAL_FORWARD, "back": VERBAL_BACK}
# Slack on the schedule's phase boundaries: elapsed_s arrives as float32 (off by ~1e-6 s at 30 s),
# far below the 0.1-s agent step, so a phase of 1.0 s lasts exactly ten steps.
_CLOCK_SLACK_S = 1e-3


@dataclass(frozen=True)
class CuePhase:
    """One phase of a blind cue schedule: which cues, for how long, and whether a lift may come in it.

    Attributes:
        push: ``"none"``, ``"soft"`` or ``"firm"``: the push held through the phase.
        verbal: ``"none"``, ``"forward"`` or ``"back"``: the words said (again whenever silent)
            through the phase.
        duration_s: How long the phase lasts [s] (at least one 0.1-s agent step).
        lift: Whether the lift rule may lift during this phase.
    """

    push: str = "none"
    verbal: str = "none"
    duration_s: float = 1.0
    lift: bool = True

    def __post_init__(self) -> None:
        """Validate choices and ranges."""
        if self.push not in _PUSHES:
            raise ValueError(f"CuePhase.push must be one of {list(_PUSHES)}, got {self.push!r}")
        if self.verbal not in _VERBALS:
            raise ValueError(f"CuePhase.verbal must be one of {list(_VERBALS)}, got {self.verbal!r}")
        check_number("CuePhase.duration_s", self.duration_s, 0.1, 3600.0)
        check_flag("CuePhase.lift", self.lift)


@dataclass(frozen=True)
class BlindSettings:
    """Settings of :class:`BlindAgent`: a fixed cue schedule and a lift rule on the lean and the clock.

    The **schedule** runs on the episode clock alone: the phases of ``schedule`` in order,
    each for its ``duration_s``; then either the whole schedule again (``repeat``) or the
    *final phase* -- ``push`` and ``words`` -- held to the end. With an empty schedule the
    final phase is all there is (the original one-routine blind family).

    The **lift rule** reads only the shoulder estimate ``x_hat_m`` and the clock: lift once
    the lean (``x_hat_m >= lean_m``) has held ``hold_s``, no earlier than ``min_time_s``,
    during a phase whose ``lift`` flag is set (``final_lift`` for the final phase); and,
    from ``last_call_s`` on, on any lean of at least ``last_call_lean_m`` (a last chance
    before the time limit). With ``release_on_lean`` every cue stops while the person leans.

    Attributes:
        push: ``"none"``, ``"soft"`` or ``"firm"``: the push of the final phase.
        words: Say "lean forward" (repeated whenever silent) in the final phase.
        lean_m: Lift once the shoulder estimate is at least this far forward [m].
        min_time_s: Never lift before this much of the episode has passed [s].
        release_on_lean: Stop pushing and talking while the person leans (push until lean).
        hold_s: The lean must have held this long before a lift [s].
        schedule: The opening phases (:class:`CuePhase`), played in order from the start.
        repeat: Play ``schedule`` over and over (the final phase is then never reached).
        final_lift: Whether the lift rule may lift during the final phase.
        last_call_s: From this episode time on, lift on a lean of ``last_call_lean_m``
            whatever the phase, timer and hold [s]; None: no last call.
        last_call_lean_m: The lean a last-call lift needs [m].
    """

    push: str = "soft"
    words: bool = True
    lean_m: float = 0.16
    min_time_s: float = 0.0
    release_on_lean: bool = False
    hold_s: float = 0.0
    schedule: tuple[CuePhase, ...] = ()
    repeat: bool = False
    final_lift: bool = True
    last_call_s: float | None = None
    last_call_lean_m: float = _DEFAULT_LEAN_M

    def __post_init__(self) -> None:
        """Validate choices and ranges (each error names its field)."""
        if self.push not in _PUSHES:
            raise ValueError(f"BlindSettings.push must be one of {list(_PUSHES)}, got {self.push!r}")
        for name in ("words", "release_on_lean", "repeat", "final_lift"):
            check_flag(f"BlindSettings.{name}", getattr(self, name))
        check_number("BlindSettings.lean_m", self.lean_m, 0.0, 1.0)
        check_number("BlindSettings.min_time_s", self.min_time_s, 0.0, 3600.0)
        check_number("BlindSettings.hold_s", self.hold_s, 0.0, 3600.0)
        if not isinstance(self.schedule, tuple) or not all(isinstance(p, CuePhase) for p in self.schedule):
            raise ValueError(f"BlindSettings.schedule must be a tuple of CuePhase, got {self.schedule!r}")
        if self.repeat and not self.schedule:
            raise ValueError("BlindSettings.repeat needs a non-empty BlindSettings.schedule to repeat")
        if self.last_call_s is not None:
            check_number("BlindSettings.last_call_s", self.last_call_s, 0.0, 3600.0)
        check_number("BlindSettings.last_call_lean_m", self.last_call_lean_m, 0.0, 1.0)

    @property
    def phases(self) -> tuple[CuePhase, ...]:
        """The schedule's phases followed, without ``repeat``, by the held final phase."""
        if self.repeat:
            return self.schedule
        final = CuePhase(self.push, "forward" if self.words else "none", 3600.0, self.final_lift)
        return (*self.schedule, final)


@dataclass(frozen=True)
class _BlindTable:
    """Blind settings as arrays, one row per setting (one row serves every env).

    ``phase_end_s[r, k]`` is the schedule time at which phase ``k`` ends (``inf`` past the
    last); the phase at schedule time ``t`` is the number of ends ``<= t``, which reaches the
    final phase's column after the last opening phase.
    """

    phase_end_s: NDArray[np.float64]  # (R, P)
    cycle_s: NDArray[np.float64]  # (R,) schedule length when repeating, else inf
    push: NDArray[np.int64]  # (R, P + 1)
    verbal: NDArray[np.int64]  # (R, P + 1)
    lift_ok: NDArray[np.bool_]  # (R, P + 1)
    lean_m: NDArray[np.float64]  # (R,)
    min_time_s: NDArray[np.float64]
    hold_s: NDArray[np.float64]
    release: NDArray[np.bool_]
    last_call_s: NDArray[np.float64]
    last_call_lean_m: NDArray[np.float64]

    @classmethod
    def of(cls, settings: Sequence[BlindSettings]) -> _BlindTable:
        rows = len(settings)
        width = max(len(s.schedule) for s in settings)
        ends = np.full((rows, width), np.inf)
        push = np.zeros((rows, width + 1), dtype=np.int64)
        verbal = np.zeros((rows, width + 1), dtype=np.int64)
        lift_ok = np.zeros((rows, width + 1), dtype=bool)
        for r, s in enumerate(settings):
            phases = s.phases
            ends[r, : len(s.schedule)] = np.cumsum([p.duration_s for p in s.schedule])
            push[r, : len(phases)] = [_PUSHES[p.push] for p in phases]
            verbal[r, : len(phases)] = [_VERBALS[p.verbal] for p in phases]
            lift_ok[r, : len(phases)] = [p.lift for p in phases]

        def column(get: Any) -> NDArray[Any]:
            return np.array([get(s) for s in settings])

        return cls(
            phase_end_s=ends,
            cycle_s=column(lambda s: sum(p.duration_s for p in s.schedule) if s.repeat else np.inf),
            push=push,
            verbal=verbal,
            lift_ok=lift_ok,
            lean_m=column(lambda s: s.lean_m),
            min_time_s=column(lambda s: s.min_time_s),
            hold_s=column(lambda s: s.hold_s),
            release=column(lambda s: s.release_on_lean).astype(bool),
            last_call_s=column(lambda s: np.inf if s.last_call_s is None else s.last_call_s),
            last_call_lean_m=column(lambda s: s.last_call_lean_m),
        )


class BlindAgent(ScriptedAgent):
    """A fixed cue schedule with a lift rule on the lean and the clock: never reads the mind.

    It reads three features and nothing else: ``elapsed_s`` (its clock, which sets the
    schedule's phase), ``verbal_cue`` (whether its own utterance is still playing, so
    words are repeated only when silent) and ``x_hat_m`` (the filter's shoulder estimate,
    for the lift rule). No estimate of ``xi``, judgment or ``P(xi)`` ever enters; see
    :class:`BlindSettings` for the schedule and the rule.

    ``settings`` is one :class:`BlindSettings` for every env, or a sequence giving env
    ``i`` its own (how :mod:`agents.tune_baselines` scores many candidates in one batched env).
    """

    name = "blind"
    needs = ("elapsed_s", "verbal_cue", "x_hat_m")
    GUIDE, LEANING = 0, 1

    def __init__(
        self,
        features: Sequence[str] | None = None,
        action_type: str = "multidiscrete",
        seed: int | None = None,
        settings: BlindSettings | Sequence[BlindSettings] | None = None,
    ) -> None:
        """See :class:`ScriptedAgent`; ``settings`` default to the hard level's tuned ones."""
        super().__init__(features, action_type, seed)
        if settings is None:
            settings = TUNED_BLIND["hard"]
        per_env = not isinstance(settings, BlindSettings)
        rows: tuple[BlindSettings, ...] = tuple(settings) if not isinstance(settings, BlindSettings) else (settings,)
        if not rows or not all(isinstance(s, BlindSettings) for s in rows):
            raise ValueError(
                f"BlindAgent settings must be a BlindSettings or a non-empty sequence of them, got {settings!r}"
            )
        self.settings: BlindSettings | tuple[BlindSettings, ...] = rows if per_env else rows[0]
        self._table = _BlindTable.of(rows)
        self._per_env = per_env

    def _decide(
        self, obs: NDArray[np.float64], memory: PhaseState, now: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
        n = obs.shape[0]
        t = self._table
        if self._per_env and t.lean_m.shape[0] != n:
            raise ValueError(f"BlindAgent has settings for {t.lean_m.shape[0]} envs, got {n} observations")
        row = np.arange(n) if self._per_env else np.zeros(n, dtype=np.int64)
        x = self._column(obs, "x_hat_m")
        silent = self._column(obs, "verbal_cue") == 0.0
        # The schedule's phase follows from the clock alone (modulo the cycle when repeating).
        position_s = np.mod(now + _CLOCK_SLACK_S, t.cycle_s[row])
        phase = np.sum(t.phase_end_s[row] <= position_s[:, None], axis=1)
        leaning = x >= t.lean_m[row]
        # The lean's clock: phase LEANING starts when the lean appears, ends when it is lost.
        memory.enter(leaning & (memory.phase == self.GUIDE), self.LEANING, now)
        memory.enter(~leaning & (memory.phase == self.LEANING), self.GUIDE, now)
        held = now - memory.phase_start_s >= t.hold_s[row] - _EPS_S
        lift = leaning & held & (now >= t.min_time_s[row] - _EPS_S) & t.lift_ok[row, phase]
        lift |= (now >= t.last_call_s[row] - _EPS_S) & (x >= t.last_call_lean_m[row])
        guiding = ~lift & ~(leaning & t.release[row])
        push = np.where(guiding, t.push[row, phase], PUSH_NONE)
        verbal = np.where(guiding & silent, t.verbal[row, phase], VERBAL_NONE)
        return push, verbal, np.where(lift, LIFT, WAIT)


# Winners of `python -m agents.tune_baselines blind --level LEVEL` (the coarse-to-fine search of that module's
# docstring on the training personas from seed 1,000,000; success on its final 1000 episodes in the comments).
# Rerun after a model change.
_EXPLAIN_AND_GUIDE = (CuePhase("soft", "forward", 1.0), CuePhase("none", "forward", 2.0))
TUNED_BLIND: dict[str, BlindSettings] = {
    # One routine held from the start (a member of the original family): 100.0 % (as the original winner).
    "v0": BlindSettings(push="soft", words=True, lean_m=0.12, hold_s=1.0),
    "easy": BlindSettings(push="soft", words=True, lean_m=0.12, hold_s=1.0),
    # A guided push for 1 s, then 2 s of words alone, over and over; lift on a 0.16-m lean: 89.1 % (original
    # family's winner on the same episodes: 74.9 %).
    "medium": BlindSettings(lean_m=0.16, schedule=_EXPLAIN_AND_GUIDE, repeat=True),
    # The same schedule and rule: 80.2 % (original family's winner: 59.8 %).
    "hard": BlindSettings(lean_m=0.16, schedule=_EXPLAIN_AND_GUIDE, repeat=True),
}
"""The tuned blind policy of each level (``v0``: the ``-v0`` ids)."""


# --- the probing caregiver: reads the mind from the answer to a cue ---


@dataclass(frozen=True)
class ProbingSettings:
    """Settings of :class:`ProbingCaregiver` (see the module docstring for the cycle).

    Attributes:
        burst_s: Length of a recruiting burst (soft push + "lean forward") [s].
        push_below_m: Push only while the shoulder estimate is behind this [m].
        settle_s: Silence between the burst and the probe [s].
        window_s: How long a probe's answer is watched for [s].
        answer_m: Forward displacement since the probe began that counts as an answer [m].
        lean_m: Lift only with the shoulder estimate at least this far forward [m].
    """

    burst_s: float = 0.5
    push_below_m: float = 0.32
    settle_s: float = 0.3
    window_s: float = 1.2
    answer_m: float = 0.02
    lean_m: float = 0.16

    def __post_init__(self) -> None:
        """Validate ranges."""
        for name in ("burst_s", "settle_s", "window_s"):
            check_number(f"ProbingSettings.{name}", getattr(self, name), 0.0, 60.0)
        for name in ("push_below_m", "answer_m", "lean_m"):
            check_number(f"ProbingSettings.{name}", getattr(self, name), 0.0, 1.0)


class ProbingCaregiver(ScriptedAgent):
    """Recruit, settle, probe with words alone, lift on a forward answer (module docstring)."""

    name = "prober"
    needs = ("elapsed_s", "x_hat_m")
    RECRUIT, SETTLE, PROBE = 0, 1, 2

    def __init__(
        self,
        features: Sequence[str] | None = None,
        action_type: str = "multidiscrete",
        seed: int | None = None,
        settings: ProbingSettings | None = None,
    ) -> None:
        """See :class:`ScriptedAgent`; ``settings`` default to :class:`ProbingSettings`."""
        super().__init__(features, action_type, seed)
        self.settings = settings or ProbingSettings()

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
    level: str | None = None,
) -> ScriptedAgent:
    """Build a scripted agent by name (see :data:`SCRIPTED_AGENTS`).

    ``level`` (a difficulty name, or None for the ``-v0`` ids) picks the blind policy tuned
    for that level (:data:`TUNED_BLIND`); the other agents do not depend on it.
    """
    if name not in SCRIPTED_AGENTS:
        raise ValueError(f"unknown scripted agent {name!r}; known: {', '.join(SCRIPTED_AGENTS)}")
    if name == BlindAgent.name:
        return BlindAgent(features, action_type, seed, settings=TUNED_BLIND[level or "v0"])
    return SCRIPTED_AGENTS[name](features, action_type, seed)
