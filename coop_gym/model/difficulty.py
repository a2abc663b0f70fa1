"""Difficulty levels: how much of the hidden mental state a caregiver must read to succeed.

In the paper's linear model (``-v0``, and the ``easy`` level) the intention moves forward
only while ``xi = +1``, and ``+1`` is absorbing under a gentle routine, so "leaning" is a
sufficient statistic for "cooperative": a policy that never reads the mind (push gently,
say "lean forward", lift once the shoulder is forward) succeeds as often as the oracle.

The harder levels switch on the failure scenarios of the paper (§III) and changes of mind,
each a documented knob of :mod:`coop_gym.model.params`, applied to every persona:

* **pushed lean without cooperation** (``Intention.passive_follow_rate_per_s``): an
  unresponsive person bent forward by a push stays bent, so a pushed lean looks like a
  voluntary one;
* **looking ready while not ready** (``Intention.spontaneous_lean_rate_per_s``): an
  unresponsive person left waiting leans forward on their own, as far as they can;
* **willingness that lapses** (``Cooperativeness.lapse_rate_per_s``,
  ``refusal_rate_per_s``) and **wears down under pushing**
  (``Cooperativeness.pushed_lapse_rate_per_s``): ``+1`` is no longer absorbing, and a
  caregiver who keeps pushing loses the person's lead;
* **words alone rarely persuade** (``Cooperativeness.words_alone_rate_per_s`` scaled down):
  recruiting takes a guided push, which is what makes a pushed lean ambiguous.

What stays readable is the answer to a cue: asked to "lean forward" without a push, a
cooperative person leans further (eq. 6, ``k4``), a passive one does not move, a resisting
one leans back. A careful caregiver who probes can tell; the lean itself cannot.

The anatomical range is widened (``Intention.max_m`` 0.45 m) so a person who is already
leaning has room to answer. Unsafe lifts are priced so that no gamble pays
(:attr:`Difficulty.reward`).

``hard-v2`` (``CoopGym/SitToStandHard-v2``) is ``hard`` with two knobs changed: a guided push
recruits more slowly and willingness, once won, lapses half as often (docs/HARD_LEVEL.md: the
knobs and the command that scores them). An id's level never changes; other knobs are a new
level and a new id.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

from coop_gym.model.params import PersonParams
from coop_gym.model.personas import Persona

__all__ = ["DIFFICULTIES", "Difficulty", "get_difficulty"]


@dataclass(frozen=True)
class Difficulty:
    """One difficulty level: the realism knobs it sets on every persona, and its reward.

    Attributes:
        name: ``easy``, ``medium``, ``hard`` or ``hard-v2``.
        passive_follow_rate_per_s: ``Intention.passive_follow_rate_per_s`` [1/s].
        spontaneous_lean_rate_per_s: ``Intention.spontaneous_lean_rate_per_s`` [1/s].
        max_lean_m: ``Intention.max_m`` and ``Intention.spontaneous_lean_m`` [m]; None keeps
            the persona's.
        lapse_rate_per_s: ``Cooperativeness.lapse_rate_per_s`` [1/s].
        pushed_lapse_rate_per_s: ``Cooperativeness.pushed_lapse_rate_per_s`` [1/s].
        refusal_rate_per_s: ``Cooperativeness.refusal_rate_per_s`` [1/s].
        guided_push_scale: Multiplies ``Cooperativeness.guided_push_rate_per_s``.
        words_alone_scale: Multiplies ``Cooperativeness.words_alone_rate_per_s``.
        push_compliance_scale: Multiplies ``Biomechanics.push_compliance_m_per_s2_n``: how far
            a push bends anyone, whatever they think. Off (1) at every shipped level; a knob
            for candidate levels (``scripts/level_candidates.py``, docs/HARD_LEVEL.md).
        stiffness_factor_unresponsive: ``Biomechanics.stiffness_factor_unresponsive``; None
            keeps the persona's (1 = an unresponsive person is bent as far as a willing one).
            None at every shipped level, like ``push_compliance_scale``.
        unsafe_penalty: ``RewardWeights.unsafe`` of the level.
        premature_penalty: ``RewardWeights.premature`` of the level.
    """

    name: str
    passive_follow_rate_per_s: float = 0.0
    spontaneous_lean_rate_per_s: float = 0.0
    max_lean_m: float | None = None
    lapse_rate_per_s: float = 0.0
    pushed_lapse_rate_per_s: float = 0.0
    refusal_rate_per_s: float = 0.0
    guided_push_scale: float = 1.0
    words_alone_scale: float = 1.0
    push_compliance_scale: float = 1.0
    stiffness_factor_unresponsive: float | None = None
    # Safety priced like safety: with +1 for a success, a lift that risks an unsafe outcome
    # pays only if P(success) > 10 * P(unsafe) (+ P(premature)): the deadline gamble of -v0
    # (lift whenever P(success) > 1/3) is gone.
    unsafe_penalty: float = 10.0
    premature_penalty: float = 1.0

    def personas_at(self, personas: Sequence[Persona]) -> tuple[Persona, ...]:
        """``personas`` with their parameters at this level (:meth:`apply`; names and variation kept).

        A persona's ``level_factors`` scale this level's knobs for that persona alone.
        """
        return tuple(dataclasses.replace(p, params=self.scaled(p.level_factors).apply(p.params)) for p in personas)

    def scaled(self, factors: Sequence[tuple[str, float]]) -> Difficulty:
        """This level with each ``(knob, factor)`` knob multiplied by its factor."""
        return dataclasses.replace(self, **{knob: getattr(self, knob) * f for knob, f in factors}) if factors else self

    def apply(self, person: PersonParams) -> PersonParams:
        """``person`` at this level (every other parameter as it was)."""
        intent, coop = person.intention, person.cooperativeness
        max_m = intent.max_m if self.max_lean_m is None else self.max_lean_m
        intent = dataclasses.replace(
            intent,
            passive_follow_rate_per_s=self.passive_follow_rate_per_s,
            spontaneous_lean_rate_per_s=self.spontaneous_lean_rate_per_s,
            # A spontaneous lean goes as far as the person can (the same depth a cooperative one reaches).
            spontaneous_lean_m=max_m if self.max_lean_m is not None else intent.spontaneous_lean_m,
            max_m=max_m,
        )
        coop = dataclasses.replace(
            coop,
            lapse_rate_per_s=self.lapse_rate_per_s,
            pushed_lapse_rate_per_s=self.pushed_lapse_rate_per_s,
            refusal_rate_per_s=self.refusal_rate_per_s,
            guided_push_rate_per_s=coop.guided_push_rate_per_s * self.guided_push_scale,
            words_alone_rate_per_s=coop.words_alone_rate_per_s * self.words_alone_scale,
        )
        body = person.biomechanics
        body = dataclasses.replace(
            body,
            push_compliance_m_per_s2_n=body.push_compliance_m_per_s2_n * self.push_compliance_scale,
            stiffness_factor_unresponsive=(
                body.stiffness_factor_unresponsive
                if self.stiffness_factor_unresponsive is None
                else self.stiffness_factor_unresponsive
            ),
        )
        return dataclasses.replace(person, biomechanics=body, intention=intent, cooperativeness=coop)

    @property
    def reward(self) -> dict[str, float]:
        """The level's ``RewardWeights`` fields that differ from the defaults."""
        return {"unsafe": self.unsafe_penalty, "premature": self.premature_penalty}


# Values chosen by measurement (docs/HARD_LEVEL.md): oracle - best blind >= 30 points while a
# probing caregiver beats the best blind policy by >= 15 (against the blind family of that time).
_HARD = Difficulty(
    "hard",
    passive_follow_rate_per_s=2.0,
    spontaneous_lean_rate_per_s=0.2,
    max_lean_m=0.45,
    lapse_rate_per_s=0.1,
    pushed_lapse_rate_per_s=1.2,
    refusal_rate_per_s=0.03,
    guided_push_scale=0.8,
    words_alone_scale=0.25,
)

DIFFICULTIES: dict[str, Difficulty] = {
    d.name: d
    for d in (
        # The paper's model (as -v0) with the safety-priced reward: reading the mind is not needed.
        Difficulty("easy"),
        Difficulty(
            "medium",
            passive_follow_rate_per_s=1.0,
            spontaneous_lean_rate_per_s=0.1,
            max_lean_m=0.40,
            lapse_rate_per_s=0.05,
            pushed_lapse_rate_per_s=0.6,
            refusal_rate_per_s=0.015,
            guided_push_scale=0.9,
            words_alone_scale=0.5,
        ),
        _HARD,
        # The hard level again, against the widened blind family (docs/HARD_LEVEL.md, "The knobs of
        # hard-v2"): recruiting slower makes a pushed lean more often not yet cooperation (what
        # costs blind), willingness steadier once won gives the readers back the lapses between
        # their reading and the lift. Oracle - best blind >= 30 points with the belief caregiver
        # the best reader.
        dataclasses.replace(_HARD, name="hard-v2", guided_push_scale=0.45, lapse_rate_per_s=0.05),
    )
}
"""The levels: ``easy``, ``medium`` and ``hard`` of the ``-v1`` ids, ``hard-v2`` of ``CoopGym/SitToStandHard-v2``."""


def get_difficulty(name: str | Difficulty) -> Difficulty:
    """Look up a level by name; an unknown name raises ``ValueError`` listing the known ones."""
    if isinstance(name, Difficulty):
        return name
    try:
        return DIFFICULTIES[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown difficulty {name!r}; known: {', '.join(DIFFICULTIES)}") from None
