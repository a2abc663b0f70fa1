r"""The command line of :mod:`agents.evaluate`: ``python -m agents.evaluate ...``.

A module of its own because it loads saved models: SB3 bundles (:mod:`agents.rl`) and
RLlib runs (:mod:`agents.rl.rllib`), which themselves evaluate through :mod:`agents.evaluate`.
Kept here, the imports run one way (``cli -> rl -> evaluate``). Examples::

    python -m agents.evaluate --agent handbook --personas test --episodes 1000
    python -m agents.evaluate --model runs/.../model.zip --json
    python -m agents.evaluate --model runs/...__rllib_ppo__.../    # an RLlib run folder
    python -m agents.evaluate --model pretrained:hard-ppo --compare blind,prober,oracle
    python -m agents.evaluate --compare blind,prober,oracle --env CoopGym/SitToStandHard-v2 --human played.csv
    python -m agents.evaluate --compare random,lift_at_once,push_then_lift,handbook,oracle \\
        --csv out.csv --plot out.png

Every row and score has its own name, and nothing given is left out unsaid: a ``--runs``
run without a score, an agent given twice and a ``--human`` CSV of several env ids without
``--env`` are usage errors naming them (exit 2); two models whose folders share a name are
named by their paths. Importing this module does not import torch; ``--model`` loads SB3 lazily.
"""

from __future__ import annotations

import json
import sys
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

import tyro

import coop_gym  # registers the env ids
from agents.base import Agent, feature_mismatch
from agents.caregivers.scripted import SCRIPTED_AGENTS
from agents.evaluate import (
    DEFAULT_ENV_ID,
    PLOT_SUFFIXES,
    EvaluationResult,
    evaluate,
    print_table,
    results_json,
    write_csv,
    write_json,
)
from agents.evaluate.runs import (
    RunScore,
    aggregate_runs,
    finished_run_score,
    is_run_folder,
    run_folders_in,
    training_seed,
)
from agents.pretrained import PREFIX, is_pretrained, pretrained_names
from agents.run_folder import ENSEMBLE_PREFIX, MODEL_FILE, is_rllib_run
from coop_gym.cli import BadArgs, fail, output_path_problem, parse, seed_range_problem
from coop_gym.model.personas import resolve_personas

__all__ = ["PROG", "Args", "args_problem", "main"]


PROG = "python -m agents.evaluate"
DESCRIPTION = "Score agents on the same seeded sit-to-stand episodes (episode k uses seed + k)."
# The help of the flags that name the package's agents and models (read from where they are
# defined) or take a paragraph to explain.
_AGENT_HELP = f"a scripted agent: {', '.join(SCRIPTED_AGENTS)}"
_MODEL_HELP = (
    "a saved SB3 model (.zip, loaded with agents.rl.load_agent), an RLlib run folder (agents.rl.rllib) "
    f"or a model shipped with the package ({', '.join(PREFIX + n for n in pretrained_names())}); "
    "ensemble:MODEL+MODEL+...: saved MLP models acting on their mean action probabilities (agents.rl.ensemble)"
)
_ENV_HELP = f"env id (default: the models' env, scripted agents' too; else {DEFAULT_ENV_ID})"
_COMPARE_HELP = (
    "comma-separated agents to evaluate into one table: scripted names and/or model paths "
    "(--agent/--model, if given, are added first; each agent once). A model's row is named algo:FILE (its file's "
    "stem; a train.py run's model.zip: algo:FOLDER), or algo:PATH where two models share that name"
)
_HUMAN_HELP = (
    "add the episodes played with python -m agents.tools.play as the 'human' row (replayed on their own seeds; "
    "scored against blind and oracle on those seeds, never the best non-oracle). A CSV of several env ids "
    "needs --env: its episodes of that env are scored"
)
_RUNS_HELP = (
    "train.py run folders (or folders of them): the IQM of the learned agents' mind-reading scores "
    "across the runs (training seeds), stratified bootstrap 95% CI, per algorithm; nothing is played. "
    "A run that did not finish with a score, or one given twice, is an error naming it"
)
_THREADS_HELP = (
    "torch CPU threads of a --model's policy (as train.py: these small networks gain nothing from more, "
    "and evaluations side by side contend for the cores under torch's default)"
)


@dataclass
class Args:
    """The command line's arguments; each field's docstring (or ``help``) is its ``--help``.

    The agent is one of ``--agent``, ``--model``, ``--compare``, ``--human``; or ``--runs``.
    """

    agent: Annotated[str | None, tyro.conf.arg(help=_AGENT_HELP)] = None
    model: Annotated[str | None, tyro.conf.arg(help=_MODEL_HELP)] = None
    compare: Annotated[str | None, tyro.conf.arg(help=_COMPARE_HELP)] = None
    human: Annotated[str | None, tyro.conf.arg(metavar="CSV", help=_HUMAN_HELP)] = None
    runs: Annotated[list[str] | None, tyro.conf.arg(metavar="RUN [RUN ...]", help=_RUNS_HELP)] = None
    env: Annotated[str | None, tyro.conf.arg(help=_ENV_HELP)] = None
    personas: str = "test"
    """train, train_wide, validation, test, all, a persona name or names joined by ','"""
    episodes: int = 1000
    """number of seeded episodes"""
    seed: int = 0
    """seed of episode 0"""
    n_envs: int = 64
    """episodes played side by side"""
    threads: Annotated[int, tyro.conf.arg(help=_THREADS_HELP)] = 1
    backend: Literal["auto", "vector", "single"] = "auto"
    """batched vector env or single envs"""
    stochastic: bool = False
    """sample actions instead of deterministic ones"""
    by_persona: bool = False
    """also show one row per agent and persona"""
    json: bool = False
    """print one JSON object instead of the table"""
    csv: str | None = None
    """write the summary rows to this CSV file"""
    json_out: str | None = None
    """write the summaries and episode records to this JSON file"""
    plot: str | None = None
    """write a bar chart of outcome rates per agent to this PNG file"""

    def __post_init__(self) -> None:
        """The first value no evaluation can use is a usage error naming it (``--runs`` is checked as it is read)."""
        if self.runs is not None and not self.runs:
            raise BadArgs("--runs: expected at least one argument")
        if not self.runs and (problem := args_problem(self)):
            raise BadArgs(problem)


def _personas_arg(text: str) -> str | list[str]:
    return text if "," not in text else [p.strip() for p in text.split(",") if p.strip()]


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code (usage errors exit 2)."""
    args = parse(Args, argv, PROG, DESCRIPTION)
    if args.runs:
        return _report_runs(args.runs, args.json)
    entries = _entries(args)
    names = _model_names(entries)
    # Every model is loaded and matched to its env before any episode is played.
    planned = [_planned(args, entry, names.get(entry, entry)) for entry in entries]
    if args.env is None:
        planned = _scripted_on_the_models_env(planned)
    human_env = _human_env(args.human, args.env, planned) if args.human else DEFAULT_ENV_ID
    results: list[EvaluationResult] = []
    for agent, env_id, label in planned:
        try:
            result = evaluate(
                agent,
                env_id,
                _personas_arg(args.personas),
                args.episodes,
                args.seed,
                n_envs=args.n_envs,
                deterministic=not args.stochastic,
                env_kwargs=None if isinstance(agent, str) else getattr(agent, "env_kwargs", None),
                name=label,
                backend=args.backend,
            )
        except ValueError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        results.append(result)
    if args.human:
        from agents.tools.play_log import score_played

        try:
            results.append(score_played(args.human, human_env))
        except ValueError as exc:
            print(f"error: --human {args.human}: {exc}", file=sys.stderr)
            return 2
    return _report(args, results)


def _human_env(human: str, env: str | None, planned: list[tuple[Agent | str, str, str]]) -> str:
    """The env whose played episodes ``--human`` scores: ``--env``, else the agents' env, else the CSV's only one.

    Without ``--env``, a CSV holding episodes of several env ids is a usage error (as is an
    unreadable CSV): scoring the episodes of one env id would leave the others out unsaid.
    """
    envs = sorted({env_id for _, env_id, _ in planned})
    if len(envs) > 1:
        fail(PROG, f"--human: the agents play on different envs ({', '.join(envs)}): give --env")
    if env is not None:
        return env
    from agents.tools.play_log import read_played

    try:
        played = sorted({e.env_id for e in read_played(human)})
    except (OSError, ValueError) as exc:
        fail(PROG, f"--human {human}: {exc}")
    if len(played) > 1:
        fail(
            PROG,
            f"--human: {human} holds episodes of {len(played)} env ids ({', '.join(played)}): "
            "give --env ID to score those of one",
        )
    return envs[0] if envs else played[0] if played else DEFAULT_ENV_ID


def _entries(args: Args) -> list[str]:
    """The agents to evaluate (scripted names, model paths): ``--agent``, ``--model``, then ``--compare``'s."""
    entries: list[str] = []
    if args.agent:
        entries.append(args.agent)
    if args.model:
        entries.append(args.model)
    if args.compare:
        entries.extend(e.strip() for e in args.compare.split(",") if e.strip())
    return entries


def args_problem(args: Args) -> str | None:
    """The first argument no evaluation can use (None if all are fine); checked before any model is loaded."""
    entries = _entries(args)
    if not entries and not args.human:
        return "give --agent NAME, --model PATH, --compare NAME,NAME,... or --human CSV"
    if args.human and not Path(args.human).is_file():
        return f"--human: no played-episodes CSV at {args.human} (python -m agents.tools.play writes one)"
    if args.episodes < 1:
        return f"--episodes must be >= 1, got {args.episodes}"
    if args.n_envs < 1:
        return f"--n-envs must be >= 1, got {args.n_envs}"
    if args.threads < 1:
        return f"--threads must be >= 1, got {args.threads}"
    problem = seed_range_problem("--seed", args.seed, args.episodes)  # episode k uses seed + k
    if problem:
        return problem
    try:
        resolve_personas(_personas_arg(args.personas))
    except ValueError as exc:
        return f"--personas: {exc}"
    if args.env is not None and args.env not in coop_gym.ENV_IDS:
        return f"--env: unknown env id {args.env!r} (not a coop_gym env); coop_gym ids: {', '.join(coop_gym.ENV_IDS)}"
    for flag, value in (("--csv", args.csv), ("--json-out", args.json_out), ("--plot", args.plot)):
        problem = output_path_problem(value) if value else None
        if problem:
            return f"{flag}: {problem}"
    if args.plot and Path(args.plot).suffix.lower() not in PLOT_SUFFIXES:
        return f"--plot: unsupported file type {Path(args.plot).suffix or '(none)'!r}; use {', '.join(PLOT_SUFFIXES)}"
    return _entries_problem(entries)


def _entries_problem(entries: list[str]) -> str | None:
    """The first agent given twice, or neither a scripted agent nor a saved model (None if all are fine)."""
    given: dict[str, str] = {}
    for entry in entries:
        if entry.startswith(ENSEMBLE_PREFIX):
            members = entry.removeprefix(ENSEMBLE_PREFIX).split("+")
            if missing := [m for m in members if not is_pretrained(m) and not Path(m).exists()]:
                return f"{entry!r}: no saved model at {', '.join(map(repr, missing))}"
            continue
        same = entry if entry in SCRIPTED_AGENTS or is_pretrained(entry) else _model_file(entry)
        if same in given:  # two rows of one agent, and one score would overwrite the other
            first = given[same]
            twice = f"{entry!r} is given twice" if first == entry else f"{first!r} and {entry!r} are one model"
            return f"{twice} (--agent, --model and --compare together): list each agent once"
        given[same] = entry
        if is_pretrained(entry) and entry.removeprefix(PREFIX) not in pretrained_names():
            return f"unknown pretrained model {entry!r}; known: {', '.join(PREFIX + n for n in pretrained_names())}"
        if entry not in SCRIPTED_AGENTS and not is_pretrained(entry) and not Path(entry).exists():
            return f"{entry!r} is neither a scripted agent ({', '.join(SCRIPTED_AGENTS)}) nor an existing model file"
    return None


def _model_file(entry: str) -> str:
    """The model file a saved-model entry names, resolved: a run folder's ``model.zip``, ``x`` for ``x.zip``."""
    path = Path(entry)
    if path.is_dir() and not is_rllib_run(path):
        path = path / MODEL_FILE
    elif not path.exists() and path.with_suffix(".zip").exists():
        path = path.with_suffix(".zip")
    return str(path.resolve())


def _model_names(entries: list[str]) -> dict[str, str]:
    """The name of each saved model path in the table: its file's, or the path as given where names are shared.

    A model file is named by its stem (``logs/seed3.zip``: ``seed3``; RL Zoo's
    ``logs/ppo/<env>_1/<env>.zip``: ``<env>``); a ``train.py`` run folder, or the ``model.zip``
    inside it, by the folder, whose name says env, algorithm, seed and time. Two models of one
    name would share a row name, and one result would overwrite the other wherever results are
    keyed by name (the mind-reading scores).
    """
    paths = [e for e in entries if e not in SCRIPTED_AGENTS and not is_pretrained(e)]
    names = {}
    for entry in paths:
        path = Path(entry)
        in_run_folder = path.is_dir() or path.name == MODEL_FILE
        names[entry] = ((path if path.is_dir() else path.parent).name if in_run_folder else "") or path.stem
    shared = Counter(names.values())
    return {e: name if shared[name] == 1 else e for e, name in names.items()}


def _planned(args: Args, entry: str, name: str) -> tuple[Agent | str, str, str]:
    """``(agent, env_id, label)`` of one entry: a scripted name, or a model loaded and matched to its env.

    ``name`` is a saved model's name in the label (:func:`_model_names`).
    """
    if entry in SCRIPTED_AGENTS:
        return entry, args.env or DEFAULT_ENV_ID, entry
    import torch

    torch.set_num_threads(args.threads)  # the policy's forward passes (SB3's and RLlib's)
    if not is_pretrained(entry) and is_rllib_run(entry):
        from agents.rl.rllib import load_rllib_agent

        try:
            rllib_agent = load_rllib_agent(entry)
        except (OSError, ValueError) as exc:
            fail(PROG, f"--model {entry}: {exc}")
        env_id = args.env or rllib_agent.env_id or DEFAULT_ENV_ID
        return rllib_agent, env_id, f"rllib_ppo:{name}"
    from agents.rl import load_agent, observation_features

    try:
        loaded = load_agent(entry)
    except (OSError, ValueError) as exc:
        fail(PROG, f"--model {entry}: {exc}")
    env_id = args.env or loaded.env_id or DEFAULT_ENV_ID
    problem = feature_mismatch(loaded.features, observation_features(env_id, env_kwargs=loaded.env_kwargs), env_id)
    if problem:
        fail(PROG, f"--model {entry}: {problem}")
    label = loaded.name if is_pretrained(entry) or entry.startswith(ENSEMBLE_PREFIX) else f"{loaded.algo}:{name}"
    return loaded, env_id, label


def _scripted_on_the_models_env(planned: list[tuple[Agent | str, str, str]]) -> list[tuple[Agent | str, str, str]]:
    """Without ``--env``, scripted agents play on the models' env, so a comparison compares like with like."""
    model_envs = sorted({env_id for agent, env_id, _ in planned if not isinstance(agent, str)})
    if not model_envs or all(not isinstance(agent, str) for agent, _, _ in planned):
        return planned
    if len(model_envs) > 1:
        fail(PROG, f"the models were trained on different envs ({', '.join(model_envs)}): give --env")
    return [(agent, model_envs[0] if isinstance(agent, str) else env_id, label) for agent, env_id, label in planned]


def _report(args: Args, results: list[EvaluationResult]) -> int:
    """Print the results (table or JSON) and write the files asked for; the exit code."""
    if args.json:
        print(json.dumps(results_json(results)))
    else:
        room = print_table(results)  # with the headroom and mind-reading lines given an oracle and a blind agent
        if room is None and len(results) > 1:
            print("(add blind and oracle to --compare for the value of reading the mind and each mind-reading score)")
        if args.by_persona:
            split = [sub for r in results for sub in _split_named(r)]
            print_table(split, title="by persona")
    try:
        if args.csv:
            write_csv(results, args.csv)
        if args.json_out:
            write_json(results, args.json_out, episodes=True)
        if args.plot:
            from agents.tools.plots import plot_outcome_rates

            plot_outcome_rates(results, args.plot)
    except OSError as exc:  # e.g. a full disk: the file is not there (never half-written)
        print(f"error: could not write {exc.filename or 'output'}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    return 0


def _report_runs(folders: list[str], as_json: bool) -> int:
    """``--runs``: the IQM of the mind-reading score per algorithm across the runs' ``results.json``.

    Every run given, or found in a folder given, is counted or refused with a usage error
    naming it: an IQM over fewer runs than asked would pass for the one asked for.
    """
    runs = _run_scores(folders)
    report = {}
    for algo in sorted({r[1] for r in runs.values()}):
        of_algo = {folder: r for folder, r in runs.items() if r[1] == algo}
        episodes = {r[3] for r in of_algo.values()}
        if len(episodes) > 1:
            scored = "; ".join(
                f"personas {key[0]}, {key[1]} episodes from seed {key[2]}: "
                + ", ".join(str(f) for f, r in of_algo.items() if r[3] == key)
                for key in sorted(episodes, key=str)
            )
            fail(PROG, f"--runs: the {algo} runs were scored on different episodes ({scored}); give like runs")
        aggregate = aggregate_runs(of_algo.values())
        assert aggregate is not None
        report[algo] = aggregate.as_json()
        if not as_json:
            levels = ", ".join(f"{env_id}: {n}" for env_id, n in aggregate.runs.items())
            print(f"{algo}: mind-reading score {aggregate.text()} ({levels})")
    if as_json:
        print(json.dumps(report))
    return 0


def _run_scores(folders: list[str]) -> dict[Path, RunScore]:
    """The score of every run folder given or inside a folder given; a usage error for any run without one."""
    runs: dict[Path, RunScore] = {}
    given: set[Path] = set()
    for folder in folders:
        if not Path(folder).is_dir():
            fail(PROG, f"--runs: {folder} is not a folder")
        inside = [Path(folder)] if is_run_folder(folder) else run_folders_in(folder)
        if not inside:
            fail(PROG, f"--runs: {folder} is neither a train.py run folder nor a folder of them")
        for run in inside:
            if run.resolve() in given:  # counted twice, one seed would weigh double
                fail(PROG, f"--runs: {run} is given twice")
            given.add(run.resolve())
            try:
                runs[run] = finished_run_score(run)
            except ValueError as exc:
                fail(PROG, f"--runs: {run}: {exc}; finish it or leave it out")
    _one_run_per_seed(runs)
    return runs


def _one_run_per_seed(runs: dict[Path, RunScore]) -> None:
    """A usage error where two runs are one training seed (copies, or one seed trained twice).

    The IQM and its bootstrap are across training seeds: a seed counted twice weighs double and
    narrows the interval as if it were another seed.
    """
    by_seed: dict[tuple[str, str, int], list[Path]] = {}
    for run, (env_id, algo, _, _) in runs.items():
        seed = training_seed(run)
        if seed is not None:
            by_seed.setdefault((env_id, algo, seed), []).append(run)
    for (env_id, algo, seed), same in by_seed.items():
        if len(same) > 1:
            folders = ", ".join(str(run) for run in same)
            fail(
                PROG,
                f"--runs: {folders} are one training seed ({algo} seed {seed} on {env_id}); "
                "the IQM is across training seeds: give each seed once",
            )


def _split_named(result: EvaluationResult) -> list[EvaluationResult]:
    out = []
    for persona, sub in result.by_persona().items():
        out.append(
            EvaluationResult(
                f"{result.agent} / {persona}",
                sub.env_id,
                sub.personas,
                sub.seed,
                sub.records,
                sub.wall_time_s,
                sub.backend,
                sub.env_kwargs,
            )
        )
    return out
