"""The one protocol every agent follows, and helpers shared by the scripted agents.

Scripted and learned agents are scored by the same code (:mod:`agents.evaluate`), so
they share Stable-Baselines3's call: ``predict(obs, state, episode_start, deterministic)
-> (actions, state)``. ``obs`` is batched over a leading env axis; ``episode_start``
marks the envs whose episode has just begun (so per-env memory must be reset).

Nothing here imports torch or SB3.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from coop_gym.envs.config import ACTION_TYPES
from coop_gym.model.params import Cues

__all__ = [
    "LIFT",
    "PUSH_FIRM",
    "PUSH_NONE",
    "PUSH_SOFT",
    "VERBAL_BACK",
    "VERBAL_FORWARD",
    "VERBAL_NONE",
    "WAIT",
    "Agent",
    "action_type_of",
    "encode_actions",
    "feature_mismatch",
    "features_of",
    "require_features",
]

# Component indices of the default MultiDiscrete([3, 3, 2]) action (docs/ARCHITECTURE.md).
PUSH_NONE, PUSH_SOFT, PUSH_FIRM = 0, 1, 2
VERBAL_NONE, VERBAL_BACK, VERBAL_FORWARD = 0, 1, 2
WAIT, LIFT = 0, 1

_MULTI_SHAPE = (3, 3, 2)


@runtime_checkable
class Agent(Protocol):
    """Anything with Stable-Baselines3's ``predict``: SB3 models and the scripted agents."""

    def predict(
        self,
        observation: NDArray[np.floating[Any]],
        state: Any = None,
        episode_start: NDArray[np.bool_] | None = None,
        deterministic: bool = True,
    ) -> tuple[NDArray[Any], Any]:
        """Actions for a batch of observations, and the state to pass back next call."""
        ...


def encode_actions(
    push: NDArray[np.integer[Any]],
    verbal: NDArray[np.integer[Any]],
    lift: NDArray[np.integer[Any]],
    action_type: str,
    cues: Cues | None = None,
) -> NDArray[Any]:
    """Turn per-env component choices into actions of ``action_type``.

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
        return np.asarray(np.ravel_multi_index((push, verbal, lift), _MULTI_SHAPE), dtype=np.int64)
    if action_type == "continuous":
        cues = cues or Cues()
        # Inverse of the env's map push = (a0 + 1) / 2 * firm_push_n.
        force = np.array([0.0, cues.soft_push_n, cues.firm_push_n])[push]
        a0 = 2.0 * force / cues.firm_push_n - 1.0
        a1 = np.array([0.0, -1.0, 1.0])[verbal]
        a2 = np.where(lift == 1, 1.0, -1.0)
        return np.clip(np.stack([a0, a1, a2], axis=-1), -1.0, 1.0).astype(np.float32)
    raise ValueError(f"action_type must be one of {list(ACTION_TYPES)}, got {action_type!r}")


def features_of(env: Any) -> tuple[str, ...]:
    """The observation feature names of a single or vector env (``env.unwrapped.features``)."""
    for candidate in (env, getattr(env, "unwrapped", None)):
        names = getattr(candidate, "features", None)
        if names is not None:
            return tuple(names)
    raise ValueError(f"{type(env).__name__} has no `features` attribute; is it a coop_gym env?")


def action_type_of(env: Any) -> str:
    """The action type of a single or vector coop_gym env."""
    for candidate in (env, getattr(env, "unwrapped", None)):
        value = getattr(candidate, "action_type", None)
        if isinstance(value, str):
            return value
    raise ValueError(f"{type(env).__name__} has no `action_type` attribute; is it a coop_gym env?")


def feature_mismatch(trained: Sequence[str] | None, observed: Sequence[str], env_id: str = "the env") -> str | None:
    """One line naming how a model's observation features differ from an env's (None if they match or are unknown).

    Example:
        >>> feature_mismatch(["a", "b"], ["a", "c", "d"], "E-v0")
        "the model's 2 observation features differ from E-v0's 3: missing ['b'], extra ['c', 'd']"
        >>> feature_mismatch(["a", "b"], ["b", "a"], "E-v0")
        "the model's 2 observation features differ from E-v0's 2: same names in another order ['b', 'a']"
    """
    if trained is None or tuple(trained) == tuple(observed):
        return None
    missing = [f for f in trained if f not in observed]
    extra = [f for f in observed if f not in trained]
    detail = (
        f"missing {missing}, extra {extra}" if missing or extra else f"same names in another order {list(observed)}"
    )
    return f"the model's {len(trained)} observation features differ from {env_id}'s {len(observed)}: {detail}"


def require_features(features: Sequence[str], needed: Sequence[str], agent: str) -> dict[str, int]:
    """Column index of each needed feature; a clear error when the observation lacks one."""
    names = tuple(features)
    missing = [f for f in needed if f not in names]
    if missing:
        raise ValueError(
            f"{agent} needs observation feature(s) {missing}, but the observation holds {list(names)}; "
            "use an env whose observation mode provides them"
        )
    return {f: names.index(f) for f in needed}
