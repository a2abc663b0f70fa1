"""Agents for the coop_gym envs: scripted baselines, SB3 learners, one evaluation path.

Every agent follows SB3's ``predict(obs, state, episode_start, deterministic) -> (actions,
state)`` (:class:`agents.base.Agent`), so :func:`agents.evaluate.evaluate` scores scripted
and learned agents on the same seeded episodes (``agents.evaluate`` is that module: use
``from agents.evaluate import evaluate``).

The rooms: :mod:`agents.caregivers` (the scripted caregivers, one base class), :mod:`agents.evaluate`,
:mod:`agents.rl` (the learners: SB3, RLlib), :mod:`agents.trainer` (``train.py``'s pieces, the learners'
defaults), :mod:`agents.tools` (play, record, plots); docs/ARCHITECTURE.md says where a new piece goes.

``import agents`` stays light: torch and Stable-Baselines3 load only when a learned-agent
name (``load_agent``, ``SB3Agent``, ``make_model``, ``make_sb3_vec_env`` ...) is first used.
"""

from __future__ import annotations

import importlib
from typing import Any

from agents.base import Agent, action_type_of, encode_actions, features_of
from agents.caregivers.scripted import (
    SCRIPTED_AGENTS,
    HandbookCaregiver,
    HandbookSettings,
    LiftAtOnceAgent,
    OracleAgent,
    OracleSettings,
    PushThenLiftAgent,
    PushThenLiftSettings,
    RandomAgent,
    ScriptedAgent,
    make_scripted,
)
from agents.hyperparams import ALGORITHMS, DEFAULT_ENV_IDS, HYPERPARAMS, TrainingConfig, hyperparams_for

# name -> module, imported on first use, so `import agents` stays cheap: agents.evaluate
# builds envs and tables, the rest need torch / SB3.
_LAZY = {
    "EpisodeRecord": "agents.evaluate",
    "EvaluationResult": "agents.evaluate",
    "wilson_interval": "agents.evaluate",
    "SB3Agent": "agents.rl",
    "ObsNormalizer": "agents.rl.normalize",
    "load_agent": "agents.rl",
    "load_model": "agents.rl",
    "make_model": "agents.rl",
    "make_train_env": "agents.rl",
    "save_agent": "agents.rl",
    "SB3VecEnvAdapter": "agents.rl.sb3_vec",
    "make_sb3_vec_env": "agents.rl.sb3_vec",
}


def __getattr__(name: str) -> Any:
    """Import the torch/SB3-dependent names lazily (PEP 562)."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'agents' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


__all__ = [
    "ALGORITHMS",
    "DEFAULT_ENV_IDS",
    "HYPERPARAMS",
    "SCRIPTED_AGENTS",
    "Agent",
    "EpisodeRecord",
    "EvaluationResult",
    "HandbookCaregiver",
    "HandbookSettings",
    "LiftAtOnceAgent",
    "ObsNormalizer",
    "OracleAgent",
    "OracleSettings",
    "PushThenLiftAgent",
    "PushThenLiftSettings",
    "RandomAgent",
    "SB3Agent",
    "SB3VecEnvAdapter",
    "ScriptedAgent",
    "TrainingConfig",
    "action_type_of",
    "encode_actions",
    "features_of",
    "hyperparams_for",
    "load_agent",
    "load_model",
    "make_model",
    "make_sb3_vec_env",
    "make_scripted",
    "make_train_env",
    "save_agent",
    "wilson_interval",
]
