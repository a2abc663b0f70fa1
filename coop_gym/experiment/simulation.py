"""The paper's experiment (§V) on simulated subjects: trial design, configuration and simulation.

Bell & Asada tested four subjects on the same 25 trials. Each trial requested a
cooperativeness ``xi`` in {-1, 0, +1} (the subject *acts* it for the whole trial), and
gave a physical cue {none, soft, hard}, a verbal cue {none, "lean back", "lean
forward"} and, when both, a relative timing in {-4..4} s between them. The thresholded
Kalman filter judged each trial 0.75 s after the initial cue onset (threshold 0.3).
Here the subjects are simulated people drawn from the persona population
(:mod:`coop_gym.model.personas`, with per-person variation) whose ``xi`` is held at the
requested value within a trial, as in the experiment.

Trial layout (every trial has the same length, so trials batch): ``quiet_s`` of quiet,
then the cues -- the physical cue at ``quiet_s + max(0, -d)``, the verbal cue at
``quiet_s + max(0, d)`` with ``d`` the relative timing (verbal minus physical) -- then
quiet until ``quiet_s + 4 s + cue length + after_s``. The initial cue onset is always at
``quiet_s``; the judgment is taken :class:`~estimator.judgment.ThresholdJudgment`
``delay_s`` later, on the same step rule as the environments' judgment tracker.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from coop_gym.model.difficulty import get_difficulty
from coop_gym.model.dynamics import simulate
from coop_gym.model.params import Cues, PersonParams, Realism, Timing
from coop_gym.model.personas import Persona, resolve_personas, sample_person
from estimator.judgment import ThresholdJudgment, first_judgment_step
from estimator.multiple_model import TRIAL_PROBABILITY_FLOOR, TRIAL_SWITCHING_RATE_PER_S
from estimator.paper import PAPER_RESULTS, XI_VALUES

__all__ = [
    "ExperimentData",
    "ProtocolConfig",
    "TrialSpec",
    "draw_trials",
    "judgment_step",
    "run_experiment",
]

PHYSICAL_CUES: tuple[str, str, str] = ("none", "soft", "hard")
VERBAL_CUES: tuple[str, str, str] = ("none", "back", "forward")
RELATIVE_TIMINGS_S: tuple[int, ...] = (-4, -3, -2, -1, 0, 1, 2, 3, 4)

# --------------------------------------------------------------------------- configuration


@dataclass(frozen=True)
class ProtocolConfig:
    """Settings of the simulated experiment.

    Attributes:
        n_subjects: Simulated subjects (paper: 4).
        n_trials: Trials per subject, the same for every subject (paper: 25).
        personas: Persona set the subjects are drawn from (``"all"``, ``"train"``, a name...).
        requested_mix: ``"paper"``: the requested ``xi`` counts follow the paper's
            32 : 24 : 44 % (8 / 6 / 11 of 25 trials), in random order; ``"uniform"``:
            each trial's ``xi`` drawn uniformly; ``"balanced"``: equal counts (the
            calibration sessions use this).
        quiet_s: Quiet before the initial cue onset [s].
        physical_duration_s: How long a push lasts [s].
        after_s: Quiet after the latest possible cue ends [s].
        initial_lean_std_m: Std of a subject's posture at the start of a trial [m].
        calibration_trials: Labelled trials per subject in the separate calibration
            session (balanced over ``xi``) used by the ``identified`` estimator.
        judgment: The thresholded judgment (paper: 0.75 s, 0.3).
        realism: Simulator realism switches.
        timing: Time base.
        cues: Cue magnitudes and the utterance length.
        switching_rate_per_s: IMM's mode-switching rate [1/s].
        probability_floor: Mode-probability floor of the multiple-model estimators.
        difficulty: The ``-v1`` level the subjects are at (``None``: the ``-v0`` model): each
            persona's parameters pass through the level's changes, and the ``switching``
            estimator models that level's person.
    """

    n_subjects: int = 4
    n_trials: int = 25
    personas: str | Persona | tuple[str | Persona, ...] = "all"
    requested_mix: Literal["paper", "uniform", "balanced"] = "paper"
    quiet_s: float = 2.0
    physical_duration_s: float = 1.0
    after_s: float = 3.0
    initial_lean_std_m: float = 0.005
    calibration_trials: int = 30
    judgment: ThresholdJudgment = field(default_factory=ThresholdJudgment)
    realism: Realism = field(default_factory=Realism)
    timing: Timing = field(default_factory=Timing)
    cues: Cues = field(default_factory=Cues)
    switching_rate_per_s: float = TRIAL_SWITCHING_RATE_PER_S
    probability_floor: float = TRIAL_PROBABILITY_FLOOR
    difficulty: str | None = None

    def __post_init__(self) -> None:
        """Validate counts and durations."""
        for name in ("n_subjects", "n_trials", "calibration_trials"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 10_000:
                raise ValueError(f"ProtocolConfig.{name} must be an int in [1, 10000], got {value!r}")
        if self.requested_mix not in ("paper", "uniform", "balanced"):
            raise ValueError(
                f"ProtocolConfig.requested_mix must be 'paper', 'uniform' or 'balanced', got {self.requested_mix!r}"
            )
        for name, low, high in (
            ("quiet_s", 0.1, 60.0),
            ("physical_duration_s", 0.02, 10.0),
            ("after_s", 0.0, 60.0),
            ("initial_lean_std_m", 0.0, 0.1),
            ("switching_rate_per_s", 0.0, 100.0),
        ):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not low <= value <= high:
                raise ValueError(f"ProtocolConfig.{name} must be in [{low}, {high}], got {value!r}")
        if not 0.0 <= self.probability_floor < 1.0 / 3.0:
            raise ValueError(f"ProtocolConfig.probability_floor must be in [0, 1/3), got {self.probability_floor!r}")
        resolve_personas(self.personas)  # raises on an unknown name
        if self.difficulty is not None:
            get_difficulty(self.difficulty)  # raises on an unknown level
        if self.quiet_s + self.judgment.delay_s > self.trial_s:
            raise ValueError("the judgment must fall inside the trial")

    @property
    def trial_s(self) -> float:
        """Length of every trial [s]."""
        longest = max(self.physical_duration_s, self.cues.verbal_duration_s)
        return self.quiet_s + max(abs(t) for t in RELATIVE_TIMINGS_S) + longest + self.after_s

    @property
    def n_steps(self) -> int:
        """Samples per trial."""
        return round(self.trial_s / self.timing.dt_s)

    @property
    def onset_step(self) -> int:
        """Index of the first step with a cue acting (the initial cue onset)."""
        return round(self.quiet_s / self.timing.dt_s)


@dataclass(frozen=True)
class TrialSpec:
    """One trial's parameters, shared by every subject.

    Attributes:
        requested_xi: The cooperativeness the subject is asked to act, in {-1, 0, +1}.
        physical_cue: ``"none"``, ``"soft"`` or ``"hard"``.
        verbal_cue: ``"none"``, ``"back"`` or ``"forward"``.
        relative_timing_s: Verbal onset minus physical onset [s] when both are given, else 0.
    """

    requested_xi: int
    physical_cue: str
    verbal_cue: str
    relative_timing_s: int = 0

    def __post_init__(self) -> None:
        """Validate the fields."""
        if self.requested_xi not in XI_VALUES:
            raise ValueError(f"TrialSpec.requested_xi must be -1, 0 or 1, got {self.requested_xi!r}")
        if self.physical_cue not in PHYSICAL_CUES:
            raise ValueError(f"TrialSpec.physical_cue must be one of {PHYSICAL_CUES}, got {self.physical_cue!r}")
        if self.verbal_cue not in VERBAL_CUES:
            raise ValueError(f"TrialSpec.verbal_cue must be one of {VERBAL_CUES}, got {self.verbal_cue!r}")
        if self.physical_cue == "none" and self.verbal_cue == "none":
            raise ValueError("a trial needs at least one cue")
        if self.relative_timing_s not in RELATIVE_TIMINGS_S:
            raise ValueError(
                f"TrialSpec.relative_timing_s must be in {RELATIVE_TIMINGS_S}, got {self.relative_timing_s!r}"
            )
        both = self.physical_cue != "none" and self.verbal_cue != "none"
        if not both and self.relative_timing_s != 0:
            raise ValueError("relative_timing_s applies only when both cues are given")

    def cues(self, config: ProtocolConfig) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Per-step push force [N] and verbal cue of this trial, each (``config.n_steps``,)."""
        dt = config.timing.dt_s
        n = config.n_steps
        push = np.zeros(n)
        verbal = np.zeros(n)
        d = self.relative_timing_s
        if self.physical_cue != "none":
            start = config.onset_step + round(max(0, -d) / dt)
            force = config.cues.soft_push_n if self.physical_cue == "soft" else config.cues.firm_push_n
            push[start : start + round(config.physical_duration_s / dt)] = force
        if self.verbal_cue != "none":
            start = config.onset_step + round(max(0, d) / dt)
            verbal[start : start + round(config.cues.verbal_duration_s / dt)] = (
                1.0 if self.verbal_cue == "forward" else -1.0
            )
        return push, verbal


def draw_trials(config: ProtocolConfig, rng: np.random.Generator) -> tuple[TrialSpec, ...]:
    """Draw the trial set (once per seed; every subject gets the same trials).

    Cues are uniform over {none, soft, hard} x {none, back, forward} without the
    cue-less pair; the relative timing is uniform over -4..4 s when both cues are given.
    """
    n = config.n_trials
    if config.requested_mix in ("paper", "balanced"):
        counts = PAPER_RESULTS.matrix.sum(axis=1).astype(np.float64) if config.requested_mix == "paper" else np.ones(3)
        # Largest-remainder rounding of the paper's proportions to n trials.
        raw = counts / counts.sum() * n
        per_class = np.floor(raw).astype(np.int64)
        for k in np.argsort(-(raw - per_class), kind="stable")[: n - int(per_class.sum())]:
            per_class[k] += 1
        requested = rng.permutation(np.repeat(np.array(XI_VALUES), per_class))
    else:
        requested = rng.choice(np.array(XI_VALUES), size=n)
    pairs = [(p, v) for p in PHYSICAL_CUES for v in VERBAL_CUES if (p, v) != ("none", "none")]
    specs = []
    for k in range(n):
        physical, verbal = pairs[int(rng.integers(len(pairs)))]
        timing = int(rng.choice(RELATIVE_TIMINGS_S))
        both = physical != "none" and verbal != "none"
        specs.append(TrialSpec(int(requested[k]), physical, verbal, timing if both else 0))
    return tuple(specs)


def judgment_step(config: ProtocolConfig, push_force_n: NDArray[np.float64], verbal_cue: NDArray[np.float64]) -> int:
    """Step index at which the environments' judgment tracker judges the initial cue onset.

    :func:`~estimator.judgment.first_judgment_step` over the cue sequence, so the protocol and
    the environments sample ``xi_hat`` on exactly the same step.
    """
    active = (np.asarray(push_force_n) > 0.0) | (np.asarray(verbal_cue) != 0.0)
    return first_judgment_step(active, config.judgment, config.timing.dt_s)


# --------------------------------------------------------------------------- the experiment


@dataclass(frozen=True, eq=False)
class ExperimentData:
    """One simulated run of the protocol (arrays are (S subjects, N trials, T steps, ...)).

    Attributes:
        config: The settings.
        seed: The seed everything was drawn from.
        trials: The N trial specs.
        personas: Each subject's persona.
        subjects: Each subject's (varied) parameters.
        push_force_n: (N, T) commanded push [N] (the same for every subject).
        verbal_cue: (N, T) verbal cue.
        measured_force_n: (S, N, T) force-sensor reading [N].
        measured_position_m: (S, N, T) camera reading of the shoulder [m].
        true_state: (S, N, T, 4) ``x, xdot, eta, xi``.
        judgment_step: (N,) step index of the judgment.
        calibration: Per subject, the labelled calibration session (specs, forces,
            verbal cues, positions) for the ``identified`` estimator, or ``None``.
    """

    config: ProtocolConfig
    seed: int
    trials: tuple[TrialSpec, ...]
    personas: tuple[Persona, ...]
    subjects: tuple[PersonParams, ...]
    push_force_n: NDArray[np.float64]
    verbal_cue: NDArray[np.float64]
    measured_force_n: NDArray[np.float64]
    measured_position_m: NDArray[np.float64]
    true_state: NDArray[np.float64]
    judgment_step: NDArray[np.int64]
    calibration: tuple[dict[str, Any], ...] | None = None

    @property
    def requested(self) -> NDArray[np.int64]:
        """(S, N) requested ``xi`` of every subject's trials."""
        xi = np.array([t.requested_xi for t in self.trials], dtype=np.int64)
        return np.tile(xi, (len(self.subjects), 1))


def _simulate_session(
    config: ProtocolConfig,
    person: PersonParams,
    trials: Sequence[TrialSpec],
    seeds: Sequence[np.random.SeedSequence],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Simulate one subject's trials; each trial from its own seed. Returns force, position, state."""
    n, t = len(trials), config.n_steps
    force = np.empty((n, t))
    position = np.empty((n, t))
    state = np.empty((n, t, 4))
    for k, (spec, ss) in enumerate(zip(trials, seeds, strict=True)):
        rng = np.random.default_rng(ss)
        x0 = float(rng.normal(0.0, config.initial_lean_std_m))
        push, verbal = spec.cues(config)
        traj = simulate(
            person, push, verbal, rng, initial_xi=spec.requested_xi, x0_m=x0, hold_xi=True, timing=config.timing
        )
        force[k] = traj.measured_force_n
        position[k] = traj.measured_position_m
        state[k] = traj.true_state
    return force, position, state


def _draw_subjects(
    config: ProtocolConfig, rng: np.random.Generator
) -> tuple[tuple[Persona, ...], tuple[PersonParams, ...]]:
    """The subjects: each a persona drawn from the pool, then a person around it, then the realism switches."""
    pool = resolve_personas(config.personas)
    if config.difficulty is not None:
        pool = get_difficulty(config.difficulty).personas_at(pool)
    personas, subjects = [], []
    for _ in range(config.n_subjects):
        persona = pool[int(rng.integers(len(pool)))]
        person = sample_person(persona, rng, vary=config.realism.person_variation)
        personas.append(persona)
        subjects.append(person.with_realism(config.realism))
    return tuple(personas), tuple(subjects)


def _calibration_sessions(
    config: ProtocolConfig, subjects: Sequence[PersonParams], seeds: np.random.SeedSequence
) -> tuple[dict[str, Any], ...]:
    """Each subject's labelled calibration session: ``calibration_trials`` trials of a balanced mix."""
    calib_config = dataclasses.replace(config, n_trials=config.calibration_trials, requested_mix="balanced")
    sessions = []
    for person, ss in zip(subjects, seeds.spawn(len(subjects)), strict=True):
        spec_ss, sim_ss = ss.spawn(2)
        specs = draw_trials(calib_config, np.random.default_rng(spec_ss))
        force, position, _ = _simulate_session(config, person, specs, sim_ss.spawn(len(specs)))
        sessions.append(
            {
                "trials": specs,
                "measured_force_n": force,
                "verbal_cue": np.stack([sp.cues(config)[1] for sp in specs]),
                "measured_position_m": position,
            }
        )
    return tuple(sessions)


def run_experiment(config: ProtocolConfig, seed: int, *, with_calibration: bool = False) -> ExperimentData:
    """Simulate the experiment: draw trials and subjects from ``seed``, then every trial.

    Independent streams (``SeedSequence.spawn``) for the trial set, the subjects, each
    subject's trials and the calibration sessions, so asking for the calibration
    session does not change the test data.

    Args:
        config: Settings.
        seed: Non-negative seed.
        with_calibration: Also simulate each subject's labelled calibration session.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative int, got {seed!r}")
    root = np.random.SeedSequence(int(seed))
    trial_ss, subject_ss, data_ss, calib_ss = root.spawn(4)
    trials = draw_trials(config, np.random.default_rng(trial_ss))
    personas, subjects = _draw_subjects(config, np.random.default_rng(subject_ss))
    cues = [spec.cues(config) for spec in trials]
    push = np.stack([c[0] for c in cues])
    verbal = np.stack([c[1] for c in cues])
    s, n, t = config.n_subjects, config.n_trials, config.n_steps
    force = np.empty((s, n, t))
    position = np.empty((s, n, t))
    state = np.empty((s, n, t, 4))
    for i, (person, ss) in enumerate(zip(subjects, data_ss.spawn(s), strict=True)):
        force[i], position[i], state[i] = _simulate_session(config, person, trials, ss.spawn(n))
    calibration = _calibration_sessions(config, subjects, calib_ss) if with_calibration else None
    steps = np.array([judgment_step(config, push[k], verbal[k]) for k in range(n)], dtype=np.int64)
    return ExperimentData(
        config=config,
        seed=int(seed),
        trials=trials,
        personas=personas,
        subjects=subjects,
        push_force_n=push,
        verbal_cue=verbal,
        measured_force_n=force,
        measured_position_m=position,
        true_state=state,
        judgment_step=steps,
        calibration=calibration,
    )
