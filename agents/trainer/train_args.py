"""The checks behind ``train.py``'s typed ``Args``, and its command line parsed with them.

``train.py`` holds the ``Args`` dataclass (its field docstrings are the ``--help``, tyro parses
it, as CleanRL does); this module is what stands behind it:

* :func:`args_problem` -- the first value no run can use (a wrong type, a count out of range,
  an unknown name, a framework that cannot run, a path that cannot be written), one message
  naming the flag. ``Args.__post_init__`` raises it as :class:`BadArgs`, so every ``Args`` --
  parsed from the command line or read back from a run's ``args.json`` -- passed the same checks.
* :func:`parse_train_args` -- the command line parsed into ``Args``; with ``--resume`` the
  saved settings (:func:`resume_settings`) are the defaults, and a flag contradicting them is named.

No torch at import: a usage error comes back in a second.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import sys
import types
import typing
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, TypeVar

from agents.run_folder import ARGS_FILE, MODEL_FILE, TRAINING_FILE, is_unfinished_run
from coop_gym.cli import BadArgs, fail, parse

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

__all__ = [
    "PROG",
    "RUN_FIELDS",
    "BadArgs",
    "RunCannotContinue",
    "RunProblem",
    "args_problem",
    "baseline_names",
    "keep_of",
    "learner_framework",
    "parse_train_args",
    "personas_arg",
    "read_training",
    "recorded_settings",
    "resume_settings",
    "run_problem",
    "seeds_of",
    "settings_framework",
    "usage_error",
]

ArgsT = TypeVar("ArgsT", bound="DataclassInstance")

PROG = "python train.py"

RUN_FIELDS = (
    "algo",
    "env",
    "seed",
    "seeds",
    "timesteps",
    "n_envs",
    "eval_episodes",
    "eval_seed",
    "eval_personas",
    "baselines",
    "eval_points",
    "select_points",
    "select_episodes",
    "select_on",
    "keep",
    "checkpoint_every",
    "framework",
    "policy_lag",
)
"""Settings that define a run: ``--resume`` of an unfinished run takes them from its ``args.json``."""
RECORDED_FIELDS = ("algo", "env", "seed", "timesteps", "n_envs")
"""What every ``args.json`` written by ``train.py`` records (``env``, ``timesteps`` and ``n_envs``
may be null: the algorithm's own); a file without them is not a run's settings."""


class RunProblem(ValueError):
    """A saved file that cannot be used (a damaged model or summary): exit status 2, one line."""

    status = 2


class RunCannotContinue(RunProblem):
    """A run folder that cannot go on as it is (its model gone, a foreign checkpoint, not writable): exit status 1.

    Raised before the folder is changed, so its ``INTERRUPTED`` marker still says how it stopped.
    """

    status = 1


def learner_framework(args: Any) -> str:
    """``--framework``, or the algorithm's own when not given: ``jax`` for PPO, ``sb3`` for the others."""
    if args.framework is not None:
        return str(args.framework)
    return "jax" if args.algo == "ppo" else "sb3"


def keep_of(args: Any) -> str:
    """``--keep``, or its default: ``ensemble`` for PPO (an MLP policy, what an ensemble plays), else ``best``."""
    keep = getattr(args, "keep", None)
    return str(keep) if keep is not None else ("ensemble" if args.algo == "ppo" else "best")


def seeds_of(args: Any) -> int:
    """``--seeds``, or its default: 6 for PPO on the JAX learner (six runs fit ``train.py``'s five minutes), else 1."""
    seeds = getattr(args, "seeds", None)
    if seeds is not None:
        return int(seeds)
    return 6 if args.algo == "ppo" and learner_framework(args) == "jax" and not args.eval_only else 1


def settings_framework(args: Any, algo: str) -> str:
    """Whose settings (``hyperparams_for``) a run of ``algo`` takes: ``jax`` for a JAX learner, else SB3's."""
    from agents.hyperparams import JAX_ALGORITHMS

    return "jax" if learner_framework(args) == "jax" and algo in JAX_ALGORITHMS else "sb3"


# --- the checks -------------------------------------------------------------------


def args_problem(args: Any) -> str | None:
    """The first value of ``train.Args`` no run can use (None if all are fine)."""
    return (
        _type_problem(args)
        or _problem_with_numbers(args)
        or _problem_with_names(args)
        or _problem_with_framework(args)
        or _problem_with_paths(args)
    )


def _type_problem(args: Any) -> str | None:
    """The first field whose value is not of its annotated type (what a hand-edited ``args.json`` can hold)."""
    hints = typing.get_type_hints(type(args))
    for field in dataclasses.fields(args):
        value, hint = getattr(args, field.name), hints[field.name]
        options = typing.get_args(hint) if typing.get_origin(hint) in (types.UnionType, typing.Union) else (hint,)
        if not any(_is_a(value, option) for option in options):
            return f"{field.name} must be {' or '.join(_type_name(o) for o in options)}, got {value!r}"
    return None


def _is_a(value: Any, option: Any) -> bool:
    """Whether ``value`` is of the type ``option`` (a class, None or a Literal); a bool is no int."""
    if typing.get_origin(option) is Literal:
        return any(value == choice and type(value) is type(choice) for choice in typing.get_args(option))
    if option is type(None):
        return value is None
    return isinstance(value, option) and (option is bool or not isinstance(value, bool))


def _type_name(option: Any) -> str:
    """``int``, ``None`` or ``one of 'ppo', 'dqn'``."""
    if typing.get_origin(option) is Literal:
        return "one of " + ", ".join(repr(choice) for choice in typing.get_args(option))
    return "None" if option is type(None) else str(option.__name__)


def _problem_with_numbers(args: Any) -> str | None:
    """The first count or seed out of range (None if all are fine)."""
    from agents.hyperparams import hyperparams_for
    from coop_gym.cli import seed_range_problem

    for name in ("timesteps", "n_envs"):
        value = getattr(args, name)
        if value is not None and value < 1:
            return f"--{name.replace('_', '-')} must be >= 1, got {value}"
        if value is not None and value > sys.maxsize:  # TrainingConfig's own bound: a run that would never end
            return f"--{name.replace('_', '-')} must be <= {sys.maxsize}, got {value}"
    if args.eval_episodes < 1:
        return f"--eval-episodes must be >= 1, got {args.eval_episodes}"
    if args.seed < 0 or args.eval_seed < 0:
        return "--seed and --eval-seed must be >= 0"
    # Envs are seeded seed .. seed + n_envs - 1 and episodes eval_seed .. eval_seed + eval_episodes - 1.
    n_envs = args.n_envs or hyperparams_for(args.algo, None, settings_framework(args, args.algo)).n_envs
    if getattr(args, "seeds", None) is not None and args.seeds < 1:
        return f"--seeds must be >= 1, got {args.seeds}"
    problem = seed_range_problem("--seed", args.seed, n_envs + seeds_of(args) - 1)
    problem = problem or seed_range_problem("--eval-seed", args.eval_seed, args.eval_episodes)
    if problem:
        return problem
    if args.eval_points < 0 or args.threads < 1:
        return "--eval-points must be >= 0 and --threads >= 1"
    if args.select_points < 0 or args.select_episodes < 1:
        return "--select-points must be >= 0 and --select-episodes >= 1"
    if getattr(args, "select_on", "train") != "train" and args.select_points == 0:  # nothing would be selected
        return f"--select-on {args.select_on} needs --select-points >= 1 (0 saves the last policy, selecting none)"
    if args.checkpoint_every is not None and args.checkpoint_every < 0:
        return f"--checkpoint-every must be >= 0, got {args.checkpoint_every}"
    return None


def _problem_with_names(args: Any) -> str | None:
    """The first unknown env id, persona or baseline (None if all are known)."""
    import coop_gym
    from agents.caregivers.scripted import SCRIPTED_AGENTS
    from coop_gym.model.personas import resolve_personas

    if args.env is not None and args.env not in coop_gym.ENV_IDS:
        return f"--env: unknown env id {args.env!r} (not a coop_gym env); coop_gym ids: {', '.join(coop_gym.ENV_IDS)}"
    try:
        resolve_personas(personas_arg(args.eval_personas))
    except ValueError as exc:
        return f"--eval-personas: {exc}"
    names = baseline_names(args.baselines)
    unknown = [b for b in names if b not in SCRIPTED_AGENTS]
    if unknown:
        return f"--baselines: unknown agent(s) {unknown}; known: {', '.join(SCRIPTED_AGENTS)}"
    twice = sorted({b for b in names if names.count(b) > 1})
    if twice:  # two rows of one agent, and one result would overwrite the other in results.json
        return f"--baselines: {', '.join(repr(b) for b in twice)} given twice; list each agent once"
    return None


def _problem_with_framework(args: Any) -> str | None:
    """What ``--framework rllib`` (and the flags that go with it) cannot do (None if it can)."""
    if args.framework == "rllib" and (args.algo != "ppo" or args.eval_only or args.resume or args.num_env_runners < 0):
        return "--framework rllib trains ppo only (no --eval-only/--resume) with --num-env-runners >= 0"
    if args.framework != "rllib" and (args.num_env_runners != 0 or args.address is not None):
        flags = "--num-env-runners" if args.num_env_runners != 0 else "--address"
        return f"{flags} is for --framework rllib; the {learner_framework(args)} learner trains in this process"
    if args.framework == "rllib" and importlib.util.find_spec("ray") is None:
        return '--framework rllib needs Ray RLlib: pip install "torch==2.13.0" -e ".[train,rllib]"'
    from agents.hyperparams import JAX_ALGORITHMS

    if args.framework == "jax" and args.algo not in JAX_ALGORITHMS and not args.eval_only:  # asked for by name
        trains = " and ".join(JAX_ALGORITHMS)
        return f"--framework jax trains {trains} only, not --algo {args.algo}; use --framework sb3"
    if getattr(args, "policy_lag", None) is not None and (args.algo != "ppo" or learner_framework(args) != "jax"):
        return "--policy-lag needs --algo ppo and --framework jax"
    if (
        learner_framework(args) == "jax"
        and not args.eval_only
        and not all(importlib.util.find_spec(name) for name in ("jax", "optax"))
    ):
        return '--framework jax needs JAX and optax: pip install "torch==2.13.0" -e ".[train]"'
    return None


def _problem_with_paths(args: Any) -> str | None:
    """--eval-only with --resume, a missing --model, or an --out where no run folder can be made (None if fine)."""
    from coop_gym.cli import output_path_problem

    if args.eval_only and args.resume is not None:
        return "--eval-only and --resume exclude each other"
    if seeds_of(args) > 1 and (args.eval_only or args.framework == "rllib"):  # only a --seeds given asks for it
        return f"--seeds {args.seeds} trains several seeds; not with --eval-only or --framework rllib"
    if keep_of(args) == "ensemble" and args.algo != "ppo":
        return f"--keep ensemble plays PPO's MLP policies as one, not {args.algo}'s: give --keep best"
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


def personas_arg(text: str) -> str | list[str]:
    """A persona set name (``"test"``) as it is, names joined by ``,`` as a list."""
    return [p.strip() for p in text.split(",") if p.strip()] if "," in text else text


def baseline_names(text: str) -> list[str]:
    """Scripted agent names joined by ``,`` (empty: none)."""
    return [b.strip() for b in text.split(",") if b.strip()]


# --- the command line -------------------------------------------------------------


def parse_train_args(args_type: type[ArgsT], argv: list[str] | None, description: str) -> ArgsT:
    """``argv`` (default: ``sys.argv[1:]``) parsed into ``args_type`` and checked; usage errors exit with status 2.

    With ``--resume`` the run's (or model's) saved settings are the defaults of a second parse, so
    the flags not given take them; a given flag that contradicts the run is an error naming it.
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse(args_type, argv, PROG, description)
    resume = getattr(args, "resume", None)
    if resume is None:
        return args
    try:
        saved = resume_settings(Path(resume), args_type)
        defaults = dataclasses.replace(args_type(), **saved)
    except RunCannotContinue as exc:
        sys.exit(run_problem(exc))
    except (BadArgs, ValueError) as exc:
        fail(PROG, str(exc))
    resumed = parse(args_type, argv, PROG, description, default=defaults)
    conflicts = [
        f"--{name.replace('_', '-')} {getattr(resumed, name)!r} (the run has {value!r})"
        for name, value in saved.items()
        if getattr(resumed, name) != value
    ]
    if conflicts:
        fail(PROG, f"--resume {resume}: {'; '.join(conflicts)} contradict the saved run; leave them out")
    return resumed


def usage_error(message: str) -> int:
    """A problem found after parsing (e.g. a damaged model): one line on stderr; exit status 2."""
    print(f"{PROG}: error: {message}", file=sys.stderr)
    return 2


def run_problem(exc: RunProblem) -> int:
    """A saved file a run cannot use: one line on stderr; exit status 2, or 1 for a run that cannot continue."""
    print(f"{PROG}: error: {exc}", file=sys.stderr)
    return exc.status


# --- what --resume continues ------------------------------------------------------


def resume_settings(path: Path, args_type: type[Any]) -> dict[str, Any]:
    """The settings ``--resume path`` continues with (a subset of :data:`RUN_FIELDS`).

    An unfinished run resumes in place with its own ``args.json`` (read back through
    ``args_type``: typed and checked like the command line); a finished run or a saved model
    starts a new run from the model, with its algorithm and env.

    Raises:
        ValueError: nothing resumable at ``path``; the message starts with ``--resume`` and names the file.
    """
    if not (path.exists() or path.with_suffix(".zip").exists()):
        raise ValueError(f"--resume: nothing saved at {path}")
    if not is_unfinished_run(path):  # a finished run or a model: a new run continuing the model
        from agents.rl import resolve_saved

        try:
            _, info = resolve_saved(path)
        except (OSError, ValueError) as exc:
            raise ValueError(f"--resume: {exc}") from None
        framework = info.get("framework") if info.get("framework") in ("sb3", "jax") else "sb3"
        saved = (("algo", info.get("algo")), ("env", info.get("env_id")), ("framework", framework))
        return {k: v for k, v in saved if v}
    recorded = _with_defaults(recorded_settings(path, args_type))
    read_training(path)  # a damaged summary is named now, before the resume touches the folder
    return {name: recorded[name] for name in RUN_FIELDS if name in recorded}


def recorded_settings(run_dir: Path, args_type: type[Any]) -> dict[str, Any]:
    """What an unfinished run recorded in ``args.json``: its :data:`RUN_FIELDS` and the model it continued.

    Read back through ``args_type`` (``train.Args``), so a value of the wrong type or out of
    range is named as on the command line.

    Raises:
        ValueError: an unreadable or incomplete file, or a bad value; the message names the file.
    """
    file = run_dir / ARGS_FILE
    try:
        recorded = json.loads(file.read_text())
        if not isinstance(recorded, dict):
            raise ValueError("not a JSON object")
    except (OSError, ValueError) as exc:
        raise ValueError(f"--resume: {file} is unreadable ({exc})") from None
    if recorded.get("eval_only"):
        raise ValueError(
            f"--resume: {run_dir} was an --eval-only run; run it again: --eval-only --model {recorded.get('model')}"
        )
    settings = {name: recorded[name] for name in (*RUN_FIELDS, "resume") if name in recorded}
    settings.setdefault("framework", "sb3")  # written before there was a choice: SB3's run
    settings.setdefault("select_on", "train")  # likewise: selected on the training personas
    settings.setdefault("seeds", 1)  # likewise: one training seed
    settings.setdefault("keep", "best")  # likewise: the best seed kept
    try:
        args_type(**settings)
    except BadArgs as exc:
        raise ValueError(f"--resume: {file}: {exc}") from None
    missing = [name for name in RECORDED_FIELDS if name not in recorded]
    if missing:
        raise ValueError(f"--resume: {file} does not record the run's settings: {', '.join(missing)} missing")
    return settings


def _with_defaults(settings: dict[str, Any]) -> dict[str, Any]:
    """Run settings with the algorithm's defaults filled in (older args.json files hold None)."""
    from agents.hyperparams import hyperparams_for

    out = dict(settings)
    algo = out.get("algo", "ppo")
    framework = out.get("framework") or ("jax" if algo == "ppo" else "sb3")
    framework = framework if framework in ("sb3", "jax") else "sb3"  # rllib: the SB3 settings' env and budget
    config = hyperparams_for(algo, out.get("env") or hyperparams_for(algo).env_id, framework)
    out["env"] = out.get("env") or config.env_id
    out["timesteps"] = out.get("timesteps") or config.total_timesteps
    out["n_envs"] = out.get("n_envs") or config.n_envs
    if out.get("checkpoint_every") is None:
        out["checkpoint_every"] = max(1, out["timesteps"] // 10)
    return out


def read_training(run_dir: Path) -> dict[str, Any] | None:
    """The training summary of a run that finished training (``training.json``), or None if it did not.

    Raises:
        RunProblem: the file is there but damaged; the message names it.
        RunCannotContinue: training finished but the model it saved is gone.
    """
    file = run_dir / TRAINING_FILE
    if not file.exists():
        return None
    try:
        finished = json.loads(file.read_text())
        if not (isinstance(finished, dict) and {"training", "learning_curve", "start_steps"} <= finished.keys()):
            raise ValueError("not a training summary")
    except (OSError, ValueError) as exc:
        raise RunProblem(f"--resume: {file} is unreadable ({exc}); remove it to train this run again") from None
    if not (run_dir / MODEL_FILE).exists():  # nothing to evaluate: say so before the folder is touched
        raise RunCannotContinue(
            f"--resume {run_dir}: training finished ({TRAINING_FILE}) but its {MODEL_FILE} is missing; "
            f"put the model back to evaluate it, or remove {TRAINING_FILE} to train the run again"
        )
    return finished
