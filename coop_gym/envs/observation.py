"""What an observation holds: the features, their bounds, and their scaling to about [-1, 1]."""

from __future__ import annotations

import operator
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

__all__ = [
    "FEATURES",
    "FEATURE_BOUNDS",
    "FEATURE_SCALES",
    "OBSERVATION_SCALES",
    "PROBABILITY_FEATURES",
    "observation_features",
    "observation_scaler",
    "observation_scales",
    "observation_space_for",
    "scaled_feature_names",
    "unit_observation_space",
]


# --- observation ----------------------------------------------------------------

FEATURES: tuple[str, ...] = (
    "measured_position_m",
    "measured_force_n",
    "verbal_cue",
    "time_since_cue_onset_s",
    "x_hat_m",
    "xdot_hat_m_per_s",
    "eta_hat_m",
    "xi_hat",
    "xi_std",
    "judgment",
    "elapsed_s",
    "p_uncooperative",
    "p_unresponsive",
    "p_cooperative",
    "true_xi",
)
"""Every quantity an observation can hold; each observation mode selects some of them."""

FEATURE_BOUNDS: dict[str, tuple[float, float]] = {
    "measured_position_m": (-1.0, 1.0),
    "measured_force_n": (-20.0, 220.0),
    "verbal_cue": (-1.0, 1.0),
    "time_since_cue_onset_s": (0.0, 3600.0),
    "x_hat_m": (-2.0, 2.0),
    "xdot_hat_m_per_s": (-10.0, 10.0),
    "eta_hat_m": (-10.0, 10.0),
    "xi_hat": (-10.0, 10.0),
    "xi_std": (0.0, 10.0),
    "judgment": (-1.0, 1.0),
    "elapsed_s": (0.0, 3600.0),
    "p_uncooperative": (0.0, 1.0),
    "p_unresponsive": (0.0, 1.0),
    "p_cooperative": (0.0, 1.0),
    "true_xi": (-1.0, 1.0),
}
"""Observation bounds per feature (low, high); observations are clipped into them."""
if tuple(FEATURE_BOUNDS) != FEATURES:  # not an assert: it must hold under python -O too
    raise RuntimeError("FEATURE_BOUNDS must give the bounds of every feature of FEATURES, in order")

# Slices of FEATURES: the readings, the filter's belief and the clock; the multiple-model
# probabilities; the oracle's true xi comes last.
_BELIEF = FEATURES[: FEATURES.index("p_uncooperative")]
PROBABILITY_FEATURES: tuple[str, ...] = FEATURES[FEATURES.index("p_uncooperative") : FEATURES.index("true_xi")]
_RAW = ("measured_position_m", "measured_force_n", "verbal_cue", "time_since_cue_onset_s", "elapsed_s")
_CLOCKS = ("time_since_cue_onset_s", "elapsed_s")  # bounded by the episode length


def observation_features(observation_mode: str, estimator: str) -> tuple[str, ...]:
    """The features (names from :data:`FEATURES`) an observation holds, in order."""
    if observation_mode == "raw":
        return _RAW
    names = _BELIEF + (PROBABILITY_FEATURES if estimator != "kalman" else ())
    return (*names, "true_xi") if observation_mode == "oracle" else names


def observation_space_for(features: Sequence[str], episode_s: float) -> spaces.Box:
    """A float32 Box over ``features`` with the bounds of :data:`FEATURE_BOUNDS`."""
    low = np.array([FEATURE_BOUNDS[f][0] for f in features], dtype=np.float32)
    high = np.array([FEATURE_BOUNDS[f][1] if f not in _CLOCKS else episode_s for f in features], dtype=np.float32)
    return spaces.Box(low, high, dtype=np.float32)


# --- unit scaling: every feature about [-1, 1] for a policy network with default settings --

OBSERVATION_SCALES: tuple[str, ...] = ("none", "unit")
"""``none``: features in their units (clipped into :data:`FEATURE_BOUNDS`); ``unit``: each
divided by its :data:`FEATURE_SCALES` entry and clipped into [-1, 1]."""

FEATURE_SCALES: dict[str, float | None] = {
    "measured_position_m": 0.5,
    "measured_force_n": 40.0,
    "verbal_cue": 1.0,
    "time_since_cue_onset_s": None,
    "x_hat_m": 0.5,
    "xdot_hat_m_per_s": 0.5,
    "eta_hat_m": 0.5,
    "xi_hat": 2.0,
    "xi_std": 1.25,
    "judgment": 1.0,
    "elapsed_s": None,
    "p_uncooperative": 1.0,
    "p_unresponsive": 1.0,
    "p_cooperative": 1.0,
    "true_xi": 1.0,
}
"""What each feature is divided by under ``observation_scale="unit"``, in its units (None: the
episode length, ``timing.episode_s``).

Not the bounds of :data:`FEATURE_BOUNDS`: those are loose clip limits (x_hat +-2 m, xi_hat +-10)
and dividing by them would squeeze the values a policy must tell apart into +-0.05. A scale is
the range the feature really spans, read from 96,000 steps of random cues on the paper model, the
hard level and the IMM estimator: shoulder and intended position reach 0.5 m (0.48 m at the 99.9th
percentile), speed 0.5 m/s (0.25 m/s), the push reading 32 N (firm push 30 N plus noise), xi_hat
+-3 (+-1.8), its standard deviation 1.05 (its prior). Values beyond a scale saturate at +-1: a
lean past 0.5 m or an estimate past +-2 means the same to a policy as one at it.
"""
if tuple(FEATURE_SCALES) != FEATURES:  # not an assert: it must hold under python -O too
    raise RuntimeError("FEATURE_SCALES must give the scale of every feature of FEATURES, in order")


def observation_scales(features: Sequence[str], episode_s: float) -> NDArray[np.float32]:
    """The divisor of each of ``features`` under ``observation_scale="unit"`` (:data:`FEATURE_SCALES`)."""
    return np.array([FEATURE_SCALES[f] or episode_s for f in features], dtype=np.float32)


def unit_observation_space(features: Sequence[str], episode_s: float) -> spaces.Box:
    """The Box of the unit-scaled observation: the physical bounds over the scales, cut to [-1, 1].

    Every feature's range is [-1, 1] or [0, 1], except ``measured_force_n``'s [-0.5, 1]
    (its physical low is -20 N, the scale 40 N).
    """
    physical = observation_space_for(features, episode_s)
    scales = observation_scales(features, episode_s)
    low = np.maximum(physical.low / scales, np.float32(-1.0))
    high = np.minimum(physical.high / scales, np.float32(1.0))
    return spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)


def scaled_feature_names(features: Sequence[str], episode_s: float) -> tuple[str, ...]:
    """Names of the unit-scaled features: ``"x_hat_m/0.5"`` is ``x_hat_m`` over 0.5 m.

    A feature with scale 1 keeps its name. The names differ from the physical ones on
    purpose: an agent that reads features by name in their units (the scripted caregivers
    read ``x_hat_m`` in metres) refuses a unit-scaled env instead of misreading it.
    """
    scales = observation_scales(features, episode_s)
    return tuple(f if s == 1.0 else f"{f}/{float(s):g}" for f, s in zip(features, scales, strict=True))


def observation_scaler(
    features: Sequence[str], episode_s: float, observation_scale: str
) -> Callable[[NDArray[np.float32]], NDArray[np.float32]]:
    """The env's observation from the core's physical observation rows (one row or a batch).

    Returns:
        A function that gives a fresh array (Gymnasium 1.4's checker refuses returns that
        share memory): a copy under ``"none"``; under ``"unit"``, ``physical / scale``
        clipped into :func:`unit_observation_space` (float32 arithmetic).
    """
    if observation_scale == "none":
        return operator.methodcaller("copy")
    space = unit_observation_space(features, episode_s)
    return _UnitScaler(
        observation_scales(features, episode_s), space.low.astype(np.float32), space.high.astype(np.float32)
    )


@dataclass(frozen=True)
class _UnitScaler:
    """``clip(physical / scales, low, high)`` in float32 (a class, not a closure: envs pickle)."""

    scales: NDArray[np.float32]
    low: NDArray[np.float32]
    high: NDArray[np.float32]

    def __call__(self, physical: NDArray[np.float32]) -> NDArray[np.float32]:
        """The unit observation of physical observation rows, a fresh array."""
        observation = np.divide(physical, self.scales)
        return np.clip(observation, self.low, self.high, out=observation)  # type: ignore[no-any-return]
