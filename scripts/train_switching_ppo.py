"""Train the pretrained caregiver ``hard-ppo-switching``: PPO on the hard level observing the switching filter.

``train.py`` trains on a registered id as registered; this model's env adds the switching
particle filter's estimate (``p_uncooperative``, ``p_unresponsive``, ``p_cooperative``) to the
default observation, i.e. ``gym.make("CoopGym/SitToStandHard-v1", estimator="switching",
estimator_options=...)``. Everything else is PPO's hard-level default of
:mod:`agents.hyperparams` (the same ``make_train_env`` / ``make_model`` as ``train.py``)::

    python scripts/train_switching_ppo.py --out /tmp/pre/switching --timesteps 1000000 --seed 0

The filter runs with fewer particles than its default (``--n-particles 256 --hypotheses 32``):
a step of 8 envs with the default 1024 particles costs several times PPO's own step, and the
policy meets the same smaller filter when it is scored (the model card records the kwargs).
Writes ``model.zip`` (self-contained, :func:`agents.rl.save_agent`) and ``training.json``.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import tyro


@dataclass
class Args:
    """Command-line arguments; each field's docstring is its ``--help``."""

    out: str = "runs/hard-ppo-switching"
    """folder that receives model.zip and training.json"""
    env: str = "CoopGym/SitToStandHard-v1"
    """the hard level's id (default -v1, as hard-ppo-switching's recorded command; or CoopGym/SitToStandHard-v2)"""
    timesteps: int = 1_000_000
    """training env steps"""
    seed: int = 0
    """seed of training (envs seed .. seed + n_envs - 1, network init, sampling)"""
    n_particles: int = 256
    """particles of the switching filter"""
    hypotheses: int = 32
    """push-compliance hypotheses of the switching filter"""
    threads: int = 1
    """torch CPU threads"""


def env_kwargs(args: Args) -> dict[str, object]:
    """The env kwargs the model is trained (and scored) with."""
    return {
        "estimator": "switching",
        "estimator_options": {"n_particles": args.n_particles, "hypotheses": args.hypotheses},
    }


def main() -> None:
    """Train, save the model and the training summary."""
    args = tyro.cli(Args)
    import torch

    from agents.hyperparams import hyperparams_for
    from agents.rl import make_model, make_train_env, save_agent

    torch.set_num_threads(args.threads)
    config = hyperparams_for("ppo", args.env)
    kwargs = env_kwargs(args)
    out = Path(args.out)
    env = make_train_env(
        args.env,
        config.n_envs,
        args.seed,
        personas=config.personas,
        normalize=config.normalize,
        monitor_file=out / "monitor.csv",
        env_kwargs=kwargs,
    )
    model = make_model(config, env, args.seed, verbose=1)
    started = time.perf_counter()
    model.learn(total_timesteps=args.timesteps)
    wall_time_s = time.perf_counter() - started
    save_agent(model, out, algo="ppo", env_id=args.env)
    env.close()
    summary = {
        "env_id": args.env,
        "env_kwargs": kwargs,
        "seed": args.seed,
        "timesteps": int(model.num_timesteps),
        "n_envs": config.n_envs,
        "personas": config.personas,
        "wall_time_s": wall_time_s,
    }
    (out / "training.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(f"trained {model.num_timesteps} steps in {wall_time_s:.0f} s -> {out / 'model.zip'}")


if __name__ == "__main__":
    main()
