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
from numpy.typing import ArrayLike, NDArray

from estimator.compiled.cache import guard_kernel_cache
from estimator.kalman import NOMINAL, NOMINAL_COLUMNS, nominal_row
from estimator.mode_kernels import N_MODES, NON_FINITE_INPUT, STATE_WIDTH, filter_sequences
from estimator.nominal import NominalModel
from estimator.validate import is_number

__all__ = [
    "MODE_VALUES",
    "TRIAL_PROBABILITY_FLOOR",
    "TRIAL_SWITCHING_RATE_PER_S",
    "IMMEstimator",
    "MultipleModelEstimator",
    "confident_judgment",
    "map_judgment",
    "sequential_judgment",
    "switching_transition_matrix",
]

MODE_VALUES: NDArray[np.int64] = np.array([-1, 0, 1], dtype=np.int64)
"""Cooperativeness of each mode, in the order of every ``(..., 3)`` probability array."""

TRIAL_PROBABILITY_FLOOR = 1e-4
"""Mode-probability floor for judging the paper's cue trials (the simulated protocol's and the
offline estimator's default): a trial is short, so a floor this low lets one trial's evidence
decide while no mode is ever ruled out for good."""
TRIAL_SWITCHING_RATE_PER_S = 0.05
"""IMM's mode-switching rate on the paper's cue trials [1/s]: a subject acts one requested
``xi`` per trial, so a switch within a trial's 10 s is rare."""

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
    _floor_before_update = False

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
        self.means = np.zeros((n, N_MODES, STATE_WIDTH))
        cov_shape = (
            (n, N_MODES, STATE_WIDTH, STATE_WIDTH) if self._per_mode_covariance else (n, STATE_WIDTH, STATE_WIDTH)
        )
        self.P = np.zeros(cov_shape)
        self.log_mu = np.zeros((n, N_MODES))
        self._probs = np.zeros((n, N_MODES))
        self._mean = np.zeros((n, STATE_WIDTH))
        self._shape = (n,)
        # The MMAE mixes the probability floor in before each update (log_keep, log_floor); the IMM folds it
        # into its transitions (_log_trans, set by IMMEstimator). The other kind's kernel arguments go unused.
        eps = self.probability_floor
        floor_first = self._floor_before_update
        self._log_keep = math.log1p(-N_MODES * eps) if floor_first else 0.0
        self._log_floor = math.log(eps) if floor_first and eps > 0 else -math.inf
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
        p0 = np.zeros((idx.shape[0], STATE_WIDTH, STATE_WIDTH))
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
        if status == NON_FINITE_INPUT:
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
        return filter_sequences(
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
    _floor_before_update = True

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
