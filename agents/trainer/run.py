"""One ``train.py`` run: its plan and run folder, then training with checkpoints (SB3's learners, or :mod:`agents.ppo`).

* :func:`plan_run` -- what the run does, settled before any work: the algorithm's settings
  (:mod:`agents.hyperparams`) overridden by the flags, a saved model checked against the env,
  and the run folder (the unfinished one being resumed, or a new one holding ``args.json``);
* :func:`train` -- the training env, the model (restored from the last checkpoint, continued
  from a saved model, or new), the callbacks (learning curve, selection of the saved policy,
  checkpoints), ``learn``, then the saved agent and ``training.json``; with ``--seeds N``, N such runs
  in ``RUN/seeds/``, kept as one (``--keep ensemble``) or the one best on the validation people. The JAX
  learner (``--framework jax``) trains :class:`agents.ppo.PPO` (``--algo recurrent_ppo``:
  :class:`agents.ppo.recurrent.RecurrentPPO`) with the same tools at its rollout ends (:mod:`agents.rl.ppo_run`).

What happens after training (the evaluation against the baselines, the report) is
:func:`agents.trainer.run_report.evaluate_and_report`; the arguments are ``train.Args``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import os
import shutil
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch
from stable_baselines3.common.vec_env import VecNormalize

from agents.hyperparams import hyperparams_for
from agents.rl import (
    CheckpointCallback,
    OutcomeStatsCallback,
    PeriodicEvalCallback,
    SelectionCallback,
    TrainingInterrupted,
    cleanrl_logger,
    latest_checkpoint,
    load_agent,
    load_to_continue,
    make_model,
    make_train_env,
    restore_checkpoint,
    save_agent,
    saved_model_problem,
)
from agents.run_folder import (
    AGENT_FILE,
    ARGS_FILE,
    CHECKPOINTS_DIR,
    ENSEMBLE_FILE,
    MODEL_FILE,
    TRAINING_FILE,
    VECNORMALIZE_FILE,
    is_unfinished_run,
)
from agents.trainer.run_report import new_run_folder
from agents.trainer.train_args import (
    PROG,
    RunCannotContinue,
    RunProblem,
    keep_of,
    personas_arg,
    read_training,
    recorded_settings,
    seeds_of,
    settings_framework,
)
from agents.trainer.training_run import Plan, StopSignals, clean_leftovers, remove_checkpoints
from coop_gym.io import save_with, write_json

__all__ = ["SEEDS_DIR", "plan_run", "seed_folder", "train"]


def plan_run(args: Any, folder: Path | None = None) -> Plan:
    """The run's settings -- the algorithm's defaults overridden by the flags -- and its folder.

    A new run's folder is ``folder`` where given (one seed of a ``--seeds`` run), else a new one in ``args.out``.

    Raises:
        RunProblem: a damaged saved model, or one that does not fit the env (before any folder is made).
        OSError: the run folder or its ``args.json`` could not be written.
    """
    torch.set_num_threads(args.threads)
    in_place = args.resume is not None and is_unfinished_run(args.resume)
    saved_agent = None
    if args.eval_only:
        try:
            saved_agent = load_agent(args.model)
        except (OSError, ValueError) as exc:
            raise RunProblem(f"--model: {exc}") from None
    algo = saved_agent.algo if saved_agent is not None else args.algo
    env_id = args.env or (saved_agent.env_id if saved_agent else None) or hyperparams_for(algo).env_id
    config = hyperparams_for(algo, env_id, settings_framework(args, algo))
    if getattr(args, "policy_lag", None) is not None:
        config = config.replace(algo_kwargs={**config.algo_kwargs, "policy_lag": args.policy_lag})
    timesteps = args.timesteps or config.total_timesteps
    checkpoint_every = args.checkpoint_every if args.checkpoint_every is not None else max(1, timesteps // 10)
    # A model must meet the observation it was trained on: checked before any folder is made.
    problem = None
    if saved_agent is not None and args.model is not None:
        problem = saved_model_problem("--model", args.model, env_id, saved_agent)
    elif args.resume is not None and not in_place:
        problem = saved_model_problem("--resume", args.resume, env_id)
    if problem:
        raise RunProblem(problem)
    n_envs = args.n_envs or config.n_envs
    if config.framework == "jax" and not args.eval_only:
        from agents.rl.ppo_run import learner_config

        try:
            learner_config(config.replace(n_envs=n_envs))
        except ValueError as exc:
            raise RunProblem(f"--n-envs {n_envs}: {exc}") from None
    plan = Plan(Path(), algo, env_id, config, timesteps, n_envs, checkpoint_every, None)
    return _open_run_folder(args, plan, in_place, folder)


def _open_run_folder(args: Any, plan: Plan, in_place: bool, folder: Path | None) -> Plan:
    """The run folder: the unfinished one being resumed, or a new one holding the run's settings."""
    if in_place:
        run_dir = Path(args.resume)
        source_model = recorded_settings(run_dir, type(args)).get("resume")  # the model this run continued
        if not os.access(run_dir, os.W_OK | os.X_OK):  # e.g. a read-only mount: say so before any work
            raise RunCannotContinue(
                f"--resume {run_dir}: the run folder is not writable; copy it to a writable place "
                f"(cp -a {run_dir} COPY), then {PROG} --resume COPY"
            )
        clean_leftovers(run_dir)
        print(f"resuming run folder: {run_dir}")
        return dataclasses.replace(plan, run_dir=run_dir, source_model=source_model)
    if folder is not None:
        folder.mkdir(parents=True, exist_ok=True)  # a seed's folder left without args.json is begun again
    run_dir = folder or new_run_folder(args.out, plan.env_id, plan.algo, args.seed)
    settings = dataclasses.asdict(args) | {
        "algo": plan.algo,
        "env": plan.env_id,
        "timesteps": plan.timesteps,
        "n_envs": plan.n_envs,
        "checkpoint_every": plan.checkpoint_every,
        "seeds": seeds_of(args),
    }
    try:
        write_json(run_dir / ARGS_FILE, settings)
    except OSError:
        with contextlib.suppress(OSError):
            run_dir.rmdir()  # still empty: no run to resume, so no folder left behind
        raise
    print(f"run folder: {run_dir}")
    return dataclasses.replace(plan, run_dir=run_dir, source_model=args.resume)


def train(args: Any, plan: Plan, stop: StopSignals) -> dict[str, Any]:
    """Train to the step budget, checkpointing on the way; the training summary (also in ``training.json``).

    With ``--seeds N``, each seed is a run of its own in ``RUN/seeds/seed_S/``; the one that scores best on the
    validation people (never the held-out personas) lends ``RUN`` its model, normaliser and monitor, and with
    ``--keep ensemble`` ``RUN/ensemble.json`` names them all (:func:`_train_seeds`); ``training.json`` lists every
    seed's score. A stopped run resumes seed by seed: finished seeds are kept, a begun one continues.

    Raises:
        agents.trainer.training_run.Stopped: a signal stopped training (after a checkpoint) or came after its last
            rollout.
        RunProblem: a damaged saved model (the message names it).
        RunCannotContinue: a damaged or foreign checkpoint (the message names it).
    """
    if seeds_of(args) > 1:
        return _train_seeds(args, plan, stop)
    if plan.config.framework == "jax":
        return _train_learner(args, plan, stop)
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
    model, env, state, start_steps = _model_to_train(args, plan, env, checkpoint)
    model.set_logger(cleanrl_logger(run_dir / "tb"))
    callbacks, curve, selection, elapsed, _ = _callbacks(args, plan, stop, state, start_steps, int(model.num_timesteps))
    stop.in_training = True
    try:
        model.learn(
            total_timesteps=start_steps + plan.timesteps - int(model.num_timesteps),
            reset_num_timesteps=checkpoint is None and plan.source_model is None,
            progress_bar=args.progress,
            callback=callbacks,
        )
    except TrainingInterrupted:  # stopped on request at a rollout boundary, after a checkpoint
        stop.check()
        raise  # not reached: only a signal asks for it
    finally:
        stop.in_training = False
    env.close()
    return _finish(plan, model, start_steps, elapsed(), curve, selection, stop)


def _finish(
    plan: Plan,
    model: Any,
    start_steps: int,
    train_s: float,
    curve: PeriodicEvalCallback | None,
    selection: SelectionCallback | None,
    stop: StopSignals,
) -> dict[str, Any]:
    """After ``learn``: the kept policy saved, ``training.json`` written, the checkpoints removed; the summary."""
    training = _training_summary(plan, model, start_steps, train_s)
    if selection is not None:  # the best-validated policy is the one saved
        training["selected"] = selection.finish(model)
        _print_selection(training["selected"])
    save_agent(model, plan.run_dir, algo=plan.algo, env_id=plan.env_id)
    # Training is over: the summary marks it, and the checkpoints have served their purpose.
    finished = {"training": training, "learning_curve": curve.history if curve else [], "start_steps": start_steps}
    write_json(plan.run_dir / TRAINING_FILE, finished)
    remove_checkpoints(plan.run_dir)
    stop.check()  # the signal came after the last rollout boundary
    return finished


def _train_learner(args: Any, plan: Plan, stop: StopSignals) -> dict[str, Any]:
    """:func:`train` on the JAX learner (:func:`agents.rl.ppo_run.make_learner`), the run's tools at its rollout ends.

    Raises:
        as :func:`train`.
    """
    from agents.ppo.sb3_format import to_sb3
    from agents.rl.ppo_run import RunHooks, continue_from_saved, make_learner, restore_learner

    run_dir, config = plan.run_dir, plan.config
    learner = make_learner(config.replace(n_envs=plan.n_envs), plan.env_id, args.seed)
    checkpoint, state, start_steps = latest_checkpoint(run_dir), {}, 0
    try:
        if checkpoint is not None:
            expected = {"algo": plan.algo, "env_id": plan.env_id, "framework": "jax", "n_envs": plan.n_envs}
            state = restore_learner(checkpoint, learner, run_dir, expected)
            start_steps = state["start_steps"]
            print(f"continuing from {checkpoint} at {learner.num_timesteps} steps")
        elif plan.source_model is not None:
            continue_from_saved(learner, plan.source_model)
            start_steps = learner.num_timesteps
            print(f"continuing {plan.algo} from {plan.source_model} at {start_steps} steps")
    except (OSError, ValueError) as exc:
        if checkpoint is None:
            raise RunProblem(f"--resume: {exc}") from exc
        remedy = f"remove {checkpoint} to resume from the checkpoint before it (or from the start)"
        raise RunCannotContinue(f"--resume {plan.run_dir}: {exc}; {remedy}") from exc
    logger = cleanrl_logger(run_dir / "tb")
    _, curve, selection, elapsed, checkpoint_state = _callbacks(args, plan, stop, state, start_steps, 0)
    hooks = RunHooks(
        run_dir,
        algo=plan.algo,
        env_id=plan.env_id,
        logger=logger,
        curve=curve,
        selection=selection,
        every=plan.checkpoint_every,
        stop_requested=stop.requested,
        extra=checkpoint_state,
        start_steps=learner.num_timesteps,
        monitor_append=checkpoint is not None,
        progress=_progress_bar(start_steps + plan.timesteps - learner.num_timesteps) if args.progress else None,
    )
    stop.in_training = True
    try:
        learner.learn(start_steps + plan.timesteps, hooks)
    except TrainingInterrupted:  # stopped on request at a rollout boundary, after a checkpoint
        stop.check()
        raise  # not reached: only a signal asks for it
    finally:
        stop.in_training = False
        if hooks.progress is not None:
            hooks.progress.close()
    model = to_sb3(learner)
    model.set_logger(logger)
    learner.env.close()
    return _finish(plan, model, start_steps, elapsed(), curve, selection, stop)


SEEDS_DIR = "seeds"
"""The folder of a ``--seeds`` run that holds one run folder per training seed."""

KEPT_FILES = (MODEL_FILE, VECNORMALIZE_FILE, AGENT_FILE, "monitor.csv")
"""What the kept seed's run folder lends the run: the saved agent and its training monitor."""


def seed_folder(run_dir: Path, seed: int) -> Path:
    """The run folder of one training seed of a ``--seeds`` run."""
    return Path(run_dir) / SEEDS_DIR / f"seed_{seed}"


def _train_seeds(args: Any, plan: Plan, stop: StopSignals) -> dict[str, Any]:
    """Train ``args.seeds`` seeds; the training summary (``training.json``).

    ``RUN`` takes the model of the seed best on the validation people; with ``--keep ensemble`` its
    ``ensemble.json`` names every seed's folder, and ``RUN`` loads as them played as one
    (:mod:`agents.rl.ensemble`).

    Raises:
        agents.trainer.training_run.Stopped: a signal stopped one seed's training (after its checkpoint).
        RunProblem / RunCannotContinue: as :func:`agents.trainer.run.train`, for the seed that met it.
    """
    seeds = list(range(args.seed, args.seed + seeds_of(args)))
    finished = {seed: _train_one(args, plan, seed, stop) for seed in seeds}
    scores = [_validation_score(args, plan, seed) for seed in seeds]
    stop.check()
    kept = max(scores, key=lambda score: score["success_rate"])  # ties: the lowest seed
    for name in KEPT_FILES:
        source = seed_folder(plan.run_dir, kept["seed"]) / name
        if source.exists():  # written whole or not at all, as every file of a run folder
            save_with(plan.run_dir / name, functools.partial(shutil.copyfile, source))
    summary = finished[kept["seed"]]
    training = {**summary["training"], "kept_seed": kept["seed"], "seeds": scores, "keep": keep_of(args)}
    rates = ", ".join(f"seed {s['seed']} {s['success_rate']:.1%}" for s in scores)
    print(f"best seed {kept['seed']}: validation people's success {rates} ({args.select_episodes} episodes)")
    if keep_of(args) == "ensemble":
        training["ensemble"] = _keep_ensemble(args, plan, seeds)
    result = {**summary, "training": training}
    write_json(plan.run_dir / TRAINING_FILE, result)
    return result


def _keep_ensemble(args: Any, plan: Plan, seeds: list[int]) -> dict[str, Any]:
    """Write ``RUN/ensemble.json`` naming the seeds' folders; the ensemble's score on the validation people."""
    members = [str(seed_folder(plan.run_dir, seed).relative_to(plan.run_dir)) for seed in seeds]
    write_json(plan.run_dir / ENSEMBLE_FILE, {"members": members})
    score = _validation_score(args, plan, None)
    print(f"kept the {len(seeds)} seeds as one: validation people's success {score['success_rate']:.1%}")
    return score


def _train_one(args: Any, plan: Plan, seed: int, stop: StopSignals) -> dict[str, Any]:
    """One seed's training summary: read back if it finished, else trained (resumed in place if begun)."""
    folder = seed_folder(plan.run_dir, seed)
    finished = read_training(folder)
    if finished is not None:
        return finished
    begun = is_unfinished_run(folder)
    seed_args = dataclasses.replace(
        args, seed=seed, seeds=1, out=str(folder.parent), resume=str(folder) if begun else plan.source_model
    )
    print(f"training seed {seed} ({seed - args.seed + 1} of {seeds_of(args)})")
    seed_plan = plan_run(seed_args, folder=None if begun else folder)
    return train(seed_args, seed_plan, stop)


def _validation_score(args: Any, plan: Plan, seed: int | None) -> dict[str, Any]:
    """One seed's saved policy (None: the run's ensemble) scored on the validation people (the selection's episodes)."""
    from agents.evaluate import evaluate
    from agents.rl import load_agent
    from agents.rl.callbacks import VALIDATION_SEED

    agent = load_agent(plan.run_dir if seed is None else seed_folder(plan.run_dir, seed))
    result = evaluate(agent, plan.env_id, "validation", args.select_episodes, VALIDATION_SEED)
    return {
        "seed": seed,
        "success_rate": result.success_rate,
        "unsafe_rate": result.unsafe_rate,
        "episodes": args.select_episodes,
        "personas": "validation",
    }


def _model_to_train(args: Any, plan: Plan, env: Any, checkpoint: Path | None) -> tuple[Any, Any, dict[str, Any], int]:
    """``(model, env, checkpoint state, start steps)``: restored, continued from a saved model, or new.

    Raises:
        RunProblem: a damaged checkpoint or saved model (the message names it).
    """
    if checkpoint is not None:
        expected = {"algo": plan.algo, "env_id": plan.env_id, "framework": plan.config.framework, "n_envs": plan.n_envs}
        try:
            model, state = restore_checkpoint(checkpoint, env, expected)
        except (OSError, ValueError) as exc:
            remedy = f"remove {checkpoint} to resume from the checkpoint before it (or from the start)"
            raise RunCannotContinue(f"--resume {plan.run_dir}: {exc}; {remedy}") from exc
        print(f"continuing from {checkpoint} at {model.num_timesteps} steps")
        return model, env, state, state["start_steps"]
    if plan.source_model is not None:
        # A new run from a saved model: its own statistics come along and keep updating.
        try:
            model, env = load_to_continue(plan.source_model, env)
        except (OSError, ValueError) as exc:
            raise RunProblem(f"--resume: {exc}") from exc
        print(f"continuing {plan.algo} from {plan.source_model} at {model.num_timesteps} steps")
        return model, env, {}, int(model.num_timesteps)
    if plan.config.normalize:
        env = VecNormalize(env, norm_obs=True, norm_reward=False)
    return make_model(plan.config, env, args.seed), env, {}, 0


def _progress_bar(total: int) -> Any:
    """The progress bar SB3's ``learn(progress_bar=True)`` shows (tqdm's rich bar) over ``total`` steps."""
    from tqdm.rich import tqdm

    return tqdm(total=total)


def _training_summary(plan: Plan, model: Any, start_steps: int, train_s: float) -> dict[str, Any]:
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


_SELECTED_ON = {"train": "training personas", "validation": "validation people"}


def _print_selection(selected: dict[str, Any]) -> None:
    """One line: which policy is saved and how it and the final policy scored on validation."""
    final = selected["scores"][-1]  # the final policy is scored last
    print(
        f"saved the policy at {selected['timesteps']} steps: validation success "
        f"{selected['validation_success_rate']:.1%} on the {_SELECTED_ON.get(selected['personas'], 'people')} "
        f"({selected['episodes']} episodes; the final policy {final['success_rate']:.1%})"
    )


def _callbacks(
    args: Any, plan: Plan, stop: StopSignals, state: dict[str, Any], start_steps: int, model_steps: int
) -> tuple[
    list[Any], PeriodicEvalCallback | None, SelectionCallback | None, Callable[[], float], Callable[[], dict[str, Any]]
]:
    """``(callbacks, learning curve or None, selection or None, training-seconds clock, a checkpoint's run state)``."""
    # Periodic scores on the evaluation personas: the learning curve only, never a selection.
    callbacks: list[Any] = [OutcomeStatsCallback()]
    curve = None
    if args.eval_points > 0:
        every = max(1, plan.timesteps // args.eval_points)
        episodes = min(200, args.eval_episodes)
        personas = personas_arg(args.eval_personas)
        curve = PeriodicEvalCallback(plan.algo, plan.env_id, personas, episodes, args.eval_seed, every, start_steps)
        if state:
            _restore_curve(curve, state)
        callbacks.append(curve)
    # Scores on validation episodes (--select-on's people) in the last half: the saved policy.
    selection = None
    if args.select_points > 0:
        half = plan.timesteps // 2
        every = max(1, (plan.timesteps - half) // args.select_points)
        folder = plan.run_dir / CHECKPOINTS_DIR
        start = start_steps + half
        points, episodes = args.select_points, args.select_episodes
        selection = SelectionCallback(
            folder, plan.algo, plan.env_id, episodes, points, start, every, personas=args.select_on
        )
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
            **_curve_state(curve),
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
    return callbacks, curve, selection, elapsed, checkpoint_state


# The learning curve's part of a checkpoint, under the keys checkpoints have always used.
def _curve_state(curve: PeriodicEvalCallback | None) -> dict[str, Any]:
    state = curve.state() if curve else {"history": [], "next": None}
    return {"curve_history": state["history"], "curve_next": state["next"]}


def _restore_curve(curve: PeriodicEvalCallback, state: dict[str, Any]) -> None:
    curve.restore({"history": state["curve_history"], "next": state["curve_next"]})
