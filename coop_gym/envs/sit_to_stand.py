"""The single sit-to-stand environment."""

from __future__ import annotations

from collections.abc import Sequence
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
from coop_gym.envs.core import FEATURES, REWARD_TERMS, SitToStandCore
from coop_gym.model.params import Cues, Realism, Timing
from coop_gym.model.personas import Persona, resolve_personas
from estimator.judgment import ThresholdJudgment

__all__ = [
    "FEATURE_BOUNDS",
    "SitToStandEnv",
    "action_space_for",
    "decode_actions",
    "observation_features",
    "observation_space_for",
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

_BELIEF = (
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
)
_PROBABILITIES = ("p_uncooperative", "p_unresponsive", "p_cooperative")
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
    idx = a.astype(np.int64)
    if action_type == "discrete":
        if np.any(idx < 0) or np.any(idx >= N_FLAT_ACTIONS):
            raise ValueError(f"discrete action must be in [0, {N_FLAT_ACTIONS - 1}], got {actions!r}")
        idx = np.stack(np.unravel_index(idx, (3, 3, 2)), axis=1)
    elif np.any(idx < 0) or np.any(idx >= np.array([3, 3, 2])):
        raise ValueError(
            f"multidiscrete action must be [push 0..2, verbal 0..2, lift 0..1], got {np.asarray(actions).tolist()!r}"
        )
    push = np.array([0.0, soft, firm])[idx[:, 0]]
    return push, _VERBAL_FROM_INDEX[idx[:, 1]], idx[:, 2] == 1


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

    A persona is drawn from ``personas`` and a person around it (about 15 % variation
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
    batched :class:`coop_gym.envs.vector.SitToStandVectorEnv`; env ``i`` seeded ``s + i``
    matches a single env seeded ``s + i``.

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

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

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
    ) -> None:
        """Create the env; see the class docstring for the arguments."""
        _check_choice("observation_mode", observation_mode, OBSERVATION_MODES)
        _check_choice("action_type", action_type, ACTION_TYPES)
        _check_choice("estimator", estimator, ESTIMATORS)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode = render_mode
        self.observation_mode = observation_mode
        self.action_type = action_type
        self.personas = resolve_personas(personas)
        self.timing: Timing = as_dataclass(Timing, timing, "timing")
        self.cues: Cues = as_dataclass(Cues, cues, "cues")
        self.core = SitToStandCore(
            1,
            self.personas,
            self.timing,
            self.cues,
            as_dataclass(Realism, realism, "realism"),
            as_dataclass(LiftCriteria, lift, "lift"),
            as_dataclass(RewardWeights, reward, "reward"),
            as_dataclass(ThresholdJudgment, judgment, "judgment"),
            estimator,
            estimator_options,
        )
        self.features = observation_features(observation_mode, estimator)
        self._feature_index = np.array([FEATURES.index(f) for f in self.features])
        self.observation_space = observation_space_for(self.features, self.timing.episode_s)
        self.action_space = action_space_for(action_type)
        self._low = self.observation_space.low.astype(np.float64)
        self._high = self.observation_space.high.astype(np.float64)
        self._needs_reset = True
        self._outcome = Outcome.NONE
        self._renderer: Any = None
        self._last_lift = False

    # --- Gymnasium API ----------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Start an episode; ``options`` may fix ``persona`` (a name) and ``initial_xi``."""
        persona_index, initial_xi = self._reset_options(options)
        super().reset(seed=seed)
        self.core.reset_env(0, self.np_random, persona_index, initial_xi)
        self._needs_reset = False
        self._outcome = Outcome.NONE
        self._last_lift = False
        obs = self._observation()
        info = self._info(reward_terms=None)
        if self.render_mode == "human":
            self.render()
        return obs, info

    def step(self, action: Any) -> tuple[NDArray[np.float32], SupportsFloat, bool, bool, dict[str, Any]]:
        """Apply one action for 0.1 s (5 simulation steps) or lift."""
        if self._needs_reset:
            raise RuntimeError("SitToStandEnv.step() called before reset() or after the episode ended; call reset()")
        push, verbal, lift = decode_actions(
            np.asarray(action)[None] if np.ndim(action) > 0 or self.action_type != "discrete" else [action],
            self.action_type,
            self.cues,
            1,
        )
        out = self.core.step(push, verbal, lift)
        self._outcome = Outcome(int(out.outcome[0]))
        self._last_lift = bool(lift[0])
        terminated = bool(out.terminated[0])
        if terminated:
            self._needs_reset = True
        terms = {name: float(out.reward_terms[0, k]) for k, name in enumerate(REWARD_TERMS)}
        obs = self._observation()
        info = self._info(reward_terms=terms)
        if self.render_mode == "human":
            self.render()
        return obs, float(out.reward[0]), terminated, False, info

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

    # --- helpers ----------------------------------------------------------------

    def render_state(self) -> Any:
        """A :class:`coop_gym.envs.rendering.RenderState` snapshot of the current step."""
        from coop_gym.envs.rendering import RenderState

        f = self.core.out.features[0]
        truth = self.core.true_state(0)
        probs = None
        if self.core.mm is not None:
            probs = (
                float(f[FEATURES.index("p_uncooperative")]),
                float(f[FEATURES.index("p_unresponsive")]),
                float(f[FEATURES.index("p_cooperative")]),
            )
        return RenderState(
            time_s=float(f[FEATURES.index("elapsed_s")]),
            shoulder_position_m=truth["true_x_m"],
            push_force_n=float(self.core.out.push_force_n[0]) if not self._needs_reset or self._outcome else 0.0,
            verbal_cue=int(f[FEATURES.index("verbal_cue")]),
            xi_estimate=float(f[FEATURES.index("xi_hat")]),
            xi_std=float(f[FEATURES.index("xi_std")]),
            threshold=float(self.core.judgment.threshold),
            judgment=int(f[FEATURES.index("judgment")]),
            true_xi=truth["true_xi"],
            outcome=self._outcome.label if self._outcome != Outcome.NONE else None,
            probabilities=probs,
            lift=self._last_lift,
            success_lean_m=float(self.core.lift.success_lean_m),
        )

    def _reset_options(self, options: dict[str, Any] | None) -> tuple[int | None, int | None]:
        """Validate ``reset(options=...)``: ``persona`` (a name of this env's) and ``initial_xi``."""
        if not options:
            return None, None
        if not isinstance(options, dict):
            raise ValueError(f"reset options must be a dict, got {type(options).__name__}")
        unknown = sorted(set(options) - {"persona", "initial_xi"})
        if unknown:
            raise ValueError(f"unknown reset option(s) {unknown}; known: ['initial_xi', 'persona']")
        persona_index = None
        if "persona" in options:
            names = [p.name for p in self.personas]
            if options["persona"] not in names:
                raise ValueError(f"reset option persona={options['persona']!r} is not one of this env's {names}")
            persona_index = names.index(options["persona"])
        xi = options.get("initial_xi")
        if xi is not None and (isinstance(xi, bool) or xi not in (-1, 0, 1)):
            raise ValueError(f"reset option initial_xi must be -1, 0 or 1, got {xi!r}")
        return persona_index, xi

    def _observation(self) -> NDArray[np.float32]:
        f = self.core.out.features[0, self._feature_index]
        return np.clip(f, self._low, self._high).astype(np.float32)

    def _info(self, reward_terms: dict[str, float] | None) -> dict[str, Any]:
        core = self.core
        f = core.out.features[0]
        info: dict[str, Any] = core.true_state(0)
        info["persona"] = core.personas[int(core.persona_index[0])].name
        info["outcome"] = self._outcome.label
        info["judgment"] = int(f[FEATURES.index("judgment")])
        info["xi_estimate"] = float(f[FEATURES.index("xi_hat")])
        info["push_force_n"] = float(core.out.push_force_n[0]) if reward_terms is not None else 0.0
        info["verbal_cue"] = int(f[FEATURES.index("verbal_cue")])
        info["elapsed_s"] = float(f[FEATURES.index("elapsed_s")])
        if core.mm is not None:
            info["xi_probabilities"] = f[FEATURES.index("p_uncooperative") : FEATURES.index("p_cooperative") + 1].copy()
        info["reward_terms"] = reward_terms if reward_terms is not None else dict.fromkeys(REWARD_TERMS, 0.0)
        return info


def _check_choice(name: str, value: Any, choices: Sequence[str]) -> None:
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name} must be one of {list(choices)}, got {value!r}")
