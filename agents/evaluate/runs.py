"""The mind-reading score across training seeds: read the runs' ``results.json``, aggregate rliable's way.

Each finished ``train.py`` run folder holds ``results.json`` with the learned agent's
mind-reading score on its level (the first result of ``evaluation.results``). Runs of one
algorithm that were scored on the same episodes (personas, count and seed of the evaluation)
are comparable; :func:`scores_by_level` collects their scores per env id and
:func:`~agents.evaluate.headroom.iqm_across_runs` turns them into the interquartile mean
with a stratified bootstrap interval.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from agents.evaluate.headroom import AggregateScore, iqm_across_runs
from agents.run_folder import ARGS_FILE, COMPLETE_FILE, INTERRUPTED_FILE, TRAINING_FILE

__all__ = [
    "RESULTS_FILE",
    "RunScore",
    "aggregate_runs",
    "finished_run_score",
    "is_run_folder",
    "read_run_score",
    "run_folders_in",
    "run_score_of",
    "runs_in",
    "scores_by_level",
    "training_seed",
]

RESULTS_FILE = "results.json"
"""Written last by every finished run (``train.py``, ``--framework rllib``)."""

RunScore = tuple[str, str, float, tuple[Any, ...]]
"""``(env id, algorithm, score, evaluation key)`` of one run (the key: personas, episodes, seed)."""

_RUN_FILES = (ARGS_FILE, TRAINING_FILE, RESULTS_FILE, COMPLETE_FILE, INTERRUPTED_FILE)
"""A folder holding any of these is a run folder, finished or not (``args.json`` is written first)."""


def run_score_of(results: dict[str, Any]) -> RunScore | None:
    """The learned agent's mind-reading score in a run's ``results.json`` content (None without one)."""
    try:
        evaluation = results["evaluation"]
        score = evaluation["results"][0].get("mind_reading_score")
    except (KeyError, IndexError, TypeError, AttributeError):
        return None
    try:
        score = float(score)
    except (TypeError, ValueError):  # null: no blind and oracle beside it, or the score is undefined
        return None
    if not math.isfinite(score):
        return None
    algo = f"{results.get('framework', 'sb3')}:{results.get('algo')}"
    key = (str(evaluation.get("personas")), evaluation.get("episodes"), evaluation.get("seed"))
    return str(results.get("env_id")), algo, score, key


def is_run_folder(folder: str | Path) -> bool:
    """Whether ``folder`` is a ``train.py`` run folder, finished or not (it holds a file every run writes)."""
    folder = Path(folder)
    return folder.is_dir() and any((folder / name).exists() for name in _RUN_FILES)


def run_folders_in(folder: str | Path) -> list[Path]:
    """The run folders directly inside ``folder`` (``train.py``'s ``--out``), sorted; other folders are not runs."""
    folder = Path(folder)
    return [f for f in sorted(folder.iterdir()) if is_run_folder(f)] if folder.is_dir() else []


def finished_run_score(folder: str | Path) -> RunScore:
    """The learned agent's mind-reading score of a finished run folder.

    A folder without the ``COMPLETE`` marker but with ``results.json`` counts as finished:
    ``results.json`` is only written once a run is scored.

    Raises:
        ValueError: The run was interrupted or has not finished, or its ``results.json`` is
            missing, not JSON (a truncated write) or holds no mind-reading score; the
            message says which.
    """
    folder = Path(folder)
    finished = (folder / COMPLETE_FILE).exists()
    if (folder / INTERRUPTED_FILE).exists() and not finished:
        raise ValueError(f"interrupted, not finished (its {INTERRUPTED_FILE} file says how to resume it)")
    try:
        data = (folder / RESULTS_FILE).read_bytes()
    except FileNotFoundError:
        unfinished = "" if finished else f" and no {COMPLETE_FILE} marker: not finished (still training?)"
        raise ValueError(f"no {RESULTS_FILE}{unfinished}") from None
    except OSError as exc:
        raise ValueError(f"{RESULTS_FILE} is unreadable: {exc.strerror or exc}") from None
    try:
        results = json.loads(data)
    except ValueError as exc:  # UnicodeDecodeError included
        raise ValueError(f"{RESULTS_FILE} is not valid JSON (a truncated write?): {exc}") from None
    score = run_score_of(results) if isinstance(results, dict) else None
    if score is None:
        raise ValueError(
            f"{RESULTS_FILE} holds no mind-reading score of the learned agent "
            "(scored without blind and oracle, or the score is undefined)"
        )
    return score


def training_seed(folder: str | Path) -> int | None:
    """The training seed a finished run's ``results.json`` records (None where it records none)."""
    try:
        seed = json.loads((Path(folder) / RESULTS_FILE).read_bytes()).get("seed")
    except (OSError, ValueError, AttributeError):
        return None
    return seed if isinstance(seed, int) and not isinstance(seed, bool) else None


def read_run_score(folder: str | Path) -> RunScore | None:
    """The learned agent's mind-reading score of a finished run folder (None: unfinished, or no score)."""
    try:
        return finished_run_score(folder)
    except ValueError:
        return None


def scores_by_level(runs: Iterable[RunScore]) -> dict[str, list[float]]:
    """The scores of ``runs`` grouped by env id (each env id is one level: one stratum)."""
    grouped: dict[str, list[float]] = {}
    for env_id, _, score, _ in runs:
        grouped.setdefault(env_id, []).append(score)
    return grouped


def aggregate_runs(runs: Iterable[RunScore], like: RunScore | None = None) -> AggregateScore | None:
    """IQM of the learned agents' scores over runs, stratified by level (None if there is none).

    ``like`` keeps only the runs comparable with it: the same algorithm, scored on the same
    evaluation episodes (its own level or others).
    """
    kept = [r for r in runs if like is None or (r[1] == like[1] and r[3] == like[3])]
    return iqm_across_runs(scores_by_level(kept)) if kept else None


def runs_in(folder: str | Path, exclude: str | Path | None = None) -> list[RunScore]:
    """The scores of the finished runs directly inside ``folder`` (e.g. ``train.py``'s ``--out``), but ``exclude``.

    Runs that did not finish or hold no score are left out: other training seeds beside a
    run may still be training (``python -m agents.evaluate --runs`` refuses them instead).
    """
    skip = Path(exclude).resolve() if exclude is not None else None
    folders = [f for f in run_folders_in(folder) if f.resolve() != skip]
    return [r for r in (read_run_score(f) for f in folders) if r is not None]
