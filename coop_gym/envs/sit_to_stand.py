"""The single sit-to-stand environment."""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import EnvSpec
from numpy.typing import NDArray

from coop_gym.envs.arguments import EnvArguments, parse_reset_options
from coop_gym.envs.config import Outcome
from coop_gym.envs.core import ConfiguredEnv, render_state_for
from coop_gym.envs.kernels.report import REPORT, episode_end
from coop_gym.envs.observation import observation_features

__all__ = [
    "SitToStandEnv",
    "observation_features",  # the contract's, for the importers of this module (agents.caregivers.scripted)
]


class SitToStandEnv(ConfiguredEnv, gym.Env[NDArray[np.float32], Any]):
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

    ``observation_scale="unit"`` (the ``...Unit-v0`` / ``-v1`` / ``-v2`` ids) divides each feature
    by a scale (``coop_gym.envs.contract.FEATURE_SCALES``) and clips into [-1, 1]: positions
    0.5 m, speed 0.5 m/s, force 40 N, ``xi`` estimate 2, its std 1.25, clocks the episode
    length (30 s), the rest 1. Every feature then spans [-1, 1] or [0, 1] (the force
    [-0.5, 1]), so a policy network learns with a library's default settings. The features
    are renamed by their scale (``"x_hat_m/0.5"``) and ``info["unscaled_obs"]`` holds the
    observation above, in its units.

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

    Termination: the robot lifts (``info["outcome"]`` says how it went). Truncation: the
    episode's length, ``timing.max_episode_steps`` (the steps of ``timing.episode_s``):
    30 s (300 steps) by the ``TimeLimit`` rule (a lift on the last step is truncated too) but from
    the env, so any ``timing`` gives the episode it asks for (``timing={"episode_s": 60}``: 600 steps);
    ``info["outcome"]`` is ``"timeout"`` on that step. Both envs end episodes by one rule,
    :func:`coop_gym.envs.kernels.report.episode_end`. The registered ids add no ``TimeLimit``
    wrapper; ``env.spec.max_episode_steps`` reports the length (``Timing.max_episode_steps``), and
    ``gym.make(id, max_episode_steps=n)`` adds a ``TimeLimit`` of ``n`` steps. Stepping after
    either end raises ``RuntimeError`` until ``reset()``.

    ## Arguments

    ``gymnasium.make("CoopGym/SitToStand-v0", personas="train", observation_mode="belief",
    action_type="multidiscrete", estimator="kalman", realism=None, reward=None, lift=None,
    judgment=None, timing=None, cues=None, render_mode=None)``. ``personas``: ``"train"``,
    ``"test"``, ``"all"``, a name or a list of names (``coop_gym.PERSONAS``). ``realism``,
    ``reward``, ``lift``, ``judgment``, ``timing``, ``cues``: the dataclass or a dict of its
    fields. Unknown names and out-of-range values raise ``ValueError``; an unknown keyword
    raises ``TypeError``. The keywords are those of :class:`coop_gym.envs.contract.EnvArguments`
    (shared by the vector env and the registered ids), plus ``difficulty`` (``-v1`` ids),
    ``observation_scale`` (``"none"`` or ``"unit"``, see "Observation Space") and ``info_mode``:

    * ``"default"``: ``info`` holds ``true_x_m``, ``true_xdot_m_per_s``, ``true_eta_m``,
      ``true_xi``, ``persona`` (name), ``outcome`` (label), ``judgment``, ``xi_estimate``,
      ``push_force_n``, ``verbal_cue``, ``elapsed_s``, ``reward_terms`` (a dict) and, with a
      multiple-model estimator, ``xi_probabilities``;
    * ``"numeric"``: NumPy numbers only, no labels, no nested dicts (for TensorDict-based
      clients such as TorchRL): ``persona_index``, ``outcome_code`` (an ``Outcome`` value),
      ``reward_success`` ... ``reward_force``, ``p_uncooperative`` ... ``p_cooperative``
      instead (``coop_gym.envs.contract.NUMERIC_INFO_KEYS``).

    ## Vectorized environment

    ``gymnasium.make_vec("CoopGym/SitToStand-v0", num_envs=N)`` builds the natively
    batched :class:`coop_gym.envs.vector.SitToStandVectorEnv` (one compiled call steps all
    ``N``; ``autoreset_mode`` next-step, same-step or disabled); env ``i`` seeded ``s + i``
    matches a single env seeded ``s + i``, across autoresets too. For Stable-Baselines3,
    ``agents.rl.sb3_vec.make_sb3_vec_env(id, N, seed)`` wraps it as an SB3 ``VecEnv``.

    Random stream: a reset draws ``integers``, the person's variation normals, ``random``
    and one normal from ``self.np_random``; each non-lift step then draws 25 standard normals.

    ## Version History

    * v0: initial release.
    * v1: difficulty levels (``difficulty``) and the safety-priced reward.
    * v2: the ``hard-v2`` level, two of ``hard``'s knobs changed (``difficulty="hard-v2"``):
      ``SitToStandHard-v2`` and its ``Discrete``, ``HeldOut`` and ``Unit`` variants.
    * ``Unit`` ids (``SitToStandUnit-v0``, ``SitToStandHardUnit-v1``, ...): the ids they
      scale, with ``observation_scale="unit"``; same task and dynamics, so same version
      (a new name, not a ``-v2``: Gymnasium warns that an id is out of date once a higher
      version of its name is registered).

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
    _spec: EnvSpec | None = None

    def __init__(self, **kwargs: Any) -> None:
        """Create the env from the keywords of :class:`~coop_gym.envs.contract.EnvArguments` (see "Arguments")."""
        arguments = EnvArguments.from_keywords(type(self).__name__, kwargs)
        config = arguments.resolve(self.metadata["render_modes"])
        self.difficulty = arguments.difficulty
        self._take_config(config, 1)
        self.observation_space = config.observation_space()  # type: ignore[assignment]
        self.action_space = config.action_space()
        # Hot-path views and tables, built once (each step reads them instead of recomputing).
        self._cmd = self.core.cmd
        self._obs_row = self.core.obs[0]
        self._report_row = self.core.report[0]
        self._needs_reset = True
        self._stepped = False
        self._outcome = int(Outcome.NONE)
        self._episode_steps = 0
        self._max_episode_steps = config.timing.max_episode_steps
        self._renderer: Any = None
        self._last_lift = False

    # --- Gymnasium API ----------------------------------------------------------

    @property  # type: ignore[override]
    def spec(self) -> EnvSpec | None:
        """The registration's spec, its ``max_episode_steps`` the episode length of this env's ``timing``.

        The ids register no ``TimeLimit`` (the env truncates at its length), so ``gym.make`` hands over a
        spec without a length; clients that read ``env.spec.max_episode_steps`` (sb3-contrib's
        ``TimeFeatureWrapper``, ``gym.make(env.spec)``) get the length the env really has.
        """
        return self._spec

    @spec.setter
    def spec(self, value: EnvSpec | None) -> None:
        if value is not None and value.max_episode_steps is None:
            value = dataclasses.replace(value, max_episode_steps=self.timing.max_episode_steps)
        self._spec = value

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
        self._episode_steps = 0
        self._last_lift = False
        obs = self._observe(self._obs_row)
        info = self._info.single(self._report_row.tolist())
        if self.render_mode == "human":
            self.render()
        return obs, info

    def step(self, action: Any) -> tuple[NDArray[np.float32], SupportsFloat, bool, bool, dict[str, Any]]:
        """Apply one action for 0.1 s (5 simulation steps) or lift."""
        if self._needs_reset:
            # Terminated or truncated alike: the episode is over.
            raise RuntimeError("SitToStandEnv.step() called before reset() or after the episode ended; call reset()")
        self.core.step_commands(self._actions.single(action, self._cmd))
        r = self._report_row.tolist()
        self._episode_steps += 1
        outcome, terminated, truncated = episode_end(
            int(r[REPORT.outcome]), self._episode_steps, self._max_episode_steps, self._max_episode_steps
        )
        self._outcome = outcome
        self._report_row[REPORT.outcome] = r[REPORT.outcome] = outcome
        self._last_lift = terminated
        self._needs_reset = terminated or truncated
        self._stepped = True
        obs = self._observe(self._obs_row)
        info = self._info.single(r)
        if self.render_mode == "human":
            self.render()
        return obs, r[REPORT.reward], terminated, truncated, info

    def render(self) -> NDArray[np.uint8] | None:
        """Draw the person, the cues, the estimate gauge and the true ``xi``."""
        if self.render_mode is None:
            gym.logger.warn('render() called without a render_mode; e.g. gym.make(id, render_mode="rgb_array")')
            return None
        from coop_gym.envs.render.renderer import SitToStandRenderer

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
        state = {k: v for k, v in self.__dict__.items() if k not in ("_cmd", "_obs_row", "_report_row")}
        state["_renderer"] = None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Restore, re-pointing the row views at the unpickled core (which rebuilds itself)."""
        self.__dict__.update(state)
        self._cmd = self.core.cmd
        self._obs_row = self.core.obs[0]
        self._report_row = self.core.report[0]

    # --- helpers ----------------------------------------------------------------

    def render_state(self) -> Any:
        """A :class:`coop_gym.envs.render.renderer.RenderState` snapshot of the current step."""
        return render_state_for(self.core, 0, self._outcome, self._last_lift, self._stepped)
