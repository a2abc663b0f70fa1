"""The mental-state-blind baselines: a fixed schedule of cues and a lift rule on the lean and the clock.

A blind caregiver never reads the cue-response evidence: it plays its own schedule of cue
phases (push, words, duration; then repeated, or a routine held to the end) and lifts once the
shoulder estimate has shown a lean for long enough, at the times its schedule allows. It reads
only ``elapsed_s``, ``verbal_cue`` (its own utterance) and ``x_hat_m``. The best of the family
on each level (:data:`TUNED_BLIND`, searched by :mod:`agents.tune.baselines`) anchors the value
of reading the mind and every mind-reading score.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.base import LIFT, PUSH_BY_NAME, PUSH_NONE, VERBAL_BY_NAME, VERBAL_NONE, WAIT
from agents.caregivers.scripted_base import EPS_S as _EPS_S
from agents.caregivers.scripted_base import PhaseState, ScriptedAgent
from coop_gym.envs.config import LiftCriteria
from estimator.validate import check_flag, check_number

__all__ = ["TUNED_BLIND", "BlindAgent", "BlindSettings", "CuePhase"]

_DEFAULT_LEAN_M = LiftCriteria().success_lean_m


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
        if self.push not in PUSH_BY_NAME:
            raise ValueError(f"CuePhase.push must be one of {list(PUSH_BY_NAME)}, got {self.push!r}")
        if self.verbal not in VERBAL_BY_NAME:
            raise ValueError(f"CuePhase.verbal must be one of {list(VERBAL_BY_NAME)}, got {self.verbal!r}")
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
        if self.push not in PUSH_BY_NAME:
            raise ValueError(f"BlindSettings.push must be one of {list(PUSH_BY_NAME)}, got {self.push!r}")
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
            push[r, : len(phases)] = [PUSH_BY_NAME[p.push] for p in phases]
            verbal[r, : len(phases)] = [VERBAL_BY_NAME[p.verbal] for p in phases]
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


# Winners of `python -m agents.tune.baselines blind --level LEVEL` (the coarse-to-fine search of that
# module's docstring on the training personas from seed 1,000,000); the command prints the finalists' success on its
# final 1000 episodes, and docs/HARD_LEVEL.md ("The blind family") keeps the final table. Rerun after a
# model change.
_EXPLAIN_AND_GUIDE = (CuePhase("soft", "forward", 1.0), CuePhase("none", "forward", 2.0))
TUNED_BLIND: dict[str, BlindSettings] = {
    # One routine held from the start (a member of the original one-routine family).
    "v0": BlindSettings(push="soft", words=True, lean_m=0.12, hold_s=1.0),
    "easy": BlindSettings(push="soft", words=True, lean_m=0.12, hold_s=1.0),
    # A guided push for 1 s, then 2 s of words alone, over and over; lift on a 0.16-m lean. A short push
    # recruits without bending a passive person far, and a person never left idle does not lean alone.
    "medium": BlindSettings(lean_m=0.16, schedule=_EXPLAIN_AND_GUIDE, repeat=True),
    "hard": BlindSettings(lean_m=0.16, schedule=_EXPLAIN_AND_GUIDE, repeat=True),
    "hard-v2": BlindSettings(lean_m=0.16, schedule=_EXPLAIN_AND_GUIDE, repeat=True),
}
"""The tuned blind policy of each level (``v0``: the ``-v0`` ids)."""


class BlindAgent(ScriptedAgent):
    """A fixed cue schedule with a lift rule on the lean and the clock: never reads the mind.

    It reads three features and nothing else: ``elapsed_s`` (its clock, which sets the
    schedule's phase), ``verbal_cue`` (whether its own utterance is still playing, so
    words are repeated only when silent) and ``x_hat_m`` (the filter's shoulder estimate,
    for the lift rule). No estimate of ``xi``, judgment or ``P(xi)`` ever enters; see
    :class:`BlindSettings` for the schedule and the rule.

    ``settings`` is one :class:`BlindSettings` for every env, or a sequence giving env
    ``i`` its own (how :mod:`agents.tune.baselines` scores many candidates in one batched env).
    """

    name = "blind"
    needs = ("elapsed_s", "verbal_cue", "x_hat_m")
    tuned = TUNED_BLIND
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
