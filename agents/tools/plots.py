"""Figures of an evaluation and of a training run (matplotlib, Agg backend, PNG files)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from coop_gym.envs.config import Outcome
from coop_gym.io import save_figure

__all__ = ["plot_learning_curve", "plot_outcome_rates"]

# Episode outcomes in report order (as agents.evaluate.OUTCOMES), from the enum: plots need not import evaluate.
_OUTCOMES: tuple[str, ...] = tuple(o.label for o in Outcome if o is not Outcome.NONE)
_OUTCOME_COLOURS = {"success": "#2e7d32", "unsafe": "#c62828", "premature": "#ef6c00", "timeout": "#757575"}


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")  # files only; never open a window
    import matplotlib.pyplot as plt

    return plt


def plot_outcome_rates(results: Sequence[Any], path: str | Path, title: str | None = None) -> Path:
    """Grouped bars of the outcome rates per agent, with 95 % Wilson intervals.

    Args:
        results: :class:`agents.evaluate.EvaluationResult` objects, one per agent.
        path: PNG file to write.
        title: Figure title (default: env id, personas and episode count).

    Returns:
        The path written.
    """
    if not results:
        raise ValueError("plot_outcome_rates needs at least one result")
    plt = _pyplot()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    names = [r.agent for r in results]
    x = np.arange(len(results))
    width = 0.8 / len(_OUTCOMES)
    fig, ax = plt.subplots(figsize=(max(6.0, 1.4 * len(results) + 2.0), 4.0))
    for k, outcome in enumerate(_OUTCOMES):
        rates = np.array([r.rate(outcome) for r in results])
        intervals = np.array([r.interval(outcome) for r in results])
        err = np.vstack([rates - intervals[:, 0], intervals[:, 1] - rates])
        ax.bar(
            x + (k - (len(_OUTCOMES) - 1) / 2) * width,
            100 * rates,
            width,
            yerr=100 * np.clip(err, 0.0, None),
            capsize=2,
            label=outcome,
            color=_OUTCOME_COLOURS[outcome],
        )
    ax.set_xticks(x, names, rotation=20, ha="right")
    ax.set_ylabel("episodes [%]")
    # Headroom above 100 % keeps the legend clear of the bars.
    ax.set_ylim(0, 122)
    ax.set_yticks(range(0, 101, 20))
    first = results[0]
    ax.set_title(title or f"{first.env_id} | {','.join(first.personas)} | {first.episodes} episodes")
    ax.legend(ncols=len(_OUTCOMES), fontsize="small", loc="upper center")
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
    plt.close(fig)
    return path


def plot_learning_curve(
    timesteps: Sequence[float],
    returns: Sequence[float],
    path: str | Path,
    eval_timesteps: Sequence[float] = (),
    eval_success: Sequence[float] = (),
    reference: dict[str, float] | None = None,
    title: str = "learning curve",
) -> Path:
    """Training episode returns (smoothed) and, if given, periodic evaluation success rates.

    Args:
        timesteps: Env step at which each training episode ended.
        returns: The training episodes' returns.
        path: PNG file to write.
        eval_timesteps: Env steps of the periodic evaluations.
        eval_success: Success rate of each periodic evaluation (0..1).
        reference: Horizontal reference success rates (e.g. ``{"handbook": 0.99}``).
        title: Figure title.

    Returns:
        The path written.
    """
    plt = _pyplot()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    t = np.asarray(timesteps, dtype=float)
    r = np.asarray(returns, dtype=float)
    fig, ax = plt.subplots(figsize=(7.0, 4.0))
    if len(r):
        window = max(1, min(200, len(r) // 20))
        smooth = np.convolve(r, np.ones(window) / window, mode="valid")
        ax.plot(t, r, ".", ms=1, alpha=0.15, color="#1565c0")
        ax.plot(t[window - 1 :], smooth, color="#1565c0", label=f"training return (mean of {window})")
    ax.set_xlabel("env steps")
    ax.set_ylabel("episode return")
    ax.set_title(title)
    handles, labels = ax.get_legend_handles_labels()
    if len(eval_success):
        ax2 = ax.twinx()
        ax2.plot(eval_timesteps, 100 * np.asarray(eval_success), "o-", color="#2e7d32", label="eval success")
        for k, (name, value) in enumerate((reference or {}).items()):
            ax2.axhline(100 * value, ls="--", lw=1, color=f"C{k + 3}", label=f"{name} success")
        ax2.set_ylabel("eval success [%]")
        ax2.set_ylim(0, 105)
        h2, l2 = ax2.get_legend_handles_labels()
        handles, labels = handles + h2, labels + l2
    if handles:
        ax.legend(handles, labels, fontsize="small", loc="lower right")
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
    plt.close(fig)
    return path
