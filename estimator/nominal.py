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
from numpy.typing import NDArray

from compiled.checks import is_number, python_scalar

__all__ = ["STATE_DIM", "NominalModel"]

STATE_DIM = 4
"""Length of the paper filter's state ``[x, xdot, eta, xi]``."""


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
    # The paper filter's tuning, calibrated with experiment/calibrate.py so that the
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
        dt = self.dt_s
        a = np.eye(STATE_DIM)
        # eq. 1: x' = x + dt*xdot ; xdot' = xdot + dt*(-lambda1*xdot + k1*(eta - x)) (+ B*c_p)
        a[0, 1] = dt
        a[1, 0] = -self.voluntary_gain_per_s2 * dt
        a[1, 1] = 1.0 - self.damping_rate_per_s * dt
        a[1, 2] = self.voluntary_gain_per_s2 * dt
        # eq. 6: eta' = eta + xi*(k3*c_p + k4*c_v)*dt -- bilinear, so the cue enters A.
        a[2, 3] = (self.push_gain_m_per_s_n * push_force_n + self.verbal_gain_m_per_s * verbal_cue) * dt
        return a

    @property
    def input_vector(self) -> NDArray[np.float64]:
        """``B`` (4,): the push force's direct effect on velocity, ``k2*dt`` (eq. 1)."""
        return np.array([0.0, self.push_compliance_m_per_s2_n * self.dt_s, 0.0, 0.0])

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
