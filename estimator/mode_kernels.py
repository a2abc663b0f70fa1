"""The compiled steps of the multiple-model estimators: one Kalman filter per mode of ``xi``.

The symbols are those of :mod:`estimator.multiple_model`: per mode the state ``[x, xdot, eta]``,
``F`` (3, 3) the upper-left block of the nominal transition (:func:`estimator.nominal.euler_transition`),
``B_xi`` the mode's input, ``P`` (3, 3), ``S`` and ``K`` (3,) covariance, innovation variance and
gain. :func:`filter_sequences` runs the MMAE (modes fixed) or the IMM (modes switch) over
``(N, T)`` input sequences; :func:`mode_mean_step` and :func:`mode_covariance_step` are the
per-mode steps the system identification reuses.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from estimator.compiled.cache import guard_kernel_cache
from estimator.kalman import NOMINAL, nominal_parameters, predict_covariance
from estimator.nominal import euler_step, euler_transition

__all__ = [
    "NON_FINITE_INPUT",
    "N_MODES",
    "OK",
    "STATE_WIDTH",
    "filter_sequences",
    "mode_covariance_step",
    "mode_mean_step",
]

N_MODES = 3
STATE_WIDTH = 3
"""Length of a mode's state ``[x, xdot, eta]``."""
_LOG_2PI = math.log(2.0 * math.pi)

# Status codes returned by the compiled kernels (checked in Python, so the hot loop
# raises clear errors without a separate NumPy validation pass).
OK = 0
NON_FINITE_INPUT = 1


@njit(cache=True, error_model="numpy", inline="always")
def _log_normalise(log_mu: NDArray[np.float64]) -> None:
    """Normalise three log-probabilities in place with log-sum-exp."""
    mx = max(log_mu[0], max(log_mu[1], log_mu[2]))
    if not math.isfinite(mx):
        # All modes impossible (cannot happen with a positive prior or floor): reset to uniform.
        for j in range(N_MODES):
            log_mu[j] = -math.log(3.0)
        return
    total = 0.0
    for j in range(N_MODES):
        total += math.exp(log_mu[j] - mx)
    # Subtract mx first: forming mx + log(total) would round at the scale of |mx| (a
    # log-likelihood of -1e7 leaves the probabilities summing to 1 only to ~1e-9).
    log_total = math.log(total)
    for j in range(N_MODES):
        log_mu[j] = (log_mu[j] - mx) - log_total


@njit(cache=True, error_model="numpy", inline="always")
def _logaddexp(a: float, b: float) -> float:
    """``log(exp(a) + exp(b))`` without overflow; -inf arguments allowed."""
    if a < b:
        a, b = b, a
    if b == -np.inf:
        return a
    return a + math.log1p(math.exp(b - a))


@njit(cache=True, error_model="numpy", inline="always")
def mode_covariance_step(P: NDArray[np.float64], nominal: NDArray[np.float64], K: NDArray[np.float64]) -> float:
    """Predict and Joseph-update one mode covariance ``P`` (3, 3) in place; write the gain ``K`` (3,).

    The prediction is the paper filter's (:func:`~estimator.kalman.predict_covariance`). The update
    symmetrises the prediction first and expands the Joseph form for ``H = [1, 0, 0]`` entry by
    entry, where the paper filter's (:func:`~estimator.kalman.kalman_step`) multiplies it out as
    filterpy does: the two round differently, and each filter's recorded numbers are its own.

    Returns:
        The innovation variance ``S``.
    """
    # P = F P F^T + Q, F the upper-left (3, 3) block of the nominal A, which the cues do not enter.
    predict_covariance(P, STATE_WIDTH, euler_transition(nominal_parameters(nominal), 0.0, 0.0), nominal)
    p00, p11, p22 = P[0, 0], P[1, 1], P[2, 2]
    # Symmetrise the prediction (the two sides agree up to rounding).
    p01 = 0.5 * (P[0, 1] + P[1, 0])
    p02 = 0.5 * (P[0, 2] + P[2, 0])
    p12 = 0.5 * (P[1, 2] + P[2, 1])
    r = nominal[NOMINAL.r_position]
    # Scalar measurement H = [1, 0, 0]: S = H P H^T + R, K = P H^T / S.
    S = p00 + r
    k0 = p00 / S
    k1 = p01 / S
    k2 = p02 / S
    K[0] = k0
    K[1] = k1
    K[2] = k2
    # Joseph form P = (I - K H) P (I - K H)^T + K R K^T; with H = [1, 0, 0] entry (i, j)
    # is P_ij - K_i P_0j - P_i0 K_j + K_i K_j (P_00 + R) = P_ij - K_i P_0j - P_i0 K_j + K_i K_j S.
    P[0, 0] = p00 - 2.0 * k0 * p00 + k0 * k0 * S
    P[1, 1] = p11 - 2.0 * k1 * p01 + k1 * k1 * S
    P[2, 2] = p22 - 2.0 * k2 * p02 + k2 * k2 * S
    v01 = p01 - k0 * p01 - p00 * k1 + k0 * k1 * S
    v02 = p02 - k0 * p02 - p00 * k2 + k0 * k2 * S
    v12 = p12 - k1 * p02 - p01 * k2 + k1 * k2 * S
    P[0, 1] = v01
    P[1, 0] = v01
    P[0, 2] = v02
    P[2, 0] = v02
    P[1, 2] = v12
    P[2, 1] = v12
    return S


@njit(cache=True, error_model="numpy", inline="always")
def mode_mean_step(
    m: NDArray[np.float64],
    nominal: NDArray[np.float64],
    xi: float,
    push_force_n: float,
    verbal_cue: float,
    measured_position_m: float,
    K: NDArray[np.float64],
) -> float:
    """Predict ``m = F m + B_xi u`` and update with gain ``K``, in place on ``m`` (3,).

    The mean is predicted by :func:`~estimator.nominal.euler_step` (the difference form of
    eqs. 1 and 6), whose rounding the multiple-model estimators' recorded numbers are.

    Returns:
        The innovation ``y - H m`` of the predicted mean.
    """
    p0, p1, p2 = euler_step(nominal_parameters(nominal), m[0], m[1], m[2], xi, push_force_n, verbal_cue)
    innovation = measured_position_m - p0
    m[0] = p0 + K[0] * innovation
    m[1] = p1 + K[1] * innovation
    m[2] = p2 + K[2] * innovation
    return innovation


@njit(cache=True, error_model="numpy", inline="always")
def _inputs_finite(push_force_n: NDArray[np.float64], verbal_cue: NDArray[np.float64], y: NDArray[np.float64]) -> bool:
    for i in range(y.shape[0]):
        if not (math.isfinite(push_force_n[i]) and math.isfinite(verbal_cue[i]) and math.isfinite(y[i])):
            return False
    return True


@njit(cache=True, error_model="numpy", inline="always")
def _write_outputs(
    i: int,
    means: NDArray[np.float64],
    log_mu: NDArray[np.float64],
    probs: NDArray[np.float64],
    mean_out: NDArray[np.float64],
) -> None:
    for j in range(N_MODES):
        probs[i, j] = math.exp(log_mu[i, j])
    for k in range(STATE_WIDTH):
        acc = 0.0
        for j in range(N_MODES):
            acc += probs[i, j] * means[i, j, k]
        mean_out[i, k] = acc


@njit(cache=True, error_model="numpy")
def _mmae_env_step(
    i: int,
    means: NDArray[np.float64],
    P: NDArray[np.float64],
    log_mu: NDArray[np.float64],
    nominal: NDArray[np.float64],
    log_keep: float,
    log_floor: float,
    push_force_n: float,
    verbal_cue: float,
    measured_position_m: float,
    K: NDArray[np.float64],
) -> None:
    """One MMAE step of env ``i``: shared Riccati (``P[i, 0]``), three mean updates, Bayes on the modes."""
    row = nominal[i]
    # One covariance recursion serves all modes: F, Q, H, R are mode-independent.
    S = mode_covariance_step(P[i, 0], row, K)
    log_S_term = _LOG_2PI + math.log(S)
    for j in range(N_MODES):
        xi = float(j - 1)
        innovation = mode_mean_step(means[i, j], row, xi, push_force_n, verbal_cue, measured_position_m, K)
        # Floor: mix the prediction with the uniform distribution, mu_j <- (1 - 3 eps) mu_j + eps.
        lp = log_mu[i, j]
        if log_floor > -np.inf:
            lp = _logaddexp(log_keep + lp, log_floor)
        # Bayes: log mu_j += log N(innovation_j; 0, S).
        log_mu[i, j] = lp - 0.5 * (log_S_term + innovation * innovation / S)
    _log_normalise(log_mu[i])


@njit(cache=True, error_model="numpy")
def _imm_env_step(
    i: int,
    means: NDArray[np.float64],
    P: NDArray[np.float64],
    log_mu: NDArray[np.float64],
    nominal: NDArray[np.float64],
    log_trans: NDArray[np.float64],
    push_force_n: float,
    verbal_cue: float,
    measured_position_m: float,
    K: NDArray[np.float64],
    mixed_m: NDArray[np.float64],
    mixed_P: NDArray[np.float64],
    log_cbar: NDArray[np.float64],
    w: NDArray[np.float64],
) -> None:
    """One IMM cycle (Bar-Shalom): interaction/mixing, mode-matched filtering, mode update."""
    row = nominal[i]
    lt = log_trans[i]
    lm = log_mu[i]
    for j in range(N_MODES):
        # Predicted mode probability cbar_j = sum_s p_sj mu_s.
        log_cbar[j] = _log_sum_exp(lt[0, j] + lm[0], lt[1, j] + lm[1], lt[2, j] + lm[2])
        for s in range(N_MODES):
            if log_cbar[j] == -np.inf:
                # Mode j unreachable (zero transitions and no floor): keep its filter, probability stays 0.
                w[s] = 1.0 if s == j else 0.0
            else:
                # Mixing weights mu_{s|j} = p_sj mu_s / cbar_j.
                w[s] = math.exp(lt[s, j] + lm[s] - log_cbar[j])
        # Mixed initial condition: m0_j = sum_s mu_{s|j} m_s,
        # P0_j = sum_s mu_{s|j} (P_s + (m_s - m0_j)(m_s - m0_j)^T).
        for k in range(STATE_WIDTH):
            acc = 0.0
            for s in range(N_MODES):
                acc += w[s] * means[i, s, k]
            mixed_m[j, k] = acc
        for a in range(STATE_WIDTH):
            for b in range(a, STATE_WIDTH):
                acc = 0.0
                for s in range(N_MODES):
                    da = means[i, s, a] - mixed_m[j, a]
                    db = means[i, s, b] - mixed_m[j, b]
                    acc += w[s] * (P[i, s, a, b] + da * db)
                mixed_P[j, a, b] = acc
                mixed_P[j, b, a] = acc
    for j in range(N_MODES):
        for k in range(STATE_WIDTH):
            means[i, j, k] = mixed_m[j, k]
            for b in range(STATE_WIDTH):
                P[i, j, k, b] = mixed_P[j, k, b]
        # Mode-matched Kalman filter, then mu_j proportional to Lambda_j cbar_j.
        S = mode_covariance_step(P[i, j], row, K)
        innovation = mode_mean_step(means[i, j], row, float(j - 1), push_force_n, verbal_cue, measured_position_m, K)
        lm[j] = log_cbar[j] - 0.5 * (_LOG_2PI + math.log(S) + innovation * innovation / S)
    _log_normalise(lm)


@njit(cache=True, error_model="numpy", inline="always")
def _log_sum_exp(log_a: float, log_b: float, log_c: float) -> float:
    """``log(exp(log_a) + exp(log_b) + exp(log_c))`` of the three modes' terms, shifted by their maximum.

    ``-inf`` when all three are (a mode no mode can reach). Scalars in and out, so the IMM's
    loop over modes keeps no extra array references.
    """
    largest = max(max(max(-np.inf, log_a), log_b), log_c)
    if largest == -np.inf:
        return -np.inf
    return largest + math.log(math.exp(log_a - largest) + math.exp(log_b - largest) + math.exp(log_c - largest))


@njit(cache=True, error_model="numpy")
def filter_sequences(
    means: NDArray[np.float64],
    P: NDArray[np.float64],
    log_mu: NDArray[np.float64],
    nominal: NDArray[np.float64],
    mixing: bool,
    log_keep: float,
    log_floor: float,
    log_trans: NDArray[np.float64],
    push_force_n: NDArray[np.float64],
    verbal_cue: NDArray[np.float64],
    measured_position_m: NDArray[np.float64],
    probs_seq: NDArray[np.float64],
    probs: NDArray[np.float64],
    mean_out: NDArray[np.float64],
) -> int:
    """Filter (N, T) sequences: MMAE (``mixing`` off) or IMM (on); ``step`` is the case T = 1.

    ``P`` is (N, 1, 3, 3) for the MMAE's shared covariance, (N, 3, 3, 3) for the IMM's
    per-mode ones. The MMAE reads ``log_keep``/``log_floor`` (its probability floor), the
    IMM ``log_trans`` (the floor is folded into it). Writes ``probs_seq`` (N, T, 3) after
    each step and the final ``probs`` (N, 3) and ``mean_out`` (N, 3).
    """
    n_env, n_steps = measured_position_m.shape
    for i in range(n_env):
        if not _inputs_finite(push_force_n[i], verbal_cue[i], measured_position_m[i]):
            return NON_FINITE_INPUT
    K = np.empty(STATE_WIDTH)
    mixed_m = np.empty((N_MODES, STATE_WIDTH))
    mixed_P = np.empty((N_MODES, STATE_WIDTH, STATE_WIDTH))
    log_cbar = np.empty(N_MODES)
    w = np.empty(N_MODES)
    for i in range(n_env):
        for t in range(n_steps):
            if mixing:
                _imm_env_step(
                    i, means, P, log_mu, nominal, log_trans,
                    push_force_n[i, t], verbal_cue[i, t], measured_position_m[i, t], K, mixed_m, mixed_P, log_cbar, w,
                )  # fmt: skip
            else:
                _mmae_env_step(
                    i, means, P, log_mu, nominal, log_keep, log_floor,
                    push_force_n[i, t], verbal_cue[i, t], measured_position_m[i, t], K,
                )  # fmt: skip
            for j in range(N_MODES):
                probs_seq[i, t, j] = math.exp(log_mu[i, j])
        _write_outputs(i, means, log_mu, probs, mean_out)
    return OK


guard_kernel_cache(__name__)
