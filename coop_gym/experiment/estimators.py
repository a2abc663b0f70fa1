"""Estimators of cooperativeness on the simulated experiment, as a registry of named estimators.

Every estimator judges the same simulated data (:func:`estimate`, ``name`` from
:data:`ESTIMATORS`); all judge on the same step as the paper (0.74 s on the tracker's
clock) unless ``decision="sequential"`` lets a multiple-model estimator decide earlier
when confident:

* ``kalman`` -- the paper's filter (:class:`~estimator.kalman.FastKalmanFilter`, equal
  to the filterpy reference) on the persona's nominal model
  (:func:`coop_gym.envs.core.nominal_model_for`: the persona's typical gains, not the
  subject's varied ones), thresholded at +/-0.3. Its probabilities for log loss / Brier /
  ECE come from :func:`~estimator.judgment.gaussian_xi_probabilities`.
* ``multiple_model`` / ``imm`` -- MMAE and IMM of :mod:`estimator.multiple_model` on
  the same nominal model, MAP judgment.
* ``delay_aware`` -- the same MMAE fed the *delayed* intention drive
  (:func:`~coop_gym.experiment.banks.intention_drive`, the persona's typical reaction
  delay): the linear model with the person's reaction delay, on the unchanged kernel.
* ``persona_bank`` -- a bank of three delay-aware filters, one per ``xi``, each with its
  own push compliance (the persona's state-dependent stiffness) and the persona's noise
  intensities (:func:`~coop_gym.experiment.banks.bank_log_likelihoods`); Bayes over the
  three, MAP.
* ``calibrated`` -- ``persona_bank`` with a per-subject temperature and class offsets
  learned on a separate labelled calibration session of that subject
  (:func:`fit_recalibration`): the subject's history, used discriminatively.
* ``identified`` -- per-subject, per-``xi`` models fitted by maximum likelihood
  (:func:`estimator.identification.identify.identify`) on the calibration session
  (:func:`~coop_gym.experiment.banks.identified_banks`): the subject's history, used
  generatively.
* ``switching`` -- the switching particle filter the belief caregiver reads
  (:mod:`estimator.particle`, built as the envs' ``estimator="switching"`` builds it): the
  level's person (:attr:`ProtocolConfig.difficulty`) with ``xi`` as a switching mode, on
  parameter hypotheses drawn around the training personas, never the subject's own. MAP of
  its ``P(xi)``.
* ``oracle`` -- the bank on each subject's *true* parameters: not an estimator but the
  information bound of linear delay-aware filters at the judgment instant.

``python -m coop_gym.experiment.calibrate`` reports all of them over 20 seeds; their table is
``python bench/papers_experiment.py`` (``bench/results/papers_experiment.json``, docs/BENCHMARKS.md,
"The paper's experiment"). MMAE and IMM on the paper's nominal model need more evidence for
their MAP than the 0.3 threshold, and the nominal model misses the reaction delay; at the
0.75-s judgment the person has been responding for only 0.75 s minus that delay, which bounds
what any filter (the oracle included) can know then.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from coop_gym.envs.switching import level_filter
from coop_gym.experiment.banks import (
    bank_log_likelihoods,
    drive_model,
    identified_banks,
    intention_drive,
    oracle_banks,
    persona_banks,
    subject_models,
)
from coop_gym.experiment.simulation import ExperimentData, judgment_step
from estimator.judgment import gaussian_xi_probabilities
from estimator.kalman import FastKalmanFilter, nominal_row
from estimator.multiple_model import IMMEstimator, MultipleModelEstimator, map_judgment, sequential_judgment
from estimator.nominal import NominalModel

__all__ = [
    "ESTIMATORS",
    "ESTIMATOR_REGISTRY",
    "NEEDS_CALIBRATION",
    "EstimateResult",
    "estimate",
    "fit_recalibration",
    "gaussian_xi_probabilities",
]

SWITCHING_STREAM = 0x5317C4
"""Mixed with the experiment's seed into the particles' random streams (``switching``)."""

# --------------------------------------------------------------------------- estimation


@dataclass(frozen=True, eq=False)
class EstimateResult:
    """What an estimator made of an experiment (arrays are (S subjects, N trials, ...)).

    Attributes:
        estimator: Its name.
        judgment: (S, N) judged ``xi`` in {-1, 0, +1}.
        probabilities: (S, N, 3) ``P(xi = -1, 0, +1)`` at the judgment, ordered as :data:`XI_VALUES`
            (for the KF, :func:`~estimator.judgment.gaussian_xi_probabilities` of its ``xi`` marginal).
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


def _rows(models: Sequence[NominalModel], n_trials: int) -> NDArray[np.float64]:
    """One packed nominal row per trial: each subject's model repeated over its trials."""
    return np.ascontiguousarray(np.repeat(np.stack([nominal_row(m) for m in models]), n_trials, axis=0))


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


# --------------------------------------------------------------------------- the registry


@dataclass(frozen=True, eq=False)
class _Inputs:
    """An experiment as (S*N, T) filter inputs, and the options every estimator may read."""

    data: ExperimentData
    base: NominalModel | None
    banks: Sequence[Sequence[NominalModel]] | None
    models: tuple[NominalModel, ...]
    force: NDArray[np.float64]
    verbal: NDArray[np.float64]
    position: NDArray[np.float64]
    judge_at: NDArray[np.int64]
    decision: Literal["map", "sequential"]
    error_rate: float

    @property
    def n_trials(self) -> int:
        return int(self.data.measured_position_m.shape[1])

    @property
    def prior(self) -> NominalModel:
        return self.models[0]


@dataclass(frozen=True, eq=False)
class _Judgments:
    """What an estimator made of the (S*N) flattened trials."""

    judged: NDArray[np.int64]
    probabilities: NDArray[np.float64]
    step: NDArray[np.int64]
    xi: NDArray[np.float64]
    xi_std: NDArray[np.float64]
    states: NDArray[np.float64]


def _kalman(inputs: _Inputs) -> _Judgments:
    """The paper's filter, thresholded at the paper's step; probabilities from its Gaussian ``xi`` marginal."""
    kf = FastKalmanFilter(_rows(inputs.models, inputs.n_trials), inputs.position[:, 0], prior=inputs.prior)
    means, covs, _ = kf.run(inputs.force, inputs.verbal, inputs.position)
    xi = means[..., 3]
    xi_std = np.sqrt(np.maximum(covs[..., 3, 3], 0.0))
    at = (np.arange(xi.shape[0]), inputs.judge_at)
    return _Judgments(
        judged=inputs.data.config.judgment.judge(xi[at]),
        probabilities=gaussian_xi_probabilities(xi[at], xi_std[at]),
        step=inputs.judge_at,
        xi=xi,
        xi_std=xi_std,
        states=means[..., :3],
    )


PosteriorEstimator = Callable[[_Inputs], NDArray[np.float64]]
"""Gives (S*N, T, 3) probabilities ``P(xi = -1, 0, +1)`` after each step."""


def _judge_posterior(estimator: PosteriorEstimator) -> Callable[[_Inputs], _Judgments]:
    """MAP judgment of a posterior estimator, at the paper's step or (sequential) earlier when confident."""

    def judge(inputs: _Inputs) -> _Judgments:
        probs_seq = estimator(inputs)
        xi = probs_seq[..., 2] - probs_seq[..., 0]
        xi_std = np.sqrt(np.maximum(probs_seq[..., 2] + probs_seq[..., 0] - xi**2, 0.0))
        step = inputs.judge_at
        if inputs.decision == "sequential":
            onset = inputs.data.config.onset_step
            _, seq_step = sequential_judgment(probs_seq, error_rate=inputs.error_rate, start_step=onset)
            early = (seq_step >= 0) & (seq_step <= step)
            step = np.where(early, seq_step, step)
        probs = probs_seq[np.arange(probs_seq.shape[0]), step]
        states = np.full((*probs_seq.shape[:2], 3), np.nan)
        return _Judgments(map_judgment(probs), probs, step, xi, xi_std, states)

    return judge


def _multiple_model(inputs: _Inputs) -> NDArray[np.float64]:
    """MMAE on the persona's nominal model."""
    rows = _rows(inputs.models, inputs.n_trials)
    floor = inputs.data.config.probability_floor
    mm = MultipleModelEstimator(rows, inputs.position[:, 0], prior=inputs.prior, probability_floor=floor)
    return mm.run(inputs.force, inputs.verbal, inputs.position)


def _imm(inputs: _Inputs) -> NDArray[np.float64]:
    """IMM on the persona's nominal model (``xi`` may switch)."""
    config = inputs.data.config
    imm = IMMEstimator(
        _rows(inputs.models, inputs.n_trials), inputs.position[:, 0], prior=inputs.prior,
        probability_floor=config.probability_floor, switching_rate_per_s=config.switching_rate_per_s,
    )  # fmt: skip
    return imm.run(inputs.force, inputs.verbal, inputs.position)


def _switching(inputs: _Inputs) -> NDArray[np.float64]:
    """The switching particle filter (the envs' ``estimator="switching"``) on the level's person."""
    config = inputs.data.config
    n = inputs.position.shape[0]
    seeds = np.random.SeedSequence([inputs.data.seed, SWITCHING_STREAM]).spawn(n)
    rngs = [np.random.default_rng(s) for s in seeds]
    pf = level_filter(config.timing, config.realism, rngs, {"difficulty": config.difficulty})
    pf.reset(np.arange(n), inputs.position[:, 0])
    return pf.run(inputs.force, inputs.verbal, inputs.position)


def _persona_delays(data: ExperimentData) -> list[float]:
    return [p.params.intention.reaction_delay_s for p in data.personas]


def _delay_aware(inputs: _Inputs) -> NDArray[np.float64]:
    """MMAE fed the persona's delayed intention drive."""
    data = inputs.data
    drive = _subject_drive(data, data.measured_force_n, data.verbal_cue, inputs.models, _persona_delays(data))
    rows = _rows([drive_model(m) for m in inputs.models], inputs.n_trials)
    floor = data.config.probability_floor
    mm = MultipleModelEstimator(rows, inputs.position[:, 0], prior=inputs.prior, probability_floor=floor)
    return mm.run(inputs.force, drive, inputs.position)


BankSource = Callable[[ExperimentData, "NominalModel | None"], Sequence[Sequence[NominalModel]]]


def _banks(inputs: _Inputs, default_banks: BankSource) -> Sequence[Sequence[NominalModel]]:
    """The per-subject per-mode banks: given, or built by ``default_banks``; three models per subject."""
    data = inputs.data
    banks = inputs.banks if inputs.banks is not None else default_banks(data, inputs.base)
    if len(banks) != len(data.subjects) or any(len(b) != 3 for b in banks):
        raise ValueError(f"banks must hold 3 models for each of the {len(data.subjects)} subjects")
    return banks


def _bank_log_likelihoods(
    inputs: _Inputs, banks: Sequence[Sequence[NominalModel]], true_delays: bool = False
) -> NDArray[np.float64]:
    """(S*N, T, 3) log-likelihoods of the banks on the delayed drive (persona's or, for the oracle, true delays)."""
    data = inputs.data
    delays = [p.intention.reaction_delay_s for p in data.subjects] if true_delays else _persona_delays(data)
    drive = _subject_drive(data, data.measured_force_n, data.verbal_cue, inputs.models, delays)
    rows = _mode_rows(banks, inputs.n_trials)
    return bank_log_likelihoods(rows, inputs.force, drive, inputs.position, inputs.prior)


def _bank(default_banks: BankSource, *, true_delays: bool = False) -> PosteriorEstimator:
    """Bayes over a bank of three delay-aware filters, one per ``xi``."""

    def posterior(inputs: _Inputs) -> NDArray[np.float64]:
        log_lik = _bank_log_likelihoods(inputs, _banks(inputs, default_banks), true_delays)
        return _posterior(log_lik, inputs.data.config.probability_floor)

    return posterior


def _calibrated(inputs: _Inputs) -> NDArray[np.float64]:
    """The persona bank recalibrated per subject on its labelled calibration session."""
    banks = _banks(inputs, persona_banks)
    log_lik = _bank_log_likelihoods(inputs, banks)
    n = inputs.n_trials
    # Per subject: temperature and class offsets learned on its calibration session.
    for i, (ll, labels) in enumerate(_calibration_log_likelihoods(inputs.data, banks, inputs.base)):
        theta = fit_recalibration(ll, labels)
        block = slice(i * n, (i + 1) * n)
        log_lik[block] = log_lik[block] * math.exp(-theta[0]) + np.array([theta[1], 0.0, theta[2]])
    return _posterior(log_lik, inputs.data.config.probability_floor)


ESTIMATOR_REGISTRY: dict[str, Callable[[_Inputs], _Judgments]] = {
    "kalman": _kalman,
    "multiple_model": _judge_posterior(_multiple_model),
    "imm": _judge_posterior(_imm),
    "delay_aware": _judge_posterior(_delay_aware),
    "persona_bank": _judge_posterior(_bank(persona_banks)),
    "calibrated": _judge_posterior(_calibrated),
    "identified": _judge_posterior(_bank(identified_banks)),
    "switching": _judge_posterior(_switching),
    "oracle": _judge_posterior(_bank(oracle_banks, true_delays=True)),
}
"""Every estimator by name (see the module docstring): each judges the flattened trials."""

ESTIMATORS: tuple[str, ...] = tuple(ESTIMATOR_REGISTRY)
"""Estimators the protocol can score, in report order."""

NEEDS_CALIBRATION: frozenset[str] = frozenset({"calibrated", "identified"})
"""Estimators that learn from each subject's separate, labelled calibration session."""


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
    if estimator not in ESTIMATOR_REGISTRY:
        raise ValueError(f"unknown estimator {estimator!r}; choose from {', '.join(ESTIMATORS)}")
    if decision not in ("map", "sequential"):
        raise ValueError(f"decision must be 'map' or 'sequential', got {decision!r}")
    s, n, t = data.measured_position_m.shape
    force, verbal, position = _flatten(data.measured_force_n, data.verbal_cue, data.measured_position_m)
    inputs = _Inputs(
        data=data, base=base, banks=banks, models=subject_models(data, base),
        force=force, verbal=verbal, position=position, judge_at=np.tile(data.judgment_step, s),
        decision=decision, error_rate=error_rate,
    )  # fmt: skip
    out = ESTIMATOR_REGISTRY[estimator](inputs)
    # On the judgment tracker's clock (time since onset, as the envs report it): the paper step is 0.74 s.
    latency = np.asarray((out.step - data.config.onset_step) * data.config.timing.dt_s, dtype=np.float64)
    return EstimateResult(
        estimator=estimator,
        judgment=np.asarray(out.judged, dtype=np.int64).reshape(s, n),
        probabilities=out.probabilities.reshape(s, n, 3),
        latency_s=latency.reshape(s, n),
        xi_trace=out.xi.reshape(s, n, t),
        state_trace=out.states.reshape(s, n, t, 3),
        xi_std_trace=out.xi_std.reshape(s, n, t),
    )
