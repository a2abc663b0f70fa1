r"""One evaluation path for every agent: the same seeded episodes, the same metrics.

Episode ``k`` of an evaluation is the env reset with seed ``seed + k``: the persona,
the person drawn around it, the initial ``xi`` and all noise follow from that seed, so
every agent meets exactly the same people (:mod:`agents.evaluate.episodes` plays them,
many side by side).

Metrics (:mod:`agents.evaluate.results`): success, unsafe-lift, premature and timeout rates
(95 % Wilson intervals), mean time to lift, mean and peak push force, number of cues, and
return (mean, std). A comparison with an oracle and a blind policy also reports what reading
the mind is worth and the mind-reading score of each agent (:mod:`agents.evaluate.headroom`);
tables and files: :mod:`agents.evaluate.report`.

Command line: ``python -m agents.evaluate --agent handbook --personas test`` (see
:mod:`agents.tools.evaluate_cli`, kept apart because it loads saved models through
:mod:`agents.rl` and :mod:`agents.rl.rllib`, which evaluate through this module).

Importing this module does not import torch.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym

import coop_gym  # noqa: F401 -- registers the env ids
from agents.base import Agent, feature_mismatch
from agents.caregivers.scripted import SCRIPTED_AGENTS, ScriptedAgent, make_scripted
from agents.caregivers.scripted_base import unit_id_hint
from agents.evaluate.episodes import make_slots, play
from agents.evaluate.headroom import (
    BLIND_AGENTS,
    ORACLE_AGENTS,
    AggregateScore,
    Headroom,
    MindReadingScore,
    headroom,
    iqm_across_runs,
)
from agents.evaluate.report import (
    TABLE_COLUMNS,
    print_table,
    results_json,
    results_table,
    summaries,
    table_rows,
    write_csv,
    write_json,
)
from agents.evaluate.results import (
    DEFAULT_ENV_ID,
    OUTCOMES,
    PLOT_SUFFIXES,
    EpisodeRecord,
    EvaluationResult,
    wilson_interval,
)
from coop_gym.cli import SEED_LIMIT, output_path_problem
from coop_gym.model.personas import Persona, resolve_personas
from estimator.validate import check_integer

__all__ = [
    "BLIND_AGENTS",
    "DEFAULT_ENV_ID",
    "ORACLE_AGENTS",
    "OUTCOMES",
    "PLOT_SUFFIXES",
    "TABLE_COLUMNS",
    "AggregateScore",
    "EpisodeRecord",
    "EvaluationResult",
    "Headroom",
    "MindReadingScore",
    "env_kwargs_for",
    "evaluate",
    "headroom",
    "iqm_across_runs",
    "output_path_problem",
    "print_table",
    "results_json",
    "results_table",
    "summaries",
    "table_rows",
    "wilson_interval",
    "write_csv",
    "write_json",
]


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
    if "p_cooperative" in needs and kwargs.get("estimator", spec_kwargs.get("estimator", "kalman")) == "kalman":
        # The belief caregiver reads the switching particle filter's P(xi = +1).
        kwargs["estimator"] = "switching"
    mode = kwargs.get("observation_mode", spec_kwargs.get("observation_mode", "belief"))
    if mode == "raw" and any(f not in ("measured_position_m", "verbal_cue", "elapsed_s") for f in needs):
        kwargs["observation_mode"] = "belief"
    return kwargs


def evaluate(
    agent: Agent | str,
    env_id: str = DEFAULT_ENV_ID,
    personas: str | Sequence[str | Persona] = "test",
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
        personas: What :func:`~coop_gym.model.personas.resolve_personas` takes (the env plays those people).
        episodes: Number of episodes; episode ``k`` is seeded ``seed + k``.
        seed: Seed of episode 0.
        n_envs: Episodes played side by side (at most ``episodes``).
        deterministic: Passed to ``predict``.
        env_kwargs: Extra env kwargs (``personas`` is set from ``personas``).
        name: Name of the agent in the result (default: its class or scripted name).
        backend: ``"vector"`` or ``"auto"`` (the batched env), ``"single"`` (one env per
            slot). Both give identical episodes.
        progress: Called as ``progress(done, episodes)`` when episodes finish.

    Returns: The :class:`EvaluationResult`.

    Raises:
        ValueError: bad counts, unknown agent or persona names, or an agent whose
            observation does not match the env's.
    """
    _check_counts(episodes, n_envs, seed, backend)
    resolved = resolve_personas(personas if isinstance(personas, str) else list(personas))
    label = name or (agent if isinstance(agent, str) else getattr(agent, "name", type(agent).__name__))
    kwargs = env_kwargs_for(agent, env_id, env_kwargs) if isinstance(agent, str) else dict(env_kwargs or {})
    kwargs["personas"] = list(resolved)  # the people, not their names: "train_wide" is named as "train"
    slots = make_slots(env_id, min(n_envs, episodes), kwargs, backend)
    start_time = time.perf_counter()
    try:
        policy = _policy(agent, slots.features, slots.action_type, env_id, kwargs, seed)
        records = play(policy, slots, episodes, seed, deterministic, progress)
    finally:
        slots.close()
    return EvaluationResult(
        agent=str(label),
        env_id=env_id,
        personas=tuple(p.name for p in resolved),
        seed=seed,
        records=tuple(records),
        wall_time_s=time.perf_counter() - start_time,
        backend=slots.backend,
        env_kwargs={k: v for k, v in kwargs.items() if k != "personas"},
    )


def _policy(
    agent: Agent | str, features: tuple[str, ...], action_type: str, env_id: str, kwargs: dict[str, Any], seed: int
) -> Agent:
    """The agent to play: a scripted agent built for the env's level by name, or ``agent`` checked to fit."""
    if not isinstance(agent, str):
        _check_agent_fits(agent, features, env_id)
        return agent
    if agent not in SCRIPTED_AGENTS:
        raise ValueError(f"unknown agent {agent!r}; scripted agents: {', '.join(SCRIPTED_AGENTS)}")
    level = kwargs.get("difficulty", gym.spec(env_id).kwargs.get("difficulty"))
    try:
        return make_scripted(agent, features, action_type, seed=seed, level=level)
    except ValueError as exc:
        raise ValueError(f"{exc}{unit_id_hint(env_id)}") from None


def _check_counts(episodes: Any, n_envs: Any, seed: Any, backend: str) -> None:
    """ValueError naming the first bad count, seed or backend of :func:`evaluate`."""
    check_integer("episodes", episodes, 1, SEED_LIMIT)
    check_integer("n_envs", n_envs, 1, SEED_LIMIT)
    check_integer("seed", seed, 0, SEED_LIMIT - 1)
    if seed + episodes > SEED_LIMIT:
        raise ValueError(f"seed + episodes must be <= 2**32 (episode k uses seed + k), got seed={seed}")
    if backend not in ("auto", "vector", "single"):
        raise ValueError(f"backend must be 'auto', 'vector' or 'single', got {backend!r}")


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
