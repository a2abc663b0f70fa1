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
from typing import Literal

import numpy as np
import scipy.optimize
from numba import njit
from numpy.typing import ArrayLike, NDArray

from compiled.cache import guard_kernel_cache
from compiled.checks import is_integer, is_number, python_scalar
from estimator.kalman import NOMINAL, nominal_row
from estimator.mode_kernels import N_MODES, mode_covariance_step, mode_mean_step
from estimator.nominal import NominalModel

__all__ = [
    "DEFAULT_FITTED_FIELDS",
    "IdentificationResult",
    "Trial",
    "identify",
    "simulate_nominal",
    "simulate_nominal_trials",
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
    bounds = [(t - _LOG_BOUND, t + _LOG_BOUND) for t in theta0]
    rng = np.random.default_rng(seed)
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
    best = min(runs, key=lambda r: r.fun)
    scale = objective.scale
    standard_errors = _log_standard_errors(objective.costs, best.x, scale)
    fitted = {name: float(np.exp(best.x[n])) for n, name in enumerate(fields)}
    dts = {t.dt_s for t in packed.trials}
    if len(dts) == 1:
        fitted["dt_s"] = float(next(iter(dts)))
    return IdentificationResult(
        model=initial.replace(**fitted),
        negative_log_likelihood=float(best.fun) / scale,
        n_iterations=int(best.nit),
        success=bool(best.success),
        message=str(best.message),
        n_measurements=packed.n_measurements,
        fitted_fields=fields,
        restart_negative_log_likelihoods=tuple(float(r.fun) / scale for r in runs),
        standard_errors=dict(zip(fields, standard_errors.tolist(), strict=True)),
    )


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


# --------------------------------------------------------------------------- simulation


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
    dt = model.dt_s
    q_std = np.sqrt(np.diag(model.process_covariance))[:3]
    states = np.empty((n, t_len, 4))
    s = np.broadcast_to(initial_state, (n, 3)).astype(np.float64).copy()
    states[:, 0, :3] = s
    states[:, :, 3] = xi
    lam, k1, k2 = model.damping_rate_per_s, model.voluntary_gain_per_s2, model.push_compliance_m_per_s2_n
    k3, k4 = model.push_gain_m_per_s_n, model.verbal_gain_m_per_s
    for t in range(1, t_len):
        cp, cv = push_force_n[:, t], verbal_cue[:, t]
        x, xdot, eta = s[:, 0], s[:, 1], s[:, 2]
        w = rng.normal(0.0, 1.0, (n, 3)) * q_std
        # eq. 1 (Euler, as NominalModel.transition_matrix and B): the same discretisation the filter assumes.
        new_x = x + dt * xdot
        new_xdot = xdot + dt * (-lam * xdot + k1 * (eta - x) + k2 * cp)
        # eq. 6: eta' = eta + xi (k3 c_p + k4 c_v) dt, xi held at its given value (no random walk).
        new_eta = eta + xi[:, t] * (k3 * cp + k4 * cv) * dt
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
    prior that biases the fitted ``lambda1`` and ``k2`` upward by about 10%.

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
    dt = model.dt_s
    duration = max(1, round(cue_duration_s / dt))
    margin = round(0.5 / dt)
    last_onset = max(1, n_steps - duration - margin)
    if xi is None:
        xis = rng.integers(-1, 2, n_trials)
    else:
        xis = np.broadcast_to(np.asarray(xi, dtype=np.int64), (n_trials,))
        if not np.all(np.isin(xis, (-1, 0, 1))):
            raise ValueError(f"xi must be in {{-1, 0, +1}}, got {xi!r}")
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
    xi_steps = np.repeat(xis.astype(np.float64)[:, None], n_steps, axis=1)
    start = np.zeros((n_trials, 3))
    if initial_state == "prior":
        start[:, 1] = rng.normal(0.0, model.initial_velocity_std_m_per_s, n_trials)
        start[:, 2] = rng.normal(0.0, model.initial_intention_std_m, n_trials)
    elif initial_state != "rest":
        raise ValueError(f"initial_state must be 'prior' or 'rest', got {initial_state!r}")
    measured, _ = _simulate_batch(model, cp, cv, xi_steps, rng, start)
    return [Trial(cp[i], cv[i], measured[i], xi=int(xis[i]), dt_s=dt) for i in range(n_trials)]


guard_kernel_cache(__name__)
