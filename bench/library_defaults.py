"""What a newcomer gets: SB3 with library-default hyperparameters on the registered ids.

Trains ``PPO("MlpPolicy", "CoopGym/SitToStand-v0")`` or
``DQN("MlpPolicy", "CoopGym/SitToStandDiscrete-v0")`` exactly as a user would write it
(one env, SB3's defaults, no normalisation), saves the model and scores it with the common
evaluation path (:func:`agents.evaluate.evaluate`) on ``--episodes`` held-out episodes
(seeds 0..N-1), beside the handbook caregiver on the same episodes of ``CoopGym/SitToStand-v0``
(the same model and people; the reference of every score)::

    nice python bench/library_defaults.py --algo ppo --timesteps 300000 --out runs/defaults

``--env ID`` trains on another registered id, e.g. the unit-scaled ``CoopGym/SitToStandUnit-v0``
(the model is saved as ``{algo}_{name}_{timesteps}.zip``).

``--snapshot-at 300000`` also saves (and scores) the model when training first passes 300k
steps, as ``{algo}_{name}_300000.zip``. With PPO's defaults (constant learning rate and clip
range) that model is the one a 300k-step run gives; DQN's exploration schedule spans the whole
run, so for DQN train a separate 300k run instead.

``--save`` also writes the report to ``bench/results/library_defaults_<algo>_<env>_<timesteps>.json``
(``bench/result_files.py``; ``<env>`` is the id's name after ``CoopGym/``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/result_files.py, however this runs
import torch
from held_out import held_out_report
from result_files import add_save_argument, save
from stable_baselines3 import DQN, PPO
from stable_baselines3.common.callbacks import BaseCallback

import coop_gym  # registers the ids
from agents.rl import SB3Agent
from coop_gym.cli import positive_int

ENV_IDS = {"ppo": "CoopGym/SitToStand-v0", "dqn": "CoopGym/SitToStandDiscrete-v0"}


class _Snapshots(BaseCallback):
    """Save the model once ``num_timesteps`` has reached each of ``steps``, after that rollout's update.

    ``learn(total_timesteps=n)`` stops after the update of the rollout that reaches ``n``, so the
    model saved at the start of the next rollout (or at the end of training) is that run's model.
    """

    def __init__(self, steps: list[int], path_for: Callable[[int], Path]) -> None:
        super().__init__()
        self.pending = sorted(steps)
        self.path_for = path_for

    def _save_reached(self) -> None:
        while self.pending and self.num_timesteps >= self.pending[0]:
            self.model.save(self.path_for(self.pending.pop(0)))

    def _on_rollout_start(self) -> None:
        self._save_reached()

    def _on_training_end(self) -> None:
        self._save_reached()

    def _on_step(self) -> bool:
        return True


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--algo", choices=sorted(ENV_IDS), required=True)
    parser.add_argument("--timesteps", type=positive_int, default=300_000)
    parser.add_argument("--env", choices=sorted(coop_gym.ENV_IDS), help="default: the algorithm's id in ENV_IDS")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--episodes", type=positive_int, default=1000, help="held-out episodes per score")
    parser.add_argument("--out", default="runs/defaults")
    parser.add_argument("--snapshot-at", type=int, nargs="*", default=[], help="also save at these step counts")
    add_save_argument(parser, "library_defaults_<algo>_<env>_<timesteps>.json")
    args = parser.parse_args(argv)
    if any(n < 1 or n >= args.timesteps for n in args.snapshot_at):
        parser.error(f"--snapshot-at: each must be in [1, --timesteps), got {args.snapshot_at}")
    torch.set_num_threads(1)

    cls = PPO if args.algo == "ppo" else DQN
    env_id = args.env or ENV_IDS[args.algo]
    model = cls("MlpPolicy", env_id, seed=args.seed, device="cpu")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = "" if args.env is None else env_id.split("/")[-1] + "_"

    def path_for(steps: int) -> Path:
        return out / f"{args.algo}_{name}{steps}.zip"

    started = time.perf_counter()
    model.learn(total_timesteps=args.timesteps, callback=_Snapshots(args.snapshot_at, path_for))
    wall = time.perf_counter() - started
    path = path_for(args.timesteps)
    model.save(path)
    models = {steps: cls.load(path_for(steps), device="cpu") for steps in args.snapshot_at}
    models[args.timesteps] = model
    agents = {str(n): (SB3Agent(m, args.algo, env_id, name=f"{args.algo} {n}"), True) for n, m in models.items()}
    run = {"algo": args.algo, "timesteps": args.timesteps, "seed": args.seed, "wall_time_s": wall}
    report = held_out_report(run, agents, env_id, args.episodes)
    path.with_suffix(".json").write_text(json.dumps(report, indent=2) + "\n")
    if args.save:
        stem = f"{args.algo}_{env_id.split('/')[-1]}_{args.timesteps}"
        save(args.save.replace("<algo>_<env>_<timesteps>", stem), "library_defaults", argv, report)


if __name__ == "__main__":
    main()
