"""Train a robot-caregiver guidance agent, then score it against the scripted baselines.

``python train.py`` with no arguments trains PPO on ``CoopGym/SitToStand-v0`` (training
personas only), evaluates it and every scripted baseline -- the oracle on the oracle
observation of the same episodes -- on the held-out test personas over 1000 seeded
episodes, prints the comparison table and saves everything in one run folder::

    runs/{env}__{algo}__{seed}__{time}/
        model.zip, vecnormalize.pkl, agent.json   the trained agent (agents.rl.load_agent)
        tb/                                       TensorBoard: charts/, losses/, eval/
        monitor.csv                               training episodes (return, length, outcome)
        eval.json, eval.csv                       the comparison (eval.json with every episode)
        learning_curve.png, outcome_rates.png     figures
        results.json                              summary, written last
        COMPLETE                                  marker: the run finished

A run folder without ``COMPLETE`` is a failed or interrupted run. Read top to bottom:
arguments -> training env -> model -> learn -> save -> evaluate -> report.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import importlib.util
import inspect
import itertools
import json
import sys
import time
import types
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Union, get_args, get_origin, get_type_hints

__all__ = ["Args", "main", "parse_args"]


@dataclass
class Args:
    """Command-line arguments; each field's docstring is its ``--help``."""

    algo: str = "ppo"
    """algorithm: ppo (belief observation), recurrent_ppo (raw observation, LSTM) or dqn (flat Discrete actions)"""
    env: str | None = None
    """env id to train on (default: the algorithm's own: ppo CoopGym/SitToStand-v0, recurrent_ppo
    CoopGym/SitToStandRaw-v0, dqn CoopGym/SitToStandDiscrete-v0)"""
    timesteps: int | None = None
    """training env steps (default: agents/hyperparams.py); with --resume, steps added to the saved count"""
    n_envs: int | None = None
    """parallel training envs (default: agents/hyperparams.py)"""
    seed: int = 0
    """seed of training (envs, network init, sampling)"""
    out: str = "runs"
    """folder that receives the run folder {env}__{algo}__{seed}__{time}"""
    resume: str | None = None
    """continue training a saved model (a run folder or its model.zip); the step count continues"""
    eval_episodes: int = 1000
    """seeded evaluation episodes per agent (episode k uses seed eval_seed + k)"""
    eval_seed: int = 0
    """seed of evaluation episode 0 (the same episodes for every agent)"""
    eval_personas: str = "test"
    """personas evaluated on: test (held out, never trained on), train, all, a name or names joined by ','"""
    eval_only: bool = False
    """skip training: evaluate --model against the baselines"""
    model: str | None = None
    """saved model (a run folder or its model.zip) for --eval-only"""
    baselines: str = "random,lift_at_once,push_then_lift,handbook,oracle"
    """scripted agents to compare with, joined by ',' (empty: none)"""
    eval_points: int = 8
    """evaluations during training for the learning curve (min(200, eval_episodes) episodes each; 0: none)"""
    threads: int = 1
    """torch CPU threads (1 measured fastest for these small networks on a shared 2-core machine)"""
    progress: bool = True
    """show a progress bar while training"""
    framework: str = "sb3"
    """sb3 (Stable-Baselines3, in this process) or rllib (Ray RLlib PPO, new API stack; needs the [rllib] extra)"""
    num_env_runners: int = 2
    """--framework rllib: sampling actors (0: sample in the driver)"""
    address: str | None = None
    """--framework rllib: an existing Ray cluster (ray://head:10001 or auto; default: start a local instance)"""


# --- arguments: a typed dataclass whose field docstrings are the --help -------------


def _field_docs(cls: type) -> dict[str, str]:
    """The string literal under each field of a dataclass (the attribute docstrings)."""
    tree = ast.parse(inspect.getsource(cls))
    body = tree.body[0].body  # type: ignore[attr-defined]
    docs: dict[str, str] = {}
    for node, following in itertools.pairwise(body):
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            if isinstance(following, ast.Expr) and isinstance(following.value, ast.Constant):
                docs[node.target.id] = " ".join(str(following.value.value).split())
    return docs


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python train.py", description=(__doc__ or "").split("\n\n")[0])
    docs = _field_docs(Args)
    hints = get_type_hints(Args)
    for f in dataclasses.fields(Args):
        flag = "--" + f.name.replace("_", "-")
        hint = hints[f.name]
        origin = get_origin(hint)
        if origin in (Union, types.UnionType):
            hint = next(a for a in get_args(hint) if a is not type(None))
        doc = docs.get(f.name, "")
        if hint is bool and f.default:  # on by default: --no-<flag> turns it off
            parser.add_argument(flag, action=argparse.BooleanOptionalAction, default=True, help=doc)
        elif hint is bool:
            parser.add_argument(flag, action="store_true", help=doc)
        else:
            shown = "" if f.default is None else f" (default: {f.default})"
            parser.add_argument(flag, type=hint, default=f.default, help=doc + shown, metavar=f.name.upper())
    return parser


def parse_args(argv: list[str] | None = None) -> Args:
    """Parse and validate the command line; usage errors exit with status 2."""
    import gymnasium as gym

    import coop_gym
    from agents.evaluate import output_path_problem
    from agents.hyperparams import ALGORITHMS
    from agents.scripted import SCRIPTED_AGENTS
    from coop_gym.model.personas import resolve_personas

    parser = _build_parser()
    args = Args(**vars(parser.parse_args(argv)))
    if args.algo not in ALGORITHMS:
        parser.error(f"--algo must be one of {', '.join(ALGORITHMS)}, got {args.algo!r}")
    if args.env is not None and args.env not in gym.registry:
        parser.error(f"--env: unknown env id {args.env!r}; coop_gym ids: {', '.join(coop_gym.ENV_IDS)}")
    for name in ("timesteps", "n_envs"):
        value = getattr(args, name)
        if value is not None and value < 1:
            parser.error(f"--{name.replace('_', '-')} must be >= 1, got {value}")
    if args.eval_episodes < 1:
        parser.error(f"--eval-episodes must be >= 1, got {args.eval_episodes}")
    if args.seed < 0 or args.eval_seed < 0:
        parser.error("--seed and --eval-seed must be >= 0")
    if args.eval_points < 0 or args.threads < 1:
        parser.error("--eval-points must be >= 0 and --threads >= 1")
    try:
        resolve_personas(args.eval_personas.split(",") if "," in args.eval_personas else args.eval_personas)
    except ValueError as exc:
        parser.error(f"--eval-personas: {exc}")
    unknown = [b for b in _baselines(args) if b not in SCRIPTED_AGENTS]
    if unknown:
        parser.error(f"--baselines: unknown agent(s) {unknown}; known: {', '.join(SCRIPTED_AGENTS)}")
    if args.framework not in ("sb3", "rllib"):
        parser.error(f"--framework must be sb3 or rllib, got {args.framework!r}")
    if args.framework == "rllib" and (args.algo != "ppo" or args.eval_only or args.resume or args.num_env_runners < 0):
        parser.error("--framework rllib trains ppo only (no --eval-only/--resume) with --num-env-runners >= 0")
    if args.framework == "rllib" and importlib.util.find_spec("ray") is None:
        parser.error('--framework rllib needs Ray RLlib: pip install "torch==2.13.0" -e ".[train,rllib]"')
    if args.eval_only and args.model is None:
        parser.error("--eval-only needs --model PATH")
    if args.model is not None and not args.eval_only:
        parser.error("--model is for --eval-only; use --resume PATH to continue training a model")
    problem = output_path_problem(args.out, folder=True)
    if problem:
        parser.error(f"--out: {problem}")
    if args.eval_only and args.resume is not None:
        parser.error("--eval-only and --resume exclude each other")
    for name in ("resume", "model"):
        path = getattr(args, name)
        if path is not None and not (Path(path).exists() or Path(path).with_suffix(".zip").exists()):
            parser.error(f"--{name}: nothing saved at {path}")
    return args


def _baselines(args: Args) -> list[str]:
    return [b.strip() for b in args.baselines.split(",") if b.strip()]


# --- the run --------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    """Train (unless --eval-only), evaluate against the baselines, save the run folder."""
    args = parse_args(argv)
    if args.framework == "rllib":  # Ray RLlib: its own training loop, the same run folder and evaluation
        from agents.rllib import run

        return run(args)

    import numpy as np
    import torch

    torch.set_num_threads(args.threads)

    from stable_baselines3.common.vec_env import VecNormalize

    from agents.evaluate import evaluate, print_table, write_csv, write_json
    from agents.hyperparams import hyperparams_for
    from agents.plots import plot_learning_curve, plot_outcome_rates
    from agents.rl import (
        VECNORMALIZE_FILE,
        OutcomeStatsCallback,
        PeriodicEvalCallback,
        cleanrl_logger,
        load_agent,
        load_model,
        make_model,
        make_train_env,
        save_agent,
    )

    # The defaults of the algorithm (agents/hyperparams.py), overridden by the flags.
    saved: dict[str, Any] = {}
    if args.eval_only or args.resume:
        saved = _saved_info(args.model or args.resume)
    algo = saved.get("algo", args.algo) if args.eval_only else args.algo
    env_id = args.env or saved.get("env_id") or hyperparams_for(algo).env_id
    config = hyperparams_for(algo, env_id)
    n_envs = args.n_envs or config.n_envs
    timesteps = args.timesteps or config.total_timesteps

    run_name = f"{env_id.replace('/', '-')}__{algo}__{args.seed}__{int(time.time())}"
    run_dir = Path(args.out) / run_name
    for k in range(1, 100):  # two runs started in the same second never share a folder
        try:
            run_dir.mkdir(parents=True, exist_ok=False)
            break
        except FileExistsError:
            run_dir = Path(args.out) / f"{run_name}_{k}"
    run_name = run_dir.name
    print(f"run folder: {run_dir}")
    (run_dir / "args.json").write_text(json.dumps(dataclasses.asdict(args), indent=2) + "\n")
    eval_personas: Any = args.eval_personas.split(",") if "," in args.eval_personas else args.eval_personas

    training: dict[str, Any] = {}
    curve_points: list[dict[str, Any]] = []
    if not args.eval_only:
        # Training env: training personas only; observations normalised if the config says so
        # (a resumed model brings its own statistics and keeps updating them).
        env = make_train_env(env_id, n_envs, args.seed, personas=config.personas, monitor_file=run_dir / "monitor.csv")
        resume_stats = _resume_file(args.resume, VECNORMALIZE_FILE) if args.resume else None
        if resume_stats is not None:
            env = VecNormalize.load(str(resume_stats), env)
            env.training = True
        elif config.normalize and not args.resume:
            env = VecNormalize(env, norm_obs=True, norm_reward=False)

        if args.resume:
            model, _ = load_model(args.resume, env=env)
            start_steps = int(model.num_timesteps)
            print(f"resuming {algo} from {args.resume} at {start_steps} steps")
        else:
            model = make_model(config, env, args.seed)
            start_steps = 0
        model.set_logger(cleanrl_logger(run_dir / "tb"))

        # Periodic scores on the evaluation personas (for the learning curve only; the
        # final model is the last one, never a selected one).
        every = max(1, timesteps // args.eval_points) if args.eval_points else timesteps + 1
        curve_episodes = min(200, args.eval_episodes)
        curve = PeriodicEvalCallback(algo, env_id, eval_personas, curve_episodes, args.eval_seed, every, start_steps)
        started = time.perf_counter()
        model.learn(
            total_timesteps=timesteps,
            reset_num_timesteps=not args.resume,
            progress_bar=args.progress,
            callback=[OutcomeStatsCallback(), curve],
        )
        train_s = time.perf_counter() - started
        curve_points = curve.history
        model_path = save_agent(model, run_dir, algo=algo, env_id=env_id)
        env.close()
        trained_steps = int(model.num_timesteps) - start_steps
        training = {
            "timesteps": trained_steps,
            "total_timesteps": int(model.num_timesteps),
            "resumed_from": args.resume,
            "n_envs": n_envs,
            "wall_time_s": train_s,
            "steps_per_s": trained_steps / train_s if train_s > 0 else None,
            "hyperparams": {**config.model_kwargs(), "normalize": config.normalize, "policy": config.policy},
        }
        print(f"trained {trained_steps} steps in {train_s:.0f} s ({training['steps_per_s']:.0f} steps/s)")
    else:
        assert args.model is not None  # parse_args requires --model with --eval-only
        model_path = Path(args.model)

    # Evaluate the saved agent (what a user loads) and the baselines on the same episodes.
    agent = load_agent(model_path)
    results = []
    started = time.perf_counter()
    label = f"{algo} (learned)"
    results.append(evaluate(agent, env_id, eval_personas, args.eval_episodes, args.eval_seed, name=label))
    for name in _baselines(args):
        results.append(evaluate(name, env_id, eval_personas, args.eval_episodes, args.eval_seed))
    eval_s = time.perf_counter() - started
    print_table(results)

    write_json(results, run_dir / "eval.json", episodes=True)
    write_csv(results, run_dir / "eval.csv")
    plot_outcome_rates(results, run_dir / "outcome_rates.png")
    reference = {r.agent: r.success_rate for r in results[1:] if r.agent in ("handbook", "oracle")}
    if not args.eval_only:
        steps, returns = _monitor_curve(run_dir / "monitor.csv", start_steps)
        plot_learning_curve(
            steps,
            returns,
            run_dir / "learning_curve.png",
            eval_timesteps=[p["timesteps"] for p in curve_points],
            eval_success=[p["success_rate"] for p in curve_points],
            reference=reference,
            title=f"{algo} on {env_id}: training return, success on {args.eval_personas} personas",
        )

    learned = results[0]
    handbook = next((r for r in results if r.agent == "handbook"), None)
    verdict = None
    if handbook is not None:
        verdict = {
            "higher_success_than_handbook": learned.success_rate > handbook.success_rate,
            "no_more_unsafe_than_handbook": learned.unsafe_rate <= handbook.unsafe_rate,
            "learned_success": learned.success_rate,
            "handbook_success": handbook.success_rate,
            "learned_unsafe": learned.unsafe_rate,
            "handbook_unsafe": handbook.unsafe_rate,
        }
        print(
            f"{label}: success {learned.success_rate:.3f} vs handbook {handbook.success_rate:.3f}, "
            f"unsafe {learned.unsafe_rate:.3f} vs {handbook.unsafe_rate:.3f}"
        )
    summary = {
        "run": run_name,
        "algo": algo,
        "env_id": env_id,
        "seed": args.seed,
        "model": str(model_path),
        "training": training,
        "evaluation": {
            "personas": args.eval_personas,
            "episodes": args.eval_episodes,
            "seed": args.eval_seed,
            "wall_time_s": eval_s,
            "results": [r.summary() for r in results],
        },
        "learning_curve": curve_points,
        "verdict": verdict,
        "numpy": np.__version__,
        "torch": torch.__version__,
    }
    # Written last: a run folder with results.json and COMPLETE finished; one without did not.
    (run_dir / "results.json").write_text(json.dumps(summary, indent=2) + "\n")
    (run_dir / "COMPLETE").write_text(time.strftime("%Y-%m-%dT%H:%M:%S") + "\n")
    print(f"saved: {run_dir}")
    return 0


def _saved_info(path: str | None) -> dict[str, Any]:
    """``agent.json`` beside a saved model (empty when absent)."""
    info = _resume_file(path, "agent.json") if path else None
    return json.loads(info.read_text()) if info is not None else {}


def _resume_file(path: str | None, name: str) -> Path | None:
    """A file saved beside a model (``path`` is the run folder or its model.zip)."""
    if path is None:
        return None
    folder = Path(path) if Path(path).is_dir() else Path(path).parent
    candidate = folder / name
    return candidate if candidate.exists() else None


def _monitor_curve(path: Path, start_steps: int) -> tuple[list[float], list[float]]:
    """(env step at episode end, return) of every training episode in SB3's monitor.csv."""
    import csv

    import numpy as np

    if not path.exists():
        return [], []
    with path.open() as handle:
        handle.readline()  # the JSON header line
        rows = list(csv.DictReader(handle))
    lengths = [float(r["l"]) for r in rows]
    returns = [float(r["r"]) for r in rows]
    # Episodes from parallel envs interleave; their cumulative length approximates the step count.
    steps = (start_steps + np.cumsum(lengths)).tolist()
    return steps, returns


if __name__ == "__main__":
    sys.exit(main())
