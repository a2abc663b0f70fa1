"""Playing seeded episodes side by side and recording each one.

Episode ``k`` of an evaluation is the env reset with seed ``seed + k``. Each of ``n``
slots plays one episode at a time and, when it ends, is reset with the seed of the next
unplayed episode, so the episodes do not depend on how many run side by side. The slots
are the natively batched vector env (``gymnasium.make_vec``, autoreset off, reset by
mask) or ``n`` single envs; both give identical episodes (env ``i`` seeded ``s`` equals a
single env seeded ``s``). :func:`play` turns what the slots report each step into one
:class:`~agents.evaluate.results.EpisodeRecord` per episode.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from agents.base import Agent, action_type_of, features_of
from agents.evaluate.results import LIFT_OUTCOMES, EpisodeRecord

__all__ = ["SingleEnvSlots", "VectorEnvSlots", "make_slots", "play"]


class SingleEnvSlots:
    """``n`` single envs behind the small interface the evaluator needs."""

    backend = "single"

    def __init__(self, env_id: str, n: int, env_kwargs: dict[str, Any]) -> None:
        """Make ``n`` envs of ``env_id``."""
        self.envs = [gym.make(env_id, **env_kwargs) for _ in range(n)]
        self.features = features_of(self.envs[0])
        self.action_type = action_type_of(self.envs[0])
        self.n = n

    def reset(self, seeds: NDArray[np.int64], mask: NDArray[np.bool_], obs: NDArray[np.float32]) -> list[str]:
        """Reset the masked slots with their seeds (in place in ``obs``); returns their personas."""
        personas = []
        for i in np.flatnonzero(mask):
            obs[i], info = self.envs[i].reset(seed=int(seeds[i]))
            personas.append(info["persona"])
        return personas

    def step(self, actions: NDArray[Any], obs: NDArray[np.float32]) -> dict[str, NDArray[Any]]:
        """Step every slot; returns per-slot arrays of what the records need."""
        out = _empty_step(self.n)
        for i, env in enumerate(self.envs):
            obs[i], reward, terminated, truncated, info = env.step(actions[i])
            out["reward"][i] = float(reward)
            out["done"][i] = terminated or truncated
            out["outcome"][i] = info["outcome"]
            out["push_force_n"][i] = info["push_force_n"]
            out["verbal_cue"][i] = info["verbal_cue"]
            out["elapsed_s"][i] = info["elapsed_s"]
        return out

    def close(self) -> None:
        """Close every env."""
        for env in self.envs:
            env.close()


class VectorEnvSlots:
    """The natively batched vector env, autoreset disabled, slots reset by mask."""

    backend = "vector"

    def __init__(self, env_id: str, n: int, env_kwargs: dict[str, Any]) -> None:
        """Make the vector env of ``n`` envs of ``env_id``."""
        from gymnasium.vector import AutoresetMode

        self.env = gym.make_vec(
            env_id,
            num_envs=n,
            vectorization_mode="vector_entry_point",
            autoreset_mode=AutoresetMode.DISABLED,
            **env_kwargs,
        )
        self.features = features_of(self.env)
        self.action_type = action_type_of(self.env)
        self.n = n
        self._started = False

    def reset(self, seeds: NDArray[np.int64], mask: NDArray[np.bool_], obs: NDArray[np.float32]) -> list[str]:
        """Reset the masked slots with their seeds (in place in ``obs``); returns their personas."""
        seed_list: list[int | None] = [int(s) if m else None for s, m in zip(seeds, mask, strict=True)]
        if not self._started or bool(np.all(mask)):
            new_obs, info = self.env.reset(seed=[int(s) for s in seeds])  # type: ignore[arg-type]
            self._started = True
        else:
            new_obs, info = self.env.reset(
                seed=seed_list,  # type: ignore[arg-type]
                options={"reset_mask": np.asarray(mask, dtype=bool)},
            )
        obs[mask] = new_obs[mask]
        return [str(p) for p in np.asarray(info["persona"])[mask]]

    def step(self, actions: NDArray[Any], obs: NDArray[np.float32]) -> dict[str, NDArray[Any]]:
        """Step every slot; returns per-slot arrays of what the records need."""
        new_obs, reward, terminated, truncated, info = self.env.step(actions)
        obs[:] = new_obs
        out = _empty_step(self.n)
        out["reward"][:] = reward
        out["done"][:] = np.logical_or(terminated, truncated)
        out["outcome"][:] = np.asarray(info["outcome"])
        out["push_force_n"][:] = info["push_force_n"]
        out["verbal_cue"][:] = info["verbal_cue"]
        out["elapsed_s"][:] = info["elapsed_s"]
        return out

    def close(self) -> None:
        """Close the vector env."""
        self.env.close()


def _empty_step(n: int) -> dict[str, NDArray[Any]]:
    return {
        "reward": np.zeros(n),
        "done": np.zeros(n, dtype=bool),
        "outcome": np.full(n, "none", dtype=object),
        "push_force_n": np.zeros(n),
        "verbal_cue": np.zeros(n),
        "elapsed_s": np.zeros(n),
    }


def make_slots(env_id: str, n: int, env_kwargs: dict[str, Any], backend: str) -> SingleEnvSlots | VectorEnvSlots:
    """``n`` slots of ``env_id``: ``backend`` ``"vector"`` or ``"auto"`` batch them, ``"single"`` does not."""
    if backend == "single":
        return SingleEnvSlots(env_id, n, env_kwargs)
    return VectorEnvSlots(env_id, n, env_kwargs)


def play(
    agent: Agent,
    slots: SingleEnvSlots | VectorEnvSlots,
    episodes: int,
    seed: int,
    deterministic: bool,
    progress: Callable[[int, int], None] | None,
) -> list[EpisodeRecord]:
    """Play episodes ``0 .. episodes - 1`` (seeded ``seed + k``) with ``agent``; their records in order."""
    n = slots.n
    obs = np.zeros((n, len(slots.features)), dtype=np.float32)
    # Slot i plays episode `episode_of[i]`; -1 marks a filler episode past the end
    # (all slots keep stepping together so the agent's per-env state stays aligned).
    episode_of = np.arange(n)
    seeds: NDArray[np.int64] = (seed + episode_of).astype(np.int64)
    personas = slots.reset(seeds, np.ones(n, dtype=bool), obs)
    persona_of = list(personas)
    next_episode = n
    acc = _Accumulators(n)
    episode_start = np.ones(n, dtype=bool)
    state: Any = None
    records: dict[int, EpisodeRecord] = {}
    while len(records) < episodes:
        actions, state = agent.predict(obs, state=state, episode_start=episode_start, deterministic=deterministic)
        out = slots.step(np.asarray(actions), obs)
        acc.add(out)
        done = out["done"]
        episode_start = done.copy()
        if not np.any(done):
            continue
        for i in np.flatnonzero(done).tolist():
            k = int(episode_of[i])
            if k >= 0:
                records[k] = acc.record(i, k, int(seeds[i]), persona_of[i], str(out["outcome"][i]))
            acc.clear(i)
            if next_episode < episodes:
                episode_of[i] = next_episode
                seeds[i] = seed + next_episode
                next_episode += 1
            else:
                # A filler episode, seeded past the evaluation's range and never recorded.
                episode_of[i] = -1
                seeds[i] = seed + episodes + i
        if progress is not None:
            progress(len(records), episodes)
        if len(records) < episodes:
            new_personas = slots.reset(seeds, done, obs)
            for j, persona in zip(np.flatnonzero(done).tolist(), new_personas, strict=True):
                persona_of[j] = persona
    return [records[k] for k in range(episodes)]


class _Accumulators:
    """Running per-slot sums for the episode records."""

    def __init__(self, n: int) -> None:
        self.ret = np.zeros(n)
        self.steps = np.zeros(n, dtype=np.int64)
        self.guiding_steps = np.zeros(n, dtype=np.int64)
        self.force_sum = np.zeros(n)
        self.peak = np.zeros(n)
        self.impulse = np.zeros(n)
        self.verbal = np.zeros(n, dtype=np.int64)
        self.pushes = np.zeros(n, dtype=np.int64)
        self.last_verbal = np.zeros(n)
        self.last_force = np.zeros(n)
        self.elapsed = np.zeros(n)

    def add(self, out: dict[str, NDArray[Any]]) -> None:
        force = out["push_force_n"]
        lifted = np.isin(out["outcome"], list(LIFT_OUTCOMES))
        guiding = ~lifted
        step_s = np.maximum(out["elapsed_s"] - self.elapsed, 0.0)
        self.ret += out["reward"]
        self.steps += 1
        self.guiding_steps += guiding
        self.force_sum += np.where(guiding, force, 0.0)
        self.peak = np.maximum(self.peak, force)
        self.impulse += force * step_s
        # An utterance shows in `verbal_cue` while it plays and is 0 after its last step.
        self.verbal += (out["verbal_cue"] != 0.0) & (self.last_verbal == 0.0)
        self.pushes += (force > 0.0) & (self.last_force == 0.0)
        self.last_verbal = out["verbal_cue"].astype(np.float64)
        self.last_force = force.astype(np.float64)
        self.elapsed = np.where(lifted, self.elapsed, out["elapsed_s"])

    def record(self, i: int, k: int, seed: int, persona: str, outcome: str) -> EpisodeRecord:
        guiding = int(self.guiding_steps[i])
        return EpisodeRecord(
            episode=k,
            seed=seed,
            persona=persona,
            outcome=outcome,
            episode_return=float(self.ret[i]),
            steps=int(self.steps[i]),
            duration_s=float(self.elapsed[i]),
            mean_force_n=float(self.force_sum[i] / guiding) if guiding else 0.0,
            peak_force_n=float(self.peak[i]),
            impulse_n_s=float(self.impulse[i]),
            verbal_cues=int(self.verbal[i]),
            push_onsets=int(self.pushes[i]),
        )

    def clear(self, i: int) -> None:
        for array in (
            self.ret,
            self.steps,
            self.guiding_steps,
            self.force_sum,
            self.peak,
            self.impulse,
            self.verbal,
            self.pushes,
            self.last_verbal,
            self.last_force,
            self.elapsed,
        ):
            array[i] = 0
