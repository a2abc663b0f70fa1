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

# The action encoding is the env contract's (coop_gym.envs.contract), re-exported for the agents.
from coop_gym.envs.contract import (
    LIFT,
    PUSH_BY_NAME,
    PUSH_FIRM,
    PUSH_NONE,
    PUSH_SOFT,
    VERBAL_BACK,
    VERBAL_BY_NAME,
    VERBAL_FORWARD,
    VERBAL_NONE,
    WAIT,
    encode_actions,
)

__all__ = [
    "LIFT",
    "PUSH_BY_NAME",
    "PUSH_FIRM",
    "PUSH_NONE",
    "PUSH_SOFT",
    "VERBAL_BACK",
    "VERBAL_BY_NAME",
    "VERBAL_FORWARD",
    "VERBAL_NONE",
    "WAIT",
    "Agent",
    "action_type_of",
    "encode_actions",
    "feature_mismatch",
    "features_of",
    "level_of",
    "require_features",
]


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


def level_of(env: Any) -> Any:
    """The difficulty level of a single or vector coop_gym env (``env.unwrapped.difficulty``; None for ``-v0``)."""
    return getattr(getattr(env, "unwrapped", env), "difficulty", None)


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
