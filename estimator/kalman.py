"""The paper's linear time-variant Kalman filter on ``[x, xdot, eta, xi]`` (§IV).

Two implementations of the same maths:

* :class:`PaperKalmanFilter` -- built on ``filterpy.kalman.KalmanFilter``; the
  reference, readable and slow (one Python object and several small matrix products a step).
* :class:`FastKalmanFilter` -- a batched, compiled (numba) version of the identical
  predict/update used in the environments' hot path. Tests hold both to the
  extended-precision answer within 1e-9 on long random cue sequences, wherever double
  precision allows that (tests/estimator/test_filter_properties.py), and within 1e-6 on
  edge models.

Symbols (shapes for one filter; the batched arrays add a leading env axis ``N``):

* ``m`` (4,): posterior mean ``[x, xdot, eta, xi]``.
* ``P`` (4, 4): posterior covariance.
* ``A`` (4, 4): transition built from the cues, see :meth:`NominalModel.transition_matrix`.
* ``B`` (4,): push input vector ``[0, k2*dt, 0, 0]``.
* ``H`` (1, 4): ``[1, 0, 0, 0]``.  ``Q`` (4, 4) diagonal, ``R`` scalar.
* ``S`` scalar innovation variance, ``K`` (4,) gain, ``y - H m`` the innovation.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from estimator.compiled.cache import guard_kernel_cache
from estimator.compiled.schema import index_table
from estimator.nominal import EULER_FIELDS, STATE_DIM, NominalModel, euler_transition

__all__ = [
    "NOMINAL",
    "NOMINAL_COLUMNS",
    "NOMINAL_DERIVED_COLUMNS",
    "NOMINAL_FIELDS",
    "FastKalmanFilter",
    "PaperKalmanFilter",
    "kalman_step",
    "nominal_parameters",
    "nominal_row",
    "predict_covariance",
]

NOMINAL_FIELDS: tuple[str, ...] = EULER_FIELDS
"""The :class:`NominalModel` fields ``A`` and ``B`` are made of, packed as they are."""

NOMINAL_DERIVED_COLUMNS: tuple[str, ...] = (
    "q_position",
    "q_velocity",
    "q_intention",
    "q_cooperativeness",
    "r_position",
)
"""Packed from the model's stds: the diagonal of ``Q`` and ``R`` (variances)."""

NOMINAL_COLUMNS: tuple[str, ...] = NOMINAL_FIELDS + NOMINAL_DERIVED_COLUMNS
"""Column layout of a packed nominal model row (one row per env in the batched filter)."""

NOMINAL = index_table("NominalColumns", NOMINAL_COLUMNS)
"""Column of each quantity in a packed nominal row: ``nominal[NOMINAL.voluntary_gain_per_s2]``."""


def nominal_row(model: NominalModel) -> NDArray[np.float64]:
    """Pack a :class:`NominalModel` into the row layout of :data:`NOMINAL_COLUMNS`."""
    q = np.diag(model.process_covariance)
    derived = dict(zip(NOMINAL_DERIVED_COLUMNS, (q[0], q[1], q[2], q[3], model.measurement_variance), strict=True))
    values = {**{name: getattr(model, name) for name in NOMINAL_FIELDS}, **derived}
    return np.array([values[name] for name in NOMINAL_COLUMNS])


@njit(cache=True, error_model="numpy", inline="always")
def nominal_parameters(nominal: NDArray[np.float64]) -> tuple[float, float, float, float, float, float]:
    """A nominal row's ``params`` of :func:`~estimator.nominal.euler_transition` and ``euler_step``."""
    return (
        nominal[NOMINAL.dt_s],
        nominal[NOMINAL.damping_rate_per_s],
        nominal[NOMINAL.voluntary_gain_per_s2],
        nominal[NOMINAL.push_compliance_m_per_s2_n],
        nominal[NOMINAL.push_gain_m_per_s_n],
        nominal[NOMINAL.verbal_gain_m_per_s],
    )


@njit(cache=True, error_model="numpy", inline="always")
def _needs_repair(P: NDArray[np.float64]) -> bool:
    """Whether the symmetric ``P`` (4, 4) fails a Cholesky test of positive semi-definiteness.

    Elimination without square roots (``P = L D L^T``): every pivot must be > 0, or exactly 0 with
    an exactly zero remaining column (a state the filter knows exactly, e.g. a zero prior std and
    no process noise). Passing it in floating point bounds the smallest eigenvalue below by a few
    ``eps * max(P_ii)`` (Demmel 1989). A non-finite ``P`` is left alone (returns False).
    """
    a00, a01, a02, a03 = P[0, 0], P[0, 1], P[0, 2], P[0, 3]
    a11, a12, a13 = P[1, 1], P[1, 2], P[1, 3]
    a22, a23 = P[2, 2], P[2, 3]
    a33 = P[3, 3]
    if a00 > 0.0:
        inverse = 1.0 / a00
        l1, l2, l3 = a01 * inverse, a02 * inverse, a03 * inverse
        a11 -= l1 * a01
        a12 -= l1 * a02
        a13 -= l1 * a03
        a22 -= l2 * a02
        a23 -= l2 * a03
        a33 -= l3 * a03
    elif a00 < 0.0 or a01 != 0.0 or a02 != 0.0 or a03 != 0.0:
        return _all_finite(P)
    if a11 > 0.0:
        inverse = 1.0 / a11
        l2, l3 = a12 * inverse, a13 * inverse
        a22 -= l2 * a12
        a23 -= l2 * a13
        a33 -= l3 * a13
    elif a11 < 0.0 or a12 != 0.0 or a13 != 0.0:
        return _all_finite(P)
    if a22 > 0.0:
        a33 -= (a23 / a22) * a23
    elif a22 < 0.0 or a23 != 0.0:
        return _all_finite(P)
    # NaN fails every comparison: only a finite P that has failed the test is repaired.
    return a33 < 0.0


@njit(cache=True, error_model="numpy", inline="always")
def _all_finite(P: NDArray[np.float64]) -> bool:
    for i in range(4):
        for j in range(4):
            if not math.isfinite(P[i, j]):
                return False
    return True


@njit(cache=True, error_model="numpy")
def _symmetric_eigen(A: NDArray[np.float64], V: NDArray[np.float64]) -> None:
    """Cyclic Jacobi eigendecomposition of the symmetric ``A`` (4, 4), in place.

    ``A`` becomes diagonal (its eigenvalues) and ``V`` the orthogonal matrix of eigenvectors
    (columns), so that the input equals ``V diag(A) V^T``. Rotations stop at the relative
    threshold ``|a_pq| <= 1e-18 sqrt(|a_pp a_qq|)`` (Demmel & Veselic), which gives the small
    eigenvalues of a diagonally scaled matrix to high relative accuracy. Written out rather
    than ``np.linalg.eigh``: LAPACK's binding and its error formatting cost seconds of
    compilation at every cold start, for a repair ordinary models never reach.
    """
    for i in range(4):
        for j in range(4):
            V[i, j] = 1.0 if i == j else 0.0
    for _ in range(60):
        rotated = False
        for p in range(3):
            for q in range(p + 1, 4):
                apq = A[p, q]
                app, aqq = A[p, p], A[q, q]
                if abs(apq) <= 1e-18 * math.sqrt(abs(app * aqq)):
                    A[p, q] = 0.0
                    A[q, p] = 0.0
                    continue
                rotated = True
                theta = (aqq - app) / (2.0 * apq)
                if abs(theta) > 1e150:
                    t = 0.5 / theta
                else:
                    t = math.copysign(1.0, theta) / (abs(theta) + math.sqrt(theta * theta + 1.0))
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                for k in range(4):  # A J
                    akp, akq = A[k, p], A[k, q]
                    A[k, p] = c * akp - s * akq
                    A[k, q] = s * akp + c * akq
                for k in range(4):  # J^T (A J)
                    apk, aqk = A[p, k], A[q, k]
                    A[p, k] = c * apk - s * aqk
                    A[q, k] = s * apk + c * aqk
                A[p, q] = 0.0
                A[q, p] = 0.0
                for k in range(4):  # V J
                    vkp, vkq = V[k, p], V[k, q]
                    V[k, p] = c * vkp - s * vkq
                    V[k, q] = s * vkp + c * vkq
        if not rotated:
            return


_EPS = float(np.finfo(np.float64).eps)
"""Double precision's relative spacing (2.2e-16): the floor of the repair's diagonal scale."""


@njit(cache=True, error_model="numpy")
def _nearest_psd(P: NDArray[np.float64]) -> None:
    """Project the symmetric ``P`` (4, 4) back onto the PSD cone, in place, in its own scale.

    Only for a covariance that rounding has pushed out of the PSD cone (see :func:`kalman_step`).
    The eigenvalues are clipped at 0 in the diagonally scaled matrix ``C = D^-1/2 P D^-1/2``
    (``D`` = the diagonal of ``P``, each entry raised to at least ``eps * max(P_ii)``; 1 where
    all are 0) and ``P`` becomes ``D^1/2 V max(w, 0) V^T D^1/2``. So each entry moves by at most
    ``|w_min| sqrt(P_ii P_jj)``, relative to its own variances: clipping in ``P``'s own scale
    would move a 1e-12 position variance by ``eps * 100`` when the intention variance is 100 --
    a 1 % error that the extended-precision filter shows is rounding, not information. Each
    diagonal entry is a sum of non-negative terms, so ``P_00 >= 0`` and ``S = P_00 + R >= R``
    hold exactly afterwards.
    """
    # A variance below eps * the largest one is rounding in P's own scale, not information:
    # dividing by it would blow its row's rounding up (a 5e-45 intention variance beside
    # off-diagonal rounding of 1e-18 made |C_ij| ~ 1e4 and the repaired P[1, 1] 2e9).
    largest = max(P[0, 0], P[1, 1], P[2, 2], P[3, 3])
    floor = _EPS * largest
    scale = np.empty(4)
    for i in range(4):
        variance = max(P[i, i], floor)
        scale[i] = math.sqrt(variance) if variance > 0.0 else 1.0
    C = np.empty((4, 4))
    V = np.empty((4, 4))
    for i in range(4):
        for j in range(4):
            C[i, j] = P[i, j] / (scale[i] * scale[j])
    _symmetric_eigen(C, V)
    for i in range(4):
        for j in range(i, 4):
            s = 0.0
            for k in range(4):
                s += V[i, k] * max(C[k, k], 0.0) * V[j, k]
            s *= scale[i] * scale[j]
            P[i, j] = s
            P[j, i] = s


@njit(cache=True, error_model="numpy", fastmath=False)
def kalman_step(
    m: NDArray[np.float64],
    P: NDArray[np.float64],
    nominal: NDArray[np.float64],
    push_force_n: float,
    verbal_cue: float,
    measured_position_m: float,
) -> tuple[float, float]:
    """One predict + update of the paper filter, in place on ``m`` (4,) and ``P`` (4, 4).

    The arithmetic mirrors filterpy's ``predict`` (``m = A m + B u``,
    ``P = A P A^T + Q``) and Joseph-form ``update`` so the two agree to rounding.

    Returns:
        ``(innovation, S)``: the measurement residual and its variance, for
        likelihoods (system identification, multiple-model estimators).
    """
    _predict(m, P, nominal, push_force_n, verbal_cue)
    # Guard (never taken when P stays PSD, so ordinary models keep these exact operations): a
    # prediction that rounding made indefinite would give S <= 0 and a NaN likelihood.
    if P[0, 0] < 0.0 and _needs_repair(P):
        _nearest_psd(P)
    innovation, S = _update(m, P, nominal, measured_position_m)
    # Guard: with a tiny R against a huge prior, or no process noise on a growing model, the
    # update's cancellation can leave P slightly indefinite; project it back (see _nearest_psd).
    if _needs_repair(P):
        _nearest_psd(P)
    return innovation, S


@njit(cache=True, error_model="numpy", fastmath=False, inline="always")
def _predict(
    m: NDArray[np.float64], P: NDArray[np.float64], nominal: NDArray[np.float64], push_force_n: float, verbal_cue: float
) -> None:
    """The prediction ``m = A m + B u``, ``P = A P A^T + Q``, A from the cues (eqs. 1, 6, 10 Euler-discretised)."""
    transition = euler_transition(nominal_parameters(nominal), push_force_n, verbal_cue)
    a01, a10, a11, a12, a23, b1 = transition
    m0, m1, m2, m3 = m[0], m[1], m[2], m[3]
    m[0] = m0 + a01 * m1
    m[1] = a10 * m0 + a11 * m1 + a12 * m2 + b1 * push_force_n
    m[2] = m2 + a23 * m3
    m[3] = m3
    predict_covariance(P, STATE_DIM, transition, nominal)


@njit(cache=True, error_model="numpy", fastmath=False, inline="always")
def predict_covariance(
    P: NDArray[np.float64], size: int, transition: tuple[float, ...], nominal: NDArray[np.float64]
) -> None:
    """``P = A P A^T + Q`` in place on ``P`` (size, size): the covariance prediction of every filter here.

    ``size`` 4: the paper filter's ``[x, xdot, eta, xi]``; 3: a mode of the multiple-model filters,
    ``[x, xdot, eta]`` with ``xi`` a known constant, whose ``F`` is ``A``'s upper-left block (``a23``
    unused). ``A``'s rows are ``[1, a01, 0, 0]``, ``[a10, a11, a12, 0]``, ``[0, 0, 1, a23]``,
    ``[0, 0, 0, 1]``: ``transition`` = ``(a01, a10, a11, a12, a23, b1)`` of
    :func:`~estimator.nominal.euler_transition`; ``Q``'s diagonal comes from the ``nominal`` row.
    Callers pass ``size`` as a literal, so each compiles to its own straight-line code.
    """
    a01, a10, a11, a12, a23, _ = transition
    # No temporaries: a heap allocation per call cost more than this arithmetic (the env
    # calls it 5 times per agent step).
    # A P, in place column by column (column j of A P needs only column j of P).
    for j in range(size):
        p0, p1, p2 = P[0, j], P[1, j], P[2, j]
        P[0, j] = p0 + a01 * p1
        P[1, j] = a10 * p0 + a11 * p1 + a12 * p2
        if size == STATE_DIM:
            P[2, j] = p2 + a23 * P[3, j]
    # (A P) A^T + Q, in place row by row.
    for i in range(size):
        q0, q1, q2 = P[i, 0], P[i, 1], P[i, 2]
        P[i, 0] = q0 + a01 * q1
        P[i, 1] = a10 * q0 + a11 * q1 + a12 * q2
        if size == STATE_DIM:
            P[i, 2] = q2 + a23 * P[i, 3]
    P[0, 0] += nominal[NOMINAL.q_position]
    P[1, 1] += nominal[NOMINAL.q_velocity]
    P[2, 2] += nominal[NOMINAL.q_intention]
    if size == STATE_DIM:
        P[3, 3] += nominal[NOMINAL.q_cooperativeness]


@njit(cache=True, error_model="numpy", fastmath=False, inline="always")
def _update(
    m: NDArray[np.float64], P: NDArray[np.float64], nominal: NDArray[np.float64], measured_position_m: float
) -> tuple[float, float]:
    """The update with the scalar measurement y = H s + v, H = [1 0 0 0]; returns ``(innovation, S)``."""
    innovation = measured_position_m - m[0]
    R = nominal[NOMINAL.r_position]
    S = P[0, 0] + R
    K = (P[0, 0] / S, P[1, 0] / S, P[2, 0] / S, P[3, 0] / S)
    for i in range(4):
        m[i] += K[i] * innovation
    # Joseph form: P = (I - K H) P (I - K H)^T + K R K^T, as filterpy computes it, with
    # (I - K H) P [i, j] = P[i, j] - K[i] * P[0, j] (row 0 kept before it is overwritten).
    row0 = (P[0, 0], P[0, 1], P[0, 2], P[0, 3])
    for i in range(4):
        ikhp_i0 = P[i, 0] - K[i] * row0[0]
        for j in range(4):
            # (I-KH)P(I-KH)^T [i, j] = IKHP[i, j] - IKHP[i, 0] * K[j]
            P[i, j] = (P[i, j] - K[i] * row0[j]) - ikhp_i0 * K[j] + K[i] * R * K[j]
    # Symmetrise to stop rounding from breaking P = P^T over long runs.
    for i in range(4):
        for j in range(i + 1, 4):
            s = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = s
            P[j, i] = s
    return innovation, S


@njit(cache=True, error_model="numpy")
def _kalman_run(
    m: NDArray[np.float64],
    P: NDArray[np.float64],
    nominal: NDArray[np.float64],
    push_force_n: NDArray[np.float64],
    verbal_cue: NDArray[np.float64],
    measured_position_m: NDArray[np.float64],
    means: NDArray[np.float64],
    covariances: NDArray[np.float64],
    log_likelihoods: NDArray[np.float64],
) -> None:
    # Batched over envs (axis 0) and time (axis 1 of the inputs).
    n_env, n_steps = measured_position_m.shape
    for i in range(n_env):
        for t in range(n_steps):
            innov, S = kalman_step(
                m[i], P[i], nominal[i], push_force_n[i, t], verbal_cue[i, t], measured_position_m[i, t]
            )
            means[i, t] = m[i]
            covariances[i, t] = P[i]
            log_likelihoods[i, t] = -0.5 * (math.log(2.0 * math.pi * S) + innov * innov / S)


class PaperKalmanFilter:
    """The paper's filter on filterpy: the reference implementation.

    Args:
        model: Nominal model (matrices ``A(c_p, c_v)``, ``B``, ``H``, ``Q``, ``R``).
        first_position_m: First shoulder measurement, to centre the prior.

    Example:
        >>> kf = PaperKalmanFilter(NominalModel(), first_position_m=0.0)
        >>> mean = kf.step(push_force_n=10.0, verbal_cue=1.0, measured_position_m=0.001)
        >>> mean.shape
        (4,)
    """

    def __init__(self, model: NominalModel, first_position_m: float = 0.0) -> None:
        """Create the filter centred on the first measurement."""
        self.model = model
        # filterpy (and the scipy.stats it imports, slow to load) loads only when the reference filter is built:
        # `import coop_gym` and the compiled filter never need it.
        from filterpy.kalman import KalmanFilter

        self.kf = KalmanFilter(dim_x=STATE_DIM, dim_z=1, dim_u=1)
        self.kf.x = model.initial_state(first_position_m).reshape(STATE_DIM, 1)
        self.kf.P = model.initial_covariance()
        self.kf.H = model.measurement_matrix
        self.kf.Q = model.process_covariance
        self.kf.R = np.array([[model.measurement_variance]])
        self.kf.B = model.input_vector.reshape(STATE_DIM, 1)

    def step(self, push_force_n: float, verbal_cue: float, measured_position_m: float) -> NDArray[np.float64]:
        """Predict with ``A(c_p, c_v)`` and ``B c_p``, then update with the measurement."""
        self.kf.predict(u=np.array([[push_force_n]]), F=self.model.transition_matrix(push_force_n, verbal_cue))
        self.kf.update(np.array([[measured_position_m]]))
        return self.mean

    @property
    def mean(self) -> NDArray[np.float64]:
        """Posterior mean (4,) ``[x, xdot, eta, xi]``."""
        return np.asarray(self.kf.x, dtype=np.float64).reshape(STATE_DIM).copy()

    @property
    def covariance(self) -> NDArray[np.float64]:
        """Posterior covariance (4, 4)."""
        return np.array(self.kf.P, dtype=np.float64)


class FastKalmanFilter:
    """Batched compiled paper filter: ``N`` independent filters stepped together.

    Args:
        nominal_rows: (N, len(NOMINAL_COLUMNS)) packed nominal models (:func:`nominal_row`), one per filter.
        first_position_m: (N,) first shoulder measurements.

    Example:
        >>> kf = FastKalmanFilter.from_model(NominalModel(), np.zeros(3))
        >>> kf.run(np.zeros((3, 5)), np.ones((3, 5)), np.zeros((3, 5)))[0].shape
        (3, 5, 4)
    """

    def __init__(
        self,
        nominal_rows: NDArray[np.float64],
        first_position_m: NDArray[np.float64],
        prior: NominalModel | None = None,
    ) -> None:
        """Initialise each filter at its first measurement with the prior of ``prior``."""
        self.nominal = np.ascontiguousarray(np.atleast_2d(nominal_rows), dtype=np.float64)
        if self.nominal.shape[1] != len(NOMINAL_COLUMNS):
            raise ValueError(f"nominal_rows must have {len(NOMINAL_COLUMNS)} columns, got {self.nominal.shape}")
        n_env = self.nominal.shape[0]
        first = np.asarray(first_position_m, dtype=np.float64).reshape(n_env)
        prior = prior if prior is not None else NominalModel()
        self.m = np.zeros((n_env, STATE_DIM))
        self.m[:, 0] = first
        self.m[:, 2] = first
        self.P = np.zeros((n_env, STATE_DIM, STATE_DIM))
        self.P[:, 0, 0] = self.nominal[:, NOMINAL.r_position]
        self.P[:, 1, 1] = prior.initial_velocity_std_m_per_s**2
        self.P[:, 2, 2] = prior.initial_intention_std_m**2
        self.P[:, 3, 3] = prior.initial_cooperativeness_std**2

    @classmethod
    def from_model(cls, model: NominalModel, first_position_m: NDArray[np.float64]) -> FastKalmanFilter:
        """Batch of filters that all share one nominal model, with that model's prior."""
        first = np.atleast_1d(np.asarray(first_position_m, dtype=np.float64))
        rows = np.tile(nominal_row(model), (first.shape[0], 1))
        return cls(rows, first, prior=model)

    def run(
        self,
        push_force_n: NDArray[np.float64],
        verbal_cue: NDArray[np.float64],
        measured_position_m: NDArray[np.float64],
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Filter (N, T) sequences of cues and measurements.

        Returns:
            ``(means (N, T, 4), covariances (N, T, 4, 4), log_likelihoods (N, T))``,
            the posterior after each step and each measurement's predictive log density.
        """
        y = np.ascontiguousarray(measured_position_m, dtype=np.float64)
        if y.ndim != 2 or y.shape[0] != self.m.shape[0]:
            raise ValueError(f"measured_position_m must have shape (N={self.m.shape[0]}, T), got {y.shape}")
        cp = np.ascontiguousarray(np.broadcast_to(push_force_n, y.shape), dtype=np.float64)
        cv = np.ascontiguousarray(np.broadcast_to(verbal_cue, y.shape), dtype=np.float64)
        n_env, n_steps = y.shape
        means = np.empty((n_env, n_steps, STATE_DIM))
        covariances = np.empty((n_env, n_steps, STATE_DIM, STATE_DIM))
        log_likelihoods = np.empty((n_env, n_steps))
        _kalman_run(self.m, self.P, self.nominal, cp, cv, y, means, covariances, log_likelihoods)
        return means, covariances, log_likelihoods


guard_kernel_cache(__name__)
