"""The natively batched sit-to-stand environment (``gymnasium.make_vec``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import NDArray

from coop_gym.envs.actions import CMD
from coop_gym.envs.arguments import EnvArguments, parse_reset_options
from coop_gym.envs.core import ConfiguredEnv, check_threads, render_state_for
from coop_gym.envs.kernels.report import REPORT, count_steps_and_end_episodes
from coop_gym.envs.kernels.seeding import MAX_BATCH_SEED
from estimator.compiled.rng import G_STATE
from estimator.validate import is_integer

__all__ = ["SitToStandVectorEnv"]


class SitToStandVectorEnv(ConfiguredEnv, VectorEnv):
    r"""``N`` sit-to-stand episodes stepped by one compiled call: :class:`SitToStandEnv`, batched.

    The same simulation core as the single env (see its docstring for the task, the
    spaces, the rewards and the episode end), with ``N`` envs instead of one. Env ``i``
    reset with seed ``s + i`` (``reset(seed=s)``) plays exactly what a single env reset
    with seed ``s + i`` plays under the same actions, across autoresets too.

    ## Arguments

    ``gymnasium.make_vec(id, num_envs=N, autoreset_mode=..., **env_kwargs)`` (or the class
    directly): ``num_envs``; every :class:`SitToStandEnv` keyword (the contract's
    :class:`~coop_gym.envs.contract.EnvArguments`); ``max_episode_steps``
    (truncation, inside this env; default 30 s of steps, what ``make_vec`` passes from the
    registration); ``autoreset_mode``: an ``AutoresetMode`` or its value:

    * ``NEXT_STEP`` (default): the step after an episode ends resets that env instead of
      stepping it (reward 0, not done, the reset observation and info);
    * ``SAME_STEP``: the env is reset on the step that ends its episode; the final
      observation and info are in ``infos["final_obs"]`` / ``infos["final_info"]`` (with
      ``_final_obs`` / ``_final_info`` masks);
    * ``DISABLED``: finished envs must be reset by the caller with
      ``reset(options={"reset_mask": mask})``; stepping them raises.

    ``threads``: the compiled step runs on up to this many threads (default ``None``: the cores
    this process may use); batches under 512 envs per thread step on one. Every env draws only
    from its own generator, so the results are bit-identical whatever the count.

    ## Reset

    ``reset(seed=None | int | list, options=None)``: an int seeds env ``i`` with ``seed + i``
    (``gymnasium.utils.seeding.np_random``); a list gives each env its seed (``None``: keep
    its generator). ``options["reset_mask"]`` (bool array of shape ``(N,)``) resets only
    those envs; ``options["persona"]`` / ``options["initial_xi"]`` apply to every env reset.

    ## Infos

    A dict of arrays with ``_key`` masks, as Gymnasium's vector envs return:
    ``true_x_m``, ``true_xdot_m_per_s``, ``true_eta_m``, ``true_xi``, ``persona`` (names),
    ``persona_index``, ``outcome`` (labels as in the single env), ``outcome_code``
    (:class:`Outcome` ints), ``judgment``, ``xi_estimate``, ``push_force_n``, ``verbal_cue``,
    ``elapsed_s``, ``reward_terms`` (a dict of arrays) and, with a multiple-model estimator,
    ``xi_probabilities`` (N, 3).

    ## Rendering

    ``render()`` draws env 0 (``"rgb_array"``: returns its frame).

    Example:
        >>> import gymnasium as gym
        >>> import coop_gym
        >>> envs = gym.make_vec("CoopGym/SitToStand-v0", num_envs=4)
        >>> obs, infos = envs.reset(seed=0)
        >>> obs.shape, obs.dtype
        ((4, 11), dtype('float32'))
        >>> obs, rewards, terminated, truncated, infos = envs.step(envs.action_space.sample())
        >>> rewards.shape, sorted(infos["reward_terms"])[:2]
        ((4,), ['_force', '_premature'])
    """

    metadata: ClassVar[dict[str, Any]] = {  # type: ignore[misc]
        "render_modes": ["human", "rgb_array"],
        "render_fps": 10,
        "autoreset_mode": AutoresetMode.NEXT_STEP,
    }

    def __init__(
        self,
        num_envs: int = 1,
        *,
        max_episode_steps: int | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        **kwargs: Any,
    ) -> None:
        """Create ``num_envs`` envs; ``kwargs``: the keywords of :class:`~coop_gym.envs.contract.EnvArguments`."""
        if not is_integer(num_envs) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive int, got {num_envs!r}")
        arguments = EnvArguments.from_keywords(type(self).__name__, kwargs)
        config = arguments.resolve(self.metadata["render_modes"])
        threads = check_threads(arguments.threads)
        self.difficulty = arguments.difficulty
        if max_episode_steps is None:
            max_episode_steps = config.timing.max_episode_steps
        if not is_integer(max_episode_steps):
            raise ValueError(f"max_episode_steps must be a positive int or None, got {max_episode_steps!r}")
        if max_episode_steps < 1:
            raise ValueError(f"max_episode_steps must be a positive int or None, got {max_episode_steps!r}")
        self.autoreset_mode = _autoreset_mode(autoreset_mode)
        self.metadata = {**type(self).metadata, "autoreset_mode": self.autoreset_mode}  # type: ignore[misc]
        self.num_envs = n = int(num_envs)
        self.max_episode_steps = int(max_episode_steps)
        self._take_config(config, n)
        self._episode_length = config.timing.max_episode_steps
        self.core.set_threads(threads)
        self.threads = threads
        self.single_observation_space = config.observation_space()
        self.single_action_space = config.action_space()
        self.observation_space = batch_space(self.single_observation_space, n)
        self.action_space = batch_space(self.single_action_space, n)
        self._episode_steps = np.zeros(n, dtype=np.int64)
        self._done = np.zeros(n, dtype=bool)  # finished, waiting for an (auto)reset
        self._started = np.zeros(n, dtype=bool)  # reset at least once
        self._all = np.arange(n, dtype=np.int64)
        self._renderer: Any = None
        self._env0_stepped = False
        self._env0_lift = False

    # --- Gymnasium vector API ---------------------------------------------------

    def reset(
        self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Reset all envs, or those of ``options["reset_mask"]``; see the class docstring."""
        seeds = self._seed_list(seed)
        if options is not None and not isinstance(options, dict):  # before dict(): a str would fail there, unclearly
            raise ValueError(f"reset options must be a dict, got {type(options).__name__}")
        options = dict(options) if options else {}
        mask = self._reset_mask(options.pop("reset_mask", None))
        persona_index, initial_xi = parse_reset_options(options, self.personas)
        if is_integer(seed):
            super().reset(seed=int(seed))  # the vector env's own np_random, as Gymnasium's envs do
        indices = self._all[mask]
        core = self.core
        self._seed_envs(indices, seeds)
        core.reset_envs(indices, persona_index, initial_xi)
        self._episode_steps[mask] = 0
        self._done[mask] = False
        self._started[mask] = True
        if mask[0]:
            self._env0_stepped = False
            self._env0_lift = False
        obs = self._observe(core.obs)
        infos = self._infos(core.report, mask)
        if self.render_mode == "human":
            self.render()
        return obs, infos

    def step(
        self, actions: Any
    ) -> tuple[NDArray[np.float32], NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_], dict[str, Any]]:
        """Apply one action per env for 0.1 s (or lift), with the autoreset of ``autoreset_mode``."""
        obs, rewards, terminated, truncated, final = self.step_rows(actions)
        infos = self._infos(self.core.report, None)
        if final is not None:
            done, last_obs, last_report = final
            final_obs = np.full(self.num_envs, None, dtype=object)
            for i in np.flatnonzero(done):
                final_obs[i] = last_obs[i]
            infos["final_obs"] = final_obs
            infos["_final_obs"] = done.copy()
            infos["final_info"] = self._infos(last_report, done)
            infos["_final_info"] = done.copy()
        if self.render_mode == "human":
            self.render()
        return obs, rewards, terminated, truncated, infos

    def step_rows(
        self, actions: Any
    ) -> tuple[
        NDArray[np.float32],
        NDArray[np.float64],
        NDArray[np.bool_],
        NDArray[np.bool_],
        tuple[NDArray[np.bool_], NDArray[np.float32], NDArray[np.float64]] | None,
    ]:
        """:meth:`step` without building the info dicts (for adapters that build their own).

        Returns:
            ``(obs, rewards, terminated, truncated, final)``; the infos' values are the rows
            of ``self.core.report`` (:data:`~coop_gym.envs.kernels.report.REPORT_COLUMNS`). ``final`` is
            None unless envs ended and were reset on this step (``SAME_STEP``); then it is
            ``(done, last_obs, last_report)``, observations and report rows from before the
            reset (rows of other envs are stale).
        """
        self._check_started()
        core = self.core
        self._actions.batch(actions, core.cmd)
        mode = self.autoreset_mode
        pending = self._done
        self._check_no_reset_waits()
        # NEXT_STEP: the envs that finished last step are reset now instead of stepped (in the
        # same call: on a threaded step the resets overlap the stepping).
        stepped = ~pending
        cmd = core.cmd
        cmd[:, CMD.active] = stepped
        resetting = mode == AutoresetMode.NEXT_STEP and pending.any()
        core.step_commands(cmd, reset=self._all[pending] if resetting else None)
        if stepped[0]:
            self._env0_stepped = True
            self._env0_lift = bool(cmd[0, CMD.lift] > 0.5)
        report = core.report
        n = self.num_envs
        rewards = np.empty(n)
        terminated = np.empty(n, dtype=bool)
        truncated = np.empty(n, dtype=bool)
        # Truncated by the step limit or at the episode's length of ``timing``, whichever comes first
        # (report.count_steps_and_end_episodes: report.episode_end with the step count, in one compiled pass).
        steps, length, limit = self._episode_steps, self._episode_length, self.max_episode_steps
        count_steps_and_end_episodes(report, cmd, steps, length, limit, rewards, terminated, truncated)
        done = terminated | truncated
        final = None
        if mode == AutoresetMode.NEXT_STEP:
            if resetting:
                self._restart_counts(pending)
            self._done = done
        elif mode == AutoresetMode.SAME_STEP:
            if done.any():
                final = (done, self._observe(core.obs), report.copy())
                self._reset_finished(done)
        else:
            self._done = done
        return self._observe(core.obs), rewards, terminated, truncated, final

    def _check_started(self) -> None:
        """Raise unless every env was reset."""
        if not self._started.all():
            never = np.flatnonzero(~self._started).tolist()
            raise RuntimeError(f"step() called before reset(): envs {never} were never reset; call reset()")

    def _check_no_reset_waits(self) -> None:
        """With autoreset disabled, raise if an env's episode ended and it was not reset."""
        if self.autoreset_mode == AutoresetMode.DISABLED and self._done.any():
            raise RuntimeError(
                f"envs {np.flatnonzero(self._done).tolist()} finished their episodes and autoreset is disabled; "
                'reset them with reset(options={"reset_mask": mask}) before stepping'
            )

    def render(self) -> NDArray[np.uint8] | None:  # type: ignore[override]
        """Draw env 0 (``"rgb_array"``: return its frame)."""
        if self.render_mode is None:
            gym.logger.warn('render() called without a render_mode; e.g. gym.make_vec(id, render_mode="rgb_array")')
            return None
        from coop_gym.envs.render.renderer import SitToStandRenderer

        if self._renderer is None:
            self._renderer = SitToStandRenderer()
        outcome = int(self.core.report[0, REPORT.outcome])
        state = render_state_for(self.core, 0, outcome, self._env0_lift, self._env0_stepped)
        if self.render_mode == "rgb_array":
            return self._renderer.render_rgb(state)  # type: ignore[no-any-return]
        self._renderer.render_human(state, self.metadata["render_fps"])
        return None

    def close_extras(self, **kwargs: Any) -> None:
        """Close the window, if any."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # --- helpers ----------------------------------------------------------------

    def _reset_finished(self, mask: NDArray[np.bool_]) -> None:
        """Autoreset the envs of ``mask``, each continuing its own generator."""
        if mask.any():
            self.core.reset_envs(self._all[mask])
            self._restart_counts(mask)
        self._done = np.zeros(self.num_envs, dtype=bool)

    def _restart_counts(self, mask: NDArray[np.bool_]) -> None:
        """The bookkeeping of an autoreset of the envs of ``mask`` (the core has reset them)."""
        self._episode_steps[mask] = 0
        if mask[0]:
            self._env0_stepped = False
            self._env0_lift = False

    def _seed_envs(self, indices: NDArray[np.int64], seeds: list[int | None]) -> None:
        """Give the envs of ``indices`` with a seed ``Generator(PCG64(seed))``, all in one call.

        Seeded in a batch (``SitToStandCore.seed_envs``: 10^5 envs in milliseconds, where a
        ``Generator`` object each took seconds), the same numbers as
        ``gymnasium.utils.seeding.np_random(seed)``. An env without a seed keeps its generator;
        one that has none yet is seeded from fresh entropy.
        """
        core = self.core
        batch_envs: list[int] = []
        batch_seeds: list[int] = []
        for i in indices.tolist():
            s = seeds[i]
            if s is None:
                continue
            if s <= MAX_BATCH_SEED:
                batch_envs.append(i)
                batch_seeds.append(s)
            else:
                core.set_rng(i, seeding.np_random(s)[0])
        if batch_envs:
            core.seed_envs(np.array(batch_envs, dtype=np.int64), np.array(batch_seeds, dtype=np.uint64))
        fresh = indices[core.generators[indices, G_STATE] == 0]
        if fresh.shape[0]:
            entropy = np.random.default_rng()  # OS entropy, as seeding.np_random(None)
            core.seed_envs(fresh, entropy.integers(0, MAX_BATCH_SEED, fresh.shape[0], dtype=np.uint64, endpoint=True))

    def _seed_list(self, seed: int | Sequence[int | None] | None) -> list[int | None]:
        n = self.num_envs
        if seed is None:
            return [None] * n
        if is_integer(seed):
            if seed < 0:
                raise ValueError(f"seed must be a non-negative int, got {seed!r}")
            return [int(seed) + i for i in range(n)]
        if isinstance(seed, (str, bytes)) or not isinstance(seed, (Sequence, np.ndarray)):
            raise ValueError(f"seed must be None, an int or a list of {n} ints/None, got {seed!r}")
        seeds = list(seed)
        if len(seeds) != n:
            raise ValueError(f"a list of seeds must have num_envs={n} entries, got {len(seeds)}")
        for s in seeds:
            if s is not None and (not is_integer(s) or s < 0):
                raise ValueError(f"each seed must be a non-negative int or None, got {s!r}")
        return [None if s is None else int(s) for s in seeds]

    def _reset_mask(self, mask: Any) -> NDArray[np.bool_]:
        n = self.num_envs
        if mask is None:
            return np.ones(n, dtype=bool)
        if not isinstance(mask, np.ndarray):
            raise TypeError(f'options["reset_mask"] must be a numpy array, got {type(mask).__name__}')
        if mask.dtype != np.bool_:
            raise TypeError(f'options["reset_mask"] must have dtype bool, got {mask.dtype}')
        if mask.shape != (n,):
            raise ValueError(f'options["reset_mask"] must have shape ({n},), got {mask.shape}')
        if not mask.any():
            raise ValueError('options["reset_mask"] must select at least one env')
        return mask.copy()

    def _infos(self, report: NDArray[np.float64], mask: NDArray[np.bool_] | None) -> dict[str, Any]:
        """Infos of the envs of ``mask`` (default all) from report rows (the contract's :class:`InfoBuilder`)."""
        return self._info.batched(report, mask)


def _autoreset_mode(value: AutoresetMode | str) -> AutoresetMode:
    if isinstance(value, AutoresetMode):
        return value
    for mode in AutoresetMode:
        if value in (mode.value, mode.name):
            return mode
    choices = [m.value for m in AutoresetMode] + [m.name for m in AutoresetMode]
    raise ValueError(f"autoreset_mode must be an AutoresetMode or one of {choices}, got {value!r}")
