"""System identification of the nominal model by maximum likelihood (beyond the paper's §IV).

The paper picks ``lambda1, k1..k4`` by hand. Here they are fitted, together with the
noise levels, to recorded trials by maximising the Kalman filter's innovation
likelihood (the prediction-error decomposition):

``log p(y_1..T | theta, xi) = sum_t -0.5 (log(2 pi S_t) + e_t^2 / S_t)``

where ``e_t``, ``S_t`` are the innovations and their variances of the per-mode filter
of :mod:`estimator.multiple_model` (state ``[x, xdot, eta]``, input ``B_xi``). With
``xi`` labelled, each trial uses its own mode; unlabelled, each trial's likelihood
is marginalised over ``xi`` in {-1, 0, +1} with a uniform prior:

``log p(y | theta) = logsumexp_xi(log p(y | theta, xi)) - log 3``.

The parameters are optimised in log space (so they stay positive) with L-BFGS-B and
a few restarts. Data with ``xi`` unlabelled cannot tell ``(k3, k4, xi)`` from
``(-k3, -k4, -xi)``; the log parameterisation fixes ``k3, k4 > 0``.

Since ``F``, ``Q``, ``R`` and the prior are the same for every trial with the same
``dt``, the Riccati recursion (``P``, ``S``, ``K``) is computed once per parameter
set and shared by all trials and modes; only the mean recursions run per trial.

Conventions (as :class:`estimator.kalman.FastKalmanFilter`): a trial's first
measurement initialises the filter (``s0 = [y_0, 0, y_0]``); step ``t >= 1`` predicts
with the cues at index ``t`` and updates with the measurement at index ``t``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.optimize
from numba import njit
from numpy.typing import NDArray

from estimator.compiled.cache import guard_kernel_cache
from estimator.kalman import NOMINAL, nominal_row
from estimator.mode_kernels import N_MODES, mode_covariance_step, mode_mean_step
from estimator.nominal import NominalModel
from estimator.recording import Recording
from estimator.validate import is_integer, is_number, python_scalar

__all__ = [
    "DEFAULT_FITTED_FIELDS",
    "IdentificationResult",
    "Trial",
    "identify",
    "trial_log_likelihoods",
]

_LOG_2PI = math.log(2.0 * math.pi)

# NominalModel field -> (column of the packed nominal row, power: 1 for gains, 2 for stds -> variances).
_FITTABLE: dict[str, tuple[int, int]] = {
    "damping_rate_per_s": (NOMINAL.damping_rate_per_s, 1),
    "voluntary_gain_per_s2": (NOMINAL.voluntary_gain_per_s2, 1),
    "push_compliance_m_per_s2_n": (NOMINAL.push_compliance_m_per_s2_n, 1),
    "push_gain_m_per_s_n": (NOMINAL.push_gain_m_per_s_n, 1),
    "verbal_gain_m_per_s": (NOMINAL.verbal_gain_m_per_s, 1),
    "position_process_std_m": (NOMINAL.q_position, 2),
    "velocity_process_std_m_per_s": (NOMINAL.q_velocity, 2),
    "intention_process_std_m": (NOMINAL.q_intention, 2),
    "position_noise_std_m": (NOMINAL.r_position, 2),
}

DEFAULT_FITTED_FIELDS: tuple[str, ...] = (
    "damping_rate_per_s",
    "voluntary_gain_per_s2",
    "push_compliance_m_per_s2_n",
    "push_gain_m_per_s_n",
    "verbal_gain_m_per_s",
    "velocity_process_std_m_per_s",
    "intention_process_std_m",
    "position_noise_std_m",
)
"""Fitted by default: ``lambda1, k1..k4``, velocity and intention process stds, position noise std.

The position process std is tiny next to the sensor noise and poorly identifiable;
it stays at the initial model's value unless asked for.
"""

# Log-parameter search box around the starting point: a factor e^7 (~1100) either way.
_LOG_BOUND = 7.0
# A parameter set whose filter diverges (e.g. an Euler-unstable k1) gets this per-measurement cost.
_DIVERGED_COST = 1e6


@dataclass(frozen=True, eq=False)
class Trial:
    """One recorded trial: cues, shoulder measurements and (optionally) the true ``xi``.

    Attributes:
        push_force_n: (T,) push force ``c_p`` per step [N].
        verbal_cue: (T,) verbal cue ``c_v`` per step, in {-1, 0, +1}.
        measured_position_m: (T,) measured shoulder position [m]; index 0 initialises the filter.
        xi: The trial's cooperativeness in {-1, 0, +1}, or ``None`` if unlabelled.
        dt_s: Sampling step [s].
    """

    push_force_n: NDArray[np.float64]
    verbal_cue: NDArray[np.float64]
    measured_position_m: NDArray[np.float64]
    xi: int | None = None
    dt_s: float = 0.02

    def __post_init__(self) -> None:
        """Validate shapes and values; store read-only float arrays."""
        arrays = {}
        for name in ("push_force_n", "verbal_cue", "measured_position_m"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            if arr.ndim != 1 or arr.shape[0] < 2:
                raise ValueError(f"Trial.{name} must be 1-D with at least 2 samples, got shape {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"Trial.{name} must be finite")
            arr.setflags(write=False)
            arrays[name] = arr
        lengths = {a.shape[0] for a in arrays.values()}
        if len(lengths) != 1:
            raise ValueError(f"Trial arrays must have equal lengths, got {sorted(lengths)}")
        for name, arr in arrays.items():
            object.__setattr__(self, name, arr)
        if self.xi is not None and not (is_number(self.xi) and self.xi in (-1, 0, 1)):
            raise ValueError(f"Trial.xi must be -1, 0, +1 or None, got {self.xi!r}")
        if not (is_number(self.dt_s) and math.isfinite(self.dt_s) and self.dt_s > 0):
            raise ValueError(f"Trial.dt_s must be a finite number > 0, got {self.dt_s!r}")
        if self.xi is not None:
            object.__setattr__(self, "xi", int(self.xi))
        object.__setattr__(self, "dt_s", python_scalar(self.dt_s))

    @property
    def n_steps(self) -> int:
        """Number of samples ``T``."""
        return int(self.measured_position_m.shape[0])

    @classmethod
    def from_recording(cls, recording: Recording, labelled: bool = True) -> Trial:
        """A recorded trial (:mod:`estimator.recording`) as a trial to fit: its measured force, words and shoulder.

        ``xi`` is the recording's requested one where ``labelled`` (``None`` otherwise, or where
        none was recorded), so recordings fit as :func:`identify` fits any trials:
        ``identify([Trial.from_recording(read_recording(p)) for p in paths])``.
        """
        xi = recording.requested if labelled else None
        return cls(recording.force_n, recording.verbal_cue, recording.shoulder_position_m, xi, recording.dt_s)


@dataclass(frozen=True)
class IdentificationResult:
    """Outcome of :func:`identify`.

    Attributes:
        model: The fitted nominal model (unfitted fields copied from the initial model).
        negative_log_likelihood: Total negative log-likelihood of all trials at ``model`` [nats].
        n_iterations: L-BFGS-B iterations of the best run.
        success: Whether the best run's optimiser reported convergence.
        message: The best run's optimiser message.
        n_measurements: Number of measurements that entered the likelihood.
        fitted_fields: Names of the fitted :class:`NominalModel` fields.
        restart_negative_log_likelihoods: Final value of every run (first from the initial model).
        standard_errors: Approximate relative standard error of each fitted field: the
            square root of the diagonal of the inverse Hessian of the negative log-likelihood
            in log parameters (observed Fisher information, Cramér-Rao); NaN where the
            Hessian is not positive definite.
    """

    model: NominalModel
    negative_log_likelihood: float
    n_iterations: int
    success: bool
    message: str
    n_measurements: int
    fitted_fields: tuple[str, ...]
    restart_negative_log_likelihoods: tuple[float, ...]
    standard_errors: dict[str, float] = dataclasses.field(default_factory=dict)

    def relative_errors(self, reference: NominalModel) -> dict[str, float]:
        """``fitted / reference - 1`` for every fitted field (e.g. against the simulating model)."""
        return {
            name: getattr(self.model, name) / getattr(reference, name) - 1.0
            for name in self.fitted_fields
            if getattr(reference, name) != 0
        }


# --------------------------------------------------------------------------- likelihood kernel


@njit(cache=True, error_model="numpy")
def _trial_mode_log_likelihoods(
    rows: NDArray[np.float64],
    initial_velocity_var: float,
    initial_intention_var: float,
    dts: NDArray[np.float64],
    push_force_n: NDArray[np.float64],
    verbal_cue: NDArray[np.float64],
    measured_position_m: NDArray[np.float64],
    lengths: NDArray[np.int64],
    out: NDArray[np.float64],
) -> None:
    """``out[a, i, j] = log p(y_i | theta_a, xi = j - 1)`` for parameter rows ``a``, trials ``i``.

    Trials must be sorted by ``dt`` so the shared Riccati recursion is computed once per group.
    """
    n_sets = rows.shape[0]
    n_trials, t_max = measured_position_m.shape
    gains = np.empty((t_max, 3))
    log_s = np.empty(t_max)
    inv_s = np.empty(t_max)
    row = np.empty(rows.shape[1])
    P = np.empty((3, 3))
    K = np.empty(3)
    m = np.empty(3)
    for a in range(n_sets):
        current_dt = -1.0
        for i in range(n_trials):
            if dts[i] != current_dt:
                current_dt = dts[i]
                row[:] = rows[a]
                row[NOMINAL.dt_s] = current_dt
                # Prior covariance diag(R, var(xdot0), var(eta0)), as FastKalmanFilter.
                P[:, :] = 0.0
                P[0, 0] = row[NOMINAL.r_position]
                P[1, 1] = initial_velocity_var
                P[2, 2] = initial_intention_var
                for t in range(1, t_max):
                    S = mode_covariance_step(P, row, K)
                    gains[t, 0] = K[0]
                    gains[t, 1] = K[1]
                    gains[t, 2] = K[2]
                    log_s[t] = _LOG_2PI + math.log(S)
                    inv_s[t] = 1.0 / S
            y0 = measured_position_m[i, 0]
            for j in range(N_MODES):
                m[0] = y0
                m[1] = 0.0
                m[2] = y0
                ll = 0.0
                for t in range(1, lengths[i]):
                    e = mode_mean_step(
                        m, row, float(j - 1), push_force_n[i, t], verbal_cue[i, t], measured_position_m[i, t], gains[t]
                    )
                    # Prediction-error decomposition: log N(e_t; 0, S_t).
                    ll -= 0.5 * (log_s[t] + e * e * inv_s[t])
                out[a, i, j] = ll


class _PackedTrials:
    """Trials padded into (n, T_max) arrays, sorted by ``dt`` for the kernel."""

    def __init__(self, trials: Sequence[Trial]) -> None:
        if len(trials) == 0:
            raise ValueError("need at least one trial")
        for trial in trials:
            if not isinstance(trial, Trial):
                raise ValueError(f"trials must be Trial instances, got {type(trial).__name__}")
        order = sorted(range(len(trials)), key=lambda k: trials[k].dt_s)
        self.trials = [trials[k] for k in order]
        n = len(trials)
        t_max = max(t.n_steps for t in self.trials)
        self.cp = np.zeros((n, t_max))
        self.cv = np.zeros((n, t_max))
        self.y = np.zeros((n, t_max))
        self.lengths = np.array([t.n_steps for t in self.trials], dtype=np.int64)
        self.dts = np.array([t.dt_s for t in self.trials], dtype=np.float64)
        for i, t in enumerate(self.trials):
            self.cp[i, : t.n_steps] = t.push_force_n
            self.cv[i, : t.n_steps] = t.verbal_cue
            self.y[i, : t.n_steps] = t.measured_position_m
        self.n_measurements = int(np.sum(self.lengths - 1))
        self.labels = np.array([-2 if t.xi is None else t.xi for t in self.trials], dtype=np.int64)

    def mode_log_likelihoods(self, rows: NDArray[np.float64], prior: NominalModel) -> NDArray[np.float64]:
        out = np.empty((rows.shape[0], self.y.shape[0], N_MODES))
        _trial_mode_log_likelihoods(
            np.ascontiguousarray(rows),
            prior.initial_velocity_std_m_per_s**2,
            prior.initial_intention_std_m**2,
            self.dts,
            self.cp,
            self.cv,
            self.y,
            self.lengths,
            out,
        )
        return out


def _combine_modes(mode_ll: NDArray[np.float64], labels: NDArray[np.int64] | None) -> NDArray[np.float64]:
    """Per-trial log-likelihood (..., n): the labelled mode, or logsumexp over modes - log 3."""
    if labels is not None:
        return np.take_along_axis(mode_ll, (labels + 1)[None, :, None], axis=-1)[..., 0]
    mx = np.max(mode_ll, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", over="ignore"):
        lse = mx[..., 0] + np.log(np.sum(np.exp(mode_ll - mx), axis=-1))
    return lse - math.log(N_MODES)


def trial_log_likelihoods(trials: Sequence[Trial], model: NominalModel, labelled: bool = True) -> NDArray[np.float64]:
    """Log-likelihood of each trial under ``model`` [nats], in the order given.

    Args:
        trials: Recorded or simulated trials.
        model: Nominal model to evaluate.
        labelled: Use each trial's ``xi``; otherwise marginalise over ``xi`` with a uniform prior.

    Returns:
        (n_trials,) log-likelihoods.
    """
    packed = _PackedTrials(trials)
    labels = _labels(packed, labelled)
    per_trial = _combine_modes(packed.mode_log_likelihoods(nominal_row(model)[None, :], model), labels)[0]
    # Undo the sort by dt.
    order = sorted(range(len(trials)), key=lambda k: trials[k].dt_s)
    result = np.empty(len(trials))
    result[order] = per_trial
    return result


def _labels(packed: _PackedTrials, labelled: bool) -> NDArray[np.int64] | None:
    if not labelled:
        return None
    if np.any(packed.labels == -2):
        raise ValueError("labelled=True needs every Trial.xi set; pass labelled=False to marginalise over xi")
    return packed.labels


# --------------------------------------------------------------------------- identification


def identify(
    trials: Sequence[Trial],
    initial: NominalModel | None = None,
    labelled: bool = True,
    restarts: int = 3,
    seed: int = 0,
    *,
    fitted_fields: Sequence[str] = DEFAULT_FITTED_FIELDS,
    restart_spread: float = 0.5,
    max_iterations: int = 500,
) -> IdentificationResult:
    """Fit the nominal model to trials by maximum likelihood.

    Args:
        trials: Trials to fit (at least one; with ``labelled`` each needs ``xi``).
        initial: Starting point and source of the unfitted fields (default ``NominalModel()``).
            Fitted fields must be > 0 there (they are optimised in log space).
        labelled: Use each trial's ``xi``; otherwise marginalise over ``xi`` per trial.
        restarts: Number of optimiser runs (>= 1): the first from ``initial``, the others
            from log-normal perturbations of it with std ``restart_spread``.
        seed: Seed of the restart perturbations.
        fitted_fields: :class:`NominalModel` fields to fit (default :data:`DEFAULT_FITTED_FIELDS`).
        restart_spread: Std of the restarts' log-space perturbation.
        max_iterations: L-BFGS-B iteration limit per run.

    Returns:
        The best run's fitted model and diagnostics.

    Example:
        >>> from estimator.identification.nominal_trials import simulate_nominal_trials
        >>> trials = simulate_nominal_trials(NominalModel(), 5, 300, np.random.default_rng(0))
        >>> result = identify(trials, restarts=1)
        >>> result.success, result.model.dt_s, sorted(result.standard_errors) == sorted(result.fitted_fields)
        (True, 0.02, True)
    """
    initial = initial if initial is not None else NominalModel()
    fields = _checked_fields(initial, restarts, fitted_fields)
    packed = _PackedTrials(trials)
    objective = _Objective(packed, _labels(packed, labelled), initial, fields)
    theta0 = np.log([getattr(initial, f) for f in fields])
    runs = _minimise_from_restarts(
        objective, theta0, restarts, np.random.default_rng(seed), restart_spread, max_iterations
    )
    best = min(runs, key=lambda r: r.fun)
    scale = objective.scale
    standard_errors = _log_standard_errors(objective.costs, best.x, scale)
    return IdentificationResult(
        model=initial.replace(**_fitted_values(fields, best.x, packed)),
        negative_log_likelihood=float(best.fun) / scale,
        n_iterations=int(best.nit),
        success=bool(best.success),
        message=str(best.message),
        n_measurements=packed.n_measurements,
        fitted_fields=fields,
        restart_negative_log_likelihoods=tuple(float(r.fun) / scale for r in runs),
        standard_errors=dict(zip(fields, standard_errors.tolist(), strict=True)),
    )


def _minimise_from_restarts(
    objective: _Objective,
    theta0: NDArray[np.float64],
    restarts: int,
    rng: np.random.Generator,
    restart_spread: float,
    max_iterations: int,
) -> list[scipy.optimize.OptimizeResult]:
    """L-BFGS-B runs in log space: the first from ``theta0``, the others from log-normal perturbations of it."""
    bounds = [(t - _LOG_BOUND, t + _LOG_BOUND) for t in theta0]
    runs = []
    for k in range(restarts):
        start = theta0 if k == 0 else theta0 + rng.normal(0.0, restart_spread, theta0.shape)
        res = scipy.optimize.minimize(
            objective.fun_and_grad,
            start,
            jac=True,
            method="L-BFGS-B",
            bounds=bounds,
            options={"maxiter": max_iterations, "ftol": 1e-13, "gtol": 1e-9},
        )
        runs.append(res)
    return runs


def _fitted_values(fields: tuple[str, ...], theta: NDArray[np.float64], packed: _PackedTrials) -> dict[str, float]:
    """The fitted fields' values from the log-space optimum, and the trials' ``dt_s`` when they share one."""
    fitted = {name: float(np.exp(theta[n])) for n, name in enumerate(fields)}
    dts = {t.dt_s for t in packed.trials}
    if len(dts) == 1:
        fitted["dt_s"] = float(next(iter(dts)))
    return fitted


def _checked_fields(initial: NominalModel, restarts: int, fitted_fields: Sequence[str]) -> tuple[str, ...]:
    """The fitted fields, after checking them and ``restarts`` (``ValueError`` naming the problem)."""
    if not is_integer(restarts) or restarts < 1:
        raise ValueError(f"restarts must be >= 1, got {restarts!r}")
    fields = tuple(fitted_fields)
    unknown = [f for f in fields if f not in _FITTABLE]
    if unknown or len(set(fields)) != len(fields) or not fields:
        raise ValueError(f"fitted_fields must be distinct names from {sorted(_FITTABLE)}, got {fields!r}")
    for name in fields:
        if getattr(initial, name) <= 0:
            raise ValueError(f"initial.{name} must be > 0 to be fitted in log space, got {getattr(initial, name)!r}")
    return fields


class _Objective:
    """The per-measurement negative log-likelihood of log-space parameters ``theta``, and its gradient."""

    # Central-difference step in log space.
    step = 1e-5

    def __init__(
        self, packed: _PackedTrials, labels: NDArray[np.int64] | None, initial: NominalModel, fields: tuple[str, ...]
    ) -> None:
        self.packed = packed
        self.labels = labels
        self.initial = initial
        self.base_row = nominal_row(initial)
        self.columns = np.array([_FITTABLE[f][0] for f in fields])
        self.powers = np.array([_FITTABLE[f][1] for f in fields], dtype=np.float64)
        # A per-measurement cost keeps finite differences well conditioned.
        self.scale = 1.0 / packed.n_measurements

    def rows_of(self, thetas: NDArray[np.float64]) -> NDArray[np.float64]:
        rows = np.repeat(self.base_row[None, :], thetas.shape[0], axis=0)
        rows[:, self.columns] = np.exp(thetas * self.powers)
        return rows

    def costs(self, thetas: NDArray[np.float64]) -> NDArray[np.float64]:
        mode_ll = self.packed.mode_log_likelihoods(self.rows_of(thetas), self.initial)
        cost = -_combine_modes(mode_ll, self.labels).sum(axis=-1) * self.scale
        return np.where(np.isfinite(cost), cost, _DIVERGED_COST)

    def fun_and_grad(self, theta: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
        # All 2p + 1 parameter sets in one compiled call: the value and a central-difference gradient.
        eye = np.eye(theta.shape[0]) * self.step
        batch = np.vstack([theta[None, :], theta + eye, theta - eye])
        c = self.costs(batch)
        p = theta.shape[0]
        return float(c[0]), (c[1 : p + 1] - c[p + 1 :]) / (2.0 * self.step)


def _log_standard_errors(
    costs: Callable[[NDArray[np.float64]], NDArray[np.float64]], theta: NDArray[np.float64], scale: float
) -> NDArray[np.float64]:
    """``sqrt(diag(H^-1))`` of the total negative log-likelihood's Hessian in log parameters."""
    p = theta.shape[0]
    h = 1e-3
    eye = np.eye(p) * h
    pairs = [(i, j) for i in range(p) for j in range(i, p)]
    # Four-point stencil H_ij = [f(+i+j) - f(+i-j) - f(-i+j) + f(-i-j)] / (4 h^2), all in one batch.
    batch = np.array(
        [theta + si * eye[i] + sj * eye[j] for i, j in pairs for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1))]
    )
    c = costs(batch).reshape(len(pairs), 4) / scale
    hessian = np.empty((p, p))
    for k, (i, j) in enumerate(pairs):
        hessian[i, j] = hessian[j, i] = (c[k, 0] - c[k, 1] - c[k, 2] + c[k, 3]) / (4.0 * h * h)
    try:
        np.linalg.cholesky(hessian)
    except np.linalg.LinAlgError:
        return np.full(p, np.nan)
    return np.sqrt(np.diag(np.linalg.inv(hessian)))


guard_kernel_cache(__name__)
