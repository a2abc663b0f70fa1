"""Multiple-model estimators of cooperativeness ``xi`` in {-1, 0, +1} (beyond the paper's §IV).

The paper's filter treats ``xi`` as a continuous random walk and thresholds its
estimate. Here ``xi`` is discrete: one Kalman filter per mode, and the mode
probabilities ``mu_j = P(xi = j | y_1..t)`` come from the filters' innovation
likelihoods.

Per mode the state is ``s = [x, xdot, eta]`` (``xi`` is *not* in the state, so IMM
mixing never blends it) with the Euler-discretised eqs. 1 and 6:

* ``F`` (3, 3): ``[[1, dt, 0], [-k1*dt, 1 - lambda1*dt, k1*dt], [0, 0, 1]]``, the
  upper-left block of :meth:`NominalModel.transition_matrix`, constant in time.
* ``B_xi`` (3, 2): ``[[0, 0], [k2*dt, 0], [xi*k3*dt, xi*k4*dt]]`` on ``u = [c_p, c_v]``.
* ``H`` (1, 3) = ``[1, 0, 0]``; ``Q`` (3, 3) = ``diag(q_x, q_xdot, q_eta)``; ``R`` scalar.
* ``P`` (3, 3), ``S`` scalar, ``K`` (3,): covariance, innovation variance, gain.

Since only the input differs between modes, ``P``, ``S`` and ``K`` do not depend on
the mode: :class:`MultipleModelEstimator` (MMAE, ``xi`` constant within a trial)
runs one Riccati recursion per env and three mean recursions. :class:`IMMEstimator`
(``xi`` may switch, Bar-Shalom's interacting multiple model) must keep one ``P``
per mode, because mixing adds the spread of the modes' means to each covariance.

Mode probabilities are kept as logarithms and normalised with log-sum-exp, so they
never underflow to 0/0 (filterpy's ``IMMEstimator`` and ``MMAEFilterBank`` do).
A probability floor ``epsilon`` mixes the predicted mode probabilities with the
uniform distribution each step (a near-identity Markov transition
``(1 - 3 epsilon) I + epsilon``), so no mode is ever locked out.

Arrays are batched over ``N`` envs (leading axis); modes are ordered ``xi = -1, 0, +1``
(:data:`MODE_VALUES`) in every ``(..., 3)`` array.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from compiled.cache import guard_kernel_cache
from compiled.checks import is_number
from estimator.kalman import NOMINAL, NOMINAL_COLUMNS, nominal_row, nominal_transition
from estimator.nominal import NominalModel

__all__ = [
    "MODE_VALUES",
    "IMMEstimator",
    "MultipleModelEstimator",
    "confident_judgment",
    "map_judgment",
    "mode_covariance_step",
    "mode_mean_step",
    "sequential_judgment",
    "switching_transition_matrix",
]

MODE_VALUES: NDArray[np.int64] = np.array([-1, 0, 1], dtype=np.int64)
"""Cooperativeness of each mode, in the order of every ``(..., 3)`` probability array."""

N_MODES = 3
_STATE = 3  # [x, xdot, eta] per mode
_LOG_2PI = math.log(2.0 * math.pi)

# Status codes returned by the compiled kernels (checked in Python, so the hot loop
# raises clear errors without a separate NumPy validation pass).
_OK = 0
_NON_FINITE_INPUT = 1


# --------------------------------------------------------------------------- kernels


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

    Returns:
        The innovation variance ``S``.
    """
    # F: the upper-left (3, 3) block of the nominal A, which the cues do not enter.
    dt, f10, f11, f12, _, _ = nominal_transition(nominal, 0.0, 0.0)
    # P = F P F^T + Q, with F's sparse rows [1, dt, 0], [f10, f11, f12], [0, 0, 1].
    fp00 = P[0, 0] + dt * P[1, 0]
    fp01 = P[0, 1] + dt * P[1, 1]
    fp02 = P[0, 2] + dt * P[1, 2]
    fp10 = f10 * P[0, 0] + f11 * P[1, 0] + f12 * P[2, 0]
    fp11 = f10 * P[0, 1] + f11 * P[1, 1] + f12 * P[2, 1]
    fp12 = f10 * P[0, 2] + f11 * P[1, 2] + f12 * P[2, 2]
    fp20 = P[2, 0]
    fp21 = P[2, 1]
    fp22 = P[2, 2]
    p00 = fp00 + dt * fp01 + nominal[NOMINAL.q_position]
    p01 = f10 * fp00 + f11 * fp01 + f12 * fp02
    p02 = fp02
    p11 = f10 * fp10 + f11 * fp11 + f12 * fp12 + nominal[NOMINAL.q_velocity]
    p12 = fp12
    p22 = fp22 + nominal[NOMINAL.q_intention]
    # Row 1 and 2 of (F P) F^T, column 0: symmetric counterparts computed from the other side.
    p10 = fp10 + dt * fp11
    p20 = fp20 + dt * fp21
    p21 = f10 * fp20 + f11 * fp21 + f12 * fp22
    # Symmetrise the prediction (the two sides agree up to rounding).
    p01 = 0.5 * (p01 + p10)
    p02 = 0.5 * (p02 + p20)
    p12 = 0.5 * (p12 + p21)
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

    The mean is predicted in the difference form of eqs. 1 and 6 (``xdot + dt (...)``), not by
    multiplying out :func:`~estimator.nominal.euler_transition`'s entries: the two round
    differently, and the multiple-model estimators' recorded numbers are this form's.

    Returns:
        The innovation ``y - H m`` of the predicted mean.
    """
    dt = nominal[NOMINAL.dt_s]
    m0, m1, m2 = m[0], m[1], m[2]
    # eq. 1 (Euler): x' = x + dt xdot ; xdot' = xdot + dt (-lambda1 xdot + k1 (eta - x) + k2 c_p)
    p0 = m0 + dt * m1
    p1 = m1 + dt * (
        -nominal[NOMINAL.damping_rate_per_s] * m1
        + nominal[NOMINAL.voluntary_gain_per_s2] * (m2 - m0)
        + nominal[NOMINAL.push_compliance_m_per_s2_n] * push_force_n
    )
    # eq. 6: eta' = eta + xi (k3 c_p + k4 c_v) dt -- the only place the mode enters.
    p2 = (
        m2
        + xi
        * (nominal[NOMINAL.push_gain_m_per_s_n] * push_force_n + nominal[NOMINAL.verbal_gain_m_per_s] * verbal_cue)
        * dt
    )
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
    for k in range(_STATE):
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
        # Predicted mode probability cbar_j = sum_i p_ij mu_i (log-sum-exp).
        mx = -np.inf
        for s in range(N_MODES):
            mx = max(mx, lt[s, j] + lm[s])
        if mx == -np.inf:
            # Mode j unreachable (zero transitions and no floor): keep its filter, probability stays 0.
            log_cbar[j] = -np.inf
            for s in range(N_MODES):
                w[s] = 1.0 if s == j else 0.0
        else:
            acc = 0.0
            for s in range(N_MODES):
                acc += math.exp(lt[s, j] + lm[s] - mx)
            log_cbar[j] = mx + math.log(acc)
            # Mixing weights mu_{s|j} = p_sj mu_s / cbar_j.
            for s in range(N_MODES):
                w[s] = math.exp(lt[s, j] + lm[s] - log_cbar[j])
        # Mixed initial condition: m0_j = sum_s mu_{s|j} m_s,
        # P0_j = sum_s mu_{s|j} (P_s + (m_s - m0_j)(m_s - m0_j)^T).
        for k in range(_STATE):
            acc = 0.0
            for s in range(N_MODES):
                acc += w[s] * means[i, s, k]
            mixed_m[j, k] = acc
        for a in range(_STATE):
            for b in range(a, _STATE):
                acc = 0.0
                for s in range(N_MODES):
                    da = means[i, s, a] - mixed_m[j, a]
                    db = means[i, s, b] - mixed_m[j, b]
                    acc += w[s] * (P[i, s, a, b] + da * db)
                mixed_P[j, a, b] = acc
                mixed_P[j, b, a] = acc
    for j in range(N_MODES):
        for k in range(_STATE):
            means[i, j, k] = mixed_m[j, k]
            for b in range(_STATE):
                P[i, j, k, b] = mixed_P[j, k, b]
        # Mode-matched Kalman filter, then mu_j proportional to Lambda_j cbar_j.
        S = mode_covariance_step(P[i, j], row, K)
        innovation = mode_mean_step(means[i, j], row, float(j - 1), push_force_n, verbal_cue, measured_position_m, K)
        lm[j] = log_cbar[j] - 0.5 * (_LOG_2PI + math.log(S) + innovation * innovation / S)
    _log_normalise(lm)


@njit(cache=True, error_model="numpy")
def _filter(
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
            return _NON_FINITE_INPUT
    K = np.empty(_STATE)
    mixed_m = np.empty((N_MODES, _STATE))
    mixed_P = np.empty((N_MODES, _STATE, _STATE))
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
    return _OK


# --------------------------------------------------------------------------- estimators


def _validate_mode_prior(mode_prior: ArrayLike | None) -> NDArray[np.float64]:
    if mode_prior is None:
        return np.full(N_MODES, 1.0 / N_MODES)
    prior = np.asarray(mode_prior, dtype=np.float64)
    if prior.shape != (N_MODES,) or not np.all(np.isfinite(prior)) or np.any(prior < 0) or prior.sum() <= 0:
        raise ValueError(f"mode_prior must be 3 non-negative finite weights for xi = -1, 0, +1, got {mode_prior!r}")
    return prior / prior.sum()


def _validate_floor(probability_floor: float) -> float:
    floor = float(probability_floor) if is_number(probability_floor) else math.nan
    if not (math.isfinite(floor) and 0.0 <= floor < 1.0 / N_MODES):
        raise ValueError(f"probability_floor must be in [0, 1/3), got {probability_floor!r}")
    return floor


def switching_transition_matrix(switching_rate_per_s: float, dt_s: float) -> NDArray[np.float64]:
    """Row-stochastic mode transition matrix ``p_ij = P(xi_t = j | xi_{t-1} = i)`` for one step.

    The person leaves the current mode at ``switching_rate_per_s`` (a continuous-time
    Markov chain), to either other mode with equal probability:
    ``p_ii = exp(-rate*dt)``, ``p_ij = (1 - p_ii) / 2``.

    Args:
        switching_rate_per_s: Rate of leaving a mode [1/s], >= 0.
        dt_s: Filter step [s], > 0.

    Returns:
        (3, 3) matrix, rows and columns ordered ``xi = -1, 0, +1``.
    """
    rate = float(switching_rate_per_s) if is_number(switching_rate_per_s) else math.nan
    if not (math.isfinite(rate) and rate >= 0.0):
        raise ValueError(f"switching_rate_per_s must be finite and >= 0, got {switching_rate_per_s!r}")
    if not (is_number(dt_s) and math.isfinite(dt_s) and dt_s > 0.0):
        raise ValueError(f"dt_s must be finite and > 0, got {dt_s!r}")
    stay = math.exp(-rate * dt_s)
    trans = np.full((N_MODES, N_MODES), 0.5 * (1.0 - stay))
    np.fill_diagonal(trans, stay)
    return trans


class _MultipleModelBase:
    """State and bookkeeping shared by the MMAE and IMM estimators (one ``P`` or one per mode)."""

    _per_mode_covariance = False

    def __init__(
        self,
        nominal_rows: ArrayLike,
        first_position_m: ArrayLike,
        *,
        prior: NominalModel | None = None,
        mode_prior: ArrayLike | None = None,
        probability_floor: float = 1e-6,
    ) -> None:
        rows = np.ascontiguousarray(np.atleast_2d(np.asarray(nominal_rows, dtype=np.float64)))
        if rows.ndim != 2 or rows.shape[1] != len(NOMINAL_COLUMNS):
            raise ValueError(f"nominal_rows must have shape (N, {len(NOMINAL_COLUMNS)}), got {rows.shape}")
        if not np.all(np.isfinite(rows)):
            raise ValueError("nominal_rows must be finite")
        if (
            np.any(rows[:, NOMINAL.dt_s] <= 0)
            or np.any(rows[:, NOMINAL.r_position] <= 0)
            or np.any(rows[:, NOMINAL.q_position : NOMINAL.r_position + 1] < 0)
        ):
            raise ValueError("nominal_rows need dt_s > 0, r_position > 0 and non-negative process variances")
        self.nominal = rows
        self.n_envs = rows.shape[0]
        prior = prior if prior is not None else NominalModel()
        # The prior on [xdot, eta] comes from a NominalModel, the position prior from each env's sensor (as in
        # FastKalmanFilter), so the modes start exactly like the paper filter conditioned on xi.
        self._initial_velocity_var = prior.initial_velocity_std_m_per_s**2
        self._initial_intention_var = prior.initial_intention_std_m**2
        self.mode_prior = _validate_mode_prior(mode_prior)
        with np.errstate(divide="ignore"):
            self._log_mode_prior = np.log(self.mode_prior)
        self.probability_floor = _validate_floor(probability_floor)
        n = self.n_envs
        self.means = np.zeros((n, N_MODES, _STATE))
        cov_shape = (n, N_MODES, _STATE, _STATE) if self._per_mode_covariance else (n, _STATE, _STATE)
        self.P = np.zeros(cov_shape)
        self.log_mu = np.zeros((n, N_MODES))
        self._probs = np.zeros((n, N_MODES))
        self._mean = np.zeros((n, _STATE))
        self._shape = (n,)
        # Kernel arguments of the other estimator kind (MMAE: floor; IMM: transitions), unused by this one.
        self._log_keep = 0.0
        self._log_floor = -math.inf
        self._log_trans = np.zeros((1, N_MODES, N_MODES))
        self.reset(np.arange(n), first_position_m)

    # --- state -----------------------------------------------------------------

    def reset(self, indices: ArrayLike, first_position_m: ArrayLike) -> None:
        """Restart the filters of some envs at their first shoulder measurement.

        Args:
            indices: Env indices to reset (int array or boolean mask of length N).
            first_position_m: First measured position [m] per reset env (or one value for all).
        """
        idx = np.arange(self.n_envs)[np.asarray(indices)]
        first = np.broadcast_to(np.asarray(first_position_m, dtype=np.float64), idx.shape)
        if not np.all(np.isfinite(first)):
            raise ValueError("first_position_m must be finite")
        # s0 = [y0, 0, y0]: at rest where first seen, intending to stay (as NominalModel.initial_state).
        self.means[idx, :, 0] = first[:, None]
        self.means[idx, :, 1] = 0.0
        self.means[idx, :, 2] = first[:, None]
        p0 = np.zeros((idx.shape[0], _STATE, _STATE))
        p0[:, 0, 0] = self.nominal[idx, NOMINAL.r_position]
        p0[:, 1, 1] = self._initial_velocity_var
        p0[:, 2, 2] = self._initial_intention_var
        if self._per_mode_covariance:
            self.P[idx] = p0[:, None, :, :]
        else:
            self.P[idx] = p0
        self.log_mu[idx] = self._log_mode_prior
        self._probs[idx] = self.mode_prior
        self._mean[idx] = self.means[idx, 0]

    @property
    def probabilities(self) -> NDArray[np.float64]:
        """(N, 3) mode probabilities ``P(xi = -1), P(xi = 0), P(xi = +1)`` (a copy)."""
        return self._probs.copy()

    @property
    def log_probabilities(self) -> NDArray[np.float64]:
        """(N, 3) natural-log mode probabilities (finite even where ``probabilities`` underflows to 0)."""
        return self.log_mu.copy()

    @property
    def mean(self) -> NDArray[np.float64]:
        """(N, 3) probability-weighted estimate of ``[x, xdot, eta]``."""
        return self._mean.copy()

    @property
    def expected_xi(self) -> NDArray[np.float64]:
        """(N,) posterior mean of ``xi``: ``P(xi = +1) - P(xi = -1)``."""
        return self._probs[:, 2] - self._probs[:, 0]

    @property
    def covariance(self) -> NDArray[np.float64]:
        """(N, 3, 3) covariance of the mixture ``sum_j mu_j N(m_j, P_j)`` of ``[x, xdot, eta]``."""
        mu = self._probs
        d = self.means - self._mean[:, None, :]
        spread = np.einsum("nj,nja,njb->nab", mu, d, d)
        if self._per_mode_covariance:
            return np.einsum("nj,njab->nab", mu, self.P) + spread
        return self.P + spread

    # --- stepping ----------------------------------------------------------------

    def _as_input(self, name: str, value: ArrayLike) -> NDArray[np.float64]:
        arr = np.ascontiguousarray(value, dtype=np.float64)
        if arr.shape != self._shape:
            if arr.size == 1 and arr.ndim <= 1:  # a scalar (np.ascontiguousarray makes it (1,)): one value for all
                return np.full(self._shape, arr[0])
            raise ValueError(f"{name} must have shape (N={self.n_envs},), got {arr.shape}")
        return arr

    def _as_sequence(self, name: str, value: ArrayLike, shape: tuple[int, ...]) -> NDArray[np.float64]:
        arr = np.asarray(value, dtype=np.float64)
        out = np.empty(shape)  # a fresh writable C array: one compiled signature for every caller
        try:
            out[...] = arr
        except ValueError:
            raise ValueError(f"{name} must broadcast to shape {shape}, got {arr.shape}") from None
        return out

    @staticmethod
    def _check(status: int) -> None:
        if status == _NON_FINITE_INPUT:
            raise ValueError("push_force_n, verbal_cue and measured_position_m must be finite (got NaN or inf)")

    def step(
        self,
        push_force_n: ArrayLike,
        verbal_cue: ArrayLike,
        measured_position_m: ArrayLike,
    ) -> NDArray[np.float64]:
        """Advance every env by one filter step.

        Args:
            push_force_n: (N,) push force ``c_p`` during the step [N].
            verbal_cue: (N,) verbal cue ``c_v`` in {-1, 0, +1} during the step.
            measured_position_m: (N,) shoulder position measured at the end of the step [m].

        Returns:
            (N, 3) mode probabilities after the update (a copy), ordered ``xi = -1, 0, +1``.
        """
        cp = self._as_input("push_force_n", push_force_n)
        cv = self._as_input("verbal_cue", verbal_cue)
        y = self._as_input("measured_position_m", measured_position_m)
        self._check(self._kernel_step(cp, cv, y))
        return self._probs.copy()

    def run(
        self,
        push_force_n: ArrayLike,
        verbal_cue: ArrayLike,
        measured_position_m: ArrayLike,
    ) -> NDArray[np.float64]:
        """Filter (N, T) sequences (``step`` T times, compiled end to end).

        Args:
            push_force_n: (N, T) push forces [N] (broadcastable).
            verbal_cue: (N, T) verbal cues (broadcastable).
            measured_position_m: (N, T) shoulder measurements [m].

        Returns:
            (N, T, 3) mode probabilities after each step.
        """
        shape = np.shape(measured_position_m)
        if len(shape) != 2 or shape[0] != self.n_envs:
            raise ValueError(f"measured_position_m must have shape (N={self.n_envs}, T), got {shape}")
        y = self._as_sequence("measured_position_m", measured_position_m, shape)
        cp = self._as_sequence("push_force_n", push_force_n, shape)
        cv = self._as_sequence("verbal_cue", verbal_cue, shape)
        probs_seq = np.empty((*y.shape, N_MODES))
        self._check(self._kernel_run(cp, cv, y, probs_seq))
        return probs_seq

    def _kernel_step(self, cp: NDArray[np.float64], cv: NDArray[np.float64], y: NDArray[np.float64]) -> int:
        # One step is a sequence of length 1 (views, no copies); its probabilities land in _probs.
        return self._kernel_run(cp[:, None], cv[:, None], y[:, None], self._probs[:, None, :])

    def _kernel_run(
        self, cp: NDArray[np.float64], cv: NDArray[np.float64], y: NDArray[np.float64], out: NDArray[np.float64]
    ) -> int:
        # The IMM mixes and keeps one covariance per mode; the MMAE's shared one is passed as (N, 1, 3, 3).
        P = self.P if self._per_mode_covariance else self.P[:, None]
        return _filter(
            self.means, P, self.log_mu, self.nominal, self._per_mode_covariance, self._log_keep, self._log_floor,
            self._log_trans, cp, cv, y, out, self._probs, self._mean,
        )  # fmt: skip


class MultipleModelEstimator(_MultipleModelBase):
    """Multiple-model adaptive estimator (MMAE): Bayes over ``xi`` constant within a trial.

    Each step, per env: one shared covariance recursion (``P``, ``S``, ``K``), three
    mean recursions (one per ``xi``), and
    ``log mu_j <- log mu_j - 0.5 (log(2 pi S) + e_j^2 / S)`` normalised with log-sum-exp,
    where ``e_j`` is mode ``j``'s innovation. With ``probability_floor = 0`` this is the
    exact posterior ``P(xi = j | y_1..t)`` under the nominal model.

    Args:
        nominal_rows: (N, len(NOMINAL_COLUMNS)) packed nominal models (:func:`estimator.kalman.nominal_row`),
            one per env; the ``xi`` columns are unused.
        first_position_m: (N,) first shoulder measurements [m] (initial means).
        prior: Model whose ``initial_velocity_std_m_per_s`` and ``initial_intention_std_m``
            set the prior covariance (default ``NominalModel()``).
        mode_prior: Prior weights over ``xi = -1, 0, +1`` (default uniform).
        probability_floor: ``epsilon`` in [0, 1/3): each step the mode probabilities are
            mixed as ``(1 - 3 epsilon) mu + epsilon`` before the update, so no mode is
            locked out. 0 gives exact Bayes.

    Example:
        >>> mm = MultipleModelEstimator.from_model(NominalModel(), np.zeros(2))
        >>> mm.step(np.array([10.0, 0.0]), np.array([1.0, 0.0]), np.array([0.0, 0.0])).shape
        (2, 3)
    """

    _per_mode_covariance = False

    def __init__(
        self,
        nominal_rows: ArrayLike,
        first_position_m: ArrayLike,
        *,
        prior: NominalModel | None = None,
        mode_prior: ArrayLike | None = None,
        probability_floor: float = 1e-6,
    ) -> None:
        """Create N estimators, each at its first measurement and mode prior."""
        super().__init__(
            nominal_rows, first_position_m, prior=prior, mode_prior=mode_prior, probability_floor=probability_floor
        )
        eps = self.probability_floor
        self._log_keep = math.log1p(-N_MODES * eps)
        self._log_floor = math.log(eps) if eps > 0 else -math.inf

    @classmethod
    def from_model(
        cls,
        model: NominalModel,
        first_position_m: ArrayLike,
        *,
        mode_prior: ArrayLike | None = None,
        probability_floor: float = 1e-6,
    ) -> MultipleModelEstimator:
        """Batch of estimators sharing one nominal model (and its prior); N = len(first_position_m)."""
        first = np.atleast_1d(np.asarray(first_position_m, dtype=np.float64))
        rows = np.tile(nominal_row(model), (first.shape[0], 1))
        return cls(rows, first, prior=model, mode_prior=mode_prior, probability_floor=probability_floor)


class IMMEstimator(_MultipleModelBase):
    """Interacting multiple model estimator (Bar-Shalom), for ``xi`` that may switch.

    Each step, per env, with the row-stochastic transition ``p_ij = P(xi_t = j | xi_{t-1} = i)``:

    1. ``cbar_j = sum_i p_ij mu_i``; mixing weights ``mu_{i|j} = p_ij mu_i / cbar_j``;
       ``m0_j = sum_i mu_{i|j} m_i``; ``P0_j = sum_i mu_{i|j} (P_i + (m_i - m0_j)(m_i - m0_j)^T)``.
    2. Mode-matched Kalman filter from ``(m0_j, P0_j)`` with input ``B_xi``; likelihood
       ``Lambda_j = N(e_j; 0, S_j)``.
    3. ``mu_j proportional to Lambda_j cbar_j``.

    All three in log space. The floor is folded into the transition matrix as
    ``(1 - 3 epsilon) p + epsilon``.

    Args:
        nominal_rows: (N, len(NOMINAL_COLUMNS)) packed nominal models, one per env.
        first_position_m: (N,) first shoulder measurements [m].
        prior: Model giving the prior covariance of ``[xdot, eta]`` (default ``NominalModel()``).
        mode_prior: Prior weights over ``xi = -1, 0, +1`` (default uniform).
        probability_floor: ``epsilon`` in [0, 1/3) (see above).
        switching_rate_per_s: Rate of leaving the current mode [1/s], used when
            ``transition_matrix`` is not given (see :func:`switching_transition_matrix`).
        transition_matrix: Optional (3, 3) or (N, 3, 3) row-stochastic per-step matrix.

    Example:
        >>> imm = IMMEstimator.from_model(NominalModel(), np.zeros(1), switching_rate_per_s=0.2)
        >>> probs = imm.step(np.array([10.0]), np.array([1.0]), np.array([0.0]))
        >>> probs.shape, round(float(probs.sum()), 12)
        ((1, 3), 1.0)
    """

    _per_mode_covariance = True

    def __init__(
        self,
        nominal_rows: ArrayLike,
        first_position_m: ArrayLike,
        *,
        prior: NominalModel | None = None,
        mode_prior: ArrayLike | None = None,
        probability_floor: float = 1e-6,
        switching_rate_per_s: float = 0.1,
        transition_matrix: ArrayLike | None = None,
    ) -> None:
        """Create N IMM estimators, each at its first measurement and mode prior."""
        super().__init__(
            nominal_rows, first_position_m, prior=prior, mode_prior=mode_prior, probability_floor=probability_floor
        )
        n = self.n_envs
        if transition_matrix is None:
            trans = np.stack(
                [switching_transition_matrix(switching_rate_per_s, dt) for dt in self.nominal[:, NOMINAL.dt_s]]
            )
        else:
            trans = np.broadcast_to(np.asarray(transition_matrix, dtype=np.float64), (n, N_MODES, N_MODES)).copy()
            if not np.all(np.isfinite(trans)) or np.any(trans < 0) or not np.allclose(trans.sum(axis=-1), 1.0):
                raise ValueError("transition_matrix must be row-stochastic: p_ij >= 0 and each row summing to 1")
        eps = self.probability_floor
        self.transition_matrix = (1.0 - N_MODES * eps) * trans + eps
        with np.errstate(divide="ignore"):
            self._log_trans = np.ascontiguousarray(np.log(self.transition_matrix))

    @classmethod
    def from_model(
        cls,
        model: NominalModel,
        first_position_m: ArrayLike,
        *,
        mode_prior: ArrayLike | None = None,
        probability_floor: float = 1e-6,
        switching_rate_per_s: float = 0.1,
        transition_matrix: ArrayLike | None = None,
    ) -> IMMEstimator:
        """Batch of IMM estimators sharing one nominal model; N = len(first_position_m)."""
        first = np.atleast_1d(np.asarray(first_position_m, dtype=np.float64))
        rows = np.tile(nominal_row(model), (first.shape[0], 1))
        return cls(
            rows,
            first,
            prior=model,
            mode_prior=mode_prior,
            probability_floor=probability_floor,
            switching_rate_per_s=switching_rate_per_s,
            transition_matrix=transition_matrix,
        )


# --------------------------------------------------------------------------- decisions

# Tie-break order for MAP: prefer "unresponsive" (0), the non-committal answer, then -1, then +1.
_TIE_ORDER = np.array([1, 0, 2])


def _as_probs(probs: ArrayLike) -> NDArray[np.float64]:
    p = np.asarray(probs, dtype=np.float64)
    if p.ndim == 0 or p.shape[-1] != N_MODES:
        raise ValueError(f"probabilities must have a last axis of length 3 (xi = -1, 0, +1), got shape {p.shape}")
    return p


def map_judgment(probs: ArrayLike) -> NDArray[np.int64]:
    """Maximum a posteriori ``xi``: ``argmax_j P(xi = j)``, ties going to 0, then -1.

    Args:
        probs: (..., 3) mode probabilities ordered ``xi = -1, 0, +1``.

    Returns:
        (...,) int judgments in {-1, 0, +1}.
    """
    p = _as_probs(probs)
    best = np.argmax(p[..., _TIE_ORDER], axis=-1)
    return MODE_VALUES[_TIE_ORDER[best]]


def confident_judgment(probs: ArrayLike, confidence: float = 0.9) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """MAP judgment only where its probability reaches ``confidence``; elsewhere 0, undecided.

    Args:
        probs: (..., 3) mode probabilities.
        confidence: Minimum posterior probability of the MAP mode to decide, in (0, 1].

    Returns:
        ``(judgment (...,), decided (...,))``: judgment in {-1, 0, +1} (0 where
        undecided) and whether the confidence rule decided.
    """
    if not (is_number(confidence) and 0.0 < confidence <= 1.0):
        raise ValueError(f"confidence must be in (0, 1], got {confidence!r}")
    p = _as_probs(probs)
    judgment = map_judgment(p)
    decided = p.max(axis=-1) >= confidence
    return np.where(decided, judgment, 0), decided


def sequential_judgment(
    probs: ArrayLike,
    error_rate: float = 0.05,
    start_step: int | Sequence[int] | NDArray[np.int64] = 0,
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Earliest decision, SPRT-style: stop when one mode's posterior odds beat every other's.

    Mode ``k`` is accepted at the first step ``t >= start_step`` with
    ``log P(xi = k) - max_{j != k} log P(xi = j) >= log((1 - alpha) / alpha)``, Wald's
    upper threshold with ``alpha = beta = error_rate`` applied to posterior odds
    (with a uniform prior, to likelihood ratios).

    Args:
        probs: (N, T, 3) mode probabilities over time (e.g. from ``run``).
        error_rate: ``alpha`` in (0, 0.5).
        start_step: First step at which a decision may be taken (e.g. cue onset), scalar or (N,).

    Returns:
        ``(judgment (N,), decision_step (N,))``: the accepted ``xi`` (0 if never decided)
        and the step index of the decision (-1 if never decided).
    """
    if not (is_number(error_rate) and 0.0 < error_rate < 0.5):
        raise ValueError(f"error_rate must be in (0, 0.5), got {error_rate!r}")
    p = _as_probs(probs)
    if p.ndim != 3:
        raise ValueError(f"probs must have shape (N, T, 3), got {p.shape}")
    n, t_len, _ = p.shape
    start = np.broadcast_to(np.asarray(start_step, dtype=np.int64), (n,))
    with np.errstate(divide="ignore"):
        logp = np.log(p)
    top = np.sort(logp, axis=-1)
    margin = top[..., -1] - top[..., -2]
    threshold = math.log((1.0 - error_rate) / error_rate)
    allowed = np.arange(t_len)[None, :] >= start[:, None]
    hit = (margin >= threshold) & allowed
    any_hit = hit.any(axis=1)
    step = np.where(any_hit, np.argmax(hit, axis=1), -1)
    at = np.clip(step, 0, None)
    judgment = np.where(any_hit, MODE_VALUES[np.argmax(p[np.arange(n), at], axis=-1)], 0)
    return judgment.astype(np.int64), step.astype(np.int64)


guard_kernel_cache(__name__)
