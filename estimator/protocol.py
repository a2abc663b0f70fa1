"""The paper's experiment (§V) as a reproducible protocol, and better estimators on it.

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

Estimators compared on the same simulated data (``--estimator``); all judge on the
same step as the paper (0.74 s on the tracker's clock) unless ``--decision sequential``
lets a multiple-model estimator decide earlier when confident:

* ``kalman`` -- the paper's filter (:class:`~estimator.kalman.FastKalmanFilter`, equal
  to the filterpy reference) on the persona's nominal model
  (:func:`coop_gym.envs.core.nominal_model_for`: the persona's typical gains, not the
  subject's varied ones), thresholded at +/-0.3. Its probabilities for log loss / Brier /
  ECE come from :func:`gaussian_xi_probabilities`.
* ``multiple_model`` / ``imm`` -- MMAE and IMM of :mod:`estimator.multiple_model` on
  the same nominal model, MAP judgment.
* ``delay_aware`` -- the same MMAE fed the *delayed* intention drive
  (:func:`intention_drive`, the persona's typical reaction delay): the linear model
  with the person's reaction delay, on the unchanged kernel.
* ``persona_bank`` -- a bank of three delay-aware filters, one per ``xi``, each with its
  own push compliance (the persona's state-dependent stiffness) and the persona's
  noise intensities (:func:`bank_log_likelihoods`); Bayes over the three, MAP.
* ``calibrated`` -- ``persona_bank`` with a per-subject temperature and class offsets
  learned on a separate labelled calibration session of that subject
  (:func:`fit_recalibration`): the subject's history, used discriminatively.
* ``identified`` -- per-subject, per-``xi`` models fitted by maximum likelihood
  (:func:`estimator.identify.identify`) on the calibration session
  (:func:`identified_banks`): the subject's history, used generatively.
* ``oracle`` -- the bank on each subject's *true* parameters: not an estimator but the
  information bound of linear delay-aware filters at the judgment instant.

``python -m estimator.calibrate`` reports all of them over 20 seeds. In short, on the
calibrated defaults: the thresholded KF lands near the paper's Table I; MMAE and IMM on
the paper's nominal model do *worse* than the thresholded KF (MAP needs more evidence
than the 0.3 threshold, and the nominal model misses the reaction delay); the delay-aware
and stiffness-aware bank gains about 11 points of balanced accuracy; the oracle bound is
only a couple of points above it, because at 0.75 s the person has been responding for
only ~0.45 s. Later judgments (1 s) gain much more.

Run ``python -m estimator.protocol --help``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import ndtr

from coop_gym.cli import output_path_problem, seed_range_problem
from coop_gym.cli import positive_int as _positive_int
from coop_gym.cli import seed as _seed
from coop_gym.envs.core import nominal_model_for
from coop_gym.io import save_figure
from coop_gym.model.dynamics import simulate
from coop_gym.model.params import Cues, PersonParams, Realism, Timing
from coop_gym.model.personas import Persona, resolve_personas, sample_person
from estimator import metrics
from estimator.judgment import JUDGMENT_COLUMNS, ThresholdJudgment, judgment_substep
from estimator.kalman import NOMINAL_COLUMNS, FastKalmanFilter, nominal_row
from estimator.nominal import NominalModel

__all__ = [
    "ESTIMATORS",
    "PAPER_RESULTS",
    "XI_VALUES",
    "EstimateResult",
    "ExperimentData",
    "PaperResults",
    "ProtocolConfig",
    "TrialSpec",
    "balanced_accuracy",
    "confusion_matrix",
    "draw_trials",
    "estimate",
    "main",
    "run_experiment",
    "run_protocol",
    "summarize",
]

XI_VALUES: tuple[int, int, int] = (-1, 0, 1)
"""Row/column order of every confusion table: uncooperative, unresponsive, cooperative."""

XI_NAMES: tuple[str, str, str] = ("uncooperative", "unresponsive", "cooperative")
XI_SHORT: tuple[str, str, str] = ("uncoop.", "unresp.", "coop.")
"""Column labels for narrow tables and plot ticks."""

PHYSICAL_CUES: tuple[str, str, str] = ("none", "soft", "hard")
VERBAL_CUES: tuple[str, str, str] = ("none", "back", "forward")
RELATIVE_TIMINGS_S: tuple[int, ...] = (-4, -3, -2, -1, 0, 1, 2, 3, 4)

ESTIMATORS: tuple[str, ...] = (
    "kalman",
    "multiple_model",
    "imm",
    "delay_aware",
    "persona_bank",
    "calibrated",
    "identified",
    "oracle",
)
"""Estimators the protocol can score (see the module docstring)."""

NEEDS_CALIBRATION: frozenset[str] = frozenset({"calibrated", "identified"})
"""Estimators that learn from each subject's separate, labelled calibration session."""


# --------------------------------------------------------------------------- the paper's numbers


@dataclass(frozen=True)
class PaperResults:
    """The paper's Table I on real people (N = 100), reconstructed from its text (§V-C).

    The text gives the requested counts (44 cooperative, 24 unresponsive, 32
    uncooperative), the correct rates (52.3 %, 79.2 %, 34.4 %), the precisions of
    "cooperative" (23/25) and "uncooperative" (11/16), that uncooperative trials were
    most often judged unresponsive, and that an "unresponsive" judgment came about
    equally often from each requested state. That fixes every cell but one degree of
    freedom ``a`` = #(requested 0, judged +1) = #(requested +1, judged -1) in {0, 1, 2};
    we take ``a = 1``, which makes the "unresponsive" column 20 / 19 / 20.

    Attributes:
        confusion: Counts, rows = requested ``xi`` -1, 0, +1, columns = judged -1, 0, +1.
    """

    confusion: tuple[tuple[int, int, int], ...] = ((11, 20, 1), (4, 19, 1), (1, 20, 23))

    @property
    def matrix(self) -> NDArray[np.int64]:
        """(3, 3) counts as an array."""
        return np.array(self.confusion, dtype=np.int64)

    @property
    def accuracy(self) -> float:
        """Fraction judged correctly (0.53)."""
        return accuracy(self.matrix)

    @property
    def balanced_accuracy(self) -> float:
        """Mean of the three correct rates (0.553)."""
        return balanced_accuracy(self.matrix)


PAPER_RESULTS = PaperResults()
"""The one place the paper's numbers live."""


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
    switching_rate_per_s: float = 0.05
    probability_floor: float = 1e-4

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

    Runs :func:`~estimator.judgment.judgment_substep` over the cue sequence, so the
    protocol and the environments sample ``xi_hat`` on exactly the same step.
    """
    row = np.zeros(len(JUDGMENT_COLUMNS))
    row[0] = config.timing.episode_s
    for t in range(push_force_n.shape[0]):
        active = bool(push_force_n[t] > 0.0 or verbal_cue[t] != 0.0)
        if judgment_substep(row, active, 0.0, config.judgment.delay_s, config.judgment.threshold, config.timing.dt_s):
            return t
    raise ValueError("no judgment inside the trial: no cue, or the judgment delay exceeds the trial")


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
    pool = resolve_personas(config.personas)
    subject_rng = np.random.default_rng(subject_ss)
    personas, subjects = [], []
    for _ in range(config.n_subjects):
        persona = pool[int(subject_rng.integers(len(pool)))]
        person = sample_person(persona, subject_rng, vary=config.realism.person_variation)
        personas.append(persona)
        subjects.append(person.with_realism(config.realism))
    cues = [spec.cues(config) for spec in trials]
    push = np.stack([c[0] for c in cues])
    verbal = np.stack([c[1] for c in cues])
    s, n, t = config.n_subjects, config.n_trials, config.n_steps
    force = np.empty((s, n, t))
    position = np.empty((s, n, t))
    state = np.empty((s, n, t, 4))
    for i, (person, ss) in enumerate(zip(subjects, data_ss.spawn(s), strict=True)):
        force[i], position[i], state[i] = _simulate_session(config, person, trials, ss.spawn(n))
    calibration = None
    if with_calibration:
        sessions = []
        for person, ss in zip(subjects, calib_ss.spawn(s), strict=True):
            spec_ss, sim_ss = ss.spawn(2)
            calib_config = dataclasses.replace(config, n_trials=config.calibration_trials, requested_mix="balanced")
            specs = draw_trials(calib_config, np.random.default_rng(spec_ss))
            c_force, c_position, _ = _simulate_session(config, person, specs, sim_ss.spawn(len(specs)))
            sessions.append(
                {
                    "trials": specs,
                    "measured_force_n": c_force,
                    "verbal_cue": np.stack([sp.cues(config)[1] for sp in specs]),
                    "measured_position_m": c_position,
                }
            )
        calibration = tuple(sessions)
    steps = np.array([judgment_step(config, push[k], verbal[k]) for k in range(n)], dtype=np.int64)
    return ExperimentData(
        config=config,
        seed=int(seed),
        trials=trials,
        personas=tuple(personas),
        subjects=tuple(subjects),
        push_force_n=push,
        verbal_cue=verbal,
        measured_force_n=force,
        measured_position_m=position,
        true_state=state,
        judgment_step=steps,
        calibration=calibration,
    )


# --------------------------------------------------------------------------- estimation


@dataclass(frozen=True, eq=False)
class EstimateResult:
    """What an estimator made of an experiment (arrays are (S subjects, N trials, ...)).

    Attributes:
        estimator: Its name.
        judgment: (S, N) judged ``xi`` in {-1, 0, +1}.
        probabilities: (S, N, 3) ``P(xi = -1, 0, +1)`` at the judgment, ordered as :data:`XI_VALUES`
            (for the KF, :func:`gaussian_xi_probabilities` of its ``xi`` marginal).
        latency_s: (S, N) time from the initial cue onset to the judgment [s].
        xi_trace: (S, N, T) running ``xi`` estimate (KF mean, or posterior mean ``P(+1) - P(-1)``).
        state_trace: (S, N, T, 3) running ``x, xdot, eta`` estimate (NaN where not kept).
        xi_std_trace: (S, N, T) running ``xi`` std (KF: its marginal; others: posterior std).
    """

    estimator: str
    judgment: NDArray[np.int64]
    probabilities: NDArray[np.float64]
    latency_s: NDArray[np.float64]
    xi_trace: NDArray[np.float64]
    state_trace: NDArray[np.float64]
    xi_std_trace: NDArray[np.float64]


def gaussian_xi_probabilities(mean: ArrayLike, std: ArrayLike) -> NDArray[np.float64]:
    """Map the KF's Gaussian ``xi`` marginal ``N(mean, std^2)`` to probabilities over {-1, 0, +1}.

    ``P(xi = k)`` is the Gaussian mass of ``k``'s cell ``(-inf, -0.5]``, ``(-0.5, 0.5)``,
    ``[0.5, inf)``: the probability that ``k`` is the nearest value. The KF has no
    probabilities of its own; this is the documented mapping behind its log loss, Brier
    score and ECE.

    Example:
        >>> gaussian_xi_probabilities(0.0, 1e-9).round(3).tolist()
        [0.0, 1.0, 0.0]
    """
    m = np.asarray(mean, dtype=np.float64)
    sd = np.maximum(np.asarray(std, dtype=np.float64), 1e-12)
    lo = ndtr((-0.5 - m) / sd)
    hi = ndtr((0.5 - m) / sd)
    return np.stack([lo, hi - lo, 1.0 - hi], axis=-1)


def _flatten(
    force: NDArray[np.float64], verbal: NDArray[np.float64], position: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """(S, N, T) session arrays (verbal may be (N, T)) as contiguous (S*N, T) filter inputs."""
    s, n, t = position.shape
    verbal = np.broadcast_to(verbal, (s, n, t))
    return (
        np.ascontiguousarray(force.reshape(s * n, t)),
        np.ascontiguousarray(verbal.reshape(s * n, t)),
        np.ascontiguousarray(position.reshape(s * n, t)),
    )


def subject_models(data: ExperimentData, base: NominalModel | None = None) -> tuple[NominalModel, ...]:
    """Each subject's filter model: its persona's typical gains, not the subject's varied ones."""
    return tuple(nominal_model_for(p.params, data.config.timing, base) for p in data.personas)


def _rows(models: Sequence[NominalModel], n_trials: int) -> NDArray[np.float64]:
    """One packed nominal row per trial: each subject's model repeated over its trials."""
    return np.ascontiguousarray(np.repeat(np.stack([nominal_row(m) for m in models]), n_trials, axis=0))


def intention_drive(
    force: NDArray[np.float64],
    verbal: NDArray[np.float64],
    model: NominalModel,
    delay_s: float,
    touch_threshold_n: float = 0.0,
) -> NDArray[np.float64]:
    """The delayed cue drive of the intention, ``k3*c_p(t - d) + k4*c_v(t - d)`` [m/s] (eq. 6).

    Fed to a filter whose model is :func:`drive_model` (``k3 = 0``, ``k4 = 1``) as its
    "verbal" input, this makes the mode-dependent input ``xi*(k3 c_p + k4 c_v)`` act
    ``d`` late while the push's direct effect ``k2 c_p`` stays immediate: a linear
    filter with the person's reaction delay, built on the existing kernels unchanged.

    Args:
        force: (..., T) measured push force [N].
        verbal: (..., T) verbal cue.
        model: Supplies ``k3`` and ``k4``.
        delay_s: Reaction delay ``d`` [s] (rounded to whole steps).
        touch_threshold_n: Forces below this are not felt (measured noise at rest is ignored).
    """
    felt = np.where(force >= touch_threshold_n, force, 0.0)
    drive = model.push_gain_m_per_s_n * felt + model.verbal_gain_m_per_s * np.asarray(verbal, dtype=np.float64)
    d = round(delay_s / model.dt_s)
    out = np.zeros_like(drive)
    t = int(np.shape(drive)[-1])
    if d < t:
        out[..., d:] = drive[..., : t - d]
    return out


def drive_model(model: NominalModel) -> NominalModel:
    """``model`` rewired for :func:`intention_drive` inputs: ``k3 = 0``, ``k4 = 1`` (the drive carries the gains)."""
    return model.replace(push_gain_m_per_s_n=0.0, verbal_gain_m_per_s=1.0)


def bank_log_likelihoods(
    rows_per_mode: NDArray[np.float64],
    force: NDArray[np.float64],
    drive: NDArray[np.float64],
    position: NDArray[np.float64],
    prior: NominalModel,
) -> NDArray[np.float64]:
    """Cumulative log-likelihood of each trial under each mode's own model (a generalised MMAE).

    Mode ``j`` is the paper filter with ``xi`` pinned to ``XI_VALUES[j]`` (prior variance
    and random walk of ``xi`` zero), so its innovations are those of the 3-state mode
    filter of :mod:`estimator.multiple_model`; unlike :class:`MultipleModelEstimator`,
    each mode may have its own gains (e.g. its own push compliance ``k2``).

    Args:
        rows_per_mode: (3, N, 11) packed nominal rows, per mode and trial.
        force: (N, T) measured push [N].
        drive: (N, T) the second input (:func:`intention_drive`, with :func:`drive_model` rows).
        position: (N, T) measured shoulder position [m].
        prior: Source of the prior covariance of ``xdot`` and ``eta``.

    Returns:
        (N, T, 3) ``sum_{tau <= t} log p(y_tau | y_<tau, xi = j)``.
    """
    n, t = position.shape
    out = np.empty((n, t, 3))
    q_xi = NOMINAL_COLUMNS.index("q_cooperativeness")
    for j, xi in enumerate(XI_VALUES):
        rows = np.array(rows_per_mode[j], dtype=np.float64)
        rows[:, q_xi] = 0.0
        kf = FastKalmanFilter(rows, position[:, 0], prior=prior)
        kf.m[:, 3] = float(xi)
        kf.P[:, 3, 3] = 0.0
        _, _, ll = kf.run(force, drive, position)
        out[..., j] = np.cumsum(ll, axis=1)
    return out


def _posterior(log_lik: NDArray[np.float64], floor: float) -> NDArray[np.float64]:
    """Normalise log-likelihoods (uniform prior) into probabilities, floored at ``floor``."""
    p = np.exp(log_lik - log_lik.max(axis=-1, keepdims=True))
    p /= p.sum(axis=-1, keepdims=True)
    return (1.0 - 3.0 * floor) * p + floor


def _mode_rows(banks: Sequence[Sequence[NominalModel]], n_trials: int) -> NDArray[np.float64]:
    """(3, S*N, 11) rows from per-subject triples of per-mode models."""
    return np.stack([_rows([bank[j] for bank in banks], n_trials) for j in range(3)])


def _subject_drive(
    data: ExperimentData,
    force: NDArray[np.float64],
    verbal: NDArray[np.float64],
    models: Sequence[NominalModel],
    delays_s: Sequence[float],
) -> NDArray[np.float64]:
    """Per-subject intention drive of (S, N, T) sessions, flattened to (S*N, T)."""
    s, n, t = force.shape
    verbal = np.broadcast_to(verbal, (s, n, t))
    return np.concatenate(
        [
            intention_drive(
                force[i], verbal[i], models[i], delays_s[i], data.personas[i].params.cooperativeness.touch_threshold_n
            )
            for i in range(s)
        ]
    )


def person_bank(person: PersonParams, timing: Timing, base: NominalModel | None = None) -> tuple[NominalModel, ...]:
    """Per-mode delay-aware models (``xi = -1, 0, +1``) built from a person's parameters.

    Gains from :func:`~coop_gym.envs.core.nominal_model_for`; each mode's push compliance
    scaled by the person's stiffness in that state; process noise from the person's own
    noise intensities (acceleration noise held over a step -> velocity std ``sigma_a dt``;
    intention noise ``sigma_eta sqrt(dt)`` per step), floored so the filter stays well posed.
    """
    model = nominal_model_for(person, timing, base)
    bio, intent = person.biomechanics, person.intention
    dt = timing.dt_s
    model = model.replace(
        velocity_process_std_m_per_s=max(bio.accel_noise_std_m_per_s2 * dt, 1e-5),
        intention_process_std_m=max(intent.noise_std_m_per_sqrt_s * math.sqrt(dt), 1e-5),
    )
    factors = (bio.stiffness_factor_uncooperative, bio.stiffness_factor_unresponsive, 1.0)
    k2 = model.push_compliance_m_per_s2_n
    return tuple(drive_model(model).replace(push_compliance_m_per_s2_n=k2 * f) for f in factors)


def persona_banks(data: ExperimentData, base: NominalModel | None = None) -> tuple[tuple[NominalModel, ...], ...]:
    """Each subject's per-mode models from its *persona's* typical parameters (as the KF gets its gains)."""
    return tuple(person_bank(p.params, data.config.timing, base) for p in data.personas)


def oracle_banks(data: ExperimentData, base: NominalModel | None = None) -> tuple[tuple[NominalModel, ...], ...]:
    """Per-mode models from each subject's *true* (varied) parameters: an information bound, not an estimator."""
    return tuple(person_bank(p, data.config.timing, base) for p in data.subjects)


IDENTIFIED_FIELDS: tuple[str, ...] = (
    "push_compliance_m_per_s2_n",
    "verbal_gain_m_per_s",
    "velocity_process_std_m_per_s",
    "intention_process_std_m",
    "position_noise_std_m",
)
"""Fields fitted per subject and mode (``verbal_gain`` is the drive's scale; not for ``xi = 0``)."""


def identified_banks(
    data: ExperimentData,
    base: NominalModel | None = None,
    *,
    restarts: int = 1,
    window_before_s: float = 0.5,
    window_after_s: float = 1.5,
) -> tuple[tuple[NominalModel, ...], ...]:
    """Fit each subject's per-mode models to its labelled calibration session (maximum likelihood).

    For each subject and each ``xi``, :func:`estimator.identify.identify` fits
    :data:`IDENTIFIED_FIELDS` to that subject's calibration trials of that ``xi``, on the
    delay-aware inputs (:func:`intention_drive` with the persona's typical delay). Each
    mode thus learns the subject's own dynamics, compliance (stiffness in that state)
    and response strength: the paper's "previous history of individual care recipients".
    """
    from estimator.identify import Trial, identify

    if data.calibration is None:
        raise ValueError("identified estimators need run_experiment(..., with_calibration=True)")
    dt = data.config.timing.dt_s
    banks = []
    for i, (model, persona, session) in enumerate(
        zip(subject_models(data, base), data.personas, data.calibration, strict=True)
    ):
        delay = persona.params.intention.reaction_delay_s
        touch = persona.params.cooperativeness.touch_threshold_n
        force = session["measured_force_n"]
        drive = intention_drive(force, session["verbal_cue"], model, delay, touch)
        position = session["measured_position_m"]
        requested = np.array([spec.requested_xi for spec in session["trials"]])
        window = (
            max(data.config.onset_step - round(window_before_s / dt), 0),
            min(data.config.onset_step + round(window_after_s / dt), data.config.n_steps),
        )
        # Start from the persona's per-mode models: the fit personalises them.
        start = person_bank(persona.params, data.config.timing, base)
        bank = []
        for j, xi in enumerate(XI_VALUES):
            initial = start[j]
            chosen = np.flatnonzero(requested == xi)
            if chosen.size == 0:
                bank.append(initial)
                continue
            # Fit the stretch the judgment depends on -- from just before the initial cue to
            # well after it -- so the late, saturated part of a trial does not set the model.
            lo, hi = window
            trials = [Trial(force[k, lo:hi], drive[k, lo:hi], position[k, lo:hi], int(xi), dt) for k in chosen]
            fields = tuple(f for f in IDENTIFIED_FIELDS if xi != 0 or f != "verbal_gain_m_per_s")
            fit = identify(
                trials, initial=initial, labelled=True, restarts=restarts, seed=data.seed + i, fitted_fields=fields
            )
            bank.append(fit.model)
        banks.append(tuple(bank))
    return tuple(banks)


def _calibration_log_likelihoods(
    data: ExperimentData, banks: Sequence[Sequence[NominalModel]], base: NominalModel | None
) -> list[tuple[NDArray[np.float64], NDArray[np.int64]]]:
    """Per subject: bank log-likelihoods (K, 3) at the judgment step of its calibration trials, and their labels."""
    if data.calibration is None:
        raise ValueError("this estimator needs run_experiment(..., with_calibration=True)")
    models = subject_models(data, base)
    out = []
    for i, session in enumerate(data.calibration):
        force = np.ascontiguousarray(session["measured_force_n"])
        position = np.ascontiguousarray(session["measured_position_m"])
        persona = data.personas[i].params
        drive = intention_drive(
            force, session["verbal_cue"], models[i], persona.intention.reaction_delay_s,
            persona.cooperativeness.touch_threshold_n,
        )  # fmt: skip
        k = force.shape[0]
        rows = np.stack([np.repeat(nominal_row(banks[i][j])[None, :], k, axis=0) for j in range(3)])
        steps = np.array([judgment_step(data.config, *spec.cues(data.config)) for spec in session["trials"]])
        ll = bank_log_likelihoods(rows, force, drive, position, models[i])[np.arange(k), steps]
        out.append((ll, np.array([spec.requested_xi for spec in session["trials"]], dtype=np.int64)))
    return out


def fit_recalibration(log_lik: NDArray[np.float64], labels: NDArray[np.int64], l2: float = 0.1) -> NDArray[np.float64]:
    """Fit ``logits = log_lik / T + b`` (``T > 0``, ``b_0 = 0``) to labelled trials by max likelihood.

    A per-subject temperature and class offsets (multinomial logistic recalibration):
    the bank's evidence is kept, its confidence and its per-class bias are learned from
    the subject's history. ``l2`` is a small ridge on ``b`` and ``log T``.

    Returns:
        ``[log T, b_-1, b_+1]``.
    """
    import scipy.optimize

    y = np.asarray(labels) + 1

    def nll(theta: NDArray[np.float64]) -> float:
        logits = log_lik * math.exp(-theta[0]) + np.array([theta[1], 0.0, theta[2]])
        logits = logits - logits.max(axis=1, keepdims=True)
        lp = logits - np.log(np.exp(logits).sum(axis=1, keepdims=True))
        return float(-lp[np.arange(y.size), y].sum() + l2 * np.sum(theta**2))

    return np.asarray(scipy.optimize.minimize(nll, np.zeros(3), method="Nelder-Mead").x, dtype=np.float64)


def estimate(
    data: ExperimentData,
    estimator: str = "kalman",
    *,
    base: NominalModel | None = None,
    decision: Literal["map", "sequential"] = "map",
    error_rate: float = 0.05,
    banks: Sequence[Sequence[NominalModel]] | None = None,
) -> EstimateResult:
    """Run one estimator on every trial of ``data`` and judge each trial.

    Args:
        data: The simulated experiment.
        estimator: One of :data:`ESTIMATORS`.
        base: Noise settings of the nominal models (default ``NominalModel()``).
        decision: Multiple-model judgments: ``"map"`` at the paper's judgment step, or
            ``"sequential"`` -- the earliest step after the initial onset at which one
            mode's posterior odds reach ``(1 - error_rate) / error_rate``
            (:func:`~estimator.multiple_model.sequential_judgment`), falling back to MAP
            at the paper's step; never later than the paper.
        error_rate: Of the sequential rule.
        banks: Per-subject per-mode models for the bank estimators (default: built or
            fitted as the estimator prescribes).
    """
    from estimator.multiple_model import IMMEstimator, MultipleModelEstimator, map_judgment, sequential_judgment

    if estimator not in ESTIMATORS:
        raise ValueError(f"unknown estimator {estimator!r}; choose from {', '.join(ESTIMATORS)}")
    if decision not in ("map", "sequential"):
        raise ValueError(f"decision must be 'map' or 'sequential', got {decision!r}")
    config = data.config
    s, n, t = data.measured_position_m.shape
    models = subject_models(data, base)
    prior = models[0]
    force, verbal, position = _flatten(data.measured_force_n, data.verbal_cue, data.measured_position_m)
    judge_at = np.tile(data.judgment_step, s)
    at = (np.arange(s * n), judge_at)
    states = np.full((s * n, t, 3), np.nan)
    if estimator == "kalman":
        kf = FastKalmanFilter(_rows(models, n), position[:, 0], prior=prior)
        means, covs, _ = kf.run(force, verbal, position)
        xi = means[..., 3]
        xi_std = np.sqrt(np.maximum(covs[..., 3, 3], 0.0))
        states = means[..., :3]
        judged = config.judgment.judge(xi[at])
        probs = gaussian_xi_probabilities(xi[at], xi_std[at])
        step = judge_at
    else:
        floor = config.probability_floor
        if estimator in ("multiple_model", "imm", "delay_aware"):
            if estimator == "delay_aware":
                delays = [p.params.intention.reaction_delay_s for p in data.personas]
                verbal = _subject_drive(data, data.measured_force_n, data.verbal_cue, models, delays)
                rows = _rows([drive_model(m) for m in models], n)
            else:
                rows = _rows(models, n)
            mm: Any
            if estimator == "imm":
                mm = IMMEstimator(
                    rows, position[:, 0], prior=prior, probability_floor=floor,
                    switching_rate_per_s=config.switching_rate_per_s,
                )  # fmt: skip
            else:
                mm = MultipleModelEstimator(rows, position[:, 0], prior=prior, probability_floor=floor)
            probs_seq = mm.run(force, verbal, position)
        else:
            if banks is None:
                if estimator in ("persona_bank", "calibrated"):
                    banks = persona_banks(data, base)
                elif estimator == "oracle":
                    banks = oracle_banks(data, base)
                else:
                    banks = identified_banks(data, base)
            if len(banks) != s or any(len(b) != 3 for b in banks):
                raise ValueError(f"banks must hold 3 models for each of the {s} subjects")
            if estimator == "oracle":
                delays = [p.intention.reaction_delay_s for p in data.subjects]
            else:
                delays = [p.params.intention.reaction_delay_s for p in data.personas]
            drive = _subject_drive(data, data.measured_force_n, data.verbal_cue, models, delays)
            log_lik = bank_log_likelihoods(_mode_rows(banks, n), force, drive, position, prior)
            if estimator == "calibrated":
                # Per subject: temperature and class offsets learned on its calibration session.
                for i, (ll, labels) in enumerate(_calibration_log_likelihoods(data, banks, base)):
                    theta = fit_recalibration(ll, labels)
                    block = slice(i * n, (i + 1) * n)
                    log_lik[block] = log_lik[block] * math.exp(-theta[0]) + np.array([theta[1], 0.0, theta[2]])
            probs_seq = _posterior(log_lik, floor)
        xi = probs_seq[..., 2] - probs_seq[..., 0]
        xi_std = np.sqrt(np.maximum(probs_seq[..., 2] + probs_seq[..., 0] - xi**2, 0.0))
        step = judge_at
        if decision == "sequential":
            _, seq_step = sequential_judgment(probs_seq, error_rate=error_rate, start_step=config.onset_step)
            early = (seq_step >= 0) & (seq_step <= judge_at)
            step = np.where(early, seq_step, judge_at)
        probs = probs_seq[np.arange(s * n), step]
        judged = map_judgment(probs)
    # On the judgment tracker's clock (time since onset, as the envs report it): the paper step is 0.74 s.
    latency = np.asarray((step - config.onset_step) * config.timing.dt_s, dtype=np.float64)
    return EstimateResult(
        estimator=estimator,
        judgment=np.asarray(judged, dtype=np.int64).reshape(s, n),
        probabilities=probs.reshape(s, n, 3),
        latency_s=latency.reshape(s, n),
        xi_trace=xi.reshape(s, n, t),
        state_trace=states.reshape(s, n, t, 3),
        xi_std_trace=xi_std.reshape(s, n, t),
    )


# --------------------------------------------------------------------------- scoring


def confusion_matrix(requested: ArrayLike, judged: ArrayLike) -> NDArray[np.int64]:
    """(3, 3) counts, rows = requested ``xi`` -1, 0, +1, columns = judged -1, 0, +1.

    Example:
        >>> confusion_matrix([-1, 0, 1, 1], [0, 0, 1, 1]).tolist()
        [[0, 1, 0], [0, 1, 0], [0, 0, 2]]
    """
    req = np.asarray(requested).ravel()
    jud = np.asarray(judged).ravel()
    if req.shape != jud.shape:
        raise ValueError(f"requested and judged must have the same size, got {req.shape} and {jud.shape}")
    if not (np.isin(req, XI_VALUES).all() and np.isin(jud, XI_VALUES).all()):
        raise ValueError("xi values must be -1, 0 or 1")
    out = np.zeros((3, 3), dtype=np.int64)
    np.add.at(out, (req.astype(np.int64) + 1, jud.astype(np.int64) + 1), 1)
    return out


def accuracy(confusion: ArrayLike) -> float:
    """Fraction of trials on the diagonal."""
    c = np.asarray(confusion, dtype=np.float64)
    return float(np.trace(c) / c.sum())


def balanced_accuracy(confusion: ArrayLike) -> float:
    """Mean correct rate ``P(judged = k | requested = k)`` over the requested classes present."""
    c = np.asarray(confusion, dtype=np.float64)
    rows = c.sum(axis=1)
    present = rows > 0
    return float(np.mean(np.diag(c)[present] / rows[present]))


def conditional_tables(confusion: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The paper's Tables II and III: ``P(judged | requested)`` (rows sum to 1), ``P(requested | judged)`` (columns).

    Empty rows or columns give NaN.
    """
    c = np.asarray(confusion, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return c / c.sum(axis=1, keepdims=True), c / c.sum(axis=0, keepdims=True)


def summarize(data: ExperimentData, result: EstimateResult) -> dict[str, Any]:
    """The paper's three tables and the scores of one estimator on one experiment (JSON-ready).

    Keys: ``confusion`` (rows requested -1, 0, 1; columns judged -1, 0, 1),
    ``p_estimated_given_requested``, ``p_requested_given_estimated``, ``accuracy``,
    ``balanced_accuracy``, ``log_loss``, ``brier``, ``ece``, ``mean_latency_s`` and the run's
    identification.
    """
    requested = data.requested
    conf = confusion_matrix(requested, result.judgment)
    # Calibration scores from estimator.metrics (10 top-label bins on [1/3, 1] for the ECE).
    probs = result.probabilities.reshape(-1, 3)
    probs = probs / probs.sum(axis=1, keepdims=True)
    labels = requested.ravel()
    given_req, given_est = conditional_tables(conf)
    return {
        "estimator": result.estimator,
        "seed": data.seed,
        "n_subjects": len(data.subjects),
        "n_trials": len(data.trials),
        "personas": [p.name for p in data.personas],
        "confusion": conf.tolist(),
        "p_estimated_given_requested": _nan_to_none(given_req),
        "p_requested_given_estimated": _nan_to_none(given_est),
        "accuracy": accuracy(conf),
        "balanced_accuracy": balanced_accuracy(conf),
        "log_loss": metrics.log_loss(probs, labels),
        "brier": metrics.brier_score(probs, labels),
        "ece": metrics.expected_calibration_error(probs, labels),
        "mean_latency_s": float(result.latency_s.mean()),
    }


def _nan_to_none(a: NDArray[np.float64]) -> list[list[float | None]]:
    return [[None if not math.isfinite(v) else float(v) for v in row] for row in a]


def run_protocol(
    config: ProtocolConfig,
    seed: int,
    estimator: str = "kalman",
    *,
    decision: Literal["map", "sequential"] = "map",
) -> dict[str, Any]:
    """Simulate the experiment with ``seed`` and score ``estimator`` on it (see :func:`summarize`).

    Example:
        >>> out = run_protocol(ProtocolConfig(n_subjects=1, n_trials=6), seed=0)
        >>> sum(map(sum, out["confusion"]))
        6
    """
    if estimator not in ESTIMATORS:
        raise ValueError(f"unknown estimator {estimator!r}; choose from {', '.join(ESTIMATORS)}")
    data = run_experiment(config, seed, with_calibration=estimator in NEEDS_CALIBRATION)
    return summarize(data, estimate(data, estimator, decision=decision))


# --------------------------------------------------------------------------- reporting


def _pct(v: float | None) -> str:
    return "   -  " if v is None or not math.isfinite(v) else f"{100 * v:5.1f}%"


def format_tables(summary: dict[str, Any], paper: PaperResults = PAPER_RESULTS) -> str:
    """The paper's three tables for one run, each beside the paper's numbers on real people."""
    conf = np.array(summary["confusion"])
    ours = [conf, *conditional_tables(conf)]
    theirs = [paper.matrix, *conditional_tables(paper.matrix)]
    titles = (
        "Table I   joint counts (rows: requested, columns: estimated)",
        "Table II  P(estimated | requested)",
        "Table III P(requested | estimated)",
    )
    head = "".join(f"{n:>8s}" for n in XI_SHORT)
    lines = [
        f"estimator: {summary['estimator']}, seed {summary['seed']}, {summary['n_subjects']} subjects x "
        f"{summary['n_trials']} trials (simulated)  |  paper: 4 real subjects x 25 trials",
    ]
    for k, title in enumerate(titles):
        lines += ["", f"{title}   [simulated | paper]", f"{'requested':>14s}{head}   |{head}"]
        for r, name in enumerate(XI_NAMES):
            if k == 0:
                a = "".join(f"{int(v):8d}" for v in ours[0][r])
                b = "".join(f"{int(v):8d}" for v in theirs[0][r])
            else:
                a = "".join(f"{_pct(v):>8s}" for v in ours[k][r])
                b = "".join(f"{_pct(v):>8s}" for v in theirs[k][r])
            lines.append(f"{name:>14s}{a}   |{b}")
    lines += [
        "",
        f"accuracy           {100 * summary['accuracy']:5.1f}%   (paper {100 * paper.accuracy:5.1f}%)",
        f"balanced accuracy  {100 * summary['balanced_accuracy']:5.1f}%   "
        f"(paper {100 * paper.balanced_accuracy:5.1f}%)",
        f"log loss {summary['log_loss']:.3f} nats, Brier {summary['brier']:.3f}, ECE {summary['ece']:.3f}, "
        f"judgment {summary['mean_latency_s']:.2f} s after the initial cue onset",
    ]
    return "\n".join(lines)


def aggregate(summaries: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Mean and std over seeds of every score, the per-cell rates and the counts."""
    conf = np.array([s["confusion"] for s in summaries], dtype=np.float64)
    given_req = np.array([conditional_tables(c)[0] for c in conf])
    given_est = np.array([conditional_tables(c)[1] for c in conf])
    out: dict[str, Any] = {
        "estimator": summaries[0]["estimator"],
        "seeds": [s["seed"] for s in summaries],
        "confusion_mean": conf.mean(axis=0).tolist(),
        "confusion_std": conf.std(axis=0).tolist(),
        "confusion": conf.sum(axis=0).astype(np.int64).tolist(),
    }
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        out["p_estimated_given_requested_mean"] = _nan_to_none(np.nanmean(given_req, axis=0))
        out["p_estimated_given_requested_std"] = _nan_to_none(np.nanstd(given_req, axis=0))
        out["p_requested_given_estimated_mean"] = _nan_to_none(np.nanmean(given_est, axis=0))
        out["p_requested_given_estimated_std"] = _nan_to_none(np.nanstd(given_est, axis=0))
    for key in ("accuracy", "balanced_accuracy", "log_loss", "brier", "ece", "mean_latency_s"):
        values = np.array([s[key] for s in summaries], dtype=np.float64)
        out[key] = float(values.mean())
        out[f"{key}_std"] = float(values.std())
    return out


def format_aggregate(agg: dict[str, Any], paper: PaperResults = PAPER_RESULTS) -> str:
    """Per-cell mean +/- std over seeds beside the paper (Tables I-III), and the scores."""
    p_conf = paper.matrix
    p_req, p_est = conditional_tables(p_conf)
    blocks = (
        ("Table I   counts per run (rows: requested, columns: estimated)", "confusion", p_conf, False),
        ("Table II  P(estimated | requested)", "p_estimated_given_requested", p_req, True),
        ("Table III P(requested | estimated)", "p_requested_given_estimated", p_est, True),
    )
    head = "".join(f"{n:>15s}" for n in XI_SHORT)
    lines = [f"estimator: {agg['estimator']}, {len(agg['seeds'])} seeds (mean +/- std over seeds)  |  paper: real"]
    for title, key, theirs, pct in blocks:
        paper_head = "".join(f"{n:>8s}" for n in XI_SHORT)
        lines += ["", f"{title}   [simulated | paper]", f"{'requested':>14s}{head}   |{paper_head}"]
        mean = np.array(agg[f"{key}_mean"], dtype=np.float64)
        std = np.array(agg[f"{key}_std"], dtype=np.float64)
        for r, name in enumerate(XI_NAMES):
            if pct:
                a = "".join(f"{100 * m:6.1f} +/-{100 * s:4.1f}" for m, s in zip(mean[r], std[r], strict=True))
                b = "".join(f"{_pct(v):>8s}" for v in theirs[r])
            else:
                a = "".join(f"{m:6.1f} +/-{s:4.1f}" for m, s in zip(mean[r], std[r], strict=True))
                b = "".join(f"{int(v):8d}" for v in theirs[r])
            lines.append(f"{name:>14s}{a}   |{b}")
    lines += [
        "",
        f"accuracy           {100 * agg['accuracy']:5.1f} +/- {100 * agg['accuracy_std']:4.1f}%   "
        f"(paper {100 * paper.accuracy:5.1f}%)",
        f"balanced accuracy  {100 * agg['balanced_accuracy']:5.1f} +/- {100 * agg['balanced_accuracy_std']:4.1f}%   "
        f"(paper {100 * paper.balanced_accuracy:5.1f}%)",
        f"log loss {agg['log_loss']:.3f} +/- {agg['log_loss_std']:.3f}, Brier {agg['brier']:.3f} +/- "
        f"{agg['brier_std']:.3f}, ECE {agg['ece']:.3f} +/- {agg['ece_std']:.3f}, "
        f"latency {agg['mean_latency_s']:.2f} s",
    ]
    return "\n".join(lines)


# --------------------------------------------------------------------------- figures


def plot_trial(
    data: ExperimentData,
    path: str,
    *,
    subject: int = 0,
    trial: int | None = None,
    estimator: EstimateResult | None = None,
) -> str:
    """Write the paper's Fig. 6 for one trial as a PNG: ``x, xdot, eta, xi`` estimates and truth.

    The x, xdot and eta panels show the paper filter's estimates; the xi panel shows its
    estimate with the +/- threshold band and the judgment window (and, if given, another
    estimator's posterior mean ``P(+1) - P(-1)``). By default the first trial with both cues
    and a cooperative request (the paper's example), else trial 0.

    Returns:
        ``path``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    config = data.config
    if not 0 <= subject < len(data.subjects):
        raise ValueError(f"subject must be in [0, {len(data.subjects)}), got {subject}")
    if trial is None:
        both = [
            k for k, t in enumerate(data.trials)
            if t.requested_xi == 1 and t.physical_cue != "none" and t.verbal_cue != "none"
        ]  # fmt: skip
        trial = both[0] if both else 0
    if not 0 <= trial < len(data.trials):
        raise ValueError(f"trial must be in [0, {len(data.trials)}), got {trial}")
    kf = estimate(data, "kalman")
    spec = data.trials[trial]
    time_s = (np.arange(config.n_steps) + 1) * config.timing.dt_s
    truth = data.true_state[subject, trial]
    est = kf.state_trace[subject, trial]
    fig, axes = plt.subplots(3, 2, figsize=(10, 8), sharex=True)
    ax = axes.ravel()
    ax[0].plot(time_s, 100 * data.measured_position_m[subject, trial], ".", ms=2, color="0.6", label="measured")
    panels = (("x [cm]", 0, 100.0), ("xdot [cm/s]", 1, 100.0), ("eta [cm]", 2, 100.0))
    for k, (label, col, scale) in enumerate(panels):
        ax[k].plot(time_s, scale * truth[:, col], "k-", lw=1.2, label="true")
        ax[k].plot(time_s, scale * est[:, col], "C0-", lw=1.2, label="KF estimate")
        ax[k].set_ylabel(label)
    ax[0].legend(loc="upper left", fontsize=8)
    ax[3].plot(time_s, data.push_force_n[trial], "C3-", label="push c_p [N]")
    ax[3].plot(time_s, data.measured_force_n[subject, trial], "C3.", ms=1, alpha=0.4)
    ax3b = ax[3].twinx()
    ax3b.plot(time_s, data.verbal_cue[trial], "C2-", label="verbal c_v")
    ax3b.set_ylim(-1.5, 1.5)
    ax3b.set_ylabel("verbal cue c_v")
    ax[3].set_ylabel("push [N]")
    ax[3].legend(loc="upper left", fontsize=8)
    xi_ax = ax[4]
    threshold = config.judgment.threshold
    xi_ax.axhspan(-threshold, threshold, color="0.9", label=f"unresponsive band +/-{threshold}")
    xi_ax.axhline(threshold, color="0.5", lw=0.8, ls="--")
    xi_ax.axhline(-threshold, color="0.5", lw=0.8, ls="--")
    onset_s = config.onset_step * config.timing.dt_s
    judge_s = time_s[data.judgment_step[trial]]
    xi_ax.axvspan(onset_s, judge_s, color="C1", alpha=0.15, label="judgment window")
    xi_ax.axvline(judge_s, color="C1", lw=1.0)
    xi_ax.plot(time_s, truth[:, 3], "k-", lw=1.2, label="requested (true)")
    xi_ax.plot(time_s, kf.xi_trace[subject, trial], "C0-", lw=1.2, label="KF estimate")
    if estimator is not None and estimator.estimator != "kalman":
        xi_ax.plot(
            time_s, estimator.xi_trace[subject, trial], "C4-", lw=1.2, label=f"{estimator.estimator} P(+1)-P(-1)"
        )
    judged = int(kf.judgment[subject, trial])
    xi_ax.set_title(f"KF judgment: {XI_NAMES[judged + 1]}", fontsize=9)
    xi_ax.set_ylabel("xi")
    xi_ax.set_ylim(-2.0, 2.0)
    xi_ax.legend(loc="lower left", fontsize=7)
    ax[5].axis("off")
    ax[5].text(
        0.0, 0.9,
        f"subject {subject} ({data.personas[subject].name}), trial {trial}\n"
        f"requested xi = {spec.requested_xi:+d}\nphysical cue: {spec.physical_cue}\n"
        f"verbal cue: {spec.verbal_cue}\nrelative timing: {spec.relative_timing_s:+d} s\n"
        f"judged {config.judgment.delay_s} s after the initial cue onset",
        va="top", fontsize=9,
    )  # fmt: skip
    for a in (ax[3], ax[4]):
        a.set_xlabel("time [s]")
    fig.suptitle("Fig. 6 style: paper Kalman filter on one simulated trial")
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path


def plot_confusion(summary: dict[str, Any], path: str, paper: PaperResults = PAPER_RESULTS) -> str:
    """Write the confusion matrix beside the paper's as a PNG (``P(estimated | requested)`` shading, counts)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 4))
    panels = (
        (np.array(summary["confusion"]), f"{summary['estimator']} (simulated)"),
        (paper.matrix, "paper (real people)"),
    )
    for ax, (conf, title) in zip(axes, panels, strict=True):
        rates = conditional_tables(conf)[0]
        ax.imshow(np.nan_to_num(rates), vmin=0.0, vmax=1.0, cmap="Blues")
        for r in range(3):
            for c in range(3):
                v = rates[r, c]
                txt = f"{int(conf[r, c])}\n{_pct(v)}"
                ax.text(c, r, txt, ha="center", va="center", color="white" if v > 0.5 else "black", fontsize=9)
        ax.set_xticks(range(3), list(XI_SHORT))
        ax.set_yticks(range(3), list(XI_SHORT))
        ax.set_xlabel("estimated")
        ax.set_ylabel("requested")
        ax.set_title(f"{title}\nBA {100 * balanced_accuracy(conf):.1f}%", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path


# --------------------------------------------------------------------------- command line


def build_parser() -> argparse.ArgumentParser:
    """The ``python -m estimator.protocol`` argument parser."""
    parser = argparse.ArgumentParser(
        prog="python -m estimator.protocol",
        description="Bell & Asada's cooperativeness-judgment experiment on simulated subjects: the paper's "
        "three tables side by side with its numbers on real people.",
    )
    parser.add_argument("--subjects", type=_positive_int, default=4, help="simulated subjects (paper: 4)")
    parser.add_argument("--trials", type=_positive_int, default=25, help="trials per subject (paper: 25)")
    parser.add_argument("--seed", type=_seed, default=0, help="seed of trials, subjects and noise")
    parser.add_argument("--seeds", type=_positive_int, default=1, help="run seeds seed..seed+K-1, report mean +/- std")
    parser.add_argument("--estimator", choices=ESTIMATORS, default="kalman", help="estimator to score")
    parser.add_argument(
        "--decision", choices=("map", "sequential"), default="map",
        help="multiple-model judgment: MAP at the paper's 0.75 s, or the earliest confident step up to it",
    )  # fmt: skip
    parser.add_argument("--personas", default="all", help="persona set of the subjects: all, train, test or a name")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of tables")
    parser.add_argument("--plot", metavar="PATH", help="write a Fig. 6 style trace of one trial (PNG)")
    parser.add_argument("--plot-confusion", metavar="PATH", help="write the confusion matrix beside the paper's (PNG)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point; usage errors exit with status 2."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        config = ProtocolConfig(n_subjects=args.subjects, n_trials=args.trials, personas=args.personas)
    except ValueError as err:
        parser.error(str(err))
    problem = seed_range_problem("--seed", args.seed, args.seeds)  # runs seed .. seed + seeds - 1
    if problem:
        parser.error(problem)
    for path in (args.plot, args.plot_confusion):
        if path is not None and not path.lower().endswith(".png"):
            parser.error(f"plot paths must end in .png, got {path!r}")
        # Checked before the experiment runs, so a bad path fails at once, not after the work.
        problem = output_path_problem(path) if path is not None else None
        if problem:
            parser.error(problem)
    summaries = []
    first: tuple[ExperimentData, EstimateResult] | None = None
    for seed in range(args.seed, args.seed + args.seeds):
        data = run_experiment(config, seed, with_calibration=args.estimator in NEEDS_CALIBRATION)
        result = estimate(data, args.estimator, decision=args.decision)
        summaries.append(summarize(data, result))
        if first is None:
            first = (data, result)
    assert first is not None
    if args.seeds == 1:
        out = summaries[0]
        text = format_tables(out)
    else:
        out = aggregate(summaries)
        text = format_aggregate(out)
    out["paper"] = {
        "confusion": PAPER_RESULTS.matrix.tolist(),
        "accuracy": PAPER_RESULTS.accuracy,
        "balanced_accuracy": PAPER_RESULTS.balanced_accuracy,
    }
    try:
        if args.plot:
            plot_trial(first[0], args.plot, estimator=first[1])
        if args.plot_confusion:
            plot_confusion(out, args.plot_confusion)
    except OSError as exc:  # e.g. a full disk: the file is not there (never half-written)
        print(f"error: could not write {exc.filename or 'output'}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    print(json.dumps(out) if args.json else text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
