"""The files of a saved agent and of a ``train.py`` run folder, and which kind a path holds.

A run folder ``runs/{env}__{algo}__{seed}__{time}/`` holds::

    args.json                                 the run's settings (what --resume continues)
    model.zip                                 the trained agent, self-contained (agents.rl.load_agent)
    ensemble.json                             --keep ensemble: the seeds played as one (the folder loads as them)
    vecnormalize.pkl, agent.json              the same normaliser and metadata beside it
    checkpoints/step_N/                       while training: the newest two checkpoints
    checkpoints/best_step_N.zip               while training: the best-validated policies so far
    training.json                             training summary, once training finished
    tb/                                       TensorBoard: charts/, losses/, eval/
    monitor.csv                               training episodes (return, length, outcome)
    eval.json, eval.csv                       the comparison (eval.json with every episode)
    learning_curve.png, outcome_rates.png     figures
    results.json                              summary, written last
    COMPLETE                                  marker: the run finished
    INTERRUPTED                               marker: stopped by Ctrl-C/SIGTERM; says how to resume

Every file is written atomically (:mod:`coop_gym.io`): after a crash or SIGKILL,
``python train.py --resume RUN`` continues an unfinished run in its own folder from the last
checkpoint with the run's recorded settings and reaches the same weights as a run that never
stopped. A run folder without ``COMPLETE`` is a failed or interrupted run.

One place for the names, so the trainer that writes them and the loaders that read them
agree. Plain paths and JSON: no torch, SB3 or Ray (``python -m agents.evaluate`` asks
:func:`is_rllib_run` before it decides which of them to import).
"""

from __future__ import annotations

import json
from pathlib import Path

__all__ = [
    "AGENT_FILE",
    "ARGS_FILE",
    "CHECKPOINTS_DIR",
    "COMPLETE_FILE",
    "ENSEMBLE_FILE",
    "ENSEMBLE_PREFIX",
    "INTERRUPTED_FILE",
    "MODEL_FILE",
    "RLLIB_CHECKPOINT_DIR",
    "RLLIB_FRAMEWORK",
    "TRAINING_FILE",
    "VECNORMALIZE_FILE",
    "is_rllib_run",
    "is_unfinished_run",
]

ENSEMBLE_FILE = "ensemble.json"
"""A run folder kept as an ensemble (``train.py --seeds N --keep ensemble``): its members' folders, relative to it."""
ENSEMBLE_PREFIX = "ensemble:"
"""``ensemble:MODEL+MODEL+...`` names saved agents played as one (:mod:`agents.rl.ensemble`)."""

MODEL_FILE = "model.zip"
"""The SB3 model, self-contained (metadata and normaliser inside)."""
VECNORMALIZE_FILE = "vecnormalize.pkl"
"""The observation statistics beside the model (what older run folders hold)."""
AGENT_FILE = "agent.json"
"""The agent's metadata: algorithm, env id, features, framework."""
CHECKPOINTS_DIR = "checkpoints"
"""SB3 training checkpoints, ``step_N/`` each."""
RLLIB_FRAMEWORK = "rllib"
"""``agent.json``'s ``framework`` of an RLlib run."""
RLLIB_CHECKPOINT_DIR = "checkpoint"
"""The RLlib algorithm checkpoint of an RLlib run folder."""
ARGS_FILE = "args.json"
"""The run's settings (what ``--resume`` continues)."""
TRAINING_FILE = "training.json"
"""The training summary, written once training finished."""
INTERRUPTED_FILE = "INTERRUPTED"
"""Marker: stopped by a signal; says how to resume."""
COMPLETE_FILE = "COMPLETE"
"""Marker: the run finished (written last)."""


def is_rllib_run(path: str | Path) -> bool:
    """True for a run folder (or its ``checkpoint/``) of ``train.py --framework rllib``: its ``agent.json`` says so.

    Anything else -- an SB3 model or folder, a damaged ``agent.json`` -- is False: the SB3
    loader then names what is wrong with it.
    """
    path = Path(path)
    folder = path.parent if path.name == RLLIB_CHECKPOINT_DIR else path
    info = folder / AGENT_FILE
    if not (path.is_dir() and info.exists()):
        return False
    try:
        return bool(json.loads(info.read_text()).get("framework") == RLLIB_FRAMEWORK)
    except (OSError, ValueError, AttributeError):
        return False


def is_unfinished_run(path: str | Path) -> bool:
    """True for a run folder that recorded its settings but did not finish (``--resume`` continues it in place)."""
    path = Path(path)
    return path.is_dir() and (path / ARGS_FILE).exists() and not (path / COMPLETE_FILE).exists()
