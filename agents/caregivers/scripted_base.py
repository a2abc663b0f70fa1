"""The base of every scripted caregiver: SB3's ``predict`` over per-env phase memory.

Every agent follows SB3's ``predict(obs, state, episode_start, deterministic) -> (actions,
state)`` (:class:`agents.base.Agent`), batched over a leading env axis; a single
unbatched observation gives a single action. Features are found by *name* in the
env's feature list (``env.unwrapped.features``), never by position, so the same agent
runs on every observation mode and estimator that provides what it reads.

Per-env memory (phase and phase timers) lives in a :class:`PhaseState`. It is returned
as the ``state`` of ``predict``; pass it back to keep the episode going. When the caller
passes ``state=None`` (the usual ``action, _ = agent.predict(obs)`` loop) the agent
keeps the memory itself. Memory is reset for every env marked in ``episode_start``
and for every observation whose ``elapsed_s`` is 0 (the first of an episode).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from agents.base import action_type_of, encode_actions, features_of, level_of, require_features
from coop_gym.envs.config import ACTION_TYPES
from coop_gym.envs.contract import observation_features
from coop_gym.model.difficulty import DIFFICULTIES, Difficulty
from coop_gym.registration import unit_twin

__all__ = ["EPS_S", "PhaseState", "ScriptedAgent", "unit_id_hint"]

EPS_S = 1e-6
"""Slack on clock comparisons [s]: elapsed time is a float sum of 0.1 s steps."""
_EPS_S = EPS_S


@dataclass
class PhaseState:
    """Per-env memory of a scripted agent (mutable arrays of shape (N,)).

    Attributes:
        phase: Current phase (meaning depends on the agent).
        phase_start_s: Episode time at which the phase began [s].
        count: A per-phase counter (e.g. pushes since the last explanation).
        flag: A per-phase flag (e.g. the explanation has been spoken).
        anchor: A per-phase value (e.g. the shoulder position when a probe began) [m].
    """

    phase: NDArray[np.int64]
    phase_start_s: NDArray[np.float64]
    count: NDArray[np.int64]
    flag: NDArray[np.bool_]
    anchor: NDArray[np.float64] = None  # type: ignore[assignment]  # zeros when not given

    def __post_init__(self) -> None:
        """Give ``anchor`` its zeros when it was not passed (agents that do not use it)."""
        if self.anchor is None:
            self.anchor = np.zeros(self.phase.shape[0])

    @classmethod
    def zeros(cls, n_envs: int) -> PhaseState:
        """Fresh memory for ``n_envs`` envs."""
        return cls(
            np.zeros(n_envs, dtype=np.int64),
            np.zeros(n_envs),
            np.zeros(n_envs, dtype=np.int64),
            np.zeros(n_envs, dtype=bool),
            np.zeros(n_envs),
        )

    @property
    def n_envs(self) -> int:
        """Number of envs this memory covers."""
        return int(self.phase.shape[0])

    def copy(self) -> PhaseState:
        """An independent copy (``predict`` never mutates the state it is given)."""
        return PhaseState(
            self.phase.copy(), self.phase_start_s.copy(), self.count.copy(), self.flag.copy(), self.anchor.copy()
        )

    def enter(self, mask: NDArray[np.bool_], phase: int, now_s: NDArray[np.float64]) -> None:
        """Move the envs in ``mask`` to ``phase``, starting its clock now."""
        self.phase[mask] = phase
        self.phase_start_s[mask] = now_s[mask]
        self.flag[mask] = False


class ScriptedAgent:
    """Base class: batching, feature lookup, per-env memory and action encoding.

    Subclasses set :attr:`name` and :attr:`needs` (the features they read), optionally
    :attr:`settings_class` (the frozen dataclass of their settings) and :attr:`default_observation`,
    and implement :meth:`_decide`.

    Args:
        features: Names of the observation's features, in order (``env.unwrapped.features``
            or :func:`coop_gym.envs.contract.observation_features`). Default: the
            :attr:`default_observation` mode's features under the paper's Kalman filter.
        action_type: ``"multidiscrete"`` (default), ``"discrete"`` or ``"continuous"``.
        seed: Seed of the agent's own random generator (only :class:`RandomAgent` draws).
        settings: An instance of :attr:`settings_class` (default: its defaults); agents without
            settings take none.
    """

    name: ClassVar[str] = "scripted"
    needs: ClassVar[tuple[str, ...]] = ("elapsed_s",)
    settings_class: ClassVar[type | None] = None
    default_observation: ClassVar[str] = "belief"
    """The observation mode whose features the agent reads when none are given."""
    tuned: ClassVar[Mapping[str, Any] | None] = None
    """The settings chosen for each shipped level (``v0``: the ``-v0`` ids), or None: one set for all."""

    def __init__(
        self,
        features: Sequence[str] | None = None,
        action_type: str = "multidiscrete",
        seed: int | None = None,
        settings: Any = None,
    ) -> None:
        """Check that the observation provides what the agent reads, and the settings."""
        cls = self.settings_class
        if settings is not None and (cls is None or not isinstance(settings, cls)):
            wanted = "no settings" if cls is None else f"a {cls.__name__}"
            raise ValueError(f"{type(self).__name__} takes {wanted}, got {type(settings).__name__}")
        self.settings: Any = settings if settings is not None or cls is None else cls()
        if action_type not in ACTION_TYPES:
            raise ValueError(f"action_type must be one of {list(ACTION_TYPES)}, got {action_type!r}")
        if features is None:
            features = observation_features(self.default_observation, "kalman")
        self.features = tuple(features)
        self.action_type = action_type
        self.columns = require_features(self.features, self.needs, type(self).__name__)
        self.rng = np.random.default_rng(seed)
        self._memory: PhaseState | None = None

    @classmethod
    def for_env(cls, env: Any, **kwargs: Any) -> ScriptedAgent:
        """Build the agent for a (single or vector) coop_gym env: its features, action type and level.

        An agent with :attr:`tuned` settings plays those chosen for the env's level unless
        ``settings`` is given (a level of your own has none: ValueError).
        """
        if cls.tuned is not None and kwargs.get("settings") is None:
            kwargs["settings"] = cls.chosen_settings(level_of(env))
        try:
            return cls(features_of(env), action_type_of(env), **kwargs)
        except ValueError as exc:
            raise ValueError(f"{exc}{unit_id_hint(getattr(getattr(env, 'spec', None), 'id', None))}") from None

    @classmethod
    def chosen_settings(cls, level: str | Difficulty | None) -> Any:
        """The settings :attr:`tuned` holds for ``level`` (a name, a shipped :class:`Difficulty`, or None for ``-v0``).

        Raises:
            ValueError: the agent has no table, or none was chosen for ``level`` (e.g. a level of your own).
        """
        agent = cls.__name__
        if cls.tuned is None:
            raise ValueError(f"{agent} has no settings chosen per level")
        key = "v0" if level is None else level if isinstance(level, str) else level.name
        if isinstance(level, Difficulty) and DIFFICULTIES.get(level.name) != level:
            raise ValueError(
                f"no {agent} settings were chosen for the level {level.name!r} (not a shipped level); "
                f"build {agent}(settings=...) for it"
            )
        if key not in cls.tuned:
            raise ValueError(
                f"no {agent} settings were chosen for the level {key!r}; chosen for: {', '.join(cls.tuned)}"
            )
        return cls.tuned[key]

    def reset(self) -> None:
        """Forget the memory kept for ``state=None`` callers."""
        self._memory = None

    def predict(
        self,
        observation: Any,
        state: PhaseState | None = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[NDArray[Any], PhaseState]:
        """Actions for a batch of observations (SB3's protocol).

        Args:
            observation: (N, F) batch or a single (F,) observation.
            state: The :class:`PhaseState` returned by the previous call, or None to use the
                memory the agent keeps itself.
            episode_start: (N,) bools, True where an episode has just begun (memory reset).
            deterministic: Ignored by the scripted agents except :class:`RandomAgent`'s
                documented behaviour (it always samples).

        Returns:
            ``(actions, state)``: (N, ...) actions of the agent's action type (unbatched if
            ``observation`` was), and the memory to pass back.
        """
        obs = np.asarray(observation, dtype=np.float64)
        single = obs.ndim == 1
        if single:
            obs = obs[None]
        if obs.ndim != 2 or obs.shape[1] != len(self.features):
            raise ValueError(
                f"{type(self).__name__}.predict: observation has shape {np.shape(observation)}; expected "
                f"(N, {len(self.features)}) or ({len(self.features)},) for features {list(self.features)}"
            )
        if not np.all(np.isfinite(obs)):
            raise ValueError(f"{type(self).__name__}.predict: observation contains NaN or inf")
        n = obs.shape[0]
        memory = state if state is not None else self._memory
        fresh = memory is None or memory.n_envs != n
        memory = PhaseState.zeros(n) if fresh or memory is None else memory.copy()
        now = obs[:, self.columns["elapsed_s"]]
        starts = np.full(n, fresh) | (now <= _EPS_S)
        if episode_start is not None:
            mask = np.asarray(episode_start, dtype=bool).reshape(-1)
            if mask.shape != (n,):
                raise ValueError(f"episode_start has {mask.shape[0]} entries for {n} observations")
            starts |= mask
        if np.any(starts):
            memory.enter(starts, 0, now)
            memory.count[starts] = 0
        push, verbal, lift = self._decide(obs, memory, now)
        self._memory = memory
        actions = encode_actions(push, verbal, lift, self.action_type)
        return (actions[0] if single else actions), memory

    def _decide(
        self, obs: NDArray[np.float64], memory: PhaseState, now: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
        raise NotImplementedError

    def _column(self, obs: NDArray[np.float64], feature: str) -> NDArray[np.float64]:
        return obs[:, self.columns[feature]]


def unit_id_hint(env_id: str | None) -> str:
    """What a scripted agent's error adds on a unit-scaled id: the twin id it can play ("" on other ids).

    Example:
        >>> unit_id_hint("CoopGym/SitToStandHardUnit-v2")[:60]
        '; CoopGym/SitToStandHardUnit-v2 observes unit-scaled feature'
    """
    twin = unit_twin(env_id)
    if twin is None:
        return ""
    return (
        f"; {env_id} observes unit-scaled features and the scripted agents read physical ones: "
        f"play them on its twin {twin} (the same task, physical features)"
    )
