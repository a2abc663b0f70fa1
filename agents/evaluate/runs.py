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
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from agents.evaluate.headroom import AggregateScore, iqm_across_runs

__all__ = ["RESULTS_FILE", "RunScore", "aggregate_runs", "read_run_score", "run_score_of", "runs_in", "scores_by_level"]

RESULTS_FILE = "results.json"
"""Written last by every finished run (``train.py``, ``--framework rllib``)."""

RunScore = tuple[str, str, float, tuple[Any, ...]]
"""``(env id, algorithm, score, evaluation key)`` of one run (the key: personas, episodes, seed)."""


def run_score_of(results: dict[str, Any]) -> RunScore | None:
    """The learned agent's mind-reading score in a run's ``results.json`` content (None without one)."""
    try:
        evaluation = results["evaluation"]
        score = evaluation["results"][0].get("mind_reading_score")
    except (KeyError, IndexError, TypeError, AttributeError):
        return None
    if score is None:
        return None
    algo = f"{results.get('framework', 'sb3')}:{results.get('algo')}"
    key = (str(evaluation.get("personas")), evaluation.get("episodes"), evaluation.get("seed"))
    return str(results.get("env_id")), algo, float(score), key


def read_run_score(folder: str | Path) -> RunScore | None:
    """The learned agent's mind-reading score of a finished run folder (None: unfinished, or no score)."""
    try:
        results = json.loads((Path(folder) / RESULTS_FILE).read_text())
    except (OSError, ValueError):
        return None
    return run_score_of(results) if isinstance(results, dict) else None


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
    """The scores of the finished runs directly inside ``folder`` (e.g. ``train.py``'s ``--out``), but ``exclude``."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    skip = Path(exclude).resolve() if exclude is not None else None
    folders = [f for f in sorted(folder.iterdir()) if f.is_dir() and f.resolve() != skip]
    return [r for r in (read_run_score(f) for f in folders) if r is not None]
