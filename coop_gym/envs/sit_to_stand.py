"""The single sit-to-stand environment."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from coop_gym.envs.config import (
    ACTION_TYPES,
    ESTIMATORS,
    OBSERVATION_MODES,
    LiftCriteria,
    Outcome,
    RewardWeights,
    as_dataclass,
)
from coop_gym.envs.core import (
    CMD_LIFT,
    CMD_PUSH,
    CMD_VERBAL,
    FEATURES,
    REPORT,
    REPORT_COLUMNS,
    REWARD_TERMS,
    SitToStandCore,
)
from coop_gym.model.difficulty import Difficulty, get_difficulty
from coop_gym.model.params import Cues, Realism, Timing
from coop_gym.model.personas import Persona, resolve_personas
from estimator.judgment import ThresholdJudgment

__all__ = [
    "FEATURE_BOUNDS",
    "SitToStandConfig",
    "SitToStandEnv",
    "action_space_for",
    "decode_actions",
    "observation_features",
    "observation_space_for",
    "parse_reset_options",
    "render_state_for",
    "report_info",
]

# Observation bounds per feature (low, high); observations are clipped into them.
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

# Slices of FEATURES (one list of names): the readings, the filter's belief and the clock; the
# multiple-model probabilities; the oracle's true xi comes last.
_BELIEF = FEATURES[: FEATURES.index("p_uncooperative")]
_PROBABILITIES = FEATURES[FEATURES.index("p_uncooperative") : FEATURES.index("true_xi")]
_RAW = ("measured_position_m", "measured_force_n", "verbal_cue", "time_since_cue_onset_s", "elapsed_s")

N_FLAT_ACTIONS = 18
"""Size of the flat ``Discrete`` action space: 3 pushes x 3 verbal cues x 2 lift choices."""


def observation_features(observation_mode: str, estimator: str) -> tuple[str, ...]:
    """The features (names from :data:`FEATURES`) an observation holds, in order."""
    if observation_mode == "raw":
        return _RAW
    names = _BELIEF + (_PROBABILITIES if estimator != "kalman" else ())
    return (*names, "true_xi") if observation_mode == "oracle" else names


def observation_space_for(features: Sequence[str], episode_s: float) -> spaces.Box:
    """A float32 Box over ``features`` with the bounds of :data:`FEATURE_BOUNDS`."""
    low = np.array([FEATURE_BOUNDS[f][0] for f in features], dtype=np.float32)
    high = np.array([FEATURE_BOUNDS[f][1] for f in features], dtype=np.float32)
    # Times cannot exceed the episode.
    for k, f in enumerate(features):
        if f in ("time_since_cue_onset_s", "elapsed_s"):
            high[k] = np.float32(episode_s)
    return spaces.Box(low, high, dtype=np.float32)


def action_space_for(action_type: str) -> spaces.Space[Any]:
    """The action space of an action type (see :data:`ACTION_TYPES`)."""
    if action_type == "multidiscrete":
        return spaces.MultiDiscrete([3, 3, 2])
    if action_type == "discrete":
        return spaces.Discrete(N_FLAT_ACTIONS)
    return spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)


_PUSH_LEVELS = 3
_VERBAL_FROM_INDEX = np.array([0.0, -1.0, 1.0])  # none, lean back, lean forward


def decode_actions(
    actions: Any, action_type: str, cues: Cues, n_envs: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Validate a batch of ``n_envs`` actions and turn them into cues.

    Returns:
        ``(push_force_n, verbal_cue, lift)``, each of shape (n_envs,).

    Raises:
        ValueError: naming what is wrong (shape, NaN, non-integer, out of range).
    """
    try:
        a = np.asarray(actions)
    except Exception as exc:  # e.g. ragged lists
        raise ValueError(f"action could not be read as an array: {exc}") from None
    if a.dtype == object or a.dtype.kind not in "biuf":
        raise ValueError(f"action must be numeric, got dtype {a.dtype}")
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
        idx = np.stack(np.unravel_index(a.astype(np.int64), (3, 3, 2)), axis=1)
    elif np.any(a < 0) or np.any(a >= np.array([3, 3, 2])):
        raise ValueError(
            f"multidiscrete action must be [push 0..2, verbal 0..2, lift 0..1], got {np.asarray(actions).tolist()!r}"
        )
    else:
        idx = a.astype(np.int64)
    push = np.array([0.0, soft, firm])[idx[:, 0]]
    return push, _VERBAL_FROM_INDEX[idx[:, 1]], idx[:, 2] == 1


_OUTCOME_LABELS: tuple[str, ...] = tuple(o.label for o in Outcome)


@dataclass(frozen=True)
class SitToStandConfig:
    """Validated constructor arguments shared by the single env and the vector env.

    Build it with :meth:`from_arguments` (the env kwargs; bad values raise ``ValueError``
    naming the argument); :meth:`make_core` then builds the batched simulation.

    Attributes:
        personas: The personas episodes are drawn from.
        observation_mode, action_type, estimator: See :data:`OBSERVATION_MODES`,
            :data:`ACTION_TYPES`, :data:`ESTIMATORS`.
        realism, reward, lift, judgment, timing, cues: The settings dataclasses.
        estimator_options: Keyword arguments of the multiple-model estimator.
        render_mode: ``None``, ``"human"`` or ``"rgb_array"``.
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

    @classmethod
    def from_arguments(
        cls,
        personas: str | Persona | Sequence[str | Persona] = "train",
        observation_mode: str = "belief",
        action_type: str = "multidiscrete",
        estimator: str = "kalman",
        realism: Realism | dict[str, Any] | None = None,
        reward: RewardWeights | dict[str, Any] | None = None,
        lift: LiftCriteria | dict[str, Any] | None = None,
        judgment: ThresholdJudgment | dict[str, Any] | None = None,
        timing: Timing | dict[str, Any] | None = None,
        cues: Cues | dict[str, Any] | None = None,
        estimator_options: dict[str, Any] | None = None,
        render_mode: str | None = None,
        render_modes: Sequence[str] = ("human", "rgb_array"),
        *,
        difficulty: str | Difficulty | None = None,
    ) -> SitToStandConfig:
        """Validate the env arguments (see :class:`SitToStandEnv`, "Arguments")."""
        _check_choice("observation_mode", observation_mode, OBSERVATION_MODES)
        _check_choice("action_type", action_type, ACTION_TYPES)
        _check_choice("estimator", estimator, ESTIMATORS)
        if render_mode is not None and render_mode not in render_modes:
            raise ValueError(f"render_mode must be None or one of {list(render_modes)}, got {render_mode!r}")
        if estimator_options is not None and not isinstance(estimator_options, dict):
            raise ValueError(f"estimator_options must be a dict or None, got {type(estimator_options).__name__}")
        if estimator_options and estimator == "kalman":
            raise ValueError(
                f"estimator_options {sorted(estimator_options)} are for the multiple-model estimators; "
                "estimator='kalman' takes none"
            )
        resolved = resolve_personas(personas)
        if difficulty is not None:
            # The level's knobs on every persona, and its reward unless one is given.
            level = get_difficulty(difficulty)
            resolved = tuple(dataclasses.replace(p, params=level.apply(p.params)) for p in resolved)
            if reward is None:
                reward = level.reward
        return cls(
            personas=resolved,
            observation_mode=observation_mode,
            action_type=action_type,
            estimator=estimator,
            realism=as_dataclass(Realism, realism, "realism"),
            reward=as_dataclass(RewardWeights, reward, "reward"),
            lift=as_dataclass(LiftCriteria, lift, "lift"),
            judgment=as_dataclass(ThresholdJudgment, judgment, "judgment"),
            timing=as_dataclass(Timing, timing, "timing"),
            cues=as_dataclass(Cues, cues, "cues"),
            estimator_options=estimator_options,
            render_mode=render_mode,
        )

    @property
    def features(self) -> tuple[str, ...]:
        """The observation's feature names, in order."""
        return observation_features(self.observation_mode, self.estimator)

    def observation_space(self) -> spaces.Box:
        """The observation space of one env."""
        return observation_space_for(self.features, self.timing.episode_s)

    def action_space(self) -> spaces.Space[Any]:
        """The action space of one env."""
        return action_space_for(self.action_type)

    def make_core(self, n_envs: int) -> SitToStandCore:
        """The batched simulation of ``n_envs`` envs, building this observation."""
        space = self.observation_space()
        return SitToStandCore(
            n_envs,
            self.personas,
            self.timing,
            self.cues,
            self.realism,
            self.lift,
            self.reward,
            self.judgment,
            self.estimator,
            self.estimator_options,
            observation_index=tuple(FEATURES.index(f) for f in self.features),
            observation_low=space.low.astype(np.float64),
            observation_high=space.high.astype(np.float64),
        )

    def command_table(self) -> NDArray[np.float64]:
        """(18, 1, 4) core commands ``[push_force_n, verbal_cue, lift, active]`` of each flat discrete action."""
        push, verbal, lift = decode_actions(np.arange(N_FLAT_ACTIONS), "discrete", self.cues, N_FLAT_ACTIONS)
        table = np.stack([push, verbal, lift.astype(np.float64), np.ones(N_FLAT_ACTIONS)], axis=1)
        return np.ascontiguousarray(table[:, None, :])


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
    if xi is not None and (isinstance(xi, bool) or xi not in (-1, 0, 1)):
        raise ValueError(f"reset option initial_xi must be -1, 0 or 1, got {xi!r}")
    return persona_index, None if xi is None else int(xi)


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


def render_state_for(core: SitToStandCore, i: int, outcome: int, lift: bool, stepped: bool) -> Any:
    """A :class:`coop_gym.envs.rendering.RenderState` of env ``i`` of ``core``.

    Args:
        core: The simulation.
        i: Env index.
        outcome: The env's current :class:`Outcome` code.
        lift: Whether the env's last action lifted.
        stepped: False right after a reset (no push is drawn then).
    """
    from coop_gym.envs.rendering import RenderState

    r = core.report[i]
    probs = None
    if core.mm is not None:
        probs = (
            float(r[REPORT.p_uncooperative]),
            float(r[REPORT.p_unresponsive]),
            float(r[REPORT.p_cooperative]),
        )
    return RenderState(
        time_s=float(r[REPORT.elapsed_s]),
        shoulder_position_m=float(r[REPORT.true_x_m]),
        push_force_n=float(r[REPORT.push_force_n]) if stepped else 0.0,
        verbal_cue=int(r[REPORT.verbal_cue]),
        xi_estimate=float(r[REPORT.xi_hat]),
        xi_std=float(r[REPORT.xi_std]),
        threshold=float(core.judgment.threshold),
        judgment=int(r[REPORT.judgment]),
        true_xi=int(r[REPORT.info_true_xi]),
        outcome=_OUTCOME_LABELS[outcome] if outcome != Outcome.NONE else None,
        probabilities=probs,
        lift=lift,
        success_lean_m=float(core.lift.success_lean_m),
    )


class SitToStandEnv(gym.Env[NDArray[np.float32], Any]):
    r"""A robot caregiver helps an older adult stand up -- once the person is cooperative.

    ## Description

    The simulation of Bell & Asada (ICRA 2022). A seated older adult must lean forward
    so the centre of mass moves over the feet before the robot lifts. Whether the person
    will lean is a hidden mental state, cooperativeness ``xi`` in {-1 uncooperative,
    0 unresponsive, +1 cooperative}; it shows only in how the body answers the robot's
    cues: a push on the upper back and the spoken cues "lean back" / "lean forward".
    The person follows a three-level model: biomechanics (paper eq. 1), intention
    (eq. 6) and a cue-driven Markov chain for ``xi`` encoding the caregiving handbook
    (explain first; a gentle push after an explanation is what turns a person
    cooperative; a firm unprepared push startles; "lean back" confuses; idle
    engagement drifts back). The paper's Kalman filter runs inside the env and its
    estimate is part of the observation. Simulation, sensing and filtering run at
    50 Hz; the agent acts every 0.1 s.

    ## Action Space

    ``action_type="multidiscrete"`` (default): ``MultiDiscrete([3, 3, 2])``

    | Index | Meaning      | Values                                             |
    |-------|--------------|----------------------------------------------------|
    | 0     | physical cue | 0 none, 1 soft push (10 N), 2 firm push (30 N)     |
    | 1     | verbal cue   | 0 none, 1 "lean back", 2 "lean forward" (1 s long) |
    | 2     | lift         | 0 wait, 1 lift (ends the episode)                  |

    ``"discrete"``: ``Discrete(18)``, the flat index of the three above
    (``np.ravel_multi_index(a, (3, 3, 2))``). ``"continuous"``: ``Box(-1, 1, (3,))``:
    push force ``(a0 + 1) / 2 * 30 N``, verbal ``a1 < -1/3`` back, ``> 1/3`` forward,
    lift when ``a2 > 0``. An utterance plays for 1 s; a request while one plays is ignored.

    ## Observation Space

    ``Box`` float32. ``observation_mode="belief"`` (default):

    | Index | Observation                                  | Units | Min  | Max  |
    |-------|----------------------------------------------|-------|------|------|
    | 0     | measured shoulder position (camera)          | m     | -1   | 1    |
    | 1     | measured push force                          | N     | -20  | 220  |
    | 2     | verbal cue playing (-1, 0, +1)               | -     | -1   | 1    |
    | 3     | time since the last cue onset                | s     | 0    | 30   |
    | 4     | Kalman estimate of x                         | m     | -2   | 2    |
    | 5     | Kalman estimate of xdot                      | m/s   | -10  | 10   |
    | 6     | Kalman estimate of eta (intended position)   | m     | -10  | 10   |
    | 7     | Kalman estimate of xi                        | -     | -10  | 10   |
    | 8     | standard deviation of the xi estimate        | -     | 0    | 10   |
    | 9     | latest thresholded judgment (-1, 0, +1)      | -     | -1   | 1    |
    | 10    | elapsed time                                 | s     | 0    | 30   |

    With ``estimator="multiple_model"`` or ``"imm"`` three more entries follow:
    ``P(xi = -1), P(xi = 0), P(xi = +1)``. ``"raw"`` holds only indices 0, 1, 2, 3, 10
    (a policy needs memory); ``"oracle"`` appends the true ``xi`` (an upper bound).
    Values are clipped into the bounds. The judgment is 0 until the first one is made.

    ## Rewards

    Terms (named in ``info["reward_terms"]``, weights in ``RewardWeights``): ``success``
    +1 for a lift with ``xi = +1`` and shoulder at least 0.15 m forward; ``unsafe`` -2 for
    a lift while resisting (``xi = -1``) or still upright (< 0.05 m); ``premature`` -0.5
    for any other lift; ``time`` -0.01 per second; ``force`` -0.0005 per newton-second.

    ## Starting State

    A persona is drawn from ``personas`` and a person around it (about 20 % variation
    of every gain). The person sits upright (``x ~ N(0, 5 mm)``), at rest, intending to
    stay; ``xi`` is drawn from the persona's initial probabilities.

    ## Episode End

    Termination: the robot lifts (``info["outcome"]`` says how it went). Truncation:
    30 s (300 steps) by the ``TimeLimit`` of the registration; ``info["outcome"]`` is
    ``"timeout"`` on that step.

    ## Arguments

    ``gymnasium.make("CoopGym/SitToStand-v0", personas="train", observation_mode="belief",
    action_type="multidiscrete", estimator="kalman", realism=None, reward=None, lift=None,
    judgment=None, timing=None, cues=None, render_mode=None)``. ``personas``: ``"train"``,
    ``"test"``, ``"all"``, a name or a list of names (``coop_gym.PERSONAS``). ``realism``,
    ``reward``, ``lift``, ``judgment``, ``timing``, ``cues``: the dataclass or a dict of its
    fields. Unknown names and out-of-range values raise ``ValueError``.

    ## Vectorized environment

    ``gymnasium.make_vec("CoopGym/SitToStand-v0", num_envs=N)`` builds the natively
    batched :class:`coop_gym.envs.vector.SitToStandVectorEnv` (one compiled call steps all
    ``N``; ``autoreset_mode`` next-step, same-step or disabled); env ``i`` seeded ``s + i``
    matches a single env seeded ``s + i``, across autoresets too. For Stable-Baselines3,
    ``agents.sb3_vec.make_sb3_vec_env(id, N, seed)`` wraps it as an SB3 ``VecEnv``.

    Random stream: a reset draws ``integers``, the person's variation normals, ``random``
    and one normal from ``self.np_random``; each non-lift step then draws 25 standard normals.

    ## Version History

    * v0: initial release.

    Example:
        >>> import gymnasium as gym
        >>> import coop_gym
        >>> env = gym.make("CoopGym/SitToStand-v0")
        >>> obs, info = env.reset(seed=0)
        >>> obs.shape, info["persona"] in coop_gym.TRAIN_PERSONAS
        ((11,), True)
        >>> obs, reward, terminated, truncated, info = env.step([1, 2, 0])
        >>> sorted(info["reward_terms"])
        ['force', 'premature', 'success', 'time', 'unsafe']
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["human", "rgb_array"], "render_fps": 10}  # type: ignore[misc]

    def __init__(
        self,
        personas: str | Persona | Sequence[str | Persona] = "train",
        observation_mode: str = "belief",
        action_type: str = "multidiscrete",
        estimator: str = "kalman",
        realism: Realism | dict[str, Any] | None = None,
        reward: RewardWeights | dict[str, Any] | None = None,
        lift: LiftCriteria | dict[str, Any] | None = None,
        judgment: ThresholdJudgment | dict[str, Any] | None = None,
        timing: Timing | dict[str, Any] | None = None,
        cues: Cues | dict[str, Any] | None = None,
        estimator_options: dict[str, Any] | None = None,
        render_mode: str | None = None,
        difficulty: str | None = None,
    ) -> None:
        """Create the env; see the class docstring for the arguments."""
        config = SitToStandConfig.from_arguments(
            personas,
            observation_mode,
            action_type,
            estimator,
            realism,
            reward,
            lift,
            judgment,
            timing,
            cues,
            estimator_options,
            render_mode,
            self.metadata["render_modes"],
            difficulty=difficulty,
        )
        self.config = config
        self.difficulty = difficulty
        self.render_mode = render_mode
        self.observation_mode = observation_mode
        self.action_type = action_type
        self.personas = config.personas
        self.timing = config.timing
        self.cues = config.cues
        self.core = config.make_core(1)
        self.features = config.features
        self.observation_space = config.observation_space()  # type: ignore[assignment]
        self.action_space = config.action_space()
        # Hot-path views and tables, built once (each step reads them instead of recomputing).
        self._cmd_table = config.command_table()
        self._cmd_row = self.core.cmd[0]
        self._obs_row = self.core.obs[0]
        self._report_row = self.core.report[0]
        self._persona_names = tuple(p.name for p in self.personas)
        self._firm_push_n = float(self.cues.firm_push_n)
        self._has_mm = self.core.mm is not None
        self._needs_reset = True
        self._stepped = False
        self._outcome = int(Outcome.NONE)
        self._renderer: Any = None
        self._last_lift = False

    # --- Gymnasium API ----------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Start an episode; ``options`` may fix ``persona`` (a name) and ``initial_xi``."""
        persona_index, initial_xi = parse_reset_options(options, self.personas)
        super().reset(seed=seed)
        self.core.reset_env(0, self.np_random, persona_index, initial_xi)
        self._needs_reset = False
        self._stepped = False
        self._outcome = int(Outcome.NONE)
        self._last_lift = False
        obs = self._obs_row.copy()
        info = report_info(self._report_row.tolist(), self._persona_names, self._has_mm)
        if self.render_mode == "human":
            self.render()
        return obs, info

    def step(self, action: Any) -> tuple[NDArray[np.float32], SupportsFloat, bool, bool, dict[str, Any]]:
        """Apply one action for 0.1 s (5 simulation steps) or lift."""
        if self._needs_reset:
            raise RuntimeError("SitToStandEnv.step() called before reset() or after the episode ended; call reset()")
        self.core.step_commands(self._command(action))
        r = self._report_row.tolist()
        self._outcome = outcome = int(r[REPORT.outcome])
        # A lift terminates. The episode clock of ``timing`` truncates (the registered
        # TimeLimit agrees with it for the default timing; a custom ``timing`` is honoured too).
        terminated = outcome in (Outcome.SUCCESS, Outcome.UNSAFE, Outcome.PREMATURE)
        truncated = outcome == Outcome.TIMEOUT
        self._last_lift = terminated
        self._needs_reset = terminated
        self._stepped = True
        obs = self._obs_row.copy()
        info = report_info(r, self._persona_names, self._has_mm)
        if self.render_mode == "human":
            self.render()
        return obs, r[REPORT.reward], terminated, truncated, info

    def render(self) -> NDArray[np.uint8] | None:
        """Draw the person, the cues, the estimate gauge and the true ``xi``."""
        if self.render_mode is None:
            gym.logger.warn('render() called without a render_mode; e.g. gym.make(id, render_mode="rgb_array")')
            return None
        from coop_gym.envs.rendering import SitToStandRenderer

        if self._renderer is None:
            self._renderer = SitToStandRenderer()
        state = self.render_state()
        if self.render_mode == "rgb_array":
            return self._renderer.render_rgb(state)  # type: ignore[no-any-return]
        self._renderer.render_human(state, self.metadata["render_fps"])
        return None

    def close(self) -> None:
        """Close the window, if any; safe to call twice."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __getstate__(self) -> dict[str, Any]:
        """Pickle without the renderer (pygame objects) and the row views into the core."""
        state = {k: v for k, v in self.__dict__.items() if k not in ("_cmd_row", "_obs_row", "_report_row")}
        state["_renderer"] = None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Restore, re-pointing the row views at the unpickled core (which rebuilds itself)."""
        self.__dict__.update(state)
        self._cmd_row = self.core.cmd[0]
        self._obs_row = self.core.obs[0]
        self._report_row = self.core.report[0]

    # --- helpers ----------------------------------------------------------------

    def render_state(self) -> Any:
        """A :class:`coop_gym.envs.rendering.RenderState` snapshot of the current step."""
        return render_state_for(self.core, 0, self._outcome, self._last_lift, self._stepped)

    def _command(self, action: Any) -> NDArray[np.float64]:
        """Validate one action and return its (1, 4) command for the core.

        The common cases (what ``action_space.sample()`` and SB3's ``predict`` give) are
        checked with plain Python on the action's values; anything else goes through
        :func:`decode_actions`, which accepts the same actions and names what is wrong.
        """
        kind = self.action_type
        if kind == "multidiscrete":
            if type(action) is np.ndarray and action.shape == (3,) and action.dtype.kind in "iu":
                push, verbal, lift = action.tolist()
                if 0 <= push <= 2 and 0 <= verbal <= 2 and 0 <= lift <= 1:
                    return self._cmd_table[(push * 3 + verbal) * 2 + lift]  # type: ignore[no-any-return]
        elif kind == "discrete":
            if isinstance(action, (int, np.integer)) and not isinstance(action, bool) and 0 <= action < N_FLAT_ACTIONS:
                return self._cmd_table[int(action)]  # type: ignore[no-any-return]
        elif type(action) is np.ndarray and action.shape == (3,) and action.dtype.kind == "f":
            a_push, a_verbal, a_lift = action.tolist()
            if all(math.isfinite(a) and -1.0 - 1e-6 <= a <= 1.0 + 1e-6 for a in (a_push, a_verbal, a_lift)):
                row = self._cmd_row
                # As decode_actions: push (a0 + 1) / 2 * firm, verbal in thirds, lift when a2 > 0.
                row[CMD_PUSH] = (min(max(a_push, -1.0), 1.0) + 1.0) * 0.5 * self._firm_push_n
                row[CMD_VERBAL] = -1.0 if a_verbal < -1.0 / 3.0 else (1.0 if a_verbal > 1.0 / 3.0 else 0.0)
                row[CMD_LIFT] = 1.0 if a_lift > 0.0 else 0.0
                return self.core.cmd
        # A list, not np.asarray(action)[None]: decode_actions names what is wrong with a ragged one.
        push_n, verbal_cue, lift_flag = decode_actions([action], kind, self.cues, 1)
        cmd = self.core.cmd
        cmd[0, CMD_PUSH] = push_n[0]
        cmd[0, CMD_VERBAL] = verbal_cue[0]
        cmd[0, CMD_LIFT] = 1.0 if lift_flag[0] else 0.0
        return cmd


_REPORT_LAYOUT = (
    *FEATURES,
    "reward_success",
    "reward_unsafe",
    "reward_premature",
    "reward_time",
    "reward_force",
    "reward",
    "outcome",
    "push_force_n",
    "true_x_m",
    "true_xdot_m_per_s",
    "true_eta_m",
    "info_true_xi",
    "persona_index",
)


def _check_report_layout() -> None:
    """report_info unpacks report rows by position: fail at import if the layout moved.

    An explicit check, not an ``assert``: it must hold under ``python -O`` too.
    """
    if REPORT_COLUMNS != _REPORT_LAYOUT:
        raise RuntimeError("REPORT_COLUMNS changed: update report_info")
    if REWARD_TERMS != ("success", "unsafe", "premature", "time", "force"):
        raise RuntimeError("REWARD_TERMS changed: update report_info")


_check_report_layout()


def _check_choice(name: str, value: Any, choices: Sequence[str]) -> None:
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name} must be one of {list(choices)}, got {value!r}")
