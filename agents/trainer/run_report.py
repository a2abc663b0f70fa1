"""How every training run ends: the learned agent and the baselines on the same episodes, then the files.

Both trainers (``train.py`` with SB3 through :func:`evaluate_and_report`, :func:`agents.trainer.rllib_run.run`
with RLlib) finish the same way: the saved agent and each scripted baseline are scored by
:func:`agents.evaluate.evaluate` on the same seeded episodes of the held-out personas; the
comparison table is printed with the value of reading the mind, the achieved insight and each
agent's mind-reading score; ``eval.json`` / ``eval.csv`` hold it; ``results.json`` and the
``COMPLETE`` marker are written last, so a run folder without them did not finish. The learning
curve beside it is drawn from the training episodes of SB3's ``monitor.csv`` (:func:`monitor_curve`).
"""

from __future__ import annotations

import csv
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from agents.evaluate import (
    EvaluationResult,
    Headroom,
    evaluate,
    headroom,
    print_table,
    summaries,
    write_csv,
    write_json,
)
from agents.evaluate.runs import aggregate_runs, run_score_of, runs_in
from agents.run_folder import COMPLETE_FILE, ENSEMBLE_FILE, INTERRUPTED_FILE, MODEL_FILE
from agents.trainer.train_args import baseline_names, personas_arg
from coop_gym.io import make_unique_folder, write_text
from coop_gym.io import write_json as write_json_file

if TYPE_CHECKING:
    from agents.trainer.training_run import Plan, StopSignals

__all__ = [
    "Comparison",
    "compare_with_baselines",
    "evaluate_and_report",
    "finish_run",
    "monitor_curve",
    "new_run_folder",
    "verdict_against_handbook",
    "versions",
    "warn_if_blind",
]


def new_run_folder(out: str | Path, env_id: str, algo: str, seed: int) -> Path:
    """A new run folder ``out/{env}__{algo}__{seed}__{time}`` (CleanRL's naming), never shared with another run."""
    return make_unique_folder(out, f"{env_id.replace('/', '-')}__{algo}__{seed}__{int(time.time())}")


class Comparison:
    """The learned agent (first) and the baselines, scored on the same episodes, with their headroom.

    Attributes:
        results: One :class:`~agents.evaluate.EvaluationResult` per agent, the learned one first.
        room: Headroom and mind-reading scores (None without an oracle and a blind baseline).
        settings: The run's ``train.Args`` (its evaluation settings).
        wall_time_s: Time the evaluations took [s].
    """

    def __init__(self, results: list[EvaluationResult], settings: Any, wall_time_s: float) -> None:
        """Hold the results; the headroom is computed once, here."""
        self.results = results
        self.room: Headroom | None = headroom(results)
        self.settings = settings
        self.wall_time_s = wall_time_s

    def summary(self) -> dict[str, Any]:
        """The ``evaluation`` and ``headroom`` entries of ``results.json``."""
        return {
            "evaluation": {
                "personas": self.settings.eval_personas,
                "episodes": self.settings.eval_episodes,
                "seed": self.settings.eval_seed,
                "wall_time_s": self.wall_time_s,
                "results": summaries(self.results, self.room),
            },
            "headroom": None if self.room is None else self.room.as_json(),
        }


def compare_with_baselines(
    agent: Any, label: str, env_id: str, settings: Any, run_dir: Path, after_each: Callable[[], None] | None = None
) -> Comparison:
    """Score ``agent`` and the baselines on the same episodes; print the table, write ``eval.json`` and ``eval.csv``.

    ``settings`` is the run's ``train.Args``: ``eval_personas``, ``eval_episodes``, ``eval_seed``
    and ``baselines`` say which episodes and which scripted agents. ``after_each`` is called
    after each agent's evaluation (``train.py``: :meth:`agents.trainer.training_run.StopSignals.check`).
    """
    personas = personas_arg(settings.eval_personas)
    episodes, seed = settings.eval_episodes, settings.eval_seed
    started = time.perf_counter()
    results = []
    to_score: list[tuple[Any, str | None]] = [(agent, label), *((b, None) for b in baseline_names(settings.baselines))]
    for scored, name in to_score:
        results.append(evaluate(scored, env_id, personas, episodes, seed, name=name))
        if after_each is not None:
            after_each()
    comparison = Comparison(results, settings, time.perf_counter() - started)
    print_table(results, room=comparison.room)
    write_json(results, run_dir / "eval.json", episodes=True)
    write_csv(results, run_dir / "eval.csv", room=comparison.room)
    return comparison


def evaluate_and_report(args: Any, plan: Plan, finished: dict[str, Any], stop: StopSignals) -> None:
    """Score the saved agent and the baselines on the same episodes; write the figures, results.json, COMPLETE.

    ``args`` is ``train.Args``, ``finished`` the training summary (``training.json``). A signal
    stops the run after the agent being evaluated, at the latest before ``results.json`` is written.
    """
    from agents.rl import load_agent
    from agents.tools.plots import plot_learning_curve, plot_outcome_rates

    run_dir, env_id = plan.run_dir, plan.env_id
    kept = run_dir if (run_dir / ENSEMBLE_FILE).is_file() else run_dir / MODEL_FILE  # the folder: its ensemble
    model_path = args.model if args.eval_only and args.model else kept
    # The saved agent (what a user loads) and the baselines, on the same episodes.
    label = f"{plan.algo} (learned)"
    agent = load_agent(model_path)
    comparison = compare_with_baselines(agent, label, env_id, args, run_dir, after_each=stop.check)
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
        # Which learner trained it (runs of one framework are compared across seeds).
        "framework": getattr(agent.model, "framework", "sb3"),
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
    stop.check()  # a signal whose exception was swallowed still stops the run here
    finish_run(run_dir, summary)


def monitor_curve(path: Path, start_steps: int) -> tuple[list[float], list[float]]:
    """(env step at episode end, return) of every training episode in SB3's monitor.csv."""
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


def finish_run(run_dir: Path, summary: dict[str, Any]) -> None:
    """Write ``results.json``, then the ``COMPLETE`` marker (and drop ``INTERRUPTED``): the run finished.

    With finished runs of the same algorithm on the same evaluation episodes beside it (other
    training seeds in the same ``--out``), the IQM of their mind-reading scores and this run's
    is printed and stored as ``mind_reading_across_runs``.
    """
    summary = summary | {"mind_reading_across_runs": _across_runs(run_dir, summary)}
    write_json_file(run_dir / "results.json", summary)
    (run_dir / INTERRUPTED_FILE).unlink(missing_ok=True)
    write_text(run_dir / COMPLETE_FILE, time.strftime("%Y-%m-%dT%H:%M:%S") + "\n")
    print(f"saved: {run_dir}")


def _across_runs(run_dir: Path, summary: dict[str, Any]) -> dict[str, Any] | None:
    """IQM of the mind-reading score over this run and the comparable finished runs beside it, printed."""
    own = run_score_of(summary)
    if own is None:
        return None
    aggregate = aggregate_runs([own, *runs_in(run_dir.parent, exclude=run_dir)], like=own)
    if aggregate is None:
        return None
    print(f"mind-reading score of {own[1]} across training runs in {run_dir.parent}: {aggregate.text()}")
    return aggregate.as_json()


def warn_if_blind(label: str, room: Headroom | None) -> bool | None:
    """Print a warning if the learned agent does no better than the best blind policy; whether so (None: unknown).

    A training seed is a draw: on the hard level some seeds never learn to read the person
    (docs/agents.md, "Across training seeds"), and the table alone is easy to misread.
    """
    score = room.score_of(label) if room is not None else None
    if score is None or math.isnan(score.score):
        return None
    if score.score > 0:
        return False
    print(
        f"warning: {label} does no better than the best blind policy (mind-reading score {score.score:.2f}): "
        "this training seed did not learn to read the person; a seed is a draw, train another --seed"
    )
    return True


def verdict_against_handbook(label: str, results: list[Any]) -> dict[str, Any] | None:
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


def versions() -> dict[str, str]:
    """The numpy and torch versions a run used (for ``results.json``)."""
    import numpy as np
    import torch

    return {"numpy": np.__version__, "torch": torch.__version__}
