"""Train a robot-caregiver guidance agent, then score it against the scripted baselines.

``python train.py`` trains PPO on ``CoopGym/SitToStandHard-v2`` (training personas only; ``--seeds N`` seeds played as
one), scores it and every scripted baseline on the same 1000 seeded held-out episodes, prints the comparison and saves
``runs/{env}__{algo}__{seed}__{time}/``. Ctrl-C stops at a checkpoint; ``--resume RUN`` continues it.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Literal

from agents.trainer.train_args import BadArgs, RunProblem, args_problem, parse_train_args, read_training, run_problem
from agents.trainer.training_run import Stopped, StopSignals, run_folder_of, write_failed, write_interrupted
from coop_gym.cli import exit_status

__all__ = ["Args", "main", "parse_args"]


@dataclass
class Args:
    """Command-line arguments; each field's docstring is its ``--help``."""

    algo: Literal["ppo", "recurrent_ppo", "dqn"] = "ppo"  # agents.hyperparams.ALGORITHMS
    """ppo (belief observation), recurrent_ppo (raw observation, LSTM) or dqn (flat Discrete actions)"""
    env: str | None = None
    """env id to train on; None: the algorithm's own (agents/hyperparams.py; ppo: CoopGym/SitToStandHard-v2)"""
    timesteps: int | None = None
    """training env steps; None: the algorithm's budget (agents/hyperparams.py); with --resume, steps added"""
    n_envs: int | None = None
    """parallel training envs; None: the algorithm's (agents/hyperparams.py; --framework rllib: 64 in all)"""
    seed: int = 0
    """seed of training (envs, network init, sampling)"""
    seeds: int | None = None
    """seeds trained (--seed, --seed+1, ...); None: 6 for jax ppo, else 1"""
    keep: Literal["ensemble", "best"] | None = None
    """with --seeds > 1: ensemble (the seeds act as one) or the best on the validation people; None: ensemble for ppo"""
    out: str = "runs"
    """folder that receives the run folder {env}__{algo}__{seed}__{time}"""
    resume: str | None = None
    """an unfinished run folder: resume in place from its last checkpoint; a finished one or a model: start from it"""
    eval_episodes: int = 1000
    """seeded evaluation episodes per agent (episode k uses seed eval_seed + k)"""
    eval_seed: int = 0
    """seed of evaluation episode 0 (the same episodes for every agent)"""
    eval_personas: str = "test"
    """personas evaluated on: test (held out, never trained on), validation, train, all, names joined by ','"""
    eval_only: bool = False
    """skip training: evaluate --model against the baselines"""
    model: str | None = None
    """saved model (a run folder or its model.zip) for --eval-only"""
    baselines: str = "random,lift_at_once,push_then_lift,handbook,blind,prober,belief,oracle"
    """scripted agents to compare with, joined by ','; with blind and oracle: the mind-reading score"""
    eval_points: int = 8
    """evaluations during training for the learning curve (min(200, eval_episodes) episodes each; 0: none)"""
    select_points: int = 8
    """sb3: scores on validation episodes in the last half of training; the best policy is saved (0: the last)"""
    select_episodes: int = 1000
    """validation episodes per score (never the held-out personas)"""
    select_on: Literal["train", "validation"] = "train"
    """people selected on: train (the training personas) or validation (the validation people, never trained on)"""
    checkpoint_every: int | None = None
    """env steps between checkpoints, at the next rollout boundary; None: a tenth of --timesteps; 0: on stop only"""
    threads: int = 1
    """torch CPU threads (these small networks gain little from more, and the envs need the cores)"""
    progress: bool = True
    """show a progress bar while training"""
    framework: Literal["jax", "sb3", "rllib"] | None = None
    """jax (agents/ppo, flax and optax: ppo and recurrent_ppo), sb3 or rllib; None: jax for ppo"""
    policy_lag: Literal[0, 1] | None = None
    """--framework jax, ppo: 1 runs each update on a second core while the next rollout plays (docs/agents.md,
    "Policy lag"); None: the env's (hyperparams.py JAX_POLICY_LAG: 1 on the hard level; --resume: the run's own)"""
    num_env_runners: int = 0
    """--framework rllib: sampling actors (0: in the driver, no episodes between processes; cluster: 1+ per node)"""
    address: str | None = None
    """--framework rllib: an existing Ray cluster (ray://head:10001 or auto); None: start a local instance"""

    def __post_init__(self) -> None:
        """Every Args -- parsed, or read back from a run's args.json -- passes the same checks."""
        if problem := args_problem(self):
            raise BadArgs(problem)


def parse_args(argv: list[str] | None = None) -> Args:
    """Parse and check the command line (a usage error exits with status 2); --resume fills in the run's settings."""
    return parse_train_args(Args, argv, description=(__doc__ or "").split("\n\n")[0])


def main(argv: list[str] | None = None) -> int:
    """Train (unless --eval-only), evaluate against the baselines, save the run folder; the exit status."""
    args = parse_args(argv)
    if args.framework == "rllib":  # Ray RLlib: its own training loop, the same run folder and evaluation
        from agents.trainer.rllib_run import run

        return run(args)
    from agents.trainer.run import plan_run, train
    from agents.trainer.run_report import evaluate_and_report

    stop, folder = StopSignals(), run_folder_of(args)
    try:
        plan = plan_run(args)  # the algorithm's settings overridden by the flags; the run folder
        folder = plan.run_dir
        with stop:
            finished = read_training(folder)  # a run stopped after training: only the evaluation is left
            if finished is None:
                untrained = {"training": {}, "learning_curve": [], "start_steps": 0}
                finished = untrained if args.eval_only else train(args, plan, stop)
            evaluate_and_report(args, plan, finished, stop)
        return 0
    except Stopped:
        return write_interrupted(folder, stop)
    except RunProblem as exc:  # a damaged model or checkpoint: exit status 2, or 1 for a run that cannot continue
        return run_problem(exc)
    except OSError as exc:  # e.g. a full disk
        return write_failed(exc, folder)


if __name__ == "__main__":
    sys.exit(exit_status(main))
