"""Task settings of the environments: what counts as a safe lift, and the reward weights."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

from estimator.validate import is_number, python_scalar

__all__ = [
    "ACTION_TYPES",
    "ESTIMATORS",
    "INFO_MODES",
    "OBSERVATION_MODES",
    "LiftCriteria",
    "Outcome",
    "RewardWeights",
    "as_dataclass",
]

OBSERVATION_MODES = ("belief", "raw", "oracle")
"""``belief``: measurements + estimator output; ``raw``: measurements only; ``oracle``: belief + true xi."""

ACTION_TYPES = ("multidiscrete", "discrete", "continuous")
"""``MultiDiscrete([3, 3, 2])``, flat ``Discrete(18)`` (for DQN), or ``Box(-1, 1, (3,))``."""

ESTIMATORS = ("kalman", "multiple_model", "imm", "switching")
"""The paper's thresholded KF alone, or with a multiple-model (MMAE / IMM) estimator or the switching
particle filter of the level's person (:mod:`coop_gym.envs.switching`) beside it."""

INFO_MODES: tuple[str, ...] = ("default", "numeric")
"""``default``: the info of :func:`~coop_gym.envs.info.report_info` (labels, nested
``reward_terms``); ``numeric``: numbers only, under flat keys
(:data:`~coop_gym.envs.info.NUMERIC_INFO_KEYS`), for TensorDict-based clients (TorchRL)."""


class Outcome(IntEnum):
    """How an episode ended (``NONE`` while it runs)."""

    NONE = 0
    SUCCESS = 1
    UNSAFE = 2
    PREMATURE = 3
    TIMEOUT = 4

    @property
    def label(self) -> str:
        """Lower-case name used in ``info["outcome"]`` and reports."""
        return self.name.lower()

    @property
    def terminates(self) -> bool:
        """The robot lifted (success, unsafe or premature): Gymnasium's ``terminated``."""
        return self in (Outcome.SUCCESS, Outcome.UNSAFE, Outcome.PREMATURE)

    @property
    def truncates(self) -> bool:
        """The episode reached its length without a lift (Gymnasium's ``truncated``; ``episode_end`` sets it)."""
        return self is Outcome.TIMEOUT


def _finite(instance: Any, name: str, low: float = -math.inf, high: float = math.inf) -> None:
    """Check field ``name`` of a frozen dataclass and store it as a Python number (NumPy scalars welcome)."""
    owner, value = type(instance).__name__, getattr(instance, name)
    if not is_number(value) or not math.isfinite(value):
        raise ValueError(f"{owner}.{name} must be a finite number, got {value!r}")
    if not low <= value <= high:
        raise ValueError(f"{owner}.{name} must be in [{low}, {high}], got {value!r}")
    object.__setattr__(instance, name, python_scalar(value))


@dataclass(frozen=True)
class LiftCriteria:
    """When a lift is safe (paper §II: the centre of mass must be over the feet).

    Attributes:
        success_lean_m: Forward shoulder displacement that puts the centre of mass over
            the feet [m]; a lift with ``xi = +1`` and ``x`` at least this succeeds.
        upright_m: Below this displacement the person is still upright [m]; lifting
            then (or while ``xi = -1``) is unsafe. Other lifts are premature.
    """

    success_lean_m: float = 0.15
    upright_m: float = 0.05

    def __post_init__(self) -> None:
        """Validate ranges."""
        _finite(self, "success_lean_m", 0.0, 1.0)
        _finite(self, "upright_m", -1.0, self.success_lean_m)


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the named reward terms (each appears in ``info["reward_terms"]``).

    Attributes:
        success: Reward for a successful lift.
        unsafe: Penalty (subtracted) for lifting a resisting or upright person.
        premature: Penalty (subtracted) for any other lift before the person is ready.
        time_per_s: Cost per second that passes (subtracted).
        force_per_n_s: Cost per newton-second of push (gentleness; subtracted).
    """

    success: float = 1.0
    unsafe: float = 2.0
    premature: float = 0.5
    time_per_s: float = 0.01
    force_per_n_s: float = 0.0005

    def __post_init__(self) -> None:
        """Validate ranges: weights are finite and non-negative."""
        for field in dataclasses.fields(self):
            _finite(self, field.name, 0.0, 1e6)


def as_dataclass(cls: type[Any], value: Any, argument: str) -> Any:
    """Accept an instance of ``cls``, a mapping of its fields, or None (defaults)."""
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    if isinstance(value, dict):
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(value) - known)
        if unknown:
            raise ValueError(f"{argument}: unknown {cls.__name__} field(s) {unknown}; known: {sorted(known)}")
        return cls(**value)
    raise ValueError(f"{argument} must be a {cls.__name__}, a dict of its fields or None, got {type(value).__name__}")
