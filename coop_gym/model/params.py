"""Typed, unit-annotated parameters of the three-level human model (paper §III).

One frozen dataclass per model level, plus the sensors, the cues and the timing. The
single env, the batched env and the estimator's nominal model all read these objects;
there is no second copy of any constant. Every field is validated on construction and
an out-of-range value raises ``ValueError`` naming the field.

Field names carry their units (``_m``, ``_n``, ``_s``, ``_per_s`` ...).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, ClassVar

from estimator.validate import check_choice, check_flag, check_integer, check_number

__all__ = [
    "EPISODE_CLOCK_TOLERANCE_S",
    "Biomechanics",
    "Cooperativeness",
    "Cues",
    "Intention",
    "PersonParams",
    "Realism",
    "Sensors",
    "Timing",
]


MAX_REACTION_DELAY_S = 1.2
"""Longest supported reaction delay [s]; the delay line holds this many seconds of cues."""


_RATE_RANGE = (0.0, 100.0)
"""Range of every transition rate of the cooperativeness chain [1/s]."""


def _validate_ranges(obj: Any, ranges: dict[str, tuple[float, float]]) -> None:
    """Check each field of ``obj`` named in ``ranges`` (:func:`estimator.validate.check_number`).

    A NumPy scalar is stored as the Python number of the same value (the dataclass is frozen, so
    through ``object.__setattr__``, as in its own ``__init__``).
    """
    owner = type(obj).__name__
    for name, (low, high) in ranges.items():
        _set_checked(obj, name, check_number(f"{owner}.{name}", getattr(obj, name), low, high))


def _set_checked(obj: Any, name: str, checked: Any) -> None:
    """Store a validated field's Python value if the given one was a NumPy scalar."""
    if checked is not getattr(obj, name):
        object.__setattr__(obj, name, checked)


@dataclass(frozen=True)
class Biomechanics:
    """Level 1, eq. 1: ``xddot = -lambda1*xdot + k1*(eta - x) + k2*c_p + w_x``.

    Attributes:
        damping_rate_per_s: ``lambda1`` [1/s], damping of torso motion.
        voluntary_gain_per_s2: ``k1`` [1/s^2], the person's pull of ``x`` toward ``eta``.
        push_compliance_m_per_s2_n: ``k2`` [m/(s^2 N)], acceleration per newton of push.
        accel_noise_std_m_per_s2: Std of ``w_x`` [m/s^2], held over one simulation step.
        stiffness_factor_uncooperative: Multiplies ``k2`` while ``xi = -1`` (an
            uncooperative person stiffens against a push, paper §VI). 1 = off.
        stiffness_factor_unresponsive: Multiplies ``k2`` while ``xi = 0``. 1 = off.
    """

    damping_rate_per_s: float = 6.0
    voluntary_gain_per_s2: float = 9.0
    push_compliance_m_per_s2_n: float = 0.012
    accel_noise_std_m_per_s2: float = 0.02
    # Calibrated (coop_gym/experiment/calibrate.py) so the paper's thresholded KF on the paper's
    # protocol lands near its Table I: a disengaged person holds still against a push
    # (0.5), a resisting one stiffens less but leans away (0.8).
    stiffness_factor_uncooperative: float = 0.8
    stiffness_factor_unresponsive: float = 0.5

    RANGES: ClassVar[dict[str, tuple[float, float]]] = {
        "damping_rate_per_s": (0.01, 100.0),
        "voluntary_gain_per_s2": (0.01, 1000.0),
        "push_compliance_m_per_s2_n": (0.0, 1.0),
        "accel_noise_std_m_per_s2": (0.0, 10.0),
        "stiffness_factor_uncooperative": (0.0, 10.0),
        "stiffness_factor_unresponsive": (0.0, 10.0),
    }
    """The validated range ``[low, high]`` of each numeric field."""

    def __post_init__(self) -> None:
        """Validate ranges."""
        _validate_ranges(self, self.RANGES)


@dataclass(frozen=True)
class Intention:
    """Level 2, eq. 6: ``eta[t+1] = eta[t] + xi*(k3*c_p + k4*c_v)*dt + w_eta`` plus realism.

    Attributes:
        push_gain_m_per_s_n: ``k3`` [m/(s N)], intention change per newton of push.
        verbal_gain_m_per_s: ``k4`` [m/s], intention change per unit verbal cue.
        noise_std_m_per_sqrt_s: Intensity of ``w_eta`` [m/sqrt(s)]; per-step std is
            this times ``sqrt(dt)``.
        reaction_delay_s: The intention answers the cues this long after they act [s].
        saturate: Clip ``eta`` to the anatomical range ``[min_m, max_m]``.
        min_m: Furthest the person can intend to lean back [m].
        max_m: Furthest the person can intend to lean forward [m].
        relaxation_rate_per_s: With no cue acting, ``eta`` relaxes toward upright (0) at
            this rate [1/s]; 0 = off.
        passive_follow_rate_per_s: While unresponsive (``xi = 0``) the intention follows
            the body toward where it was put, at this rate [1/s]: a weak trunk bent
            forward by a push stays bent instead of pulling back upright (the paper's
            first failure scenario, "bends forward under a push while not cooperative").
            0 = off (the paper's model).
        spontaneous_lean_rate_per_s: While unresponsive (``xi = 0``) and left waiting (no
            cue for ``Cooperativeness.idle_after_s``), the person now and then leans
            forward on their own -- to look at their feet, to reach for a stick -- at this
            rate [1/s]: looking ready while not ready (the paper's second failure
            scenario). 0 = off.
        spontaneous_lean_m: How far such a lean goes: the intention jumps forward to
            at least this [m].
    """

    push_gain_m_per_s_n: float = 0.006
    verbal_gain_m_per_s: float = 0.12
    noise_std_m_per_sqrt_s: float = 0.012
    reaction_delay_s: float = 0.3
    saturate: bool = True
    # Seated upright, the pelvis and the backrest leave only a few cm of backward lean.
    min_m: float = -0.03
    max_m: float = 0.35
    relaxation_rate_per_s: float = 0.1
    passive_follow_rate_per_s: float = 0.0
    spontaneous_lean_rate_per_s: float = 0.0
    spontaneous_lean_m: float = 0.2

    RANGES: ClassVar[dict[str, tuple[float, float]]] = {
        "passive_follow_rate_per_s": (0.0, 100.0),
        "spontaneous_lean_rate_per_s": (0.0, 100.0),
        "spontaneous_lean_m": (0.0, 1.0),
        "push_gain_m_per_s_n": (0.0, 1.0),
        "verbal_gain_m_per_s": (0.0, 10.0),
        "noise_std_m_per_sqrt_s": (0.0, 1.0),
        "reaction_delay_s": (0.0, MAX_REACTION_DELAY_S),
        "min_m": (-1.0, 0.0),
        "max_m": (0.0, 1.0),
        "relaxation_rate_per_s": (0.0, 100.0),
    }
    """The validated range ``[low, high]`` of each numeric field."""

    def __post_init__(self) -> None:
        """Validate ranges."""
        _validate_ranges(self, self.RANGES)
        _set_checked(self, "saturate", check_flag("Intention.saturate", self.saturate))


@dataclass(frozen=True)
class Cooperativeness:
    """Level 3, eq. 8: a cue-driven continuous-time Markov chain on ``xi`` in {-1, 0, +1}.

    Only neighbouring levels are reachable in one jump. The rates [1/s] encode the
    caregiving-handbook rules of paper §II; a step of length ``dt`` moves up with
    probability ``(1 - exp(-(up + down) dt)) * up / (up + down)`` (exact for a CTMC whose
    rates are constant over the step) and down likewise.

    Attributes:
        explain_calm_rate_per_s: -1 -> 0 while "lean forward" is heard (explaining calms).
        words_alone_rate_per_s: 0 -> +1 while "lean forward" is heard: people rarely act
            on words alone, so this is small.
        guided_push_rate_per_s: 0 -> +1 under a push with a recent explanation: what
            actually turns a person cooperative.
        guided_calm_rate_per_s: -1 -> 0 under a push with a recent explanation.
        push_alone_rate_per_s: 0 -> +1 under a push with no recent explanation.
        startle_rate_per_s: One level down under a firm push with no recent explanation.
        prepared_startle_rate_per_s: One level down under a firm push after explaining.
        confusion_rate_per_s: One level down while "lean back" is heard.
        drift_rate_per_s: One level toward ``baseline`` once idle for ``idle_after_s``.
        explanation_memory_s: How long a "lean forward" counts as a recent explanation [s].
        idle_after_s: No cue for this long counts as idle [s].
        touch_threshold_n: A push below this force is not felt [N].
        firm_push_threshold_n: A push at or above this force is firm [N].
        persuadability: Scales the rates toward cooperation (persona trait).
        startle_sensitivity: Scales the startle and confusion rates (persona trait).
        hearing: 0..1, how much of a verbal cue gets through: scales the verbal rates and
            how much an explanation prepares a push (persona trait).
        baseline: The level an idle person drifts back to, in {-1, 0, 1}.
        initial_p_uncooperative: Probability that an episode starts at ``xi = -1``.
        initial_p_cooperative: Probability that an episode starts at ``xi = +1``
            (the rest start at 0).
        lapse_rate_per_s: +1 -> 0 at any time: willingness lapses (attention wanders,
            fatigue, doubt), so cooperation is not absorbing. 0 = off.
        pushed_lapse_rate_per_s: +1 -> 0 while pushed (added to ``lapse_rate_per_s``): a
            willing person pushed on stops leading the movement -- pushing too long wears
            willingness down. 0 = off.
        refusal_rate_per_s: +1 -> -1 at any time: a sudden refusal (pain, fear of
            falling). The only jump of two levels. 0 = off.
    """

    explain_calm_rate_per_s: float = 0.6
    words_alone_rate_per_s: float = 0.08
    guided_push_rate_per_s: float = 1.2
    guided_calm_rate_per_s: float = 0.6
    push_alone_rate_per_s: float = 0.08
    startle_rate_per_s: float = 1.0
    prepared_startle_rate_per_s: float = 0.15
    confusion_rate_per_s: float = 0.5
    drift_rate_per_s: float = 0.05
    explanation_memory_s: float = 6.0
    idle_after_s: float = 3.0
    touch_threshold_n: float = 2.0
    firm_push_threshold_n: float = 20.0
    persuadability: float = 1.0
    startle_sensitivity: float = 1.0
    hearing: float = 1.0
    baseline: int = 0
    initial_p_uncooperative: float = 0.3
    initial_p_cooperative: float = 0.1
    lapse_rate_per_s: float = 0.0
    pushed_lapse_rate_per_s: float = 0.0
    refusal_rate_per_s: float = 0.0

    RANGES: ClassVar[dict[str, tuple[float, float]]] = {
        "lapse_rate_per_s": _RATE_RANGE,
        "pushed_lapse_rate_per_s": _RATE_RANGE,
        "refusal_rate_per_s": _RATE_RANGE,
        "explain_calm_rate_per_s": _RATE_RANGE,
        "words_alone_rate_per_s": _RATE_RANGE,
        "guided_push_rate_per_s": _RATE_RANGE,
        "guided_calm_rate_per_s": _RATE_RANGE,
        "push_alone_rate_per_s": _RATE_RANGE,
        "startle_rate_per_s": _RATE_RANGE,
        "prepared_startle_rate_per_s": _RATE_RANGE,
        "confusion_rate_per_s": _RATE_RANGE,
        "drift_rate_per_s": _RATE_RANGE,
        "explanation_memory_s": (0.0, 1000.0),
        "idle_after_s": (0.0, 1000.0),
        "touch_threshold_n": (0.0, 1000.0),
        "firm_push_threshold_n": (0.0, 1000.0),
        "persuadability": (0.0, 100.0),
        "startle_sensitivity": (0.0, 100.0),
        "hearing": (0.0, 1.0),
        "initial_p_uncooperative": (0.0, 1.0),
        "initial_p_cooperative": (0.0, 1.0),
    }
    """The validated range ``[low, high]`` of each numeric field."""

    def __post_init__(self) -> None:
        """Validate ranges."""
        _validate_ranges(self, self.RANGES)
        _set_checked(self, "baseline", check_choice("Cooperativeness.baseline", self.baseline, (-1, 0, 1)))
        if self.initial_p_uncooperative + self.initial_p_cooperative > 1.0 + 1e-12:
            raise ValueError(
                "Cooperativeness.initial_p_uncooperative + initial_p_cooperative must be <= 1, got "
                f"{self.initial_p_uncooperative} + {self.initial_p_cooperative}"
            )
        if self.firm_push_threshold_n < self.touch_threshold_n:
            raise ValueError(
                f"Cooperativeness.firm_push_threshold_n ({self.firm_push_threshold_n}) must be >= "
                f"touch_threshold_n ({self.touch_threshold_n})"
            )


@dataclass(frozen=True)
class Sensors:
    """Measurement noise of the robot's sensors.

    Attributes:
        position_noise_std_m: Std of the camera's shoulder-position reading [m].
        force_noise_std_n: Std of the force sensor's reading [N].
    """

    position_noise_std_m: float = 0.004
    force_noise_std_n: float = 0.5

    RANGES: ClassVar[dict[str, tuple[float, float]]] = {
        "position_noise_std_m": (0.0, 1.0),
        "force_noise_std_n": (0.0, 100.0),
    }
    """The validated range ``[low, high]`` of each numeric field."""

    def __post_init__(self) -> None:
        """Validate ranges."""
        _validate_ranges(self, self.RANGES)


@dataclass(frozen=True)
class Cues:
    """What the robot can do.

    Attributes:
        soft_push_n: Force of a gentle push [N].
        firm_push_n: Force of a firm push; also the top of the continuous-force variant [N].
        verbal_duration_s: How long one utterance plays [s].
    """

    soft_push_n: float = 10.0
    firm_push_n: float = 30.0
    verbal_duration_s: float = 1.0

    RANGES: ClassVar[dict[str, tuple[float, float]]] = {
        "soft_push_n": (0.0, 200.0),
        "firm_push_n": (0.0, 200.0),
        "verbal_duration_s": (0.02, 10.0),
    }
    """The validated range ``[low, high]`` of each numeric field."""

    def __post_init__(self) -> None:
        """Validate ranges."""
        _validate_ranges(self, self.RANGES)
        if self.soft_push_n > self.firm_push_n:
            raise ValueError(
                f"Cues.soft_push_n ({self.soft_push_n} N) must be <= firm_push_n ({self.firm_push_n} N): "
                "a soft push cannot be stronger than a firm one"
            )


EPISODE_CLOCK_TOLERANCE_S = 1e-9
"""A step ends at ``episode_s`` if it is within this of it [s] (:attr:`Timing.max_episode_steps`)."""


@dataclass(frozen=True)
class Timing:
    """Time base shared by simulator, sensors and filter.

    Attributes:
        dt_s: Simulation, measurement and filter step [s] (50 Hz).
        substeps: Simulation steps per agent action (agent acts every ``substeps*dt_s``).
        episode_s: An episode is truncated after this long [s].
    """

    dt_s: float = 0.02
    substeps: int = 5
    episode_s: float = 30.0

    RANGES: ClassVar[dict[str, tuple[float, float]]] = {
        "dt_s": (1e-4, 0.1),
        "episode_s": (0.1, 3600.0),
    }
    """The validated range ``[low, high]`` of each numeric field."""

    def __post_init__(self) -> None:
        """Validate ranges."""
        _validate_ranges(self, self.RANGES)
        _set_checked(self, "substeps", check_integer("Timing.substeps", self.substeps, 1, 100))

    @property
    def action_period_s(self) -> float:
        """Time between two agent actions [s]."""
        return self.dt_s * self.substeps

    @property
    def max_episode_steps(self) -> int:
        """Agent steps in one full episode: the first step at or past ``episode_s`` (to within a tolerance).

        The tolerance is :data:`EPISODE_CLOCK_TOLERANCE_S`.

        The envs end an episode after this many steps
        (:func:`coop_gym.envs.kernels.report.episode_end`, the one rule); an ``episode_s`` that is
        not a whole number of actions ends on the step that passes it.
        """
        return max(1, math.ceil((self.episode_s - EPISODE_CLOCK_TOLERANCE_S) / self.action_period_s))


@dataclass(frozen=True)
class Realism:
    """Switches for the simulator's departures from the paper's linear model.

    Each ``True`` keeps the knob at its persona's value; ``False`` turns it off.

    Attributes:
        reaction_delay: The intention answers cues after ``Intention.reaction_delay_s``.
        saturation: ``eta`` is clipped to the anatomical range.
        relaxation: ``eta`` relaxes toward upright when no cue acts.
        state_dependent_stiffness: ``k2`` depends on ``xi``.
        sensor_noise: Position and force readings are noisy.
        process_noise: ``w_x`` and ``w_eta`` are on.
        person_variation: Each episode's person varies around the persona's values.
    """

    reaction_delay: bool = True
    saturation: bool = True
    relaxation: bool = True
    state_dependent_stiffness: bool = True
    sensor_noise: bool = True
    process_noise: bool = True
    person_variation: bool = True

    def __post_init__(self) -> None:
        """Every switch must be a bool."""
        for field in dataclasses.fields(self):
            _set_checked(self, field.name, check_flag(f"Realism.{field.name}", getattr(self, field.name)))

    @classmethod
    def off(cls) -> Realism:
        """The paper's idealised linear model: every realism knob off."""
        return cls(**{f.name: False for f in dataclasses.fields(cls)})


@dataclass(frozen=True)
class PersonParams:
    """One simulated person: the three model levels and the sensors that watch them."""

    biomechanics: Biomechanics = Biomechanics()
    intention: Intention = Intention()
    cooperativeness: Cooperativeness = Cooperativeness()
    sensors: Sensors = Sensors()

    def with_realism(self, realism: Realism) -> PersonParams:
        """Return this person with the switched-off realism knobs neutralised."""
        bio, intent, sensors = self.biomechanics, self.intention, self.sensors
        if not realism.state_dependent_stiffness:
            bio = dataclasses.replace(bio, stiffness_factor_uncooperative=1.0, stiffness_factor_unresponsive=1.0)
        if not realism.process_noise:
            bio = dataclasses.replace(bio, accel_noise_std_m_per_s2=0.0)
            intent = dataclasses.replace(intent, noise_std_m_per_sqrt_s=0.0)
        if not realism.reaction_delay:
            intent = dataclasses.replace(intent, reaction_delay_s=0.0)
        if not realism.saturation:
            intent = dataclasses.replace(intent, saturate=False)
        if not realism.relaxation:
            intent = dataclasses.replace(intent, relaxation_rate_per_s=0.0)
        if not realism.sensor_noise:
            sensors = Sensors(position_noise_std_m=0.0, force_noise_std_n=0.0)
        return PersonParams(bio, intent, self.cooperativeness, sensors)
