"""The env contract: what goes into a coop_gym env and what comes out, written once.

The single env (:mod:`coop_gym.envs.sit_to_stand`), the vector env
(:mod:`coop_gym.envs.vector`), the registration, the SB3 adapter (:mod:`agents.sb3_vec`)
and the agents (:mod:`agents.base`) all call this module:

* the env's keyword arguments: :class:`EnvArguments` (names, defaults, accepted types);
  :meth:`EnvArguments.resolve` validates them into a :class:`SitToStandConfig`;
* actions both ways: :func:`action_space_for`, :func:`decode_actions` (action ->
  ``push_force_n, verbal_cue, lift``), :class:`ActionDecoder` (the envs' fast paths into
  command rows, :data:`CMD`) and :func:`encode_actions` (component choices -> action);
* the observation: :data:`FEATURES`, :data:`FEATURE_BOUNDS`, :func:`observation_features`,
  :func:`observation_space_for`; the unit scaling (:data:`OBSERVATION_SCALES`,
  :data:`FEATURE_SCALES`, :func:`observation_scales`, :func:`unit_observation_space`,
  :func:`observation_scaler`);
* the report row the kernel writes (:data:`REPORT_COLUMNS`), the episode end
  (:data:`EPISODE_END`, :func:`episode_ends`, from :class:`~coop_gym.envs.config.Outcome`)
  and the info built from it (:func:`report_info`, :func:`batched_infos`; :class:`InfoBuilder`
  for every :data:`INFO_MODES` and observation scale);
* the reset options (:func:`parse_reset_options`).
"""

from __future__ import annotations

import dataclasses
import math
import operator
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

import numpy as np
from gymnasium import spaces
from numba import njit
from numpy.typing import NDArray

from compiled.cache import guard_kernel_cache
from compiled.checks import check_choice
from compiled.schema import index_table
from coop_gym.envs.config import (
    ACTION_TYPES,
    ESTIMATORS,
    OBSERVATION_MODES,
    LiftCriteria,
    Outcome,
    RewardWeights,
    as_dataclass,
)
from coop_gym.model.difficulty import Difficulty, get_difficulty
from coop_gym.model.params import Cues, Realism, Timing
from coop_gym.model.personas import Persona, resolve_personas
from estimator.judgment import ThresholdJudgment

__all__ = [
    "ACTION_SHAPE",
    "CMD",
    "CMD_COLUMNS",
    "EPISODE_END",
    "FEATURES",
    "FEATURE_BOUNDS",
    "FEATURE_SCALES",
    "INFO_MODES",
    "LIFT",
    "NUMERIC_INFO_KEYS",
    "N_FLAT_ACTIONS",
    "OBSERVATION_SCALES",
    "PUSH_FIRM",
    "PUSH_NONE",
    "PUSH_SOFT",
    "REPORT",
    "REPORT_COLUMNS",
    "REWARD_TERMS",
    "TERMINATES",
    "TRUNCATES",
    "VERBAL_BACK",
    "VERBAL_FORWARD",
    "VERBAL_NONE",
    "WAIT",
    "ActionDecoder",
    "EnvArguments",
    "InfoBuilder",
    "SitToStandConfig",
    "action_space_for",
    "batched_infos",
    "check_outcome_codes",
    "command_table",
    "decode_actions",
    "encode_actions",
    "episode_ends",
    "observation_features",
    "observation_scaler",
    "observation_scales",
    "observation_space_for",
    "parse_reset_options",
    "report_info",
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
_PROBABILITIES = FEATURES[FEATURES.index("p_uncooperative") : FEATURES.index("true_xi")]
_RAW = ("measured_position_m", "measured_force_n", "verbal_cue", "time_since_cue_onset_s", "elapsed_s")
_CLOCKS = ("time_since_cue_onset_s", "elapsed_s")  # bounded by the episode length


def observation_features(observation_mode: str, estimator: str) -> tuple[str, ...]:
    """The features (names from :data:`FEATURES`) an observation holds, in order."""
    if observation_mode == "raw":
        return _RAW
    names = _BELIEF + (_PROBABILITIES if estimator != "kalman" else ())
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


# --- the report row: everything an observation and an info need ------------------

REWARD_TERMS: tuple[str, ...] = ("success", "unsafe", "premature", "time", "force")
"""Names of the reward terms (``info["reward_terms"]``), in report-column order."""

REPORT_COLUMNS: tuple[str, ...] = (
    *FEATURES,
    *(f"reward_{name}" for name in REWARD_TERMS),
    "reward",
    "outcome",
    "push_force_n",
    "true_x_m",
    "true_xdot_m_per_s",
    "true_eta_m",
    "info_true_xi",  # the info's true xi; the oracle's feature "true_xi" is its own column
    "persona_index",
)
"""Columns of ``SitToStandCore.report``: one float row per env with everything ``info`` needs.

Kept in one row so an env reads it with a single ``tolist()``.
"""
REPORT = index_table("ReportColumns", REPORT_COLUMNS)
"""Column of each quantity in a report row: ``report[REPORT.x_hat_m]``, ``report[REPORT.outcome]``."""

# --- episode end ------------------------------------------------------------------


def check_outcome_codes(outcome: type[IntEnum]) -> None:
    """Raise ``ValueError`` unless the enum's values are ``0 .. n-1`` in order.

    The kernel writes outcome codes into a float report column and the envs index tables
    (labels, episode end) with them, so they must be small consecutive integers. An
    explicit check, not an ``assert``: it must hold under ``python -O`` too.
    """
    codes = [int(member) for member in outcome]
    if codes != list(range(len(codes))):
        raise ValueError(f"{outcome.__name__} values must be 0 .. {len(codes) - 1} in order, got {codes}")


check_outcome_codes(Outcome)

EPISODE_END: tuple[tuple[bool, bool], ...] = tuple((o.terminates, o.truncates) for o in Outcome)
"""``(terminated, truncated)`` of each outcome code (the single env's step looks it up)."""
TERMINATES = np.array([o.terminates for o in Outcome])
"""Indexed by outcome code: does the episode terminate (the robot lifted)?"""
TRUNCATES = np.array([o.truncates for o in Outcome])
"""Indexed by outcome code: does the episode clock truncate it?"""


def episode_ends(
    outcome: NDArray[np.float64], stepped: NDArray[np.bool_], out_of_steps: NDArray[np.bool_]
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """``(terminated, truncated)`` of a batch of envs, the rule of :data:`EPISODE_END`.

    Args:
        outcome: (N,) outcome codes (the report's ``outcome`` column).
        stepped: (N,) which envs were stepped (others neither terminate nor truncate).
        out_of_steps: (N,) envs at a step limit of their own (the vector env's
            ``max_episode_steps``); they truncate, also when the step terminated them: a
            lift on the last allowed step is ``terminated`` and ``truncated``, exactly as
            Gymnasium's ``TimeLimit`` reports it for the single env.
    """
    codes = outcome.astype(np.int64)
    terminated = stepped & TERMINATES[codes]
    truncated = stepped & (out_of_steps | TRUNCATES[codes])
    return terminated, truncated


@njit(cache=True, error_model="numpy")
def count_steps_and_end_episodes(
    report: NDArray[np.float64],
    cmd: NDArray[np.float64],
    episode_steps: NDArray[np.int64],
    max_episode_steps: int,
    rewards: NDArray[np.float64],
    terminated: NDArray[np.bool_],
    truncated: NDArray[np.bool_],
) -> None:
    """The vector env's bookkeeping after a step, in one pass: :func:`episode_ends` and the step count.

    Each env stepped (``cmd`` active) counts a step in ``episode_steps`` and is out of steps at
    ``max_episode_steps``; ``rewards`` gets the report's reward of stepped envs, 0 elsewhere.
    """
    for i in range(report.shape[0]):
        if cmd[i, CMD.active] > 0.5:
            episode_steps[i] += 1
            code = int(report[i, REPORT.outcome])
            rewards[i] = report[i, REPORT.reward]
            terminated[i] = TERMINATES[code]
            truncated[i] = episode_steps[i] >= max_episode_steps or TRUNCATES[code]
        else:
            rewards[i] = 0.0
            terminated[i] = False
            truncated[i] = False


# --- actions ----------------------------------------------------------------------

ACTION_SHAPE = (3, 3, 2)
"""Choices per component of the MultiDiscrete action: push, verbal cue, lift."""
N_FLAT_ACTIONS = math.prod(ACTION_SHAPE)
"""Size of the flat ``Discrete`` action space: 3 pushes x 3 verbal cues x 2 lift choices."""

# Component values of the default MultiDiscrete([3, 3, 2]) action (docs/ARCHITECTURE.md).
PUSH_NONE, PUSH_SOFT, PUSH_FIRM = 0, 1, 2
VERBAL_NONE, VERBAL_BACK, VERBAL_FORWARD = 0, 1, 2
WAIT, LIFT = 0, 1
_VERBAL_FROM_INDEX = np.array([0.0, -1.0, 1.0])  # none, lean back, lean forward

CMD_COLUMNS: tuple[str, ...] = ("push_force_n", "verbal_cue", "lift", "active")
"""Columns of a decoded action, the core's command row: push [N], verbal request {-1, 0, 1},
lift {0, 1}, active {0, 1} (an inactive env is not stepped)."""
CMD = index_table("CommandColumns", CMD_COLUMNS)


def action_space_for(action_type: str) -> spaces.Space[Any]:
    """The action space of an action type (see :data:`~coop_gym.envs.config.ACTION_TYPES`)."""
    if action_type == "multidiscrete":
        return spaces.MultiDiscrete(list(ACTION_SHAPE))
    if action_type == "discrete":
        return spaces.Discrete(N_FLAT_ACTIONS)
    return spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)


def decode_actions(
    actions: Any, action_type: str, cues: Cues, n_envs: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Validate a batch of ``n_envs`` actions and turn them into cues.

    Returns:
        ``(push_force_n, verbal_cue, lift)``, each of shape (n_envs,).

    Raises:
        ValueError: naming what is wrong (shape, bool, NaN, non-integer, out of range).
    """
    try:
        a = np.asarray(actions)
    except Exception as exc:  # e.g. ragged lists
        raise ValueError(f"action could not be read as an array: {exc}") from None
    if a.dtype == object or a.dtype.kind not in "biuf":
        raise ValueError(f"action must be numeric, got dtype {a.dtype}")
    if a.dtype.kind == "b":
        # True is not the action 1: a bool is a mistake (a flag passed for an action).
        raise ValueError(f"{action_type} action must be numbers, not bools, got {actions!r}")
    expected = (n_envs,) if action_type == "discrete" else (n_envs, 3)
    if a.shape != expected:
        raise ValueError(
            f"action has shape {a.shape}; the {action_type} action space needs {expected[1:] or '()'}"
            + (f" per env, {expected} for {n_envs} envs" if n_envs > 1 else "")
        )
    a = a.astype(np.float64)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"action contains NaN or inf: {actions!r}")
    soft, firm = cues.soft_push_n, cues.firm_push_n
    if action_type == "continuous":
        if np.any(a < -1.0 - 1e-6) or np.any(a > 1.0 + 1e-6):
            raise ValueError(f"continuous action must lie in [-1, 1], got {actions!r}")
        push = (np.clip(a[:, 0], -1.0, 1.0) + 1.0) * 0.5 * firm
        verbal = np.where(a[:, 1] < -1.0 / 3.0, -1.0, np.where(a[:, 1] > 1.0 / 3.0, 1.0, 0.0))
        return push, verbal, a[:, 2] > 0.0
    if np.any(a != np.round(a)):
        raise ValueError(f"{action_type} action must be integers, got {actions!r}")
    # Range checked on the floats, before the int cast (1e300 would overflow it).
    if action_type == "discrete":
        if np.any(a < 0) or np.any(a >= N_FLAT_ACTIONS):
            raise ValueError(f"discrete action must be in [0, {N_FLAT_ACTIONS - 1}], got {actions!r}")
        idx = np.stack(np.unravel_index(a.astype(np.int64), ACTION_SHAPE), axis=1)
    elif np.any(a < 0) or np.any(a >= np.array(ACTION_SHAPE)):
        raise ValueError(
            f"multidiscrete action must be [push 0..2, verbal 0..2, lift 0..1], got {np.asarray(actions).tolist()!r}"
        )
    else:
        idx = a.astype(np.int64)
    push = np.array([0.0, soft, firm])[idx[:, 0]]
    return push, _VERBAL_FROM_INDEX[idx[:, 1]], idx[:, 2] == LIFT


def command_table(cues: Cues) -> NDArray[np.float64]:
    """(18, 1, 4) command rows (:data:`CMD`) of each flat discrete action, ``active = 1``."""
    push, verbal, lift = decode_actions(np.arange(N_FLAT_ACTIONS), "discrete", cues, N_FLAT_ACTIONS)
    table = np.stack([push, verbal, lift.astype(np.float64), np.ones(N_FLAT_ACTIONS)], axis=1)
    return np.ascontiguousarray(table[:, None, :])


@njit(cache=True, error_model="numpy")
def _decode_multidiscrete(actions: NDArray[np.int64], flat: NDArray[np.float64], cmd: NDArray[np.float64]) -> bool:
    # cmd[i, :3] = flat[ravel_multi_index(actions[i], ACTION_SHAPE)] for every row, or False (and
    # nothing written) when any component is out of range.
    for i in range(actions.shape[0]):
        push, verbal, lift = actions[i, 0], actions[i, 1], actions[i, 2]
        if not (0 <= push < ACTION_SHAPE[0] and 0 <= verbal < ACTION_SHAPE[1] and 0 <= lift < ACTION_SHAPE[2]):
            return False
    for i in range(actions.shape[0]):
        k = (actions[i, 0] * ACTION_SHAPE[1] + actions[i, 1]) * ACTION_SHAPE[2] + actions[i, 2]
        for j in range(CMD.active):
            cmd[i, j] = flat[k, j]
    return True


class ActionDecoder:
    """Actions of one action type -> the core's command rows, for the envs' hot paths.

    The common cases (what ``action_space.sample()`` and SB3's ``predict`` give) take a
    table look-up or plain Python; anything else goes through :func:`decode_actions`,
    which accepts the same actions and names what is wrong.

    Args:
        action_type: One of :data:`~coop_gym.envs.config.ACTION_TYPES`.
        cues: The push forces.
    """

    def __init__(self, action_type: str, cues: Cues) -> None:
        """Build the command table of the flat actions."""
        self.action_type = action_type
        self.cues = cues
        self._table = command_table(cues)
        self._flat = self._table[:, 0, : CMD.active].copy()  # [push, verbal, lift] of each flat action
        self._firm_push_n = float(cues.firm_push_n)

    def single(self, action: Any, cmd: NDArray[np.float64]) -> NDArray[np.float64]:
        """The (1, 4) command of one env's action: a row of the table, or ``cmd`` filled in."""
        kind = self.action_type
        if kind == "multidiscrete":
            if type(action) is np.ndarray and action.shape == (3,) and action.dtype.kind in "iu":
                push, verbal, lift = action.tolist()
                if 0 <= push <= 2 and 0 <= verbal <= 2 and 0 <= lift <= 1:
                    return self._table[(push * 3 + verbal) * 2 + lift]  # type: ignore[no-any-return]
        elif kind == "discrete":
            if isinstance(action, (int, np.integer)) and not isinstance(action, bool) and 0 <= action < N_FLAT_ACTIONS:
                return self._table[int(action)]  # type: ignore[no-any-return]
        elif type(action) is np.ndarray and action.shape == (3,) and action.dtype.kind == "f":
            a_push, a_verbal, a_lift = action.tolist()
            if all(math.isfinite(a) and -1.0 - 1e-6 <= a <= 1.0 + 1e-6 for a in (a_push, a_verbal, a_lift)):
                row = cmd[0]
                # As decode_actions: push (a0 + 1) / 2 * firm, verbal in thirds, lift when a2 > 0.
                row[CMD.push_force_n] = (min(max(a_push, -1.0), 1.0) + 1.0) * 0.5 * self._firm_push_n
                row[CMD.verbal_cue] = -1.0 if a_verbal < -1.0 / 3.0 else (1.0 if a_verbal > 1.0 / 3.0 else 0.0)
                row[CMD.lift] = 1.0 if a_lift > 0.0 else 0.0
                return cmd
        # A list, not np.asarray(action)[None]: decode_actions names what is wrong with a ragged one.
        push_n, verbal_cue, lift_flag = decode_actions([action], kind, self.cues, 1)
        cmd[0, CMD.push_force_n] = push_n[0]
        cmd[0, CMD.verbal_cue] = verbal_cue[0]
        cmd[0, CMD.lift] = 1.0 if lift_flag[0] else 0.0
        return cmd

    def batch(self, actions: Any, cmd: NDArray[np.float64]) -> None:
        """Write the commands of a batch of ``len(cmd)`` actions into ``cmd`` (its ``active`` column untouched)."""
        n = cmd.shape[0]
        kind = self.action_type
        a = actions
        if type(a) is np.ndarray and a.dtype.kind in "iu" and kind != "continuous":
            try:
                if kind == "multidiscrete" and a.shape == (n, 3):
                    # One compiled call checks every range and looks the rows up (int64: one
                    # compiled version; a uint64 too large wraps negative and is refused).
                    if _decode_multidiscrete(a.astype(np.int64, copy=False), self._flat, cmd):
                        return
                if kind == "discrete" and a.shape == (n,):
                    cmd[:, : CMD.active] = self._flat[np.ravel_multi_index((a,), (N_FLAT_ACTIONS,))]
                    return
            except (ValueError, TypeError):
                pass  # out of range or an unusual integer type: decode_actions decides and names the problem
        push, verbal, lift = decode_actions(actions, kind, self.cues, n)
        cmd[:, CMD.push_force_n] = push
        cmd[:, CMD.verbal_cue] = verbal
        cmd[:, CMD.lift] = lift


def encode_actions(
    push: NDArray[np.integer[Any]],
    verbal: NDArray[np.integer[Any]],
    lift: NDArray[np.integer[Any]],
    action_type: str,
    cues: Cues | None = None,
) -> NDArray[Any]:
    """Turn per-env component choices into actions of ``action_type`` (the inverse of :func:`decode_actions`).

    Args:
        push: (N,) push level 0 none, 1 soft, 2 firm.
        verbal: (N,) verbal cue 0 none, 1 "lean back", 2 "lean forward".
        lift: (N,) 0 wait, 1 lift.
        action_type: ``"multidiscrete"`` -> (N, 3) int64; ``"discrete"`` -> (N,) int64
            flat index; ``"continuous"`` -> (N, 3) float32 in [-1, 1].
        cues: Push forces of the continuous variant (default :class:`Cues`).

    Returns:
        The batch of actions.
    """
    push = np.asarray(push, dtype=np.int64)
    verbal = np.asarray(verbal, dtype=np.int64)
    lift = np.asarray(lift, dtype=np.int64)
    if action_type == "multidiscrete":
        return np.stack([push, verbal, lift], axis=-1)
    if action_type == "discrete":
        return np.asarray(np.ravel_multi_index((push, verbal, lift), ACTION_SHAPE), dtype=np.int64)
    if action_type == "continuous":
        cues = cues or Cues()
        # Inverse of decode_actions' push = (a0 + 1) / 2 * firm_push_n.
        force = np.array([0.0, cues.soft_push_n, cues.firm_push_n])[push]
        a0 = 2.0 * force / cues.firm_push_n - 1.0
        a1 = _VERBAL_FROM_INDEX[verbal]
        a2 = np.where(lift == LIFT, 1.0, -1.0)
        return np.clip(np.stack([a0, a1, a2], axis=-1), -1.0, 1.0).astype(np.float32)
    raise ValueError(f"action_type must be one of {list(ACTION_TYPES)}, got {action_type!r}")


# --- info -------------------------------------------------------------------------

_OUTCOME_LABELS: tuple[str, ...] = tuple(o.label for o in Outcome)
_OUTCOME_LABEL_ARRAY = np.array(_OUTCOME_LABELS, dtype=object)

# report_info unpacks report rows by position: fail at import if the layout moved (an explicit
# check, not an assert: it must hold under python -O too).
_REPORT_LAYOUT = (
    *FEATURES,
    *("reward_success", "reward_unsafe", "reward_premature", "reward_time", "reward_force", "reward", "outcome"),
    *("push_force_n", "true_x_m", "true_xdot_m_per_s", "true_eta_m", "info_true_xi", "persona_index"),
)


def _check_report_layout() -> None:
    if REPORT_COLUMNS != _REPORT_LAYOUT:
        raise RuntimeError("REPORT_COLUMNS changed: update report_info")


_check_report_layout()


def report_info(r: list[float], persona_names: Sequence[str], probabilities: bool) -> dict[str, Any]:
    """The single env's ``info`` dict from one row of ``SitToStandCore.report`` (as a list).

    Args:
        r: ``core.report[i].tolist()`` (one ``tolist()`` reads every value at once).
        persona_names: Names of the env's personas, by index.
        probabilities: Add ``xi_probabilities`` (a multiple-model estimator runs).
    """
    # Unpacked by position (checked against REPORT_COLUMNS at import): one bytecode
    # instead of ~25 indexed look-ups on the hot path.
    (
        _pos,
        _force,
        verbal,
        _since,
        _x_hat,
        _xdot_hat,
        _eta_hat,
        xi_hat,
        _xi_std,
        judgment,
        elapsed,
        p_uncoop,
        p_unresp,
        p_coop,
        _true_xi_feature,
        success,
        unsafe,
        premature,
        time_term,
        force_term,
        _reward,
        outcome,
        push,
        true_x,
        true_xdot,
        true_eta,
        true_xi,
        persona,
    ) = r
    info: dict[str, Any] = {
        "true_x_m": true_x,
        "true_xdot_m_per_s": true_xdot,
        "true_eta_m": true_eta,
        "true_xi": int(true_xi),
        "persona": persona_names[int(persona)],
        "outcome": _OUTCOME_LABELS[int(outcome)],
        "judgment": int(judgment),
        "xi_estimate": xi_hat,
        "push_force_n": push,
        "verbal_cue": int(verbal),
        "elapsed_s": elapsed,
    }
    if probabilities:
        info["xi_probabilities"] = np.array([p_uncoop, p_unresp, p_coop])
    info["reward_terms"] = {
        "success": success,
        "unsafe": unsafe,
        "premature": premature,
        "time": time_term,
        "force": force_term,
    }
    return info


# The vector info's keys in order: (key, report column, as int) or a derived entry (None); report_info
# gives the same keys (bar persona_index and outcome_code), one row at a time.
_INFO_COLUMNS: tuple[tuple[str, int | None, bool], ...] = (
    ("true_x_m", REPORT.true_x_m, False),
    ("true_xdot_m_per_s", REPORT.true_xdot_m_per_s, False),
    ("true_eta_m", REPORT.true_eta_m, False),
    ("true_xi", REPORT.info_true_xi, True),
    ("persona", None, False),
    ("persona_index", None, False),
    ("outcome", None, False),
    ("outcome_code", None, False),
    ("judgment", REPORT.judgment, True),
    ("xi_estimate", REPORT.xi_hat, False),
    ("push_force_n", REPORT.push_force_n, False),
    ("verbal_cue", REPORT.verbal_cue, True),
    ("elapsed_s", REPORT.elapsed_s, False),
)


def batched_infos(
    report: NDArray[np.float64],
    mask: NDArray[np.bool_] | None,
    persona_names: NDArray[Any],
    probabilities: bool,
) -> dict[str, Any]:
    """The vector env's infos (a dict of arrays with ``_key`` masks, Gymnasium style) from report rows.

    The single env's keys (:func:`report_info`) plus ``persona_index`` and ``outcome_code``
    (:class:`~coop_gym.envs.config.Outcome` ints). Entries of envs outside ``mask`` (default
    all) are zero (``None`` for labels), as Gymnasium's ``_add_info`` leaves them.
    """
    n = report.shape[0]
    r = report
    outcome = r[:, REPORT.outcome].astype(np.int64)
    persona = r[:, REPORT.persona_index].astype(np.int64)
    derived = {"persona": persona_names[persona], "persona_index": persona}
    derived |= {"outcome": _OUTCOME_LABEL_ARRAY[outcome], "outcome_code": outcome}
    values: dict[str, NDArray[Any]] = {
        key: derived[key] if column is None else (r[:, column].astype(np.int64) if as_int else r[:, column].copy())
        for key, column, as_int in _INFO_COLUMNS
    }
    if probabilities:
        values["xi_probabilities"] = r[:, REPORT.p_uncooperative : REPORT.p_cooperative + 1].copy()
    terms = {name: r[:, REPORT.reward_success + k].copy() for k, name in enumerate(REWARD_TERMS)}
    if mask is None:
        mask = np.ones(n, dtype=bool)
    elif not mask.all():
        outside = ~mask
        for array in (*values.values(), *terms.values()):
            array[outside] = None if array.dtype == object else 0
    infos: dict[str, Any] = {}
    for key, array in values.items():
        infos[key] = array
        infos[f"_{key}"] = mask.copy()
    reward_terms: dict[str, Any] = {}
    for key, array in terms.items():
        reward_terms[key] = array
        reward_terms[f"_{key}"] = mask.copy()
    infos["reward_terms"] = reward_terms
    infos["_reward_terms"] = mask.copy()
    return infos


INFO_MODES: tuple[str, ...] = ("default", "numeric")
"""``default``: the info of :func:`report_info` (labels, nested ``reward_terms``); ``numeric``:
numbers only, under flat keys (:data:`NUMERIC_INFO_KEYS`), for TensorDict-based clients (TorchRL)."""

# (key, report column, as int): the numeric info, one entry per key, scalars in the single env.
_NUMERIC_INFO: tuple[tuple[str, int, bool], ...] = (
    ("true_x_m", REPORT.true_x_m, False),
    ("true_xdot_m_per_s", REPORT.true_xdot_m_per_s, False),
    ("true_eta_m", REPORT.true_eta_m, False),
    ("true_xi", REPORT.info_true_xi, True),
    ("persona_index", REPORT.persona_index, True),
    ("outcome_code", REPORT.outcome, True),
    ("judgment", REPORT.judgment, True),
    ("xi_estimate", REPORT.xi_hat, False),
    ("push_force_n", REPORT.push_force_n, False),
    ("verbal_cue", REPORT.verbal_cue, True),
    ("elapsed_s", REPORT.elapsed_s, False),
    *((f"reward_{name}", REPORT.reward_success + k, False) for k, name in enumerate(REWARD_TERMS)),
)
_NUMERIC_PROBABILITIES: tuple[tuple[str, int, bool], ...] = tuple(
    (name, REPORT.p_uncooperative + k, False) for k, name in enumerate(_PROBABILITIES)
)
if [column for _, column, _ in _NUMERIC_PROBABILITIES] != [REPORT.p_uncooperative, REPORT.p_unresponsive,
                                                           REPORT.p_cooperative]:  # fmt: skip
    raise RuntimeError("the multiple-model probabilities must be consecutive report columns")

NUMERIC_INFO_KEYS: tuple[str, ...] = tuple(key for key, _, _ in _NUMERIC_INFO)
"""Keys of every ``info_mode="numeric"`` info, in order: the default info's numbers with the
persona as ``persona_index`` (into the env's ``personas``), the outcome as ``outcome_code`` (an
:class:`~coop_gym.envs.config.Outcome` value) and the reward terms as ``reward_<term>``. A
multiple-model estimator adds ``p_uncooperative``, ``p_unresponsive``, ``p_cooperative`` (the
default info's ``xi_probabilities``); ``observation_scale="unit"`` adds ``unscaled_obs``."""


@njit(cache=True, error_model="numpy")
def _gather_info_columns(
    report: NDArray[np.float64],
    float_columns: NDArray[np.int64],
    floats: NDArray[np.float64],
    int_columns: NDArray[np.int64],
    ints: NDArray[np.int64],
) -> None:
    # floats[k, i] = report[i, float_columns[k]] and ints[k, i] = int(report[i, int_columns[k]])
    # (truncation, as astype(np.int64)), in one call. Column by column: filling the blocks row by
    # row writes to addresses 8 KiB apart (4K aliasing with the loads), 3x slower.
    for k in range(float_columns.shape[0]):
        column = float_columns[k]
        for i in range(report.shape[0]):
            floats[k, i] = report[i, column]
    for k in range(int_columns.shape[0]):
        column = int_columns[k]
        for i in range(report.shape[0]):
            ints[k, i] = int(report[i, column])


class InfoBuilder:
    """The info of an env of ``config``, single (:meth:`single`) or batched (:meth:`batched`), from report rows.

    ``info_mode="default"`` gives :func:`report_info` / :func:`batched_infos`;
    ``"numeric"`` gives :data:`NUMERIC_INFO_KEYS` (NumPy int64 and float64 scalars in the single
    env, arrays of them with Gymnasium's ``_key`` masks in the vector env). Under
    ``observation_scale="unit"`` either adds ``unscaled_obs``: the observation in its units,
    float32, as the ``"none"`` scale gives it (the unit observation is it over the scales, clipped).

    Args:
        config: The env's settings.
    """

    def __init__(self, config: SitToStandConfig) -> None:
        """Tables of the info's keys and of the physical observation's columns and bounds."""
        self.persona_names = tuple(p.name for p in config.personas)
        self._persona_array = np.array(self.persona_names, dtype=object)
        self.probabilities = config.estimator != "kalman"
        self.numeric = config.info_mode == "numeric"
        self.unscaled = config.observation_scale == "unit"
        self._entries = _NUMERIC_INFO + (_NUMERIC_PROBABILITIES if self.probabilities else ())
        # The physical observation rebuilt from a report row exactly as the kernel builds it:
        # the features clipped in float64, then rounded to float32.
        features = config.physical_features
        self._obs_columns = np.array([REPORT_COLUMNS.index(f) for f in features], dtype=np.int64)
        physical = observation_space_for(features, config.timing.episode_s)
        self._obs_low = physical.low.astype(np.float64)
        self._obs_high = physical.high.astype(np.float64)
        self._plan_all_envs()

    def _plan_all_envs(self) -> None:
        """Where each key of an all-envs info comes from: a row of the float or the int block the kernel fills.

        ``_top``: (key, source, block row) in the info's key order, source ``"f"`` / ``"i"`` (that block),
        ``"persona"`` / ``"outcome"`` (the label of the int block's row); ``_terms``: the reward terms'.
        """
        float_columns: list[int] = []
        int_columns: list[int] = []

        def slot(column: int, as_int: bool) -> tuple[str, int]:
            # A row of its own per key: no two info arrays share memory.
            columns = int_columns if as_int else float_columns
            columns.append(column)
            return ("i" if as_int else "f"), len(columns) - 1

        def label_of(key: str) -> int:  # the int row a label is looked up from (its key comes next)
            column = REPORT.persona_index if key == "persona" else REPORT.outcome
            return len(int_columns) if column not in int_columns else int_columns.index(column)

        top: list[tuple[str, str, int]] = []
        terms: list[tuple[str, str, int]] = []
        if self.numeric:
            top = [(key, *slot(column, as_int)) for key, column, as_int in self._entries]
        else:
            # The keys of batched_infos, in its order.
            for key, column, as_int in _INFO_COLUMNS:
                if key in ("persona", "outcome"):
                    top.append((key, key, label_of(key)))
                elif key == "persona_index":
                    top.append((key, *slot(REPORT.persona_index, True)))
                elif key == "outcome_code":
                    top.append((key, *slot(REPORT.outcome, True)))
                elif column is not None:
                    top.append((key, *slot(column, as_int)))
                else:
                    raise RuntimeError(f"the info's {key!r} has no report column: update _plan_all_envs")
            terms = [(name, *slot(REPORT.reward_success + k, False)) for k, name in enumerate(REWARD_TERMS)]
        for key, source, at in top:
            if source in ("persona", "outcome") and int_columns[at] != (
                REPORT.persona_index if source == "persona" else REPORT.outcome
            ):
                raise RuntimeError(f"the info's {key!r} must come right before its int key: update _INFO_COLUMNS")
        self._top = tuple(top)
        self._terms = tuple(terms)
        self._float_columns = np.array(float_columns, dtype=np.int64)
        self._int_columns = np.array(int_columns, dtype=np.int64)
        self._mask_count = len(top) + len(terms) + (0 if self.numeric else 1 + self.probabilities) + self.unscaled

    def unscaled_observation(self, rows: NDArray[np.float64]) -> NDArray[np.float32]:
        """The physical observation of report rows (one row or a batch)."""
        values = np.take(rows, self._obs_columns, axis=-1)
        return np.clip(values, self._obs_low, self._obs_high).astype(np.float32)  # type: ignore[no-any-return]

    def single(self, r: list[float]) -> dict[str, Any]:
        """The single env's info from one report row (``core.report[i].tolist()``)."""
        if self.numeric:
            # NumPy scalars, not Python numbers: TorchRL's info reader asks each value for its dtype.
            info: dict[str, Any] = {
                key: np.int64(r[column]) if as_int else np.float64(r[column]) for key, column, as_int in self._entries
            }
        else:
            info = report_info(r, self.persona_names, self.probabilities)
        if self.unscaled:
            info["unscaled_obs"] = self.unscaled_observation(np.array(r))
        return info

    def batched(self, report: NDArray[np.float64], mask: NDArray[np.bool_] | None) -> dict[str, Any]:
        """The vector env's infos from its report rows; entries outside ``mask`` (default all) are zero."""
        if mask is None:
            return self._all_envs(report)
        outside = ~mask
        infos: dict[str, Any] = {}
        if self.numeric:
            for key, column, as_int in self._entries:
                values = report[:, column].astype(np.int64) if as_int else report[:, column].copy()
                values[outside] = 0
                infos[key] = values
                infos[f"_{key}"] = mask.copy()
        else:
            infos = batched_infos(report, mask, self._persona_array, self.probabilities)
        if self.unscaled:
            unscaled = self.unscaled_observation(report)
            unscaled[outside] = 0
            infos["unscaled_obs"] = unscaled
            infos["_unscaled_obs"] = mask.copy()
        return infos

    def _all_envs(self, report: NDArray[np.float64]) -> dict[str, Any]:
        """:meth:`batched` of every env (each step's infos), the same keys, values and dtypes, built faster.

        One compiled pass copies the report's info columns into two fresh blocks (float64 and
        int64) whose rows are the info's arrays, and the ``_key`` masks are the rows of one fresh
        all-True block: every array is new on every call and owns no memory another one uses.
        """
        n = report.shape[0]
        floats = np.empty((self._float_columns.shape[0], n))
        ints = np.empty((self._int_columns.shape[0], n), dtype=np.int64)
        _gather_info_columns(report, self._float_columns, floats, self._int_columns, ints)
        masks = iter(np.ones((self._mask_count, n), dtype=bool))
        infos: dict[str, Any] = {}
        for key, source, at in self._top:
            if source == "f":
                infos[key] = floats[at]
            elif source == "i":
                infos[key] = ints[at]
            else:
                labels = self._persona_array if source == "persona" else _OUTCOME_LABEL_ARRAY
                infos[key] = labels[ints[at]]
            infos[f"_{key}"] = next(masks)
        if self.probabilities and not self.numeric:
            infos["xi_probabilities"] = report[:, REPORT.p_uncooperative : REPORT.p_cooperative + 1].copy()
            infos["_xi_probabilities"] = next(masks)
        if not self.numeric:
            reward_terms: dict[str, Any] = {}
            for key, _, at in self._terms:
                reward_terms[key] = floats[at]
                reward_terms[f"_{key}"] = next(masks)
            infos["reward_terms"] = reward_terms
            infos["_reward_terms"] = next(masks)
        if self.unscaled:
            infos["unscaled_obs"] = self.unscaled_observation(report)
            infos["_unscaled_obs"] = next(masks)
        return infos


# --- reset options ------------------------------------------------------------------


def parse_reset_options(options: dict[str, Any] | None, personas: Sequence[Persona]) -> tuple[int | None, int | None]:
    """Validate ``reset(options=...)``: ``persona`` (a name of this env's) and ``initial_xi``.

    Returns:
        ``(persona_index, initial_xi)``, each None when not fixed.
    """
    if not options:
        return None, None
    if not isinstance(options, dict):
        raise ValueError(f"reset options must be a dict, got {type(options).__name__}")
    unknown = sorted(set(options) - {"persona", "initial_xi"})
    if unknown:
        raise ValueError(f"unknown reset option(s) {unknown}; known: ['initial_xi', 'persona']")
    persona_index = None
    if "persona" in options:
        names = [p.name for p in personas]
        if options["persona"] not in names:
            raise ValueError(f"reset option persona={options['persona']!r} is not one of this env's {names}")
        persona_index = names.index(options["persona"])
    xi = options.get("initial_xi")
    return persona_index, None if xi is None else check_choice("reset option initial_xi", xi, (-1, 0, 1))


# --- the env's keyword arguments ---------------------------------------------------


@dataclass(frozen=True)
class EnvArguments:
    """The keyword arguments of every coop_gym env, as given (the one list of them).

    :class:`~coop_gym.envs.sit_to_stand.SitToStandEnv`, the vector env and the registered
    ids (``coop_gym.registration.ENV_IDS``) take these; :meth:`resolve` validates them.
    The meaning of each is in the single env's docstring ("Arguments").
    """

    personas: str | Persona | Sequence[str | Persona] = "train"
    observation_mode: str = "belief"
    action_type: str = "multidiscrete"
    estimator: str = "kalman"
    realism: Realism | dict[str, Any] | None = None
    reward: RewardWeights | dict[str, Any] | None = None
    lift: LiftCriteria | dict[str, Any] | None = None
    judgment: ThresholdJudgment | dict[str, Any] | None = None
    timing: Timing | dict[str, Any] | None = None
    cues: Cues | dict[str, Any] | None = None
    estimator_options: dict[str, Any] | None = None
    render_mode: str | None = None
    difficulty: str | Difficulty | None = None
    # The vector env's compiled step: at most this many threads (None, the default: the cores
    # this process may use; README, "Threads").
    threads: int | None = None
    observation_scale: str = "none"
    info_mode: str = "default"

    @classmethod
    def from_keywords(cls, owner: str, keywords: Mapping[str, Any]) -> EnvArguments:
        """Build from keyword arguments; an unknown one raises ``TypeError`` naming it (as Python does)."""
        known = [f.name for f in dataclasses.fields(cls)]
        unknown = ", ".join(repr(k) for k in keywords if k not in known)
        if unknown:
            raise TypeError(f"{owner}() got an unexpected keyword argument {unknown}; its keywords: {known}")
        return cls(**keywords)

    def resolve(self, render_modes: Sequence[str] = ("human", "rgb_array")) -> SitToStandConfig:
        """Validate (``ValueError`` naming the argument) into the settings the envs build from."""
        _check_choice("observation_mode", self.observation_mode, OBSERVATION_MODES)
        _check_choice("action_type", self.action_type, ACTION_TYPES)
        _check_choice("estimator", self.estimator, ESTIMATORS)
        _check_choice("observation_scale", self.observation_scale, OBSERVATION_SCALES)
        _check_choice("info_mode", self.info_mode, INFO_MODES)
        if self.render_mode is not None and self.render_mode not in render_modes:
            raise ValueError(f"render_mode must be None or one of {list(render_modes)}, got {self.render_mode!r}")
        options = self.estimator_options
        if options is not None and not isinstance(options, dict):
            raise ValueError(f"estimator_options must be a dict or None, got {type(options).__name__}")
        if options and self.estimator == "kalman":
            raise ValueError(
                f"estimator_options {sorted(options)} are for the multiple-model estimators; "
                "estimator='kalman' takes none"
            )
        resolved = resolve_personas(self.personas)
        reward = self.reward
        if self.difficulty is not None:
            # The level's knobs on every persona, and its reward unless one is given.
            level = get_difficulty(self.difficulty)
            resolved = tuple(dataclasses.replace(p, params=level.apply(p.params)) for p in resolved)
            if reward is None:
                reward = level.reward
        return SitToStandConfig(
            personas=resolved,
            observation_mode=self.observation_mode,
            action_type=self.action_type,
            estimator=self.estimator,
            realism=as_dataclass(Realism, self.realism, "realism"),
            reward=as_dataclass(RewardWeights, reward, "reward"),
            lift=as_dataclass(LiftCriteria, self.lift, "lift"),
            judgment=as_dataclass(ThresholdJudgment, self.judgment, "judgment"),
            timing=as_dataclass(Timing, self.timing, "timing"),
            cues=as_dataclass(Cues, self.cues, "cues"),
            estimator_options=options,
            render_mode=self.render_mode,
            observation_scale=self.observation_scale,
            info_mode=self.info_mode,
        )


@dataclass(frozen=True)
class SitToStandConfig:
    """The validated settings of an env, built by :meth:`EnvArguments.resolve`.

    Attributes:
        personas: The personas episodes are drawn from.
        observation_mode, action_type, estimator: See :data:`~coop_gym.envs.config.OBSERVATION_MODES`,
            :data:`~coop_gym.envs.config.ACTION_TYPES`, :data:`~coop_gym.envs.config.ESTIMATORS`.
        realism, reward, lift, judgment, timing, cues: The settings dataclasses.
        estimator_options: Keyword arguments of the multiple-model estimator.
        render_mode: ``None``, ``"human"`` or ``"rgb_array"``.
        observation_scale: One of :data:`OBSERVATION_SCALES`.
        info_mode: One of :data:`INFO_MODES`.
    """

    personas: tuple[Persona, ...]
    observation_mode: str
    action_type: str
    estimator: str
    realism: Realism
    reward: RewardWeights
    lift: LiftCriteria
    judgment: ThresholdJudgment
    timing: Timing
    cues: Cues
    estimator_options: dict[str, Any] | None
    render_mode: str | None
    observation_scale: str = "none"
    info_mode: str = "default"

    @property
    def physical_features(self) -> tuple[str, ...]:
        """The observation's features as the core builds them (names of :data:`FEATURES`), in order."""
        return observation_features(self.observation_mode, self.estimator)

    @property
    def features(self) -> tuple[str, ...]:
        """The observation's feature names, in order (under unit scale: :func:`scaled_feature_names`)."""
        if self.observation_scale == "unit":
            return scaled_feature_names(self.physical_features, self.timing.episode_s)
        return self.physical_features

    def physical_observation_space(self) -> spaces.Box:
        """The Box of the physical observation (the core clips into it)."""
        return observation_space_for(self.physical_features, self.timing.episode_s)

    def observation_space(self) -> spaces.Box:
        """The observation space of one env."""
        if self.observation_scale == "unit":
            return unit_observation_space(self.physical_features, self.timing.episode_s)
        return self.physical_observation_space()

    def observation_scales(self) -> NDArray[np.float32]:
        """What each feature is divided by: :data:`FEATURE_SCALES` under unit scale, else ones."""
        if self.observation_scale == "unit":
            return observation_scales(self.physical_features, self.timing.episode_s)
        return np.ones(len(self.physical_features), dtype=np.float32)

    def observer(self) -> Callable[[NDArray[np.float32]], NDArray[np.float32]]:
        """The env's observation (a fresh array) from the core's physical observation rows."""
        return observation_scaler(self.physical_features, self.timing.episode_s, self.observation_scale)

    def action_space(self) -> spaces.Space[Any]:
        """The action space of one env."""
        return action_space_for(self.action_type)


def _check_choice(name: str, value: Any, choices: Sequence[str]) -> None:
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name} must be one of {list(choices)}, got {value!r}")


guard_kernel_cache(__name__)
