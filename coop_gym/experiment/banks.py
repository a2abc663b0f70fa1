"""The filters' models of each subject: the nominal model and the delay-aware banks of three modes.

The estimators of :mod:`coop_gym.experiment.estimators` read a subject through these:

* :func:`subject_models` -- the persona's nominal model (the persona's typical gains, not
  the subject's varied ones), as the paper's filter gets it;
* :func:`intention_drive` with :func:`drive_model` -- the cues delayed by the reaction
  delay, fed to the unchanged linear filters as their second input;
* a bank -- three delay-aware models, one per ``xi``, each with its own push compliance:
  from the persona's typical parameters (:func:`persona_banks`), from the subject's true
  ones (:func:`oracle_banks`, an information bound) or fitted to the subject's labelled
  calibration session (:func:`identified_banks`); :func:`bank_log_likelihoods` scores
  trials under each mode.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from coop_gym.envs.core import nominal_model_for
from coop_gym.experiment.simulation import ExperimentData
from coop_gym.model.params import PersonParams, Timing
from estimator.identification.identify import Trial, identify
from estimator.kalman import NOMINAL_COLUMNS, FastKalmanFilter
from estimator.nominal import NominalModel
from estimator.paper import XI_VALUES

__all__ = [
    "IDENTIFIED_FIELDS",
    "bank_log_likelihoods",
    "drive_model",
    "identified_banks",
    "intention_drive",
    "oracle_banks",
    "person_bank",
    "persona_banks",
    "subject_models",
]


def subject_models(data: ExperimentData, base: NominalModel | None = None) -> tuple[NominalModel, ...]:
    """Each subject's filter model: its persona's typical gains, not the subject's varied ones."""
    return tuple(nominal_model_for(p.params, data.config.timing, base) for p in data.personas)


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

    For each subject and each ``xi``, :func:`estimator.identification.identify.identify` fits
    :data:`IDENTIFIED_FIELDS` to that subject's calibration trials of that ``xi``, on the
    delay-aware inputs (:func:`intention_drive` with the persona's typical delay). Each
    mode thus learns the subject's own dynamics, compliance (stiffness in that state)
    and response strength: the paper's "previous history of individual care recipients".
    """
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
