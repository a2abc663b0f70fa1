"""The paper's Tables I-III for a run or over seeds: scores of one estimator, aggregates, text tables."""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from coop_gym.experiment.estimators import EstimateResult
from coop_gym.experiment.simulation import ExperimentData
from estimator.paper import (
    PAPER_RESULTS,
    XI_NAMES,
    XI_SHORT,
    PaperResults,
    conditional_tables,
    judgment_scores,
    nan_to_none,
    percent,
)
from estimator.paper import format_tables as paper_tables

__all__ = [
    "aggregate",
    "format_aggregate",
    "format_tables",
    "summarize",
]

# --------------------------------------------------------------------------- scoring


def summarize(data: ExperimentData, result: EstimateResult) -> dict[str, Any]:
    """The paper's three tables and the scores of one estimator on one experiment (JSON-ready).

    Keys: those of :func:`estimator.paper.judgment_scores` (``confusion``,
    ``p_estimated_given_requested``, ``p_requested_given_estimated``, ``accuracy``,
    ``balanced_accuracy``, ``log_loss``, ``brier``, ``ece``, ``mean_latency_s``) and the run's
    identification.
    """
    return {
        "estimator": result.estimator,
        "seed": data.seed,
        "n_subjects": len(data.subjects),
        "n_trials": len(data.trials),
        "personas": [p.name for p in data.personas],
        **judgment_scores(data.requested, result.judgment, result.probabilities, result.latency_s),
    }


# --------------------------------------------------------------------------- reporting


def format_tables(summary: dict[str, Any], paper: PaperResults = PAPER_RESULTS) -> str:
    """The paper's three tables for one run, each beside the paper's numbers on real people."""
    title = (
        f"estimator: {summary['estimator']}, seed {summary['seed']}, {summary['n_subjects']} subjects x "
        f"{summary['n_trials']} trials (simulated)  |  paper: 4 real subjects x 25 trials"
    )
    return paper_tables(summary, title, paper=paper)


def aggregate(summaries: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Mean and std over seeds of every score, the per-cell rates and the counts."""
    conf = np.array([s["confusion"] for s in summaries], dtype=np.float64)
    given_req = np.array([conditional_tables(c)[0] for c in conf])
    given_est = np.array([conditional_tables(c)[1] for c in conf])
    out: dict[str, Any] = {
        "estimator": summaries[0]["estimator"],
        "seeds": [s["seed"] for s in summaries],
        "confusion_mean": conf.mean(axis=0).tolist(),
        "confusion_std": conf.std(axis=0).tolist(),
        "confusion": conf.sum(axis=0).astype(np.int64).tolist(),
    }
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        out["p_estimated_given_requested_mean"] = nan_to_none(np.nanmean(given_req, axis=0))
        out["p_estimated_given_requested_std"] = nan_to_none(np.nanstd(given_req, axis=0))
        out["p_requested_given_estimated_mean"] = nan_to_none(np.nanmean(given_est, axis=0))
        out["p_requested_given_estimated_std"] = nan_to_none(np.nanstd(given_est, axis=0))
    for key in ("accuracy", "balanced_accuracy", "log_loss", "brier", "ece", "mean_latency_s"):
        values = np.array([s[key] for s in summaries], dtype=np.float64)
        out[key] = float(values.mean())
        out[f"{key}_std"] = float(values.std())
    return out


def format_aggregate(agg: dict[str, Any], paper: PaperResults = PAPER_RESULTS) -> str:
    """Per-cell mean +/- std over seeds beside the paper (Tables I-III), and the scores."""
    p_conf = paper.matrix
    p_req, p_est = conditional_tables(p_conf)
    blocks = (
        ("Table I   counts per run (rows: requested, columns: estimated)", "confusion", p_conf, False),
        ("Table II  P(estimated | requested)", "p_estimated_given_requested", p_req, True),
        ("Table III P(requested | estimated)", "p_requested_given_estimated", p_est, True),
    )
    head = "".join(f"{n:>15s}" for n in XI_SHORT)
    lines = [f"estimator: {agg['estimator']}, {len(agg['seeds'])} seeds (mean +/- std over seeds)  |  paper: real"]
    for title, key, theirs, pct in blocks:
        paper_head = "".join(f"{n:>8s}" for n in XI_SHORT)
        lines += ["", f"{title}   [simulated | paper]", f"{'requested':>14s}{head}   |{paper_head}"]
        mean = np.array(agg[f"{key}_mean"], dtype=np.float64)
        std = np.array(agg[f"{key}_std"], dtype=np.float64)
        for r, name in enumerate(XI_NAMES):
            if pct:
                a = "".join(f"{100 * m:6.1f} +/-{100 * s:4.1f}" for m, s in zip(mean[r], std[r], strict=True))
                b = "".join(f"{percent(v):>8s}" for v in theirs[r])
            else:
                a = "".join(f"{m:6.1f} +/-{s:4.1f}" for m, s in zip(mean[r], std[r], strict=True))
                b = "".join(f"{int(v):8d}" for v in theirs[r])
            lines.append(f"{name:>14s}{a}   |{b}")
    lines += [
        "",
        f"accuracy           {100 * agg['accuracy']:5.1f} +/- {100 * agg['accuracy_std']:4.1f}%   "
        f"(paper {100 * paper.accuracy:5.1f}%)",
        f"balanced accuracy  {100 * agg['balanced_accuracy']:5.1f} +/- {100 * agg['balanced_accuracy_std']:4.1f}%   "
        f"(paper {100 * paper.balanced_accuracy:5.1f}%)",
        f"log loss {agg['log_loss']:.3f} +/- {agg['log_loss_std']:.3f}, Brier {agg['brier']:.3f} +/- "
        f"{agg['brier_std']:.3f}, ECE {agg['ece']:.3f} +/- {agg['ece_std']:.3f}, "
        f"latency {agg['mean_latency_s']:.2f} s",
    ]
    return "\n".join(lines)
