"""Actions both ways: an action of each action type to the command row the step kernel reads, and back."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces
from numba import njit
from numpy.typing import NDArray

from coop_gym.envs.config import (
    ACTION_TYPES,
)
from coop_gym.model.params import Cues
from estimator.compiled.cache import guard_kernel_cache
from estimator.compiled.schema import index_table
from estimator.validate import is_integer

__all__ = [
    "ACTION_SHAPE",
    "CMD",
    "CMD_COLUMNS",
    "LIFT",
    "N_FLAT_ACTIONS",
    "PUSH_BY_NAME",
    "PUSH_FIRM",
    "PUSH_NONE",
    "PUSH_SOFT",
    "VERBAL_BACK",
    "VERBAL_BY_NAME",
    "VERBAL_FORWARD",
    "VERBAL_NONE",
    "WAIT",
    "ActionDecoder",
    "action_space_for",
    "command_table",
    "decode_actions",
    "encode_actions",
]


# --- actions ----------------------------------------------------------------------

ACTION_SHAPE = (3, 3, 2)
"""Choices per component of the MultiDiscrete action: push, verbal cue, lift."""
N_FLAT_ACTIONS = math.prod(ACTION_SHAPE)
"""Size of the flat ``Discrete`` action space: 3 pushes x 3 verbal cues x 2 lift choices."""

# Component values of the default MultiDiscrete([3, 3, 2]) action (docs/ARCHITECTURE.md).
PUSH_NONE, PUSH_SOFT, PUSH_FIRM = 0, 1, 2
VERBAL_NONE, VERBAL_BACK, VERBAL_FORWARD = 0, 1, 2
WAIT, LIFT = 0, 1
PUSH_BY_NAME = {"none": PUSH_NONE, "soft": PUSH_SOFT, "firm": PUSH_FIRM}
"""Each push component value by the name settings and displays give it, in value order."""
VERBAL_BY_NAME = {"none": VERBAL_NONE, "back": VERBAL_BACK, "forward": VERBAL_FORWARD}
"""Each verbal component value by the name settings give it, in value order."""
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


def _holds_bool(actions: Any) -> bool:
    """Whether a (nested) list or tuple of actions holds a bool or ``np.bool_`` anywhere."""
    if isinstance(actions, (bool, np.bool_)):
        return True
    if isinstance(actions, (list, tuple)):
        return any(_holds_bool(a) for a in actions)
    return isinstance(actions, np.ndarray) and actions.dtype.kind == "b"


def _validated(actions: Any, action_type: str, n_envs: int) -> NDArray[np.float64]:
    """A batch of ``n_envs`` actions as float64, checked: the right shape, finite, in range.

    The discrete types must be integers: the flat index of ``discrete``, the components of ``multidiscrete``.

    Raises:
        ValueError: naming what is wrong (shape, bool, NaN, non-integer, out of range).
    """
    try:
        a = np.asarray(actions)
    except Exception as exc:  # e.g. ragged lists
        raise ValueError(f"action could not be read as an array: {exc}") from None
    if a.dtype == object or a.dtype.kind not in "biuf":
        raise ValueError(f"action must be numeric, got dtype {a.dtype}")
    if a.dtype.kind == "b" or _holds_bool(actions):
        # True is not the action 1: a bool is a mistake (a flag passed for an action). In a list
        # beside numbers np.asarray turns it into one silently, so the elements are looked at.
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
    if action_type == "continuous":
        if np.any(a < -1.0 - 1e-6) or np.any(a > 1.0 + 1e-6):
            raise ValueError(f"continuous action must lie in [-1, 1], got {actions!r}")
        return a
    if np.any(a != np.round(a)):
        raise ValueError(f"{action_type} action must be integers, got {actions!r}")
    # Range checked on the floats, before the int cast (1e300 would overflow it).
    if action_type == "discrete":
        if np.any(a < 0) or np.any(a >= N_FLAT_ACTIONS):
            raise ValueError(f"discrete action must be in [0, {N_FLAT_ACTIONS - 1}], got {actions!r}")
    elif np.any(a < 0) or np.any(a >= np.array(ACTION_SHAPE)):
        raise ValueError(
            f"multidiscrete action must be [push 0..2, verbal 0..2, lift 0..1], got {np.asarray(actions).tolist()!r}"
        )
    return a


def command_table(cues: Cues) -> NDArray[np.float64]:
    """(18, 1, 4) command rows (:data:`CMD`) of each flat discrete action, ``active = 1``.

    The one decoding of the discrete choices: push none / soft / firm [N], verbal cue none /
    "lean back" (-1) / "lean forward" (+1), wait / lift; flat index ``(push * 3 + verbal) * 2 + lift``.
    """
    push, verbal, lift = np.unravel_index(np.arange(N_FLAT_ACTIONS), ACTION_SHAPE)
    table = np.stack(
        [
            np.array([0.0, cues.soft_push_n, cues.firm_push_n])[push],
            _VERBAL_FROM_INDEX[verbal],
            (lift == LIFT).astype(np.float64),
            np.ones(N_FLAT_ACTIONS),
        ],
        axis=1,
    )
    return np.ascontiguousarray(table[:, None, :])


@njit(cache=True, error_model="numpy")
def continuous_command(a_push: float, a_verbal: float, a_lift: float, firm_push_n: float) -> tuple[float, float, float]:
    """``(push_force_n, verbal_cue, lift)`` of a continuous action in [-1, 1]^3 (the one decoding of it).

    Push ``(a0 + 1) / 2 * firm_push_n``; the verbal cue by thirds (-1 below -1/3, +1 above 1/3,
    else none); lift when ``a2 > 0``.
    """
    push = (min(max(a_push, -1.0), 1.0) + 1.0) * 0.5 * firm_push_n
    verbal = -1.0 if a_verbal < -1.0 / 3.0 else (1.0 if a_verbal > 1.0 / 3.0 else 0.0)
    return push, verbal, 1.0 if a_lift > 0.0 else 0.0


@njit(cache=True, error_model="numpy")
def _continuous_commands(actions: NDArray[np.float64], firm_push_n: float, cmd: NDArray[np.float64]) -> None:
    for i in range(actions.shape[0]):
        push, verbal, lift = continuous_command(actions[i, 0], actions[i, 1], actions[i, 2], firm_push_n)
        cmd[i, CMD.push_force_n] = push
        cmd[i, CMD.verbal_cue] = verbal
        cmd[i, CMD.lift] = lift


@njit(cache=True, error_model="numpy")
def _multidiscrete_commands(actions: NDArray[np.int64], flat: NDArray[np.float64], cmd: NDArray[np.float64]) -> bool:
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
    """Actions of one action type -> the core's command rows: the one decoder of actions.

    The discrete types are rows of :func:`command_table`, the continuous type
    :func:`continuous_command`. The common cases (what ``action_space.sample()`` and SB3's
    ``predict`` give) take a short path; anything else is checked first and refused with a
    ``ValueError`` that names what is wrong.

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
            if is_integer(action) and 0 <= action < N_FLAT_ACTIONS:
                return self._table[int(action)]  # type: ignore[no-any-return]
        elif type(action) is np.ndarray and action.shape == (3,) and action.dtype.kind == "f":
            a_push, a_verbal, a_lift = action.tolist()
            if all(math.isfinite(a) and -1.0 - 1e-6 <= a <= 1.0 + 1e-6 for a in (a_push, a_verbal, a_lift)):
                cmd[0, : CMD.active] = continuous_command(a_push, a_verbal, a_lift, self._firm_push_n)
                return cmd
        # A list, not np.asarray(action)[None]: the check names what is wrong with a ragged one.
        self._decode(_validated([action], kind, 1), cmd)
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
                    if _multidiscrete_commands(a.astype(np.int64, copy=False), self._flat, cmd):
                        return
                if kind == "discrete" and a.shape == (n,):
                    cmd[:, : CMD.active] = self._flat[np.ravel_multi_index((a,), (N_FLAT_ACTIONS,))]
                    return
            except (ValueError, TypeError):
                pass  # out of range or an unusual integer type: the check decides and names the problem
        self._decode(_validated(actions, kind, n), cmd)

    def _decode(self, a: NDArray[np.float64], cmd: NDArray[np.float64]) -> None:
        # The commands of checked actions (see _validated).
        if self.action_type == "continuous":
            _continuous_commands(a, self._firm_push_n, cmd)
            return
        flat = a if self.action_type == "discrete" else np.ravel_multi_index(a.astype(np.int64).T, ACTION_SHAPE)
        cmd[:, : CMD.active] = self._flat[np.asarray(flat, dtype=np.int64)]


def decode_actions(
    actions: Any, action_type: str, cues: Cues, n_envs: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Check a batch of ``n_envs`` actions and turn them into cues (:class:`ActionDecoder`'s decoding).

    Returns:
        ``(push_force_n, verbal_cue, lift)``, each of shape (n_envs,).

    Raises:
        ValueError: naming what is wrong (shape, bool, NaN, non-integer, out of range).
    """
    cmd = np.zeros((n_envs, len(CMD_COLUMNS)))
    ActionDecoder(action_type, cues).batch(actions, cmd)
    return cmd[:, CMD.push_force_n].copy(), cmd[:, CMD.verbal_cue].copy(), cmd[:, CMD.lift] > 0.5


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


guard_kernel_cache(__name__)
