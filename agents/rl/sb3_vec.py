"""Stable-Baselines3 ``VecEnv`` adapter over a natively batched Gymnasium vector env.

SB3 2.9 cannot consume a ``gymnasium.vector.VectorEnv``; :class:`SB3VecEnvAdapter`
translates one (built with same-step autoreset) into SB3's ``VecEnv`` API so a PPO run
steps all its envs with one compiled call instead of ``n_envs`` Python env steps:

* ``step_wait() -> (obs, rewards, dones, infos)`` with ``dones = terminated | truncated``,
  ``infos`` a list of per-env dicts as the single env returns them (for a finished env:
  its final info, plus ``"terminal_observation"``, ``"TimeLimit.truncated"`` and
  Monitor's ``"episode": {"r", "l", "t"}`` so SB3's logger shows ``ep_rew_mean``);
* seeds set with :meth:`seed` (env ``i`` gets ``seed + i``) and options with
  ``set_options`` are used at the next :meth:`reset`, as in ``DummyVecEnv``.

:func:`make_sb3_vec_env` builds the adapter from an env id.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from numpy.typing import NDArray
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvStepReturn

from coop_gym.cli import SEED_LIMIT
from coop_gym.envs.contract import InfoBuilder
from coop_gym.envs.vector import SitToStandVectorEnv
from estimator.validate import check_integer

__all__ = ["STEP_INFOS", "SB3VecEnvAdapter", "make_sb3_vec_env"]

STEP_INFOS: tuple[str, ...] = ("all", "finished")
"""What :class:`SB3VecEnvAdapter` puts in ``infos`` each step (its ``step_infos`` argument)."""


class SB3VecEnvAdapter(VecEnv):
    """SB3's ``VecEnv`` API over a Gymnasium ``VectorEnv`` that autoresets on the same step.

    Attributes (``get_attr`` / ``set_attr`` / ``env_method``) belong to the vector env and are
    shared by all its envs: ``get_attr`` repeats the value per index, ``env_method`` calls
    the method once and repeats its result, ``set_attr`` must address every env. Only env 0
    is rendered. The envs are not wrapped in any ``gymnasium.Wrapper``
    (``env_is_wrapped`` is False), but finished episodes carry Monitor's ``"episode"`` info.

    Args:
        venv: The vector env; ``venv.metadata["autoreset_mode"]`` must be
            ``AutoresetMode.SAME_STEP`` (e.g. ``gymnasium.make_vec(id, n,
            autoreset_mode=AutoresetMode.SAME_STEP)``).
        step_infos: ``"all"``: every env's info dict on every step, as ``DummyVecEnv`` gives
            them; ``"finished"``: only the envs whose episode ended this step get theirs (with
            ``"terminal_observation"`` and ``"episode"``), the others an empty dict, and
            ``reset_infos`` are not refreshed at an autoreset -- all that SB3's PPO and
            ``VecMonitor`` read, without building hundreds of dicts per step.

    Example:
        >>> import coop_gym
        >>> venv = make_sb3_vec_env("CoopGym/SitToStand-v0", n_envs=2, seed=0)
        >>> venv.reset().shape
        (2, 11)
        >>> obs, rewards, dones, infos = venv.step(np.array([[0, 0, 1], [1, 2, 0]]))
        >>> dones.tolist(), infos[0]["outcome"], infos[0]["episode"]["l"]
        ([True, False], 'unsafe', 1)
    """

    def __init__(self, venv: VectorEnv, step_infos: str = "all") -> None:
        """Wrap ``venv`` (see the class docstring)."""
        if step_infos not in STEP_INFOS:
            raise ValueError(f"step_infos must be one of {list(STEP_INFOS)}, got {step_infos!r}")
        if not isinstance(venv, VectorEnv):
            raise TypeError(f"venv must be a gymnasium.vector.VectorEnv, got {type(venv).__name__}")
        mode = venv.metadata.get("autoreset_mode")
        if mode != AutoresetMode.SAME_STEP:
            raise ValueError(
                f"SB3VecEnvAdapter needs a vector env with autoreset_mode=AutoresetMode.SAME_STEP, got {mode!r}; "
                "build it with gymnasium.make_vec(id, num_envs, autoreset_mode=AutoresetMode.SAME_STEP)"
            )
        self.venv = venv
        self.step_infos = step_infos
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        n = venv.num_envs
        # The natively batched coop_gym env (not hidden behind a VectorWrapper, which could change
        # what step returns) gives its raw report rows: no dict-of-arrays round trip.
        self._rows_env = venv if isinstance(venv, SitToStandVectorEnv) else None
        if self._rows_env is not None:
            # The env's own info contract: its info_mode, and unscaled_obs on a unit-scaled id.
            self._info = InfoBuilder(self._rows_env.config)
        self._actions: Any = None
        self._episode_return = np.zeros(n)
        self._episode_length = np.zeros(n, dtype=np.int64)
        self._t_start = time.time()

    # --- SB3 VecEnv API -----------------------------------------------------------

    def reset(self) -> NDArray[Any]:
        """Reset every env with the seeds and options set since the last reset."""
        seeds, options = self._seeds, self._options
        seed_arg: list[int | None] | None = list(seeds) if any(s is not None for s in seeds) else None
        if all(o == options[0] for o in options):
            obs, infos = self.venv.reset(seed=seed_arg, options=dict(options[0]) or None)  # type: ignore[arg-type]
        else:
            # Different options per env: reset the envs sharing options together.
            obs, infos = None, {}
            done = np.zeros(self.num_envs, dtype=bool)
            for i in range(self.num_envs):
                if done[i]:
                    continue
                mask = np.array([not done[j] and options[j] == options[i] for j in range(self.num_envs)])
                group_seeds = [s if m else None for s, m in zip(seeds, mask, strict=True)]
                obs, group_infos = self.venv.reset(
                    seed=group_seeds,  # type: ignore[arg-type]
                    options={**options[i], "reset_mask": mask},
                )
                for k, info in enumerate(self._reset_infos(group_infos)):
                    if mask[k]:
                        self.reset_infos[k] = info
                done |= mask
        if infos:
            self.reset_infos = self._reset_infos(infos)
        self._reset_seeds()
        self._reset_options()
        self._episode_return[:] = 0.0
        self._episode_length[:] = 0
        return obs  # type: ignore[return-value]

    def step_async(self, actions: NDArray[Any]) -> None:
        """Remember the actions for :meth:`step_wait`."""
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        """Step every env; finished envs are already reset (their final data is in ``infos``)."""
        final_obs: Any = None
        finals: dict[int, dict[str, Any]] = {}
        if self._rows_env is not None:
            # coop_gym's batched env: per-env info dicts straight from its report rows.
            obs, rewards, terminated, truncated, final = self._rows_env.step_rows(self._actions)
            if self.step_infos == "all":
                per_env = self._row_infos(self._rows_env.core.report)
            else:
                per_env = [{} for _ in range(self.num_envs)]
            if final is not None:
                final_obs = final[1]
                rows = final[2]
                finals = {i: self._info.single(rows[i].tolist()) for i in np.flatnonzero(final[0]).tolist()}
        else:
            obs, rewards, terminated, truncated, infos = self.venv.step(self._actions)
            per_env = _unbatch(infos, self.num_envs) if self.step_infos == "all" else [{} for _ in range(self.num_envs)]
            if "final_info" in infos:
                final_obs = infos["final_obs"]
                finals = dict(enumerate(_unbatch(infos["final_info"], self.num_envs)))
        dones = np.logical_or(terminated, truncated)
        self._episode_return += rewards
        self._episode_length += 1
        if self.step_infos == "all":
            for i, info in enumerate(per_env):
                if not dones[i]:
                    info["TimeLimit.truncated"] = False
        if dones.any():
            now = time.time()
            for i in np.flatnonzero(dones).tolist():
                info = finals[i]
                info["terminal_observation"] = final_obs[i]
                # As SB3's DummyVecEnv: a time-limit end that is not also a termination.
                info["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
                info["episode"] = {
                    "r": round(float(self._episode_return[i]), 6),
                    "l": int(self._episode_length[i]),
                    "t": round(now - self._t_start, 6),
                }
                if self.step_infos == "all":
                    self.reset_infos[i] = per_env[i]
                per_env[i] = info
            self._episode_return[dones] = 0.0
            self._episode_length[dones] = 0
        return obs, rewards.astype(np.float32), dones, per_env

    def _reset_infos(self, infos: dict[str, Any]) -> list[dict[str, Any]]:
        """Per-env reset infos.

        From the report rows on coop_gym's batched env (exactly the single env's, the NumPy
        scalars of ``info_mode="numeric"`` included), else unbatched from the vector infos.
        """
        if self._rows_env is not None:
            return self._row_infos(self._rows_env.core.report)
        return _unbatch(infos, self.num_envs)

    def _row_infos(self, report: NDArray[np.float64]) -> list[dict[str, Any]]:
        """The single env's info dicts from the batched env's report rows (as the single env builds them)."""
        return [self._info.single(row) for row in report.tolist()]

    def close(self) -> None:
        """Close the vector env."""
        self.venv.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The vector env's attribute, once per index (it is shared by all envs)."""
        value = getattr(self.venv, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set an attribute of the vector env; ``indices`` must address every env."""
        targets = set(self._get_indices(indices))
        if targets != set(range(self.num_envs)):
            raise ValueError(
                f"set_attr({attr_name!r}) on envs {sorted(targets)}: the batched env's attributes are shared, "
                f"set them for all {self.num_envs} envs (indices=None)"
            )
        setattr(self.venv, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        """Call a method of the vector env once; its result is repeated per index."""
        result = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [result for _ in self._get_indices(indices)]

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper[Any, Any, Any, Any]], indices: VecEnvIndices = None
    ) -> list[bool]:
        """False for every env: the batched envs are not ``gymnasium.Wrapper`` objects."""
        return [False for _ in self._get_indices(indices)]

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Seeds for the next :meth:`reset`: env ``i`` gets ``seed + i`` (None: keep their generators)."""
        if seed is None:
            self._seeds = [None] * self.num_envs
        else:
            first = check_integer("seed", seed, 0, SEED_LIMIT - self.num_envs)  # env i gets seed + i
            self._seeds = [first + i for i in range(self.num_envs)]
        return list(self._seeds)

    def get_images(self) -> Sequence[NDArray[Any] | None]:
        """The frame of env 0 (the only one drawn), for ``render_mode="rgb_array"``."""
        if self.render_mode != "rgb_array":
            return [None]
        frame: Any = self.venv.render()
        return [frame]


def _unbatch(infos: dict[str, Any], n: int) -> list[dict[str, Any]]:
    """Gymnasium vector infos (dict of arrays with ``_key`` masks) -> ``n`` per-env dicts.

    1-D arrays become Python scalars (as the single env gives them), rows of wider arrays
    stay arrays, nested dicts are split the same way; ``final_obs`` / ``final_info`` are
    left to the caller.
    """
    out: list[dict[str, Any]] = [{} for _ in range(n)]
    for key, value in infos.items():
        if key.startswith("_") or key in ("final_obs", "final_info"):
            continue
        mask = infos.get(f"_{key}")
        present = [True] * n if mask is None else mask.tolist()
        if isinstance(value, dict):
            items: list[Any] = _unbatch(value, n)
        elif isinstance(value, np.ndarray) and value.ndim == 1:
            items = value.tolist()
        else:
            items = [np.array(row) for row in value]
        for i in range(n):
            if present[i]:
                out[i][key] = items[i]
    return out


def make_sb3_vec_env(
    env_id: str,
    n_envs: int,
    seed: int | None = None,
    env_kwargs: dict[str, Any] | None = None,
    *,
    step_infos: str = "all",
) -> SB3VecEnvAdapter:
    """``n_envs`` envs of ``env_id`` as one natively batched SB3 ``VecEnv``.

    Args:
        env_id: A registered id with a ``vector_entry_point`` (every ``CoopGym/`` id).
        n_envs: Number of envs.
        seed: Env ``i`` is seeded ``seed + i`` at the first reset (None: fresh entropy).
        env_kwargs: Keyword arguments of the env (e.g. ``personas``, ``reward``).
        step_infos: ``"all"`` or ``"finished"`` (:class:`SB3VecEnvAdapter`).

    Returns:
        The :class:`SB3VecEnvAdapter` (not yet reset; SB3's ``learn`` resets it).
    """
    check_integer("n_envs", n_envs, 1, SEED_LIMIT)
    if env_kwargs is not None and not isinstance(env_kwargs, dict):
        raise ValueError(f"env_kwargs must be a dict or None, got {type(env_kwargs).__name__}")
    kwargs = dict(env_kwargs or {})
    if "autoreset_mode" in kwargs:
        raise ValueError("env_kwargs must not set autoreset_mode: the SB3 adapter needs AutoresetMode.SAME_STEP")
    venv = gym.make_vec(
        env_id,
        num_envs=int(n_envs),
        vectorization_mode="vector_entry_point",
        autoreset_mode=AutoresetMode.SAME_STEP,
        **kwargs,
    )
    adapter = SB3VecEnvAdapter(venv, step_infos=step_infos)
    adapter.seed(seed)
    return adapter
