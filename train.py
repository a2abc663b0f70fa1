"""Train a robot-caregiver guidance agent, then score it against the scripted baselines.

``python train.py`` with no arguments trains PPO on ``CoopGym/SitToStandHard-v2`` (the hard
level, where reading the mind decides the outcome; training personas only), keeps the policy
that scores best on the training personas' validation episodes in the last half of training
(``--select-points``; docs/agents.md, "Which policy is saved"), evaluates it and
every scripted baseline -- the mental-state-blind policy, the probing caregiver, the belief
caregiver on the switching filter's estimate, the oracle on the oracle observation of the same
episodes -- on the held-out test personas over 1000 seeded
episodes, prints the comparison table (with each agent's mind-reading score) and saves
everything in one run folder::

    runs/{env}__{algo}__{seed}__{time}/
        args.json                                 the run's settings (what --resume continues)
        model.zip                                 the trained agent, self-contained (agents.rl.load_agent)
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

Never lose a run: every file is written atomically (:mod:`coop_gym.io`); a checkpoint is
taken every ``--checkpoint-every`` env steps at a rollout boundary; Ctrl-C or SIGTERM
stops at the next boundary with a final checkpoint (a second Ctrl-C stops at once, keeping
the last one), writes ``INTERRUPTED`` and prints the command that resumes. After a crash or
SIGKILL, ``python train.py --resume RUN`` continues the unfinished run in its own folder
from the last checkpoint with the run's recorded settings and reaches the same weights as
a run that never stopped. A run folder without ``COMPLETE`` is a failed or interrupted run.
Read top to bottom: arguments -> training env -> model -> learn -> save -> evaluate -> report.
The arguments are the typed :class:`Args`, parsed by tyro (as CleanRL does): its field
docstrings are the ``--help``.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import signal
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

import tyro

from agents.run_folder import ARGS_FILE, TRAINING_FILE, is_unfinished_run
from agents.training_run import (
    Stopped,
    StopSignals,
    clean_leftovers,
    monitor_curve,
    remove_checkpoints,
    resume_settings,
    write_interrupted,
)

__all__ = ["Args", "main", "parse_args"]

PROG = "python train.py"


@dataclass
class Args:
    """Command-line arguments; each field's docstring is its ``--help``."""

    algo: str = "ppo"
    """ppo (belief observation), recurrent_ppo (raw observation, LSTM) or dqn (flat Discrete actions)"""
    env: str | None = None
    """env id to train on; None: the algorithm's own (agents/hyperparams.py; ppo: CoopGym/SitToStandHard-v2)"""
    timesteps: int | None = None
    """training env steps; None: the algorithm's budget (agents/hyperparams.py); with --resume, steps added"""
    n_envs: int | None = None
    """parallel training envs; None: the algorithm's (agents/hyperparams.py; --framework rllib: 64 in all)"""
    seed: int = 0
    """seed of training (envs, network init, sampling)"""
    out: str = "runs"
    """folder that receives the run folder {env}__{algo}__{seed}__{time}"""
    resume: str | None = None
    """an unfinished run folder: resume in place from its last checkpoint; a finished one or a model: start from it"""
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
    baselines: str = "random,lift_at_once,push_then_lift,handbook,blind,prober,belief,oracle"
    """scripted agents to compare with, joined by ','; with blind and oracle: the mind-reading score"""
    eval_points: int = 8
    """evaluations during training for the learning curve (min(200, eval_episodes) episodes each; 0: none)"""
    select_points: int = 8
    """sb3: scores on validation episodes in the last half of training; the best policy is saved (0: the last)"""
    select_episodes: int = 1000
    """validation episodes per score (the training personas, never the held-out ones)"""
    checkpoint_every: int | None = None
    """env steps between checkpoints, at the next rollout boundary; None: a tenth of --timesteps; 0: on stop only"""
    threads: int = 1
    """torch CPU threads (these small networks gain little from more, and the envs need the cores)"""
    progress: bool = True
    """show a progress bar while training"""
    framework: str = "sb3"
    """sb3 (Stable-Baselines3, in this process) or rllib (Ray RLlib PPO, new API stack; the [rllib] extra)"""
    num_env_runners: int = 0
    """--framework rllib: sampling actors (0: in the driver, no episodes between processes; cluster: 1+ per node)"""
    address: str | None = None
    """--framework rllib: an existing Ray cluster (ray://head:10001 or auto); None: start a local instance"""


# --- arguments: tyro parses Args; the checks below name what is wrong ----------------


def _fail(message: str) -> NoReturn:
    """A usage error found after parsing: the usage line and one error line on stderr, exit status 2."""
    print(f"usage: {PROG} [-h] [OPTIONS]\n{PROG}: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def _given(argv: list[str]) -> set[str]:
    """The fields set on the command line (``--n-envs 4``, ``--n-envs=4``, ``--no-progress``)."""
    names = {f.name for f in dataclasses.fields(Args)}
    flags = {token[2:].split("=")[0].replace("-", "_") for token in argv if token.startswith("--")}
    return {name for flag in flags for name in (flag, flag.removeprefix("no_")) if name in names}


def parse_args(argv: list[str] | None = None) -> Args:
    """Parse and validate the command line; usage errors exit with status 2.

    With ``--resume`` of an unfinished run folder the run's own settings fill in the flags not
    given; a given flag that contradicts the run is an error naming it.
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    description = (__doc__ or "").split("\n\n")[0]
    args = tyro.cli(Args, args=argv, prog=PROG, description=description, config=(tyro.conf.DisallowNone,))
    if args.eval_only and args.resume is not None:
        _fail("--eval-only and --resume exclude each other")
    if args.resume is not None:
        args = _resumed(args, _given(argv))
    problem = _problem_with_numbers(args) or _problem_with_names(args) or _problem_with_framework(args)
    problem = problem or _problem_with_paths(args)
    if problem:
        _fail(problem)
    return args


def _resumed(args: Args, given: set[str]) -> Args:
    """``args`` completed from the run (or model) being resumed; contradicting flags are an error."""
    assert args.resume is not None
    try:
        saved = resume_settings(Path(args.resume))
    except ValueError as exc:
        _fail(str(exc))
    conflicts = [
        f"--{name.replace('_', '-')} {getattr(args, name)!r} (the run has {value!r})"
        for name, value in saved.items()
        if name in given and getattr(args, name) != value
    ]
    if conflicts:
        _fail(f"--resume {args.resume}: {'; '.join(conflicts)} contradict the saved run; leave them out")
    return dataclasses.replace(args, **saved)


def _problem_with_numbers(args: Args) -> str | None:
    """The first count or seed out of range (None if all are fine)."""
    from agents.hyperparams import ALGORITHMS, hyperparams_for
    from coop_gym.cli import seed_range_problem

    if args.algo not in ALGORITHMS:
        return f"--algo must be one of {', '.join(ALGORITHMS)}, got {args.algo!r}"
    for name in ("timesteps", "n_envs"):
        value = getattr(args, name)
        if value is not None and value < 1:
            return f"--{name.replace('_', '-')} must be >= 1, got {value}"
    if args.eval_episodes < 1:
        return f"--eval-episodes must be >= 1, got {args.eval_episodes}"
    if args.seed < 0 or args.eval_seed < 0:
        return "--seed and --eval-seed must be >= 0"
    # Envs are seeded seed .. seed + n_envs - 1 and episodes eval_seed .. eval_seed + eval_episodes - 1.
    n_envs = args.n_envs or hyperparams_for(args.algo).n_envs
    problem = seed_range_problem("--seed", args.seed, n_envs)
    problem = problem or seed_range_problem("--eval-seed", args.eval_seed, args.eval_episodes)
    if problem:
        return problem
    if args.eval_points < 0 or args.threads < 1:
        return "--eval-points must be >= 0 and --threads >= 1"
    if args.select_points < 0 or args.select_episodes < 1:
        return "--select-points must be >= 0 and --select-episodes >= 1"
    if args.checkpoint_every is not None and args.checkpoint_every < 0:
        return f"--checkpoint-every must be >= 0, got {args.checkpoint_every}"
    return None


def _problem_with_names(args: Args) -> str | None:
    """The first unknown env id, persona or baseline (None if all are known)."""
    import coop_gym
    from agents.run_report import baseline_names, personas_arg
    from agents.scripted import SCRIPTED_AGENTS
    from coop_gym.model.personas import resolve_personas

    if args.env is not None and args.env not in coop_gym.ENV_IDS:
        return f"--env: unknown env id {args.env!r} (not a coop_gym env); coop_gym ids: {', '.join(coop_gym.ENV_IDS)}"
    try:
        resolve_personas(personas_arg(args.eval_personas))
    except ValueError as exc:
        return f"--eval-personas: {exc}"
    unknown = [b for b in baseline_names(args.baselines) if b not in SCRIPTED_AGENTS]
    if unknown:
        return f"--baselines: unknown agent(s) {unknown}; known: {', '.join(SCRIPTED_AGENTS)}"
    return None


def _problem_with_framework(args: Args) -> str | None:
    """What ``--framework`` (and the flags that go with it) cannot do (None if it can)."""
    if args.framework not in ("sb3", "rllib"):
        return f"--framework must be sb3 or rllib, got {args.framework!r}"
    if args.framework == "rllib" and (args.algo != "ppo" or args.eval_only or args.resume or args.num_env_runners < 0):
        return "--framework rllib trains ppo only (no --eval-only/--resume) with --num-env-runners >= 0"
    if args.framework == "rllib" and importlib.util.find_spec("ray") is None:
        return '--framework rllib needs Ray RLlib: pip install "torch==2.13.0" -e ".[train,rllib]"'
    return None


def _problem_with_paths(args: Args) -> str | None:
    """A missing --model, or an --out where no run folder can be made (None if both are fine)."""
    from coop_gym.cli import output_path_problem

    if args.eval_only and args.model is None:
        return "--eval-only needs --model PATH"
    if args.model is not None and not args.eval_only:
        return "--model is for --eval-only; use --resume PATH to continue training a model"
    problem = output_path_problem(args.out, folder=True)
    if problem:
        return f"--out: {problem}"
    shipped = args.model is not None and args.model.startswith("pretrained:")  # by name: agents.rl.load_agent
    saved = args.model is not None and (Path(args.model).exists() or Path(args.model).with_suffix(".zip").exists())
    if args.model is not None and not (shipped or saved):
        return f"--model: nothing saved at {args.model}"
    return None


def _usage_error(message: str) -> int:
    """A problem found after parsing (e.g. a damaged model): one line on stderr, exit status 2."""
    print(f"{PROG}: error: {message}", file=sys.stderr)
    return 2


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
    from agents.rl import load_agent, saved_model_problem

    # The run's settings: the algorithm's defaults (agents/hyperparams.py), overridden by the flags.
    in_place = args.resume is not None and is_unfinished_run(args.resume)
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
    checkpoint_every = args.checkpoint_every if args.checkpoint_every is not None else max(1, timesteps // 10)
    # A model must meet the observation it was trained on: checked before any folder is made.
    problem = None
    if saved_agent is not None and args.model is not None:
        problem = saved_model_problem("--model", args.model, env_id, saved_agent)
    elif args.resume is not None and not in_place:
        problem = saved_model_problem("--resume", args.resume, env_id)
    if problem:
        return _usage_error(problem)
    plan = _Plan(Path(), algo, env_id, config, timesteps, args.n_envs or config.n_envs, checkpoint_every, None)
    try:
        plan = _open_run_folder(args, plan, in_place)
    except OSError as exc:
        return _write_failed(exc, Path(args.out))

    stop = StopSignals()
    try:
        with stop:
            return _run(args, stop, plan)
    except Stopped:
        return _interrupted(plan.run_dir, stop)
    except OSError as exc:
        return _write_failed(exc, plan.run_dir)


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


def _open_run_folder(args: Args, plan: _Plan, in_place: bool) -> _Plan:
    """The run folder: the unfinished one being resumed, or a new one holding the run's settings."""
    from agents.run_report import new_run_folder
    from coop_gym.io import write_json

    if in_place:
        assert args.resume is not None
        run_dir = Path(args.resume)
        recorded = json.loads((run_dir / ARGS_FILE).read_text())
        clean_leftovers(run_dir)
        print(f"resuming run folder: {run_dir}")
        # The model this run itself continued, if any.
        return dataclasses.replace(plan, run_dir=run_dir, source_model=recorded.get("resume"))
    run_dir = new_run_folder(args.out, plan.env_id, plan.algo, args.seed)
    settings = dataclasses.asdict(args) | {
        "algo": plan.algo,
        "env": plan.env_id,
        "timesteps": plan.timesteps,
        "n_envs": plan.n_envs,
        "checkpoint_every": plan.checkpoint_every,
    }
    try:
        write_json(run_dir / ARGS_FILE, settings)
    except OSError:
        run_dir.rmdir()  # still empty: no run to resume, so no folder left behind
        raise
    print(f"run folder: {run_dir}")
    return dataclasses.replace(plan, run_dir=run_dir, source_model=args.resume)


def _write_failed(exc: OSError, run_dir: Path) -> int:
    """A file could not be written (e.g. a full disk): it is not there, never half-written; exit status 1."""
    print(f"{PROG}: error: could not write {exc.filename or 'output'}: {exc.strerror or exc}", file=sys.stderr)
    print(f"{run_dir} keeps what was complete: free space, then python train.py --resume {run_dir}", file=sys.stderr)
    return 1


def _interrupted(run_dir: Path, stop: StopSignals) -> int:
    """Write the INTERRUPTED marker and say how to resume; the exit status is 128 + the signal number."""
    from agents.rl import latest_checkpoint

    return write_interrupted(run_dir, stop, latest_checkpoint(run_dir))


def _run(args: Args, stop: StopSignals, plan: _Plan) -> int:
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


# --- training -------------------------------------------------------------------


def _model_to_train(args: Args, plan: _Plan, env: Any, checkpoint: Path | None) -> tuple[Any, Any, dict[str, Any], int]:
    """``(model, env, checkpoint state, start steps)``: restored, continued from a saved model, or new.

    Raises:
        ValueError: a damaged checkpoint or saved model (the message names it).
    """
    from stable_baselines3.common.vec_env import VecNormalize

    from agents.rl import load_to_continue, make_model, restore_checkpoint

    if checkpoint is not None:
        try:
            model, state = restore_checkpoint(checkpoint, env)
        except (OSError, ValueError) as exc:
            raise ValueError(f"--resume: checkpoint {checkpoint}: {exc}") from exc
        print(f"continuing from {checkpoint} at {model.num_timesteps} steps")
        return model, env, state, state["start_steps"]
    if plan.source_model is not None:
        # A new run from a saved model: its own statistics come along and keep updating.
        try:
            model, env = load_to_continue(plan.source_model, env)
        except (OSError, ValueError) as exc:
            raise ValueError(f"--resume: {exc}") from exc
        print(f"continuing {plan.algo} from {plan.source_model} at {model.num_timesteps} steps")
        return model, env, {}, int(model.num_timesteps)
    if plan.config.normalize:
        env = VecNormalize(env, norm_obs=True, norm_reward=False)
    return make_model(plan.config, env, args.seed), env, {}, 0


def _train(args: Args, stop: StopSignals, plan: _Plan) -> dict[str, Any] | int:
    """Train to the step budget, checkpointing on the way; the training summary, or an exit status."""
    from agents.rl import TrainingInterrupted, cleanrl_logger, latest_checkpoint, make_train_env, save_agent
    from coop_gym.io import write_json

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
    model.set_logger(cleanrl_logger(run_dir / "tb"))
    callbacks, curve, selection, elapsed = _callbacks(args, plan, stop, state, start_steps, int(model.num_timesteps))
    stop.in_training = True
    try:
        model.learn(
            total_timesteps=start_steps + plan.timesteps - int(model.num_timesteps),
            reset_num_timesteps=checkpoint is None and plan.source_model is None,
            progress_bar=args.progress,
            callback=callbacks,
        )
    except TrainingInterrupted:
        return _interrupted(run_dir, stop)
    finally:
        stop.in_training = False
    training = _training_summary(plan, model, start_steps, elapsed())
    if selection is not None:  # the best-validated policy is the one saved
        training["selected"] = selection.finish(model)
        _print_selection(training["selected"])
    save_agent(model, run_dir, algo=plan.algo, env_id=plan.env_id)
    env.close()
    # Training is over: the summary marks it, and the checkpoints have served their purpose.
    finished = {"training": training, "learning_curve": curve.history if curve else [], "start_steps": start_steps}
    write_json(run_dir / TRAINING_FILE, finished)
    remove_checkpoints(run_dir)
    if stop.requested():  # the signal came after the last rollout boundary
        raise Stopped(signal.Signals(stop.signum or signal.SIGINT).name)
    return finished


def _training_summary(plan: _Plan, model: Any, start_steps: int, train_s: float) -> dict[str, Any]:
    """The ``training`` entry of ``results.json`` (printed in one line too)."""
    trained_steps = int(model.num_timesteps) - start_steps
    steps_per_s = trained_steps / train_s if train_s > 0 else None
    print(f"trained {trained_steps} steps in {train_s:.0f} s ({steps_per_s or 0:.0f} steps/s)")
    return {
        "timesteps": trained_steps,
        "total_timesteps": int(model.num_timesteps),
        "resumed_from": plan.source_model,
        "n_envs": plan.n_envs,
        "wall_time_s": train_s,
        "steps_per_s": steps_per_s,
        "hyperparams": {**plan.config.model_kwargs(), "normalize": plan.config.normalize, "policy": plan.config.policy},
        "personas": plan.config.personas,
    }


def _print_selection(selected: dict[str, Any]) -> None:
    """One line: which policy is saved and how it and the final policy scored on validation."""
    final = selected["scores"][-1]  # the final policy is scored last
    print(
        f"saved the policy at {selected['timesteps']} steps: validation success "
        f"{selected['validation_success_rate']:.1%} on the {selected['personas']} personas "
        f"({selected['episodes']} episodes; the final policy {final['success_rate']:.1%})"
    )


def _callbacks(
    args: Args, plan: _Plan, stop: StopSignals, state: dict[str, Any], start_steps: int, model_steps: int
) -> tuple[list[Any], Any, Any, Any]:
    """``(callbacks, learning-curve callback or None, selection callback or None, training-seconds clock)``."""
    from agents.rl import CheckpointCallback, OutcomeStatsCallback, PeriodicEvalCallback, SelectionCallback
    from agents.run_folder import CHECKPOINTS_DIR
    from agents.run_report import personas_arg

    # Periodic scores on the evaluation personas: the learning curve only, never a selection.
    callbacks: list[Any] = [OutcomeStatsCallback()]
    curve = None
    if args.eval_points > 0:
        every = max(1, plan.timesteps // args.eval_points)
        episodes = min(200, args.eval_episodes)
        personas = personas_arg(args.eval_personas)
        curve = PeriodicEvalCallback(plan.algo, plan.env_id, personas, episodes, args.eval_seed, every, start_steps)
        if state:
            curve.history, curve._next = state["curve_history"], state["curve_next"]
        callbacks.append(curve)
    # Scores on the training personas' validation episodes in the last half: the saved policy.
    selection = None
    if args.select_points > 0:
        half = plan.timesteps // 2
        every = max(1, (plan.timesteps - half) // args.select_points)
        folder = plan.run_dir / CHECKPOINTS_DIR
        start = start_steps + half
        points, episodes = args.select_points, args.select_episodes
        selection = SelectionCallback(folder, plan.algo, plan.env_id, episodes, points, start, every)
        if state.get("selection") is not None:
            selection.restore(state["selection"])
        callbacks.append(selection)
    wall_s = float(state.get("wall_time_s", 0.0))  # training seconds before an interruption
    started = time.perf_counter()

    def elapsed() -> float:
        return wall_s + time.perf_counter() - started

    def checkpoint_state() -> dict[str, Any]:
        return {
            "start_steps": start_steps,
            "curve_history": curve.history if curve else [],
            "curve_next": curve._next if curve else None,
            "selection": selection.state() if selection else None,
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
    return callbacks, curve, selection, elapsed


# --- evaluation and report --------------------------------------------------------


def _evaluate_and_report(args: Args, plan: _Plan, finished: dict[str, Any]) -> int:
    """Score the saved agent and the baselines on the same episodes; write the figures and results.json."""
    from agents.plots import plot_learning_curve, plot_outcome_rates
    from agents.rl import MODEL_FILE, load_agent
    from agents.run_report import (
        compare_with_baselines,
        finish_run,
        verdict_against_handbook,
        versions,
        warn_if_blind,
    )

    run_dir, env_id = plan.run_dir, plan.env_id
    model_path = args.model if args.eval_only and args.model else run_dir / MODEL_FILE
    # The saved agent (what a user loads) and the baselines, on the same episodes.
    label = f"{plan.algo} (learned)"
    comparison = compare_with_baselines(load_agent(model_path), label, env_id, args, run_dir)
    results = comparison.results
    plot_outcome_rates(results, run_dir / "outcome_rates.png")
    curve_points = finished["learning_curve"]
    if not args.eval_only:
        steps, returns = monitor_curve(run_dir / "monitor.csv", finished["start_steps"])
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
        **comparison.summary(),
        "learning_curve": curve_points,
        "verdict": verdict_against_handbook(label, results),
        **versions(),
    }
    summary["reads_no_better_than_blind"] = warn_if_blind(label, comparison.room)
    # Written last: a run folder with results.json and COMPLETE finished; one without did not.
    finish_run(run_dir, summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
