"""The env's keyword arguments, validated into the settings every env builds from; the reset options."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from coop_gym.envs.actions import action_space_for
from coop_gym.envs.config import (
    ACTION_TYPES,
    ESTIMATORS,
    INFO_MODES,
    OBSERVATION_MODES,
    LiftCriteria,
    RewardWeights,
    as_dataclass,
)
from coop_gym.envs.observation import (
    OBSERVATION_SCALES,
    observation_features,
    observation_scaler,
    observation_scales,
    observation_space_for,
    scaled_feature_names,
    unit_observation_space,
)
from coop_gym.model.difficulty import Difficulty, get_difficulty
from coop_gym.model.params import Cues, Realism, Timing
from coop_gym.model.personas import Persona, resolve_personas
from estimator.judgment import ThresholdJudgment
from estimator.validate import check_choice

__all__ = [
    "EnvArguments",
    "SitToStandConfig",
    "parse_reset_options",
]


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
    # this process may use; docs/BENCHMARKS.md, "Threads").
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
        if self.estimator == "switching":
            # The filter's people are at the env's level (the caregiver knows the task, not the person).
            options = {"difficulty": self.difficulty, **(options or {})}
        resolved = resolve_personas(self.personas)
        reward = self.reward
        if self.difficulty is not None:
            # The level's knobs on every persona, and its reward unless one is given.
            level = get_difficulty(self.difficulty)
            resolved = level.personas_at(resolved)
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
