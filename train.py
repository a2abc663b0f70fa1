"""Train a robot-caregiver guidance agent, then score it against the scripted baselines.

``python train.py`` with no arguments trains PPO on ``CoopGym/SitToStandHard-v1`` (the hard
level, where reading the mind decides the outcome; training personas only), evaluates it and
every scripted baseline -- the mental-state-blind policy, the probing caregiver, the oracle on the oracle
observation of the same episodes -- on the held-out test personas over 1000 seeded
episodes, prints the comparison table and saves everything in one run folder::

    runs/{env}__{algo}__{seed}__{time}/
        args.json                                 the run's settings (what --resume continues)
        model.zip                                 the trained agent, self-contained (agents.rl.load_agent)
        vecnormalize.pkl, agent.json              the same normaliser and metadata beside it
        checkpoints/step_N/                       while training: the newest two checkpoints
        training.json                             training summary, once training finished
        tb/                                       TensorBoard: charts/, losses/, eval/
        monitor.csv                               training episodes (return, length, outcome)
        eval.json, eval.csv                       the comparison (eval.json with every episode)
        learning_curve.png, outcome_rates.png     figures
        results.json                              summary, written last
        COMPLETE                                  marker: the run finished
        INTERRUPTED                               marker: stopped by Ctrl-C/SIGTERM; says how to resume

Never lose a run: every file is written atomically (:mod:`coop_gym.io`); a checkpoint is
taken every ``--checkpoint-every`` env steps at a rollout boundary; Ctrl-C or SIGTERM
stops at the next boundary with a final checkpoint (a second Ctrl-C stops at once, keeping
the last one), writes ``INTERRUPTED`` and prints the command that resumes. After a crash or
SIGKILL, ``python train.py --resume RUN`` continues the unfinished run in its own folder
from the last checkpoint with the run's recorded settings and reaches the same weights as
a run that never stopped. A run folder without ``COMPLETE`` is a failed or interrupted run.
Read top to bottom: arguments -> training env -> model -> learn -> save -> evaluate -> report.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import importlib.util
import inspect
import itertools
import json
import signal
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
    """env id to train on (default: the algorithm's own: ppo CoopGym/SitToStandHard-v1, recurrent_ppo
    CoopGym/SitToStandRaw-v0, dqn CoopGym/SitToStandDiscrete-v0)"""
    timesteps: int | None = None
    """training env steps (default: agents/hyperparams.py); with --resume, steps added to the saved count"""
    n_envs: int | None = None
    """parallel training envs (default: agents/hyperparams.py; --framework rllib: 64, split over the env runners)"""
    seed: int = 0
    """seed of training (envs, network init, sampling)"""
    out: str = "runs"
    """folder that receives the run folder {env}__{algo}__{seed}__{time}"""
    resume: str | None = None
    """continue a run: an unfinished run folder resumes in place from its last checkpoint with its recorded
    settings; a finished run folder or a model.zip starts a new run from that model (the step count continues)"""
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
    baselines: str = "random,lift_at_once,push_then_lift,handbook,blind,prober,oracle"
    """scripted agents to compare with, joined by ',' (empty: none)"""
    eval_points: int = 8
    """evaluations during training for the learning curve (min(200, eval_episodes) episodes each; 0: none)"""
    checkpoint_every: int | None = None
    """env steps between checkpoints, taken at the next rollout boundary (default: a tenth of --timesteps;
    0: only when interrupted)"""
    threads: int = 1
    """torch CPU threads (1 measured fastest for these small networks on a shared 2-core machine)"""
    progress: bool = True
    """show a progress bar while training"""
    framework: str = "sb3"
    """sb3 (Stable-Baselines3, in this process) or rllib (Ray RLlib PPO, new API stack; needs the [rllib] extra)"""
    num_env_runners: int = 0
    """--framework rllib: sampling actors (0: sample in the driver, measured fastest on one 2-core machine;
    on a cluster, one or more per node)"""
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


def _build_parser(suppress_defaults: bool = False) -> argparse.ArgumentParser:
    """The parser; with ``suppress_defaults`` it returns only the flags given on the command line."""
    parser = argparse.ArgumentParser(
        prog="python train.py",
        description=(__doc__ or "").split("\n\n")[0],
        argument_default=argparse.SUPPRESS if suppress_defaults else None,
    )
    docs = _field_docs(Args)
    hints = get_type_hints(Args)
    for f in dataclasses.fields(Args):
        flag = "--" + f.name.replace("_", "-")
        hint = hints[f.name]
        origin = get_origin(hint)
        if origin in (Union, types.UnionType):
            hint = next(a for a in get_args(hint) if a is not type(None))
        doc = docs.get(f.name, "")
        default = argparse.SUPPRESS if suppress_defaults else f.default
        if hint is bool and f.default:  # on by default: --no-<flag> turns it off
            parser.add_argument(flag, action=argparse.BooleanOptionalAction, default=default, help=doc)
        elif hint is bool:
            parser.add_argument(flag, action="store_true", default=default, help=doc)
        else:
            shown = "" if f.default is None else f" (default: {f.default})"
            parser.add_argument(flag, type=hint, default=default, help=doc + shown, metavar=f.name.upper())
    return parser


# Settings that define a run: --resume of an unfinished run takes them from its args.json.
RUN_FIELDS = (
    "algo",
    "env",
    "seed",
    "timesteps",
    "n_envs",
    "eval_episodes",
    "eval_seed",
    "eval_personas",
    "baselines",
    "eval_points",
    "checkpoint_every",
)
ARGS_FILE = "args.json"
TRAINING_FILE = "training.json"
INTERRUPTED_FILE = "INTERRUPTED"


def parse_args(argv: list[str] | None = None) -> Args:
    """Parse and validate the command line; usage errors exit with status 2.

    With ``--resume`` of an unfinished run folder the run's own settings fill in the flags not
    given; a given flag that contradicts the run is an error naming it.
    """
    import gymnasium as gym  # noqa: F401  (coop_gym registers into it)

    import coop_gym
    from agents.hyperparams import ALGORITHMS, hyperparams_for
    from agents.scripted import SCRIPTED_AGENTS
    from coop_gym.cli import output_path_problem, seed_range_problem
    from coop_gym.model.personas import resolve_personas

    parser = _build_parser()
    args = Args(**vars(parser.parse_args(argv)))
    given = set(vars(_build_parser(suppress_defaults=True).parse_args(argv)))
    if args.eval_only and args.resume is not None:
        parser.error("--eval-only and --resume exclude each other")
    if args.resume is not None:
        args = _resume_args(parser, args, given)
    if args.algo not in ALGORITHMS:
        parser.error(f"--algo must be one of {', '.join(ALGORITHMS)}, got {args.algo!r}")
    if args.env is not None and args.env not in coop_gym.ENV_IDS:
        parser.error(
            f"--env: unknown env id {args.env!r} (not a coop_gym env); coop_gym ids: {', '.join(coop_gym.ENV_IDS)}"
        )
    for name in ("timesteps", "n_envs"):
        value = getattr(args, name)
        if value is not None and value < 1:
            parser.error(f"--{name.replace('_', '-')} must be >= 1, got {value}")
    if args.eval_episodes < 1:
        parser.error(f"--eval-episodes must be >= 1, got {args.eval_episodes}")
    if args.seed < 0 or args.eval_seed < 0:
        parser.error("--seed and --eval-seed must be >= 0")
    # Envs are seeded seed .. seed + n_envs - 1 and episodes eval_seed .. eval_seed + eval_episodes - 1.
    n_envs = args.n_envs or hyperparams_for(args.algo).n_envs
    problem = seed_range_problem("--seed", args.seed, n_envs) or seed_range_problem(
        "--eval-seed", args.eval_seed, args.eval_episodes
    )
    if problem:
        parser.error(problem)
    if args.eval_points < 0 or args.threads < 1:
        parser.error("--eval-points must be >= 0 and --threads >= 1")
    if args.checkpoint_every is not None and args.checkpoint_every < 0:
        parser.error(f"--checkpoint-every must be >= 0, got {args.checkpoint_every}")
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
    if args.model is not None and not (Path(args.model).exists() or Path(args.model).with_suffix(".zip").exists()):
        parser.error(f"--model: nothing saved at {args.model}")
    return args


def _is_unfinished_run(path: Path) -> bool:
    return path.is_dir() and (path / ARGS_FILE).exists() and not (path / "COMPLETE").exists()


def _resume_args(parser: argparse.ArgumentParser, args: Args, given: set[str]) -> Args:
    """``args`` completed from the run (or model) being resumed; contradicting flags are an error."""
    assert args.resume is not None
    path = Path(args.resume)
    if not (path.exists() or path.with_suffix(".zip").exists()):
        parser.error(f"--resume: nothing saved at {path}")
    if _is_unfinished_run(path):
        try:
            recorded = json.loads((path / ARGS_FILE).read_text())
            if not isinstance(recorded, dict):
                raise ValueError("not a JSON object")
        except (OSError, ValueError) as exc:
            parser.error(f"--resume: {path / ARGS_FILE} is unreadable ({exc})")
        if recorded.get("eval_only"):
            parser.error(
                f"--resume: {path} was an --eval-only run; run it again: --eval-only --model {recorded.get('model')}"
            )
        recorded = _resolved(recorded)
        saved = {name: recorded[name] for name in RUN_FIELDS if name in recorded}
    else:  # a finished run or a model: a new run continuing the model, on its algorithm and env
        from agents.rl import _resolve

        try:
            _, info = _resolve(path)
        except (OSError, ValueError) as exc:
            parser.error(f"--resume: {exc}")
        saved = {k: v for k, v in (("algo", info.get("algo")), ("env", info.get("env_id"))) if v}
    conflicts = [
        f"--{name.replace('_', '-')} {getattr(args, name)!r} (the run has {value!r})"
        for name, value in saved.items()
        if name in given and getattr(args, name) != value
    ]
    if conflicts:
        parser.error(f"--resume {path}: {'; '.join(conflicts)} contradict the saved run; leave them out")
    return dataclasses.replace(args, **saved)


def _resolved(settings: dict[str, Any]) -> dict[str, Any]:
    """Run settings with the algorithm's defaults filled in (older args.json files hold None)."""
    from agents.hyperparams import hyperparams_for

    out = dict(settings)
    algo = out.get("algo", "ppo")
    config = hyperparams_for(algo, out.get("env") or hyperparams_for(algo).env_id)
    out["env"] = out.get("env") or config.env_id
    out["timesteps"] = out.get("timesteps") or config.total_timesteps
    out["n_envs"] = out.get("n_envs") or config.n_envs
    if out.get("checkpoint_every") is None:
        out["checkpoint_every"] = max(1, out["timesteps"] // 10)
    return out


def _baselines(args: Args) -> list[str]:
    return [b.strip() for b in args.baselines.split(",") if b.strip()]


def _usage_error(message: str) -> int:
    """A problem found after parsing (e.g. a damaged model): one line on stderr, exit status 2."""
    print(f"python train.py: error: {message}", file=sys.stderr)
    return 2


# --- stopping cleanly ------------------------------------------------------------


class Stopped(Exception):
    """A second Ctrl-C/SIGTERM, or one outside training: stop now."""


class _StopSignals:
    """SIGINT and SIGTERM stop training at the next rollout boundary; a second one stops at once.

    Outside training a signal stops at once. The previous handlers are restored on exit.
    """

    def __init__(self) -> None:
        self.signum: int | None = None
        self.in_training = False
        self._previous: dict[int, Any] = {}

    def requested(self) -> bool:
        return self.signum is not None

    def _handle(self, signum: int, _frame: Any) -> None:
        first = self.signum is None
        self.signum = signum
        if first and self.in_training:
            print(
                f"\n{signal.Signals(signum).name}: saving a checkpoint at the next rollout boundary "
                "(send it again to stop at once)",
                file=sys.stderr,
            )
            return
        raise Stopped(signal.Signals(signum).name)

    def __enter__(self) -> _StopSignals:
        for signum in (signal.SIGINT, signal.SIGTERM):
            self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *_: Any) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)


# --- the run --------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    """Train (unless --eval-only), evaluate against the baselines, save the run folder."""
    args = parse_args(argv)
    if args.framework == "rllib":  # Ray RLlib: its own training loop, the same run folder and evaluation
        from agents.rllib import run

        return run(args)

    import torch

    torch.set_num_threads(args.threads)

    from agents.hyperparams import hyperparams_for
    from agents.rl import load_agent
    from coop_gym.io import make_unique_folder, write_json

    # The run's settings: the algorithm's defaults (agents/hyperparams.py), overridden by the flags.
    in_place = args.resume is not None and _is_unfinished_run(Path(args.resume))
    saved_agent = None
    if args.eval_only:
        assert args.model is not None  # parse_args requires --model with --eval-only
        try:
            saved_agent = load_agent(args.model)
        except (OSError, ValueError) as exc:
            return _usage_error(f"--model: {exc}")
    algo = saved_agent.algo if saved_agent is not None else args.algo
    env_id = args.env or (saved_agent.env_id if saved_agent else None) or hyperparams_for(algo).env_id
    config = hyperparams_for(algo, env_id)
    timesteps = args.timesteps or config.total_timesteps
    n_envs = args.n_envs or config.n_envs
    checkpoint_every = args.checkpoint_every if args.checkpoint_every is not None else max(1, timesteps // 10)
    # A model must meet the observation it was trained on: checked before any folder is made.
    problem = _observation_problem(args, env_id, saved_agent, in_place)
    if problem:
        return _usage_error(problem)

    if in_place:
        assert args.resume is not None
        run_dir = Path(args.resume)
        recorded = json.loads((run_dir / ARGS_FILE).read_text())
        source_model = recorded.get("resume")  # the model this run itself continued, if any
        _clean_leftovers(run_dir)
        print(f"resuming run folder: {run_dir}")
    else:
        run_name = f"{env_id.replace('/', '-')}__{algo}__{args.seed}__{int(time.time())}"
        run_dir = make_unique_folder(args.out, run_name)  # never shared, even when started in the same second
        source_model = args.resume
        settings = dataclasses.asdict(args) | {
            "algo": algo,
            "env": env_id,
            "timesteps": timesteps,
            "n_envs": n_envs,
            "checkpoint_every": checkpoint_every,
        }
        try:
            write_json(run_dir / ARGS_FILE, settings)
        except OSError as exc:
            run_dir.rmdir()  # still empty: no run to resume, so no folder left behind
            return _write_failed(exc, run_dir)
        print(f"run folder: {run_dir}")

    stop = _StopSignals()
    try:
        with stop:
            plan = _Plan(run_dir, algo, env_id, config, timesteps, n_envs, checkpoint_every, source_model)
            return _run(args, stop, plan)
    except Stopped:
        return _interrupted(run_dir, stop)
    except OSError as exc:
        return _write_failed(exc, run_dir)


def _observation_problem(args: Args, env_id: str, saved_agent: Any, in_place: bool) -> str | None:
    """Why the model of ``--model``/``--resume`` cannot play ``env_id`` (None if it can)."""
    from agents.rl import load_model, observation_features

    flag = "--model" if args.eval_only else "--resume"
    model_features = None
    if saved_agent is not None:
        model_features = saved_agent.features
    elif args.resume is not None and not in_place:
        try:
            _, model_info = load_model(args.resume)
        except (OSError, ValueError) as exc:
            return f"--resume: {exc}"
        model_features = model_info.get("features")
    if model_features is not None:
        from agents.base import feature_mismatch

        problem = feature_mismatch(model_features, observation_features(env_id), env_id)
        return f"{flag}: {problem}" if problem else None
    if saved_agent is not None:  # an older model without feature names: compare the sizes at least
        shape, width = saved_agent.observation_space.shape, len(observation_features(env_id))
        if shape != (width,):
            return f"{flag}: the model observes shape {shape} but {env_id} gives ({width},)"
    return None


def _write_failed(exc: OSError, run_dir: Path) -> int:
    """A file could not be written (e.g. a full disk): it is not there, never half-written; exit status 1."""
    print(f"python train.py: error: could not write {exc.filename or 'output'}: {exc.strerror or exc}", file=sys.stderr)
    print(f"{run_dir} keeps what was complete: free space, then python train.py --resume {run_dir}", file=sys.stderr)
    return 1


@dataclass(frozen=True)
class _Plan:
    """What a run does, settled before any work: the folder, the algorithm, the env and the budget."""

    run_dir: Path
    algo: str
    env_id: str
    config: Any  # agents.hyperparams.TrainingConfig (imported lazily: no torch at parse time)
    timesteps: int
    n_envs: int
    checkpoint_every: int
    source_model: str | None


def _run(args: Args, stop: _StopSignals, plan: _Plan) -> int:
    """Train (or finish training), evaluate, report; returns the exit status."""
    finished_file = plan.run_dir / TRAINING_FILE
    if finished_file.exists():  # an interrupted run that had finished training
        finished = json.loads(finished_file.read_text())
    elif args.eval_only:
        finished = {"training": {}, "learning_curve": [], "start_steps": 0}
    else:
        trained = _train(args, stop, plan)
        if isinstance(trained, int):
            return trained
        finished = trained
    return _evaluate_and_report(args, plan, finished)


def _model_to_train(args: Args, plan: _Plan, env: Any, checkpoint: Path | None) -> tuple[Any, Any, dict[str, Any], int]:
    """``(model, env, checkpoint state, start steps)``: restored, continued from a saved model, or new.

    Raises:
        ValueError: a damaged checkpoint or saved model (the message names it).
    """
    from stable_baselines3.common.vec_env import VecNormalize

    from agents.rl import MODEL_FILE, VECNORMALIZE_FILE, load_model, make_model, read_bundle, restore_checkpoint

    if checkpoint is not None:
        try:
            model, state = restore_checkpoint(checkpoint, env)
        except (OSError, ValueError) as exc:
            raise ValueError(f"--resume: checkpoint {checkpoint}: {exc}") from exc
        print(f"continuing from {checkpoint} at {model.num_timesteps} steps")
        return model, env, state, state["start_steps"]
    if plan.source_model is not None:
        # A new run from a saved model: its own statistics come along and keep updating.
        model_path = Path(plan.source_model)
        model_path = model_path / MODEL_FILE if model_path.is_dir() else model_path
        _, stats = read_bundle(model_path)
        beside = model_path.parent / VECNORMALIZE_FILE
        if stats is None and beside.exists():
            stats = VecNormalize.load(str(beside), env)
        if stats is not None:
            stats.set_venv(env)
            stats.training = True
            env = stats
        try:
            model, _ = load_model(model_path, env=env)
        except (OSError, ValueError) as exc:
            raise ValueError(f"--resume: {exc}") from exc
        print(f"continuing {plan.algo} from {plan.source_model} at {model.num_timesteps} steps")
        return model, env, {}, int(model.num_timesteps)
    if plan.config.normalize:
        env = VecNormalize(env, norm_obs=True, norm_reward=False)
    return make_model(plan.config, env, args.seed), env, {}, 0


def _train(args: Args, stop: _StopSignals, plan: _Plan) -> dict[str, Any] | int:
    """Train to the step budget, checkpointing on the way; the training summary, or an exit status."""
    from agents.rl import TrainingInterrupted, cleanrl_logger, latest_checkpoint, make_train_env, save_agent
    from coop_gym.io import write_json as write_json_file

    run_dir, config = plan.run_dir, plan.config
    checkpoint = latest_checkpoint(run_dir)
    # Training env: training personas only; observations normalised if the config says so.
    env = make_train_env(
        plan.env_id,
        plan.n_envs,
        args.seed,
        personas=config.personas,
        monitor_file=run_dir / "monitor.csv",
        monitor_append=checkpoint is not None,
    )
    try:
        model, env, state, start_steps = _model_to_train(args, plan, env, checkpoint)
    except ValueError as exc:
        return _usage_error(str(exc))
    target = start_steps + plan.timesteps
    model.set_logger(cleanrl_logger(run_dir / "tb"))

    callbacks, curve, elapsed = _callbacks(args, plan, stop, state, start_steps, int(model.num_timesteps))
    stop.in_training = True
    try:
        model.learn(
            total_timesteps=target - int(model.num_timesteps),
            reset_num_timesteps=checkpoint is None and plan.source_model is None,
            progress_bar=args.progress,
            callback=callbacks,
        )
    except TrainingInterrupted:
        return _interrupted(run_dir, stop)
    finally:
        stop.in_training = False
    train_s = elapsed()
    save_agent(model, run_dir, algo=plan.algo, env_id=plan.env_id)
    env.close()
    trained_steps = int(model.num_timesteps) - start_steps
    training = {
        "timesteps": trained_steps,
        "total_timesteps": int(model.num_timesteps),
        "resumed_from": plan.source_model,
        "n_envs": plan.n_envs,
        "wall_time_s": train_s,
        "steps_per_s": trained_steps / train_s if train_s > 0 else None,
        "hyperparams": {**config.model_kwargs(), "normalize": config.normalize, "policy": config.policy},
        "personas": config.personas,
    }
    # Training is over: the summary marks it, and the checkpoints have served their purpose.
    finished = {"training": training, "learning_curve": curve.history if curve else [], "start_steps": start_steps}
    write_json_file(run_dir / TRAINING_FILE, finished)
    _remove_checkpoints(run_dir)
    print(f"trained {trained_steps} steps in {train_s:.0f} s ({training['steps_per_s']:.0f} steps/s)")
    if stop.requested():  # the signal came after the last rollout boundary
        raise Stopped(signal.Signals(stop.signum or signal.SIGINT).name)
    return finished


def _callbacks(
    args: Args, plan: _Plan, stop: _StopSignals, state: dict[str, Any], start_steps: int, model_steps: int
) -> tuple[list[Any], Any, Any]:
    """``(callbacks, learning-curve callback or None, training-seconds clock)`` of a training run."""
    from agents.rl import CheckpointCallback, OutcomeStatsCallback, PeriodicEvalCallback

    # Periodic scores on the evaluation personas (for the learning curve only; the
    # final model is the last one, never a selected one).
    callbacks: list[Any] = [OutcomeStatsCallback()]
    curve = None
    if args.eval_points > 0:
        every = max(1, plan.timesteps // args.eval_points)
        curve_episodes = min(200, args.eval_episodes)
        curve = PeriodicEvalCallback(
            plan.algo, plan.env_id, _eval_personas(args), curve_episodes, args.eval_seed, every, start_steps
        )
        if state:
            curve.history, curve._next = state["curve_history"], state["curve_next"]
        callbacks.append(curve)
    wall_s = float(state.get("wall_time_s", 0.0))  # training seconds before an interruption
    started = time.perf_counter()

    def elapsed() -> float:
        return wall_s + time.perf_counter() - started

    def checkpoint_state() -> dict[str, Any]:
        return {
            "start_steps": start_steps,
            "curve_history": curve.history if curve else [],
            "curve_next": curve._next if curve else None,
            "wall_time_s": elapsed(),
        }

    callbacks.append(
        CheckpointCallback(
            plan.run_dir,
            plan.checkpoint_every,
            algo=plan.algo,
            env_id=plan.env_id,
            stop_requested=stop.requested,
            extra=checkpoint_state,
            start_steps=model_steps,
        )
    )
    return callbacks, curve, elapsed


def _eval_personas(args: Args) -> Any:
    return args.eval_personas.split(",") if "," in args.eval_personas else args.eval_personas


def _evaluate_and_report(args: Args, plan: _Plan, finished: dict[str, Any]) -> int:
    """Score the saved agent and the baselines on the same episodes; write the figures and results.json."""
    from agents.evaluate import evaluate, headroom, print_table, write_csv, write_json
    from agents.plots import plot_learning_curve, plot_outcome_rates
    from agents.rl import MODEL_FILE, load_agent
    from coop_gym.io import write_json as write_json_file
    from coop_gym.io import write_text

    run_dir, env_id = plan.run_dir, plan.env_id
    model_path = Path(args.model) if args.eval_only and args.model else run_dir / MODEL_FILE
    eval_personas = _eval_personas(args)
    # Evaluate the saved agent (what a user loads) and the baselines on the same episodes.
    agent = load_agent(model_path)
    started = time.perf_counter()
    label = f"{plan.algo} (learned)"
    results = [evaluate(agent, env_id, eval_personas, args.eval_episodes, args.eval_seed, name=label)]
    for name in _baselines(args):
        results.append(evaluate(name, env_id, eval_personas, args.eval_episodes, args.eval_seed))
    eval_s = time.perf_counter() - started
    print_table(results)
    room = headroom(results)
    if room is not None:
        print("\n".join(room.lines()))

    write_json(results, run_dir / "eval.json", episodes=True)
    write_csv(results, run_dir / "eval.csv")
    plot_outcome_rates(results, run_dir / "outcome_rates.png")
    curve_points = finished["learning_curve"]
    if not args.eval_only:
        steps, returns = _monitor_curve(run_dir / "monitor.csv", finished["start_steps"])
        plot_learning_curve(
            steps,
            returns,
            run_dir / "learning_curve.png",
            eval_timesteps=[p["timesteps"] for p in curve_points],
            eval_success=[p["success_rate"] for p in curve_points],
            reference={r.agent: r.success_rate for r in results[1:] if r.agent in ("handbook", "oracle")},
            title=f"{plan.algo} on {env_id}: training return, success on {args.eval_personas} personas",
        )
    summary = {
        "run": run_dir.name,
        "algo": plan.algo,
        "env_id": env_id,
        "seed": args.seed,
        "model": str(model_path),
        "training": finished["training"],
        "evaluation": {
            "personas": args.eval_personas,
            "episodes": args.eval_episodes,
            "seed": args.eval_seed,
            "wall_time_s": eval_s,
            "results": [r.summary() for r in results],
        },
        "learning_curve": curve_points,
        "verdict": _verdict(label, results),
        "headroom": None
        if room is None
        else {
            **dataclasses.asdict(room),
            "value_of_reading_the_mind": room.value_of_reading_the_mind,
            "achieved_insight": room.achieved_insight,
        },
        **_versions(),
    }
    # Written last: a run folder with results.json and COMPLETE finished; one without did not.
    write_json_file(run_dir / "results.json", summary)
    (run_dir / INTERRUPTED_FILE).unlink(missing_ok=True)
    write_text(run_dir / "COMPLETE", time.strftime("%Y-%m-%dT%H:%M:%S") + "\n")
    print(f"saved: {run_dir}")
    return 0


def _verdict(label: str, results: list[Any]) -> dict[str, Any] | None:
    """The learned agent (``results[0]``) against the handbook caregiver, printed and returned."""
    learned = results[0]
    handbook = next((r for r in results if r.agent == "handbook"), None)
    if handbook is None:
        return None
    print(
        f"{label}: success {learned.success_rate:.3f} vs handbook {handbook.success_rate:.3f}, "
        f"unsafe {learned.unsafe_rate:.3f} vs {handbook.unsafe_rate:.3f}"
    )
    return {
        "higher_success_than_handbook": learned.success_rate > handbook.success_rate,
        "no_more_unsafe_than_handbook": learned.unsafe_rate <= handbook.unsafe_rate,
        "learned_success": learned.success_rate,
        "handbook_success": handbook.success_rate,
        "learned_unsafe": learned.unsafe_rate,
        "handbook_unsafe": handbook.unsafe_rate,
    }


def _versions() -> dict[str, str]:
    import numpy as np
    import torch

    return {"numpy": np.__version__, "torch": torch.__version__}


def _interrupted(run_dir: Path, stop: _StopSignals) -> int:
    """Write the INTERRUPTED marker, say how to resume; the exit status is 128 + the signal number."""
    from agents.rl import latest_checkpoint
    from coop_gym.io import write_text

    name = signal.Signals(stop.signum).name if stop.signum else "interrupt"
    checkpoint = latest_checkpoint(run_dir)
    if (run_dir / TRAINING_FILE).exists():
        state = "training had finished; resuming runs the evaluation"
    else:
        state = f"last checkpoint {checkpoint}" if checkpoint else "no checkpoint yet; resuming starts training over"
    message = f"{name}: stopped, {state}\nresume with: python train.py --resume {run_dir}\n"
    write_text(run_dir / INTERRUPTED_FILE, time.strftime("%Y-%m-%dT%H:%M:%S ") + message)
    print(f"\n{message}", end="", file=sys.stderr)
    return 128 + (stop.signum or signal.SIGINT)


def _clean_leftovers(run_dir: Path) -> None:
    """Before resuming: drop the marker and any temporary file a killed process left behind."""
    import shutil

    from coop_gym.io import TEMP_MARKER

    (run_dir / INTERRUPTED_FILE).unlink(missing_ok=True)
    for leftover in list(run_dir.rglob(f"*{TEMP_MARKER}*")):
        if leftover.is_dir():
            shutil.rmtree(leftover, ignore_errors=True)
        else:
            leftover.unlink(missing_ok=True)


def _remove_checkpoints(run_dir: Path) -> None:
    import shutil

    from agents.rl import CHECKPOINTS_DIR

    shutil.rmtree(run_dir / CHECKPOINTS_DIR, ignore_errors=True)


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
