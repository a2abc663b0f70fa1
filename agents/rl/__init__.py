"""Learned agents: SB3 PPO, sb3-contrib RecurrentPPO and SB3 DQN on the coop_gym envs.

One import for everything the trainer and the loaders use; each part has a module:

* :mod:`agents.rl.training` -- :func:`make_train_env` (the training ``VecEnv``) and
  :func:`make_model` (the algorithm with the defaults of :mod:`agents.hyperparams`);
  :func:`sb3_settings` (those defaults as the dict and wrappers an SB3 script passes);
* :mod:`agents.rl.bundle` -- :func:`save_agent` / :func:`load_agent` (:mod:`agents.rl.ensemble`'s, which
  also loads a run folder whose seeds play as one): a self-contained
  ``model.zip`` that loads as an :class:`SB3Agent`, scored by :func:`agents.evaluate.evaluate`
  like any other agent;
* :mod:`agents.rl.callbacks` -- TensorBoard under CleanRL's names, outcome rates, periodic
  evaluations, the selection of the saved policy on validation episodes;
* :mod:`agents.rl.checkpoints` -- checkpoints that continue training exactly.

Example:
    >>> from agents.rl import make_train_env, make_model
    >>> from agents.hyperparams import hyperparams_for
    >>> config = hyperparams_for("ppo")
    >>> env = make_train_env(config.env_id, n_envs=2, seed=0, normalize=True)
    >>> model = make_model(config, env, seed=0)
    >>> type(model).__name__
    'PPO'
    >>> env.close()
"""

from __future__ import annotations

from agents.rl.bundle import (
    BUNDLE_INFO,
    BUNDLE_VECNORMALIZE,
    SB3Agent,
    load_model,
    load_to_continue,
    read_bundle,
    resolve_saved,
    save_agent,
    save_model_bundle,
    saved_model_problem,
)
from agents.rl.callbacks import (
    CleanRLTensorBoard,
    OutcomeStatsCallback,
    PeriodicEvalCallback,
    SelectionCallback,
    cleanrl_logger,
)
from agents.rl.checkpoints import (
    CheckpointCallback,
    TrainingInterrupted,
    latest_checkpoint,
    restore_checkpoint,
    save_checkpoint,
)
from agents.rl.ensemble import load_agent
from agents.rl.normalize import ObsNormalizer
from agents.rl.training import (
    VEC_NORMALIZE_KWARGS,
    LinearDecay,
    SB3Settings,
    algorithm_class,
    find_vec_normalize,
    make_model,
    make_train_env,
    observation_features,
    sb3_settings,
)
from agents.run_folder import AGENT_FILE, CHECKPOINTS_DIR, MODEL_FILE, VECNORMALIZE_FILE

__all__ = [
    "AGENT_FILE",
    "BUNDLE_INFO",
    "BUNDLE_VECNORMALIZE",
    "CHECKPOINTS_DIR",
    "MODEL_FILE",
    "VECNORMALIZE_FILE",
    "VEC_NORMALIZE_KWARGS",
    "CheckpointCallback",
    "CleanRLTensorBoard",
    "LinearDecay",
    "ObsNormalizer",
    "OutcomeStatsCallback",
    "PeriodicEvalCallback",
    "SB3Agent",
    "SB3Settings",
    "SelectionCallback",
    "TrainingInterrupted",
    "algorithm_class",
    "cleanrl_logger",
    "find_vec_normalize",
    "latest_checkpoint",
    "load_agent",
    "load_model",
    "load_to_continue",
    "make_model",
    "make_train_env",
    "observation_features",
    "read_bundle",
    "resolve_saved",
    "restore_checkpoint",
    "save_agent",
    "save_checkpoint",
    "save_model_bundle",
    "saved_model_problem",
    "sb3_settings",
]
