r"""One evaluation path for every agent: the same seeded episodes, the same metrics.

Episode ``k`` of an evaluation is the env reset with seed ``seed + k``: the persona,
the person drawn around it, the initial ``xi`` and all noise follow from that seed, so
every agent meets exactly the same people. Many episodes run side by side: each of
``n_envs`` slots plays one episode at a time and, when it ends, is reset with the seed
of the next unplayed episode. The slots are either the natively batched vector env
(``gymnasium.make_vec``, when :mod:`coop_gym.envs.vector` is available) or ``n_envs``
single envs; both give identical episodes (env ``i`` seeded ``s`` equals a single env
seeded ``s``).

Metrics: success, unsafe-lift, premature and timeout rates (95 % Wilson intervals),
mean time to lift, mean and peak push force, number of cues, and return (mean, std).

Command line: ``python -m agents.evaluate --agent handbook --personas test`` (see
:mod:`agents.evaluate.cli`, kept apart because it loads saved models through
:mod:`agents.rl` and :mod:`agents.rllib`, which evaluate through this module).

Importing this module does not import torch.
"""

from __future__ import annotations

import csv
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

import coop_gym  # noqa: F401 -- registers the env ids
from agents.base import Agent, action_type_of, feature_mismatch, features_of
from agents.scripted import SCRIPTED_AGENTS, ScriptedAgent, make_scripted
from coop_gym.cli import SEED_LIMIT, output_path_problem
from coop_gym.envs.config import Outcome
from coop_gym.io import atomic_open
from coop_gym.io import write_json as atomic_write_json
from coop_gym.model.personas import resolve_personas

__all__ = [
    "OUTCOMES",
    "PLOT_SUFFIXES",
    "EpisodeRecord",
    "EvaluationResult",
    "env_kwargs_for",
    "evaluate",
    "output_path_problem",
    "results_table",
    "wilson_interval",
    "write_csv",
    "write_json",
]

DEFAULT_ENV_ID = "CoopGym/SitToStand-v0"
PLOT_SUFFIXES: tuple[str, ...] = (".png", ".pdf", ".svg")
"""File types ``--plot`` writes (matplotlib picks the format from the suffix)."""
OUTCOMES: tuple[str, ...] = tuple(o.label for o in Outcome if o is not Outcome.NONE)
"""Episode outcomes (labels of :class:`~coop_gym.envs.config.Outcome`), in report order."""

_LIFT_OUTCOMES = {o.label for o in Outcome if o.terminates}


def wilson_interval(successes: int, trials: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95 % by default).

    Args:
        successes: Number of events.
        trials: Number of trials (0 gives ``(0, 1)``).
        z: Standard normal quantile of the interval.

    Returns:
        ``(low, high)``, clipped to [0, 1].

    Example:
        >>> low, high = wilson_interval(50, 100)
        >>> round(low, 3), round(high, 3)
        (0.404, 0.596)
    """
    if trials <= 0:
        return 0.0, 1.0
    p = successes / trials
    denom = 1.0 + z * z / trials
    centre = (p + z * z / (2 * trials)) / denom
    half = z * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials)) / denom
    # The bounds at 0 and n events are exactly 0 and 1 (the formula leaves rounding dust).
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    high = 1.0 if successes == trials else min(1.0, centre + half)
    return low, high


@dataclass(frozen=True)
class EpisodeRecord:
    """What happened in one evaluation episode.

    Attributes:
        episode: Index ``k`` of the episode (its seed is ``seed + k``).
        seed: The env seed of the episode.
        persona: Name of the persona the person was drawn from.
        outcome: ``"success"``, ``"unsafe"``, ``"premature"`` or ``"timeout"``.
        episode_return: Sum of rewards.
        steps: Agent steps taken (the lift included).
        duration_s: Episode time at the end (at the lift, or the time limit) [s].
        mean_force_n: Push force averaged over the guiding steps (0 if none) [N].
        peak_force_n: Largest push force commanded [N].
        impulse_n_s: Total push impulse [N s].
        verbal_cues: Utterances started.
        push_onsets: Pushes started (a push after a step without one).
    """

    episode: int
    seed: int
    persona: str
    outcome: str
    episode_return: float
    steps: int
    duration_s: float
    mean_force_n: float
    peak_force_n: float
    impulse_n_s: float
    verbal_cues: int
    push_onsets: int

    @property
    def cues(self) -> int:
        """Cues given: utterances plus push onsets."""
        return self.verbal_cues + self.push_onsets

    @property
    def lifted(self) -> bool:
        """True when the episode ended with a lift (of any outcome)."""
        return self.outcome in _LIFT_OUTCOMES


@dataclass(frozen=True)
class EvaluationResult:
    """The episodes of one agent on one env, and their summary metrics.

    Attributes:
        agent: Name of the agent.
        env_id: The env id evaluated on.
        personas: Persona names the people were drawn from.
        seed: Seed of episode 0 (episode ``k`` uses ``seed + k``).
        records: One :class:`EpisodeRecord` per episode, in episode order.
        wall_time_s: Time the evaluation took [s].
        backend: ``"vector"`` (batched env) or ``"single"`` (one env per slot).
    """

    agent: str
    env_id: str
    personas: tuple[str, ...]
    seed: int
    records: tuple[EpisodeRecord, ...]
    wall_time_s: float = 0.0
    backend: str = "single"
    env_kwargs: dict[str, Any] = field(default_factory=dict)

    @property
    def episodes(self) -> int:
        """Number of episodes."""
        return len(self.records)

    def count(self, outcome: str) -> int:
        """Episodes that ended with ``outcome``."""
        if outcome not in OUTCOMES:
            raise ValueError(f"unknown outcome {outcome!r}; known: {list(OUTCOMES)}")
        return sum(r.outcome == outcome for r in self.records)

    def rate(self, outcome: str) -> float:
        """Fraction of episodes that ended with ``outcome``."""
        return self.count(outcome) / self.episodes if self.episodes else float("nan")

    def interval(self, outcome: str) -> tuple[float, float]:
        """95 % Wilson interval of :meth:`rate`."""
        return wilson_interval(self.count(outcome), self.episodes)

    @property
    def success_rate(self) -> float:
        """Fraction of successful lifts."""
        return self.rate("success")

    @property
    def unsafe_rate(self) -> float:
        """Fraction of unsafe lifts (resisting or upright person)."""
        return self.rate("unsafe")

    @property
    def premature_rate(self) -> float:
        """Fraction of premature lifts."""
        return self.rate("premature")

    @property
    def timeout_rate(self) -> float:
        """Fraction of episodes that reached the time limit without a lift."""
        return self.rate("timeout")

    def _mean(self, values: Sequence[float]) -> float:
        return float(np.mean(values)) if len(values) else float("nan")

    @property
    def mean_time_to_lift_s(self) -> float:
        """Mean episode time at the lift, over the episodes that lifted (NaN if none) [s]."""
        return self._mean([r.duration_s for r in self.records if r.lifted])

    @property
    def mean_time_to_success_s(self) -> float:
        """Mean episode time at a successful lift (NaN if none) [s]."""
        return self._mean([r.duration_s for r in self.records if r.outcome == "success"])

    @property
    def mean_force_n(self) -> float:
        """Push force averaged over guiding steps, then over episodes [N]."""
        return self._mean([r.mean_force_n for r in self.records])

    @property
    def peak_force_n(self) -> float:
        """Per-episode peak push force, averaged over episodes [N]."""
        return self._mean([r.peak_force_n for r in self.records])

    @property
    def max_force_n(self) -> float:
        """Largest push force commanded in any episode [N]."""
        return max((r.peak_force_n for r in self.records), default=float("nan"))

    @property
    def mean_impulse_n_s(self) -> float:
        """Push impulse per episode, averaged [N s]."""
        return self._mean([r.impulse_n_s for r in self.records])

    @property
    def mean_cues(self) -> float:
        """Cues (utterances + push onsets) per episode, averaged."""
        return self._mean([r.cues for r in self.records])

    @property
    def mean_return(self) -> float:
        """Mean episode return."""
        return self._mean([r.episode_return for r in self.records])

    @property
    def std_return(self) -> float:
        """Standard deviation of the episode return."""
        return float(np.std([r.episode_return for r in self.records])) if self.records else float("nan")

    def by_persona(self) -> dict[str, EvaluationResult]:
        """The same result split by persona (each keeps its episodes' records)."""
        names = sorted({r.persona for r in self.records})
        return {
            name: EvaluationResult(
                self.agent,
                self.env_id,
                (name,),
                self.seed,
                tuple(r for r in self.records if r.persona == name),
                self.wall_time_s,
                self.backend,
                self.env_kwargs,
            )
            for name in names
        }

    def summary(self) -> dict[str, Any]:
        """The metrics as a flat JSON-ready dict (NaN becomes None)."""
        out: dict[str, Any] = {
            "agent": self.agent,
            "env_id": self.env_id,
            "personas": list(self.personas),
            "episodes": self.episodes,
            "seed": self.seed,
        }
        for outcome in OUTCOMES:
            low, high = self.interval(outcome)
            out[f"{outcome}_rate"] = self.rate(outcome)
            out[f"{outcome}_rate_ci95"] = [low, high]
            out[f"{outcome}_count"] = self.count(outcome)
        out |= {
            "mean_time_to_lift_s": self.mean_time_to_lift_s,
            "mean_time_to_success_s": self.mean_time_to_success_s,
            "mean_force_n": self.mean_force_n,
            "peak_force_n": self.peak_force_n,
            "max_force_n": self.max_force_n,
            "mean_impulse_n_s": self.mean_impulse_n_s,
            "mean_cues": self.mean_cues,
            "mean_return": self.mean_return,
            "std_return": self.std_return,
            "wall_time_s": self.wall_time_s,
            "backend": self.backend,
        }
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in out.items()}


# --- running episodes ---------------------------------------------------------


class _SingleEnvSlots:
    """``n`` single envs behind the small interface the evaluator needs."""

    backend = "single"

    def __init__(self, env_id: str, n: int, env_kwargs: dict[str, Any]) -> None:
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
        for env in self.envs:
            env.close()


class _VectorEnvSlots:
    """The natively batched vector env, autoreset disabled, slots reset by mask."""

    backend = "vector"

    def __init__(self, env_id: str, n: int, env_kwargs: dict[str, Any]) -> None:
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


def vector_env_available() -> bool:
    """True when the natively batched vector env can be imported."""
    try:
        from coop_gym.envs import vector  # noqa: F401
    except ImportError:
        return False
    return True


def env_kwargs_for(agent_name: str, env_id: str, env_kwargs: dict[str, Any] | None = None) -> dict[str, Any]:
    """Env kwargs that give a scripted agent the observation it reads.

    The oracle needs the oracle observation (``observation_mode="oracle"``); the
    handbook and push-then-lift need the filter's estimate, so a ``raw`` env is run in
    ``belief`` mode for them. Persons, noise and dynamics do not depend on the mode, so
    the same seeds give the same episodes.
    """
    kwargs = dict(env_kwargs or {})
    if agent_name not in SCRIPTED_AGENTS:
        return kwargs
    needs = SCRIPTED_AGENTS[agent_name].needs
    if "true_xi" in needs:
        kwargs["observation_mode"] = "oracle"
        return kwargs
    spec_kwargs = dict(gym.spec(env_id).kwargs)
    mode = kwargs.get("observation_mode", spec_kwargs.get("observation_mode", "belief"))
    if mode == "raw" and any(f not in ("measured_position_m", "verbal_cue", "elapsed_s") for f in needs):
        kwargs["observation_mode"] = "belief"
    return kwargs


def evaluate(
    agent: Agent | str,
    env_id: str = DEFAULT_ENV_ID,
    personas: str | Sequence[str] = "test",
    episodes: int = 1000,
    seed: int = 0,
    *,
    n_envs: int = 64,
    deterministic: bool = True,
    env_kwargs: dict[str, Any] | None = None,
    name: str | None = None,
    backend: str = "auto",
    progress: Callable[[int, int], None] | None = None,
) -> EvaluationResult:
    """Play ``episodes`` seeded episodes with ``agent`` and collect the metrics.

    Args:
        agent: Anything with SB3's ``predict`` (scripted agents, SB3 models, the loader's
            agents) or the name of a scripted agent (built for the env; the oracle gets
            the oracle observation, see :func:`env_kwargs_for`).
        env_id: Registered env id.
        personas: ``"train"``, ``"test"``, ``"all"``, a persona name or a list of names.
        episodes: Number of episodes; episode ``k`` is seeded ``seed + k``.
        seed: Seed of episode 0.
        n_envs: Episodes played side by side (at most ``episodes``).
        deterministic: Passed to ``predict``.
        env_kwargs: Extra env kwargs (``personas`` is set from ``personas``).
        name: Name of the agent in the result (default: its class or scripted name).
        backend: ``"vector"`` (batched env), ``"single"`` (one env per slot) or ``"auto"``
            (vector when available). Both give identical episodes.
        progress: Called as ``progress(done, episodes)`` when episodes finish.

    Returns:
        The :class:`EvaluationResult`.

    Raises:
        ValueError: bad counts, unknown agent or persona names, or an agent whose
            observation does not match the env's.
    """
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes must be a positive int, got {episodes!r}")
    if isinstance(n_envs, bool) or not isinstance(n_envs, int) or n_envs < 1:
        raise ValueError(f"n_envs must be a positive int, got {n_envs!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed must be a non-negative int, got {seed!r}")
    if seed + episodes > SEED_LIMIT:
        raise ValueError(f"seed + episodes must be <= 2**32 (episode k uses seed + k), got seed={seed}")
    if backend not in ("auto", "vector", "single"):
        raise ValueError(f"backend must be 'auto', 'vector' or 'single', got {backend!r}")
    persona_names = tuple(p.name for p in resolve_personas(personas if isinstance(personas, str) else list(personas)))
    label = name or (agent if isinstance(agent, str) else getattr(agent, "name", type(agent).__name__))
    kwargs = env_kwargs_for(agent, env_id, env_kwargs) if isinstance(agent, str) else dict(env_kwargs or {})
    kwargs["personas"] = list(persona_names)
    n = min(n_envs, episodes)
    use_vector = backend == "vector" or (backend == "auto" and vector_env_available())
    slots: _SingleEnvSlots | _VectorEnvSlots = (
        _VectorEnvSlots(env_id, n, kwargs) if use_vector else _SingleEnvSlots(env_id, n, kwargs)
    )
    start_time = time.perf_counter()
    try:
        policy: Agent
        if isinstance(agent, str):
            if agent not in SCRIPTED_AGENTS:
                raise ValueError(f"unknown agent {agent!r}; scripted agents: {', '.join(SCRIPTED_AGENTS)}")
            level = kwargs.get("difficulty", gym.spec(env_id).kwargs.get("difficulty"))
            policy = make_scripted(agent, slots.features, slots.action_type, seed=seed, level=level)
        else:
            policy = agent
            _check_agent_fits(policy, slots.features, env_id)
        records = _play(policy, slots, episodes, seed, deterministic, progress)
    finally:
        slots.close()
    return EvaluationResult(
        agent=str(label),
        env_id=env_id,
        personas=persona_names,
        seed=seed,
        records=tuple(records),
        wall_time_s=time.perf_counter() - start_time,
        backend=slots.backend,
        env_kwargs={k: v for k, v in kwargs.items() if k != "personas"},
    )


def _check_agent_fits(agent: Any, features: tuple[str, ...], env_id: str) -> None:
    """Fail early, naming the mismatch, when an agent was built for another observation."""
    trained = None if isinstance(agent, ScriptedAgent) else getattr(agent, "features", None)
    problem = feature_mismatch(trained, features, env_id)
    if problem:
        raise ValueError(f"{problem}; evaluate it on the env id it was trained on")
    if isinstance(agent, ScriptedAgent) and agent.features != features:
        raise ValueError(
            f"{type(agent).__name__} was built for features {list(agent.features)} but the env observes "
            f"{list(features)}; build it with .for_env(env) or pass its name"
        )
    space = getattr(agent, "observation_space", None)
    shape = getattr(space, "shape", None)
    if shape is not None and tuple(shape) != (len(features),):
        raise ValueError(
            f"the agent expects observations of shape {tuple(shape)} but the env gives ({len(features)},) "
            f"({list(features)}); evaluate it on the env id it was trained on"
        )


def _play(
    agent: Agent,
    slots: _SingleEnvSlots | _VectorEnvSlots,
    episodes: int,
    seed: int,
    deterministic: bool,
    progress: Callable[[int, int], None] | None,
) -> list[EpisodeRecord]:
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
        lifted = np.isin(out["outcome"], list(_LIFT_OUTCOMES))
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


# --- reporting ----------------------------------------------------------------


def _pct(rate: float, interval: tuple[float, float] | None = None) -> str:
    text = f"{100 * rate:5.1f}%"
    if interval is not None:
        text += f" [{100 * interval[0]:.1f}, {100 * interval[1]:.1f}]"
    return text


def _num(value: float, digits: int = 2) -> str:
    return "-" if not math.isfinite(value) else f"{value:.{digits}f}"


TABLE_COLUMNS: tuple[str, ...] = (
    "agent",
    "episodes",
    "success [95% CI]",
    "unsafe [95% CI]",
    "premature",
    "timeout",
    "time to lift s",
    "mean force N",
    "peak force N",
    "cues",
    "return (mean ± std)",
)


def table_rows(results: Sequence[EvaluationResult]) -> list[list[str]]:
    """The rows of the comparison table, as strings (see :data:`TABLE_COLUMNS`)."""
    return [
        [
            r.agent,
            str(r.episodes),
            _pct(r.success_rate, r.interval("success")),
            _pct(r.unsafe_rate, r.interval("unsafe")),
            _pct(r.premature_rate),
            _pct(r.timeout_rate),
            _num(r.mean_time_to_lift_s),
            _num(r.mean_force_n, 1),
            _num(r.peak_force_n, 1),
            _num(r.mean_cues, 1),
            f"{r.mean_return:+.3f} ± {r.std_return:.3f}",
        ]
        for r in results
    ]


def results_table(results: Sequence[EvaluationResult], title: str | None = None) -> Any:
    """A :class:`rich.table.Table` comparing the results (one row per agent)."""
    from rich.table import Table

    if title is None and results:
        first = results[0]
        title = (
            f"{first.env_id} | personas {','.join(first.personas)} | {first.episodes} episodes, seeds {first.seed}.."
        )
    table = Table(title=title)
    for k, column in enumerate(TABLE_COLUMNS):
        table.add_column(column, justify="left" if k == 0 else "right")
    for row in table_rows(results):
        table.add_row(*row)
    return table


def print_table(results: Sequence[EvaluationResult], title: str | None = None, file: Any = None) -> None:
    """Print the comparison table to the terminal (or ``file``)."""
    from rich.console import Console

    Console(file=file, width=200).print(results_table(results, title))


def write_csv(results: Sequence[EvaluationResult], path: str | Path) -> Path:
    """Write one summary row per agent (the keys of :meth:`EvaluationResult.summary`)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = [r.summary() for r in results]
    for row in rows:
        for key, value in row.items():
            if isinstance(value, list):
                row[key] = ";".join(str(v) for v in value)
    with atomic_open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]) if rows else [])
        writer.writeheader()
        writer.writerows(rows)
    return path


def write_json(results: Sequence[EvaluationResult], path: str | Path, episodes: bool = False) -> Path:
    """Write the summaries (and with ``episodes`` every episode record) as JSON."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = results_json(results, episodes=episodes)
    atomic_write_json(path, payload)
    return path


def results_json(results: Sequence[EvaluationResult], episodes: bool = False) -> dict[str, Any]:
    """One JSON object: a single result's summary at top level, several under ``results``."""
    summaries = []
    for r in results:
        s = r.summary()
        if episodes:
            s["episode_records"] = [asdict(rec) for rec in r.records]
        summaries.append(s)
    if len(summaries) == 1:
        return summaries[0]
    return {"results": summaries}


ORACLE_AGENTS = ("oracle",)
"""Agents that see the true mental state: upper bounds, never the "best non-oracle"."""
BLIND_AGENTS = ("blind", "push_then_lift", "lift_at_once", "random")
"""Scripted agents that never use the cue-response evidence (lean, timers and pushes only)."""


@dataclass(frozen=True)
class Headroom:
    """What a comparison says about reading the mind (success rates in [0, 1]).

    Attributes:
        oracle: Best success of the agents that see the true ``xi``.
        best_blind: Best success of the mental-state-blind agents (:data:`BLIND_AGENTS`).
        best_reader: Best success of every other agent (learned or scripted, no oracle).
        best_blind_agent, best_reader_agent: Their names.
    """

    oracle: float
    best_blind: float
    best_reader: float
    best_blind_agent: str
    best_reader_agent: str

    @property
    def value_of_reading_the_mind(self) -> float:
        """Oracle minus best blind: what knowing the mental state is worth on this env."""
        return self.oracle - self.best_blind

    @property
    def achieved_insight(self) -> float:
        """Best non-oracle minus best blind: how much of it the non-oracle agents obtain."""
        return self.best_reader - self.best_blind

    def lines(self) -> list[str]:
        """Two human-readable lines for the report."""
        return [
            f"value of reading the mind = oracle {100 * self.oracle:.1f} % - best blind ({self.best_blind_agent}) "
            f"{100 * self.best_blind:.1f} % = {100 * self.value_of_reading_the_mind:+.1f} points",
            f"achieved insight = best non-oracle ({self.best_reader_agent}) {100 * self.best_reader:.1f} % - best "
            f"blind {100 * self.best_blind:.1f} % = {100 * self.achieved_insight:+.1f} points",
        ]


def headroom(results: Sequence[EvaluationResult]) -> Headroom | None:
    """:class:`Headroom` of a comparison on the same episodes; None without an oracle and a blind agent."""

    def kind(name: str) -> str:
        base = name.split(":")[0].split(" ")[0]
        return "oracle" if base in ORACLE_AGENTS else ("blind" if base in BLIND_AGENTS else "reader")

    best: dict[str, EvaluationResult] = {}
    for result in results:
        k = kind(result.agent)
        if k not in best or result.success_rate > best[k].success_rate:
            best[k] = result
    if "oracle" not in best or "blind" not in best:
        return None
    reader = best.get("reader", best["blind"])
    return Headroom(
        best["oracle"].success_rate,
        best["blind"].success_rate,
        reader.success_rate,
        best["blind"].agent,
        reader.agent,
    )
