"""The comparison as people and programs read it: a terminal table, CSV rows and JSON.

Every table and file of a comparison played on the same seeded episodes carries the
mind-reading score of each agent (:mod:`agents.evaluate.headroom`) beside its outcome rates.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from agents.evaluate.headroom import Headroom, headroom
from agents.evaluate.results import EvaluationResult
from coop_gym.io import atomic_open
from coop_gym.io import write_json as atomic_write_json

__all__ = [
    "TABLE_COLUMNS",
    "print_table",
    "results_json",
    "results_table",
    "summaries",
    "table_rows",
    "write_csv",
    "write_json",
]


def _pct(rate: float, interval: tuple[float, float] | None = None) -> str:
    text = f"{100 * rate:5.1f}%"
    if interval is not None:
        text += f" [{100 * interval[0]:.1f}, {100 * interval[1]:.1f}]"
    return text


def _num(value: float, digits: int = 2) -> str:
    return "-" if not math.isfinite(value) else f"{value:.{digits}f}"


TABLE_COLUMNS: tuple[str, ...] = (
    "agent",
    "episodes",
    "success [95% CI]",
    "unsafe [95% CI]",
    "premature",
    "timeout",
    "mind-reading [95% CI]",
    "time to lift s",
    "mean force N",
    "peak force N",
    "cues",
    "return (mean ± std)",
)


def table_rows(results: Sequence[EvaluationResult], room: Headroom | None = None) -> list[list[str]]:
    """The rows of the comparison table, as strings (see :data:`TABLE_COLUMNS`).

    ``room`` gives the mind-reading scores (``-`` without it).
    """
    rows = []
    for r in results:
        score = room.score_of(r.agent) if room is not None else None
        rows.append(
            [
                r.agent,
                str(r.episodes),
                _pct(r.success_rate, r.interval("success")),
                _pct(r.unsafe_rate, r.interval("unsafe")),
                _pct(r.premature_rate),
                _pct(r.timeout_rate),
                score.text() if score is not None else "-",
                _num(r.mean_time_to_lift_s),
                _num(r.mean_force_n, 1),
                _num(r.peak_force_n, 1),
                _num(r.mean_cues, 1),
                f"{r.mean_return:+.3f} ± {r.std_return:.3f}",
            ]
        )
    return rows


def results_table(results: Sequence[EvaluationResult], title: str | None = None, room: Headroom | None = None) -> Any:
    """A :class:`rich.table.Table` comparing the results (one row per agent)."""
    from rich.table import Table

    if title is None and results:
        first = results[0]
        title = (
            f"{first.env_id} | personas {','.join(first.personas)} | {first.episodes} episodes, seeds {first.seed}.."
        )
    table = Table(title=title)
    for k, column in enumerate(TABLE_COLUMNS):
        table.add_column(column, justify="left" if k == 0 else "right")
    for row in table_rows(results, room):
        table.add_row(*row)
    return table


def print_table(
    results: Sequence[EvaluationResult], title: str | None = None, file: Any = None, room: Headroom | None = None
) -> Headroom | None:
    """Print the comparison table (and, with an oracle and a blind agent, the headroom lines); returns the headroom.

    ``room`` defaults to :func:`~agents.evaluate.headroom.headroom` of ``results``.
    """
    from rich.console import Console

    room = room if room is not None else headroom(results)
    console = Console(file=file, width=220)
    console.print(results_table(results, title, room))
    if room is not None:
        console.print("\n".join(room.lines()), highlight=False, soft_wrap=True)
    return room


def summaries(results: Sequence[EvaluationResult], room: Headroom | None = None) -> list[dict[str, Any]]:
    """:meth:`EvaluationResult.summary` of each result, with its mind-reading score (None without one)."""
    out = []
    for r in results:
        score = room.score_of(r.agent) if room is not None else None
        if score is None or not math.isfinite(score.score):
            out.append(r.summary() | {"mind_reading_score": None, "mind_reading_score_ci95": None})
        else:
            out.append(r.summary() | {"mind_reading_score": score.score, "mind_reading_score_ci95": list(score.ci95)})
    return out


def write_csv(results: Sequence[EvaluationResult], path: str | Path, room: Headroom | None = None) -> Path:
    """Write one summary row per agent (the keys of :func:`summaries`); ``room`` defaults to the results' headroom."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = summaries(results, room if room is not None else headroom(results))
    for row in rows:
        for key, value in row.items():
            if isinstance(value, list):
                row[key] = ";".join(str(v) for v in value)
    with atomic_open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]) if rows else [])
        writer.writeheader()
        writer.writerows(rows)
    return path


def write_json(results: Sequence[EvaluationResult], path: str | Path, episodes: bool = False) -> Path:
    """Write the summaries (and with ``episodes`` every episode record) as JSON."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_json(path, results_json(results, episodes=episodes))
    return path


def results_json(results: Sequence[EvaluationResult], episodes: bool = False) -> dict[str, Any]:
    """One JSON object: a single result's summary at top level; several under ``results``, with ``headroom``."""
    room = headroom(results)
    rows = summaries(results, room)
    if episodes:
        for row, r in zip(rows, results, strict=True):
            row["episode_records"] = [asdict(rec) for rec in r.records]
    if len(rows) == 1:
        return rows[0]
    return {"results": rows, "headroom": room.as_json() if room is not None else None}
