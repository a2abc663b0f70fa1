"""``python train.py --framework rllib``: train PPO with Ray RLlib, then score it like every run.

The run folder has the SB3 path's layout (``args.json``, ``checkpoint/`` + ``agent.json`` in
place of ``model.zip``, ``eval.json``, ``eval.csv``, ``results.json``, ``COMPLETE``); the
learner itself is :mod:`agents.rl.rllib`.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import torch

from agents.hyperparams import hyperparams_for
from agents.rl.rllib import CHECKPOINT_DIR, FRAMEWORK, envs_per_runner, load_rllib_agent, ppo_config, train
from agents.run_folder import AGENT_FILE, ARGS_FILE
from agents.trainer.run_report import compare_with_baselines, finish_run, new_run_folder
from coop_gym.io import write_json

__all__ = ["run"]


def run(args: Any) -> int:
    """``python train.py --framework rllib``: train PPO with RLlib, evaluate against the baselines.

    ``args`` is ``train.Args``; the run folder has the SB3 path's layout with ``checkpoint/``
    (and ``agent.json``) in place of ``model.zip``.
    """
    import ray

    torch.set_num_threads(args.threads)
    env_id = args.env or hyperparams_for("ppo").env_id
    run_dir = new_run_folder(args.out, env_id, "rllib_ppo", args.seed)
    print(f"run folder: {run_dir}")
    write_json(run_dir / ARGS_FILE, dataclasses.asdict(args))
    # A local instance sized to the runners (plus the driver's learner), or the given cluster.
    if args.address:
        ray.init(address=args.address, log_to_driver=False)
    else:
        ray.init(num_cpus=args.num_env_runners + 1, include_dashboard=False, log_to_driver=False)
    try:
        training = _train_run(args, env_id, run_dir)
    finally:
        ray.shutdown()
    info = {"framework": FRAMEWORK, "algo": "ppo", "env_id": env_id, "checkpoint": CHECKPOINT_DIR}
    write_json(run_dir / AGENT_FILE, info | {"num_timesteps": training["timesteps"]})
    print(f"trained {training['timesteps']} steps in {training['wall_time_s']:.0f} s")

    # The same evaluation path, the same seeded episodes as every other agent.
    comparison = compare_with_baselines(load_rllib_agent(run_dir), "rllib ppo (learned)", env_id, args, run_dir)
    summary = {
        "run": run_dir.name,
        "framework": FRAMEWORK,
        "algo": "ppo",
        "env_id": env_id,
        "seed": args.seed,
        "model": str(run_dir / CHECKPOINT_DIR),
        "training": training,
        **comparison.summary(),
        "ray": ray.__version__,
        "torch": torch.__version__,
    }
    # Written last: results.json and COMPLETE mark a finished run, as on the SB3 path.
    finish_run(run_dir, summary)
    return 0


def _train_run(args: Any, env_id: str, run_dir: Path) -> dict[str, Any]:
    """Train PPO on ``env_id`` with ``train.Args``'s settings (Ray initialised); the training summary."""
    sb3 = hyperparams_for("ppo", env_id)
    timesteps = args.timesteps or sb3.total_timesteps
    per_runner = envs_per_runner(args.n_envs, args.num_env_runners)
    config = ppo_config(
        env_id,
        seed=args.seed,
        num_env_runners=args.num_env_runners,
        num_envs_per_env_runner=per_runner,
        personas=sb3.personas,
        timesteps=timesteps,
    )
    training = train(config, timesteps, run_dir / CHECKPOINT_DIR, verbose=args.progress)
    return training | {
        "num_env_runners": args.num_env_runners,
        "num_envs_per_env_runner": per_runner,
        "address": args.address,
    }
