"""The belief caregiver: probes with cues and lifts on the estimator's ``P(xi = +1)``.

It reads the mind through the switching particle filter (``estimator="switching"``,
:mod:`estimator.particle`), which models the hard level's person -- a push bends an
unresponsive person, an idle one leans on their own, willingness lapses and wears down
under pushing -- so a lean is evidence of cooperation only as far as the person model says.
The caregiver has no displacement rule of its own (unlike :class:`agents.caregivers.scripted.ProbingCaregiver`,
which lifts on a forward answer of ``answer_m``); it only chooses which cue to give:

1. **recruit**: a gentle push with "lean forward" for ``burst_s``, ended as soon as
   ``P(xi = +1) >= recruited_p`` (a guided push is what turns a person cooperative, and
   pushing on wears the willingness down), or, with ``recruit_until_m`` set, once the
   shoulder estimate reaches it (room left to answer a probe; off by default);
2. **settle**: silence for ``settle_s`` (the push's own motion dies out);
3. **probe**: "lean forward" with no push -- a cooperative person answers, a passive one does not
   move, a resisting one leans back -- watched for ``window_s``; then probe again while
   ``P(xi = +1) >= reprobe_p``, else recruit again. The words are said as the probe starts, or,
   with ``hold_words``, through the whole window (a person's intention moves only while a cue is
   heard, so a held request draws a longer answer; off by default).

It lifts while it watches a probe's answer, once ``P(xi = +1) >= lift_p`` and the shoulder
estimate is at least ``lean_m`` (what a safe lift needs of the posture: the success criterion
of :class:`coop_gym.envs.config.LiftCriteria`, 0.15 m, plus a margin for the reading). Not
during a burst or the settle after it: there the body still moves under the push, and a filter
that has the body slightly wrong reads that motion as the answer.

The settings were chosen on the TRAINING personas, each played with a filter whose hypotheses
were drawn around the OTHER training personas (``python -m agents.tune.belief``: meeting a kind
of person the caregiver has not seen is what the held-out personas test), one entry of
:data:`TUNED_BELIEF` per hard level (``agents.evaluate`` plays each level's), and are scored on
the held-out ones by :mod:`agents.evaluate`.

Example:
    >>> import gymnasium as gym
    >>> import coop_gym
    >>> env = gym.make("CoopGym/SitToStandHard-v2", estimator="switching")
    >>> agent = BeliefCaregiver.for_env(env)  # the settings chosen for the env's level
    >>> agent.settings == TUNED_BELIEF["hard-v2"]
    True
    >>> obs, _ = env.reset(seed=0)
    >>> action, _ = agent.predict(obs)
    >>> action.tolist()  # first step: recruit (soft push, "lean forward")
    [1, 2, 0]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from agents.base import LIFT, PUSH_NONE, PUSH_SOFT, VERBAL_FORWARD, VERBAL_NONE, WAIT
from agents.caregivers.scripted_base import EPS_S, PhaseState, ScriptedAgent
from estimator.validate import check_flag, check_number

__all__ = ["TUNED_BELIEF", "BeliefCaregiver", "BeliefSettings"]


@dataclass(frozen=True)
class BeliefSettings:
    """Settings of :class:`BeliefCaregiver` (see the module docstring for the cycle).

    Attributes:
        lift_p: Lift once ``P(xi = +1)`` is at least this (and the lean is ``lean_m``).
        lean_m: The shoulder estimate a lift needs [m].
        burst_s: Longest recruiting burst (soft push + "lean forward") [s].
        recruited_p: End a burst early once ``P(xi = +1)`` is at least this.
        settle_s: Silence between the burst and the probe [s].
        window_s: How long a probe is watched before the next cue [s].
        reprobe_p: After a probe window, probe again (no push) while ``P(xi = +1)`` is at least this.
        recruit_until_m: End a burst once the shoulder estimate reaches this [m]; None: no
            limit. Not chosen: on the training personas it changes nothing beyond the noise
            (docs/HARD_LEVEL.md, "The belief caregiver").
        hold_words: Say "lean forward" on every step of a probe window, not only as it starts.
            Not chosen, for the same reason (docs/HARD_LEVEL.md, "The belief caregiver on hard-v2").
    """

    lift_p: float = 0.85
    lean_m: float = 0.16
    burst_s: float = 2.0
    recruited_p: float = 0.5
    settle_s: float = 0.3
    window_s: float = 1.0
    reprobe_p: float = 0.5
    recruit_until_m: float | None = None
    hold_words: bool = False

    def __post_init__(self) -> None:
        """Validate ranges."""
        for name in ("lift_p", "recruited_p", "reprobe_p"):
            check_number(f"BeliefSettings.{name}", getattr(self, name), 0.0, 1.0)
        check_number("BeliefSettings.lean_m", self.lean_m, 0.0, 1.0)
        if self.recruit_until_m is not None:
            check_number("BeliefSettings.recruit_until_m", self.recruit_until_m, 0.0, 1.0)
        for name in ("burst_s", "settle_s", "window_s"):
            check_number(f"BeliefSettings.{name}", getattr(self, name), 0.0, 60.0)
        check_flag("BeliefSettings.hold_words", self.hold_words)


# Winners of `python -m agents.tune.belief --env ID` (its settings_grid, 128 episodes of each training
# persona from seed 1,000,000, each met by a filter drawn around the other four); the command prints every setting's
# success, and docs/HARD_LEVEL.md ("The belief caregiver") keeps the final table. Rerun after a model change.
TUNED_BELIEF: dict[str, BeliefSettings] = {
    # The grid was run on the hard levels only; the others play the defaults.
    "v0": BeliefSettings(),
    "easy": BeliefSettings(),
    "medium": BeliefSettings(),
    "hard": BeliefSettings(burst_s=3.0),
    # -v2's guided push recruits slower, so a burst ends at a lower P(xi = +1).
    "hard-v2": BeliefSettings(burst_s=3.0, recruited_p=0.3),
}
"""The belief caregiver's settings chosen on each hard level's training personas (``v0``: the ``-v0`` ids)."""


class BeliefCaregiver(ScriptedAgent):
    """Recruit, settle, probe with words alone; lift on ``P(xi = +1)`` (module docstring)."""

    name = "belief"
    needs = ("elapsed_s", "x_hat_m", "p_cooperative")
    settings_class = BeliefSettings
    tuned = TUNED_BELIEF
    RECRUIT, SETTLE, PROBE = 0, 1, 2

    def _decide(
        self, obs: NDArray[np.float64], memory: PhaseState, now: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
        s = self.settings
        p_cooperative, x_hat_m = self._column(obs, "p_cooperative"), self._column(obs, "x_hat_m")
        phase = memory.phase.copy()  # transitions are decided on the phase at the start of the step
        lift = (phase == self.PROBE) & (p_cooperative >= s.lift_p) & (x_hat_m >= s.lean_m)
        age = now - memory.phase_start_s
        # Recruit -> settle after one burst, or once recruited; settle -> probe (ask "lean forward" without a push).
        burst_over = (age >= s.burst_s - EPS_S) | (p_cooperative >= s.recruited_p)
        if s.recruit_until_m is not None:
            burst_over |= x_hat_m >= s.recruit_until_m
        memory.enter((phase == self.RECRUIT) & burst_over, self.SETTLE, now)
        asking = (phase == self.SETTLE) & (age >= s.settle_s - EPS_S)
        # A probe's window is over: ask again while cooperation is likely, else recruit again.
        over = (phase == self.PROBE) & (age >= s.window_s - EPS_S) & ~lift
        again = over & (p_cooperative >= s.reprobe_p)
        memory.enter(asking | again, self.PROBE, now)
        memory.enter(over & ~again, self.RECRUIT, now)
        asking |= again

        recruiting = (memory.phase == self.RECRUIT) & ~lift
        if s.hold_words:
            asking |= memory.phase == self.PROBE
        push = np.where(recruiting, PUSH_SOFT, PUSH_NONE)
        verbal = np.where((recruiting | asking) & ~lift, VERBAL_FORWARD, VERBAL_NONE)
        return push, verbal, np.where(lift, LIFT, WAIT)
