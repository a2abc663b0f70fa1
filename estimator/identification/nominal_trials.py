"""Trials simulated from the estimator's own nominal linear model: data whose true model is known.

System identification (:mod:`estimator.identification.identify`) is checked by fitting such trials back, and
the multiple-model estimators by reading them: ``s_t = A(c_t) s_{t-1} + B c_{p,t} + w_t``,
``y_t = x_t + v_t`` with :class:`~estimator.nominal.NominalModel`'s ``A``, ``B``, ``Q`` and ``R``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimator.identification.identify import Trial
from estimator.nominal import NominalModel, euler_step

__all__ = ["simulate_nominal", "simulate_nominal_trials"]


def _simulate_batch(
    model: NominalModel,
    push_force_n: NDArray[np.float64],
    verbal_cue: NDArray[np.float64],
    xi: NDArray[np.float64],
    rng: np.random.Generator,
    initial_state: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Simulate (n, T) cue sequences; return measurements (n, T) and states (n, T, 4)."""
    n, t_len = push_force_n.shape
    q_std = np.sqrt(np.diag(model.process_covariance))[:3]
    states = np.empty((n, t_len, 4))
    s = np.broadcast_to(initial_state, (n, 3)).astype(np.float64).copy()
    states[:, 0, :3] = s
    states[:, :, 3] = xi
    for t in range(1, t_len):
        w = rng.normal(0.0, 1.0, (n, 3)) * q_std
        # eqs. 1 and 6 as the multiple-model filters predict them, xi held at its given value (no random walk).
        new_x, new_xdot, new_eta = euler_step(
            model.euler_parameters, s[:, 0], s[:, 1], s[:, 2], xi[:, t], push_force_n[:, t], verbal_cue[:, t]
        )
        s = np.stack([new_x, new_xdot, new_eta], axis=1) + w
        states[:, t, :3] = s
    # y = H s + v, v ~ N(0, R).
    measured = states[:, :, 0] + rng.normal(0.0, model.position_noise_std_m, (n, t_len))
    return measured, states


def simulate_nominal(
    model: NominalModel,
    push_force_n: ArrayLike,
    verbal_cue: ArrayLike,
    xi: ArrayLike,
    rng: np.random.Generator,
    initial_state: ArrayLike = (0.0, 0.0, 0.0),
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Simulate one sequence from the filter's own linear model (A, B, Q, R of ``model``).

    ``s_t = A(c_t) s_{t-1} + B c_{p,t} + w_t``, ``y_t = x_t + v_t`` for ``t >= 1``,
    with ``xi`` given per step (held, not a random walk) so switching can be scripted.

    Args:
        model: Nominal model to simulate.
        push_force_n: (T,) push forces [N].
        verbal_cue: (T,) verbal cues in {-1, 0, +1}.
        xi: Cooperativeness, scalar or (T,) per step.
        rng: Random generator (all randomness comes from it).
        initial_state: ``[x, xdot, eta]`` at step 0 (default seated at rest at 0).

    Returns:
        ``(measured_position_m (T,), states (T, 4))`` with states ``[x, xdot, eta, xi]``.
    """
    cp = np.asarray(push_force_n, dtype=np.float64)
    if cp.ndim != 1:
        raise ValueError(f"push_force_n must be 1-D, got shape {cp.shape}")
    cv = np.broadcast_to(np.asarray(verbal_cue, dtype=np.float64), cp.shape)
    xis = np.broadcast_to(np.asarray(xi, dtype=np.float64), cp.shape)
    s0 = np.asarray(initial_state, dtype=np.float64).reshape(3)
    measured, states = _simulate_batch(model, cp[None, :], cv[None, :], xis[None, :], rng, s0)
    return measured[0], states[0]


def _draw_cues(
    rng: np.random.Generator,
    n_trials: int,
    n_steps: int,
    push_levels_n: Sequence[float],
    allow_no_cue: bool,
    duration: int,
    onsets: tuple[int, int],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    # Each trial's push and verbal cue, ``duration`` steps from their own onsets in [margin, last_onset].
    margin, last_onset = onsets
    cp = np.zeros((n_trials, n_steps))
    cv = np.zeros((n_trials, n_steps))
    for i in range(n_trials):
        while True:
            push = float(rng.choice(np.asarray(push_levels_n, dtype=np.float64)))
            verbal = float(rng.integers(-1, 2))
            if allow_no_cue or push != 0.0 or verbal != 0.0:
                break
        onset_p, onset_v = rng.integers(min(margin, last_onset), last_onset + 1, 2)
        cp[i, onset_p : onset_p + duration] = push
        cv[i, onset_v : onset_v + duration] = verbal
    return cp, cv


def _draw_xi(rng: np.random.Generator, n_trials: int, xi: int | Sequence[int] | None) -> NDArray[np.int64]:
    """Each trial's cooperativeness: ``xi`` given (one, or one per trial), or uniform draws in {-1, 0, +1}."""
    if xi is None:
        return rng.integers(-1, 2, n_trials)
    xis = np.broadcast_to(np.asarray(xi, dtype=np.int64), (n_trials,))
    if not np.all(np.isin(xis, (-1, 0, 1))):
        raise ValueError(f"xi must be in {{-1, 0, +1}}, got {xi!r}")
    return xis


def _draw_start(model: NominalModel, rng: np.random.Generator, n_trials: int) -> NDArray[np.float64]:
    """Each trial's ``[x, xdot, eta]`` drawn from the filter's prior around ``x = 0``."""
    start = np.zeros((n_trials, 3))
    start[:, 1] = rng.normal(0.0, model.initial_velocity_std_m_per_s, n_trials)
    start[:, 2] = rng.normal(0.0, model.initial_intention_std_m, n_trials)
    return start


def simulate_nominal_trials(
    model: NominalModel,
    n_trials: int,
    n_steps: int = 300,
    rng: np.random.Generator | None = None,
    *,
    xi: int | Sequence[int] | None = None,
    push_levels_n: Sequence[float] = (0.0, 10.0, 30.0),
    cue_duration_s: float = 1.0,
    allow_no_cue: bool = False,
    initial_state: Literal["prior", "rest"] = "prior",
) -> list[Trial]:
    """Trials like the paper's experiment, simulated from the nominal linear model.

    Each trial draws a push level (none / soft / firm) and a verbal cue (none / back /
    forward) uniformly (redrawn when both are none unless ``allow_no_cue``), each lasting
    ``cue_duration_s`` from its own onset, uniform in [0.5 s, end - cue - 0.5 s]; so
    pushes and words come alone, together, or in either order, as in the paper's
    relative timing. ``xi`` is constant within a trial.

    The initial state matters for identification: the filter's likelihood assumes
    ``xdot_0 ~ N(0, initial_velocity_std^2)`` and ``eta_0 ~ N(x_0, initial_intention_std^2)``
    (``NominalModel`` prior). ``initial_state="prior"`` draws the start from exactly that
    (so the person drifts toward a random intention at first); ``"rest"`` starts seated at
    rest (``x = xdot = eta = 0``), which a broad filter prior misdescribes -- with the default
    prior that biases the fitted ``lambda1`` and ``k2`` upward (fit ``"rest"`` trials of a known
    model with :func:`estimator.identification.identify.identify` to see by how much).

    Args:
        model: Nominal model to simulate (A, B, Q, R as the filter assumes).
        n_trials: Number of trials.
        n_steps: Samples per trial (300 = 6 s at 50 Hz).
        rng: Random generator (default ``np.random.default_rng(0)``).
        xi: Cooperativeness of every trial, one per trial, or ``None`` for uniform draws.
        push_levels_n: Push forces to draw from [N].
        cue_duration_s: Duration of each cue [s].
        allow_no_cue: Allow trials with neither cue.
        initial_state: ``"prior"`` (draw ``[x, xdot, eta]`` from the filter's prior around
            ``x = 0``) or ``"rest"`` (all zero).

    Returns:
        Labelled trials (``Trial.xi`` holds the simulated value).
    """
    rng = rng if rng is not None else np.random.default_rng(0)
    if n_trials < 1 or n_steps < 2:
        raise ValueError(f"need n_trials >= 1 and n_steps >= 2, got {n_trials!r}, {n_steps!r}")
    if initial_state not in ("prior", "rest"):
        raise ValueError(f"initial_state must be 'prior' or 'rest', got {initial_state!r}")
    dt = model.dt_s
    duration = max(1, round(cue_duration_s / dt))
    margin = round(0.5 / dt)
    last_onset = max(1, n_steps - duration - margin)
    # The draws in a fixed order (xi, cues, start, noise), so a seed gives the same trials.
    xis = _draw_xi(rng, n_trials, xi)
    cp, cv = _draw_cues(rng, n_trials, n_steps, push_levels_n, allow_no_cue, duration, (margin, last_onset))
    xi_steps = np.repeat(xis.astype(np.float64)[:, None], n_steps, axis=1)
    start = _draw_start(model, rng, n_trials) if initial_state == "prior" else np.zeros((n_trials, 3))
    measured, _ = _simulate_batch(model, cp, cv, xi_steps, rng, start)
    return [Trial(cp[i], cv[i], measured[i], xi=int(xis[i]), dt_s=dt) for i in range(n_trials)]
