"""The estimator's nominal model: the paper's linear three-level model (§IV).

The filter does not see the simulator's richer truth (reaction delay, saturation,
state-dependent stiffness, per-person variation); it assumes the linear model below.
That gap is deliberate: it is what makes estimation hard on real people.

Symbols (paper notation), state ``s = [x, xdot, eta, xi]``:

* ``A`` (4, 4): state transition, built each step from the known cues (eq. 9).
* ``B`` (4,): input vector for the push force ``c_p``.
* ``H`` (1, 4): measurement matrix ``[1, 0, 0, 0]`` (shoulder position only).
* ``Q`` (4, 4): process-noise covariance per filter step.
* ``R`` (1, 1): measurement-noise variance of the shoulder position.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from estimator.compiled.cache import guard_kernel_cache
from estimator.validate import is_number, python_scalar

__all__ = ["EULER_FIELDS", "STATE_DIM", "NominalModel", "euler_step", "euler_transition"]

STATE_DIM = 4
"""Length of the paper filter's state ``[x, xdot, eta, xi]``."""

EULER_FIELDS: tuple[str, ...] = (
    "dt_s",
    "damping_rate_per_s",
    "voluntary_gain_per_s2",
    "push_compliance_m_per_s2_n",
    "push_gain_m_per_s_n",
    "verbal_gain_m_per_s",
)
"""The :class:`NominalModel` fields eqs. 1 and 6 read, in the order of the ``params`` tuple of
:func:`euler_transition` and :func:`euler_step`."""


def _require_positive(name: str, value: Any, *, allow_zero: bool = False) -> float:
    """``value`` as a Python float if finite and positive (or zero where allowed); NumPy scalars welcome."""
    if not is_number(value) or not math.isfinite(value):
        raise ValueError(f"NominalModel.{name} must be a finite number, got {value!r}")
    if value < 0 or (value == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"NominalModel.{name} must be {bound}, got {value!r}")
    return float(python_scalar(value))


@dataclass(frozen=True)
class NominalModel:
    """Parameters of the paper's linear model, as the filter assumes them.

    Attributes:
        dt_s: Filter step [s] (the paper's measurement rate; 0.02 s = 50 Hz).
        damping_rate_per_s: ``lambda1``, damping of torso motion [1/s] (eq. 1).
        voluntary_gain_per_s2: ``k1``, pull of the torso toward the intention [1/s^2].
        push_compliance_m_per_s2_n: ``k2``, acceleration per newton of push [m/(s^2 N)].
        push_gain_m_per_s_n: ``k3``, intention change per newton of push [m/(s N)] (eq. 6).
        verbal_gain_m_per_s: ``k4``, intention change per unit verbal cue [m/s] (eq. 6).
        position_noise_std_m: Standard deviation of the shoulder measurement [m] (``R``).
        velocity_process_std_m_per_s: Per-step std of the velocity process noise [m/s].
        intention_process_std_m: Per-step std of the intention random walk [m].
        cooperativeness_process_std: Per-step std of the ``xi`` random walk (eq. 10).
        position_process_std_m: Per-step std of the position process noise [m].
        initial_velocity_std_m_per_s: Prior std of ``xdot`` at the first step [m/s].
        initial_intention_std_m: Prior std of ``eta`` at the first step [m].
        initial_cooperativeness_std: Prior std of ``xi`` at the first step.
    """

    dt_s: float = 0.02
    damping_rate_per_s: float = 6.0
    voluntary_gain_per_s2: float = 9.0
    push_compliance_m_per_s2_n: float = 0.012
    push_gain_m_per_s_n: float = 0.006
    verbal_gain_m_per_s: float = 0.12
    position_noise_std_m: float = 0.004
    # The paper filter's tuning, calibrated with coop_gym/experiment/calibrate.py so that the
    # thresholded judgment on the paper's protocol lands near the paper's Table I.
    velocity_process_std_m_per_s: float = 0.015
    intention_process_std_m: float = 0.002
    cooperativeness_process_std: float = 0.05
    position_process_std_m: float = 1e-4
    initial_velocity_std_m_per_s: float = 0.05
    initial_intention_std_m: float = 0.05
    initial_cooperativeness_std: float = 1.0

    def __post_init__(self) -> None:
        """Validate every field: finite, and positive where a scale or rate."""
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            # Gains may be zero (a person deaf to words has k4 = 0); the step may not.
            allow_zero = field.name not in ("dt_s", "position_noise_std_m")
            object.__setattr__(self, field.name, _require_positive(field.name, value, allow_zero=allow_zero))

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> NominalModel:
        """Build from a mapping, rejecting unknown keys by name."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"unknown NominalModel field(s): {', '.join(unknown)}")
        return cls(**values)

    def replace(self, **changes: Any) -> NominalModel:
        """Return a copy with some fields changed (validated again)."""
        return self.from_dict({**dataclasses.asdict(self), **changes})

    # --- the paper's matrices -------------------------------------------------

    def transition_matrix(self, push_force_n: float, verbal_cue: float) -> NDArray[np.float64]:
        """``A(c_p, c_v)`` (4, 4): the Euler-discretised eqs. 1, 6 and 10.

        Args:
            push_force_n: Measured push force ``c_p`` [N] during the step.
            verbal_cue: Verbal cue ``c_v`` in {-1, 0, +1} during the step.
        """
        a = np.eye(STATE_DIM)
        entries = euler_transition(self.euler_parameters, float(push_force_n), float(verbal_cue))
        a[0, 1], a[1, 0], a[1, 1], a[1, 2], a[2, 3], _ = entries
        return a

    @property
    def euler_parameters(self) -> tuple[float, ...]:
        """The fields of :data:`EULER_FIELDS`: the ``params`` of :func:`euler_transition` and :func:`euler_step`."""
        return tuple(getattr(self, name) for name in EULER_FIELDS)

    @property
    def input_vector(self) -> NDArray[np.float64]:
        """``B`` (4,): the push force's direct effect on velocity, ``k2*dt`` (eq. 1)."""
        return np.array([0.0, euler_transition(self.euler_parameters, 0.0, 0.0)[5], 0.0, 0.0])

    @property
    def measurement_matrix(self) -> NDArray[np.float64]:
        """``H`` (1, 4) = ``[1, 0, 0, 0]``: only the shoulder position is measured."""
        return np.array([[1.0, 0.0, 0.0, 0.0]])

    @property
    def process_covariance(self) -> NDArray[np.float64]:
        """``Q`` (4, 4): diagonal process-noise covariance per step."""
        return np.diag(
            [
                self.position_process_std_m**2,
                self.velocity_process_std_m_per_s**2,
                self.intention_process_std_m**2,
                self.cooperativeness_process_std**2,
            ]
        )

    @property
    def measurement_variance(self) -> float:
        """``R`` (scalar): variance of the shoulder-position measurement [m^2]."""
        return self.position_noise_std_m**2

    def initial_covariance(self) -> NDArray[np.float64]:
        """``P0`` (4, 4): prior covariance; the position prior is the sensor's."""
        return np.diag(
            [
                self.position_noise_std_m**2,
                self.initial_velocity_std_m_per_s**2,
                self.initial_intention_std_m**2,
                self.initial_cooperativeness_std**2,
            ]
        )

    def initial_state(self, first_position_m: float) -> NDArray[np.float64]:
        """``s0`` (4,): at rest where first seen, intending to stay, ``xi`` unknown (0)."""
        return np.array([first_position_m, 0.0, first_position_m, 0.0])


@njit(cache=True, error_model="numpy", inline="always")
def euler_transition(
    params: tuple[float, ...], push_force_n: float, verbal_cue: float
) -> tuple[float, float, float, float, float, float]:
    """The entries of ``A`` and ``B`` that differ from ``I`` and 0: eqs. 1 and 6, Euler-discretised.

    The matrix form of the nominal transition: :meth:`NominalModel.transition_matrix`, the
    paper filter's :func:`~estimator.kalman.kalman_step` and every covariance prediction read it
    from here. ``params`` = ``(dt, lambda1, k1, k2, k3, k4)``, the fields of :data:`EULER_FIELDS`
    (symbols as in :class:`NominalModel`).

    Returns:
        ``(a01, a10, a11, a12, a23, b1)``: eq. 1, ``x' = x + dt xdot`` and
        ``xdot' = xdot + dt (-lambda1 xdot + k1 (eta - x) + k2 c_p)``, gives ``a01 = dt``,
        ``a10 = -k1 dt``, ``a11 = 1 - lambda1 dt``, ``a12 = k1 dt`` and ``b1 = k2 dt``; eq. 6,
        ``eta' = eta + xi (k3 c_p + k4 c_v) dt`` (bilinear, so the cue enters ``A``), gives
        ``a23 = (k3 c_p + k4 c_v) dt``.
    """
    dt, lambda1, k1, k2, k3, k4 = params
    a01 = dt
    a10 = -k1 * dt
    a11 = 1.0 - lambda1 * dt
    a12 = k1 * dt
    a23 = (k3 * push_force_n + k4 * verbal_cue) * dt
    b1 = k2 * dt
    return a01, a10, a11, a12, a23, b1


@njit(cache=True, error_model="numpy", inline="always")
def euler_step(
    params: tuple[float, ...],
    x: Any,
    xdot: Any,
    eta: Any,
    xi: Any,
    push_force_n: Any,
    verbal_cue: Any,
) -> tuple[Any, Any, Any]:
    """One Euler step of eqs. 1 and 6 in their difference form: ``(x', xdot', eta')``.

    The same discretisation as :func:`euler_transition`, associated as the equations are
    written (``xdot + dt (...)``) rather than multiplied out of ``A``'s entries. The two round
    differently, and each keeps its recorded numbers: the paper filter's mean is ``A m + B u``
    (:func:`euler_transition`), the multiple-model filters' mode means
    (:func:`~estimator.mode_kernels.mode_mean_step`) and the nominal trials
    (:mod:`estimator.identification.nominal_trials`) are this form. Scalars or arrays of one shape (NumPy's
    element-wise operations, the same numbers); ``params`` = ``(dt, lambda1, k1, k2, k3, k4)``,
    the fields of :data:`EULER_FIELDS` (symbols as in :class:`NominalModel`).
    """
    dt, lambda1, k1, k2, k3, k4 = params
    # eq. 1: x' = x + dt xdot ; xdot' = xdot + dt (-lambda1 xdot + k1 (eta - x) + k2 c_p)
    x_next = x + dt * xdot
    xdot_next = xdot + dt * (-lambda1 * xdot + k1 * (eta - x) + k2 * push_force_n)
    # eq. 6: eta' = eta + xi (k3 c_p + k4 c_v) dt -- the only place the mode enters.
    eta_next = eta + xi * (k3 * push_force_n + k4 * verbal_cue) * dt
    return x_next, xdot_next, eta_next


guard_kernel_cache(__name__)
