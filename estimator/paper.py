"""The paper's numbers (§V-C), the scores its tables are made of, and the tables as text.

Every confusion table is ordered by :data:`XI_VALUES` (rows requested, columns judged). The
simulated protocol (:mod:`coop_gym.experiment.tables`) and the offline estimator of recordings
(:mod:`estimator.estimate`) both score and print through :func:`judgment_scores` and
:func:`format_tables`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimator import metrics

__all__ = [
    "PAPER_RESULTS",
    "XI_NAMES",
    "XI_SHORT",
    "XI_VALUES",
    "PaperResults",
    "accuracy",
    "balanced_accuracy",
    "conditional_tables",
    "confusion_matrix",
    "format_tables",
    "judgment_scores",
    "nan_to_none",
    "percent",
]

XI_VALUES: tuple[int, int, int] = (-1, 0, 1)
"""Row/column order of every confusion table: uncooperative, unresponsive, cooperative."""

XI_NAMES: tuple[str, str, str] = ("uncooperative", "unresponsive", "cooperative")
XI_SHORT: tuple[str, str, str] = ("uncoop.", "unresp.", "coop.")
"""Column labels for narrow tables and plot ticks."""


def confusion_matrix(requested: ArrayLike, judged: ArrayLike) -> NDArray[np.int64]:
    """(3, 3) counts, rows = requested ``xi`` -1, 0, +1, columns = judged -1, 0, +1.

    Example:
        >>> confusion_matrix([-1, 0, 1, 1], [0, 0, 1, 1]).tolist()
        [[0, 1, 0], [0, 1, 0], [0, 0, 2]]
    """
    req = np.asarray(requested).ravel()
    jud = np.asarray(judged).ravel()
    if req.shape != jud.shape:
        raise ValueError(f"requested and judged must have the same size, got {req.shape} and {jud.shape}")
    if not (np.isin(req, XI_VALUES).all() and np.isin(jud, XI_VALUES).all()):
        raise ValueError("xi values must be -1, 0 or 1")
    out = np.zeros((3, 3), dtype=np.int64)
    np.add.at(out, (req.astype(np.int64) + 1, jud.astype(np.int64) + 1), 1)
    return out


def accuracy(confusion: ArrayLike) -> float:
    """Fraction of trials on the diagonal."""
    c = np.asarray(confusion, dtype=np.float64)
    return float(np.trace(c) / c.sum())


def balanced_accuracy(confusion: ArrayLike) -> float:
    """Mean correct rate ``P(judged = k | requested = k)`` over the requested classes present."""
    c = np.asarray(confusion, dtype=np.float64)
    rows = c.sum(axis=1)
    present = rows > 0
    return float(np.mean(np.diag(c)[present] / rows[present]))


def conditional_tables(confusion: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The paper's Tables II and III: ``P(judged | requested)`` (rows sum to 1), ``P(requested | judged)`` (columns).

    Empty rows or columns give NaN.
    """
    c = np.asarray(confusion, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return c / c.sum(axis=1, keepdims=True), c / c.sum(axis=0, keepdims=True)


@dataclass(frozen=True)
class PaperResults:
    """The paper's Table I on real people (N = 100), reconstructed from its text (§V-C).

    The text gives the requested counts (44 cooperative, 24 unresponsive, 32
    uncooperative), the correct rates (52.3 %, 79.2 %, 34.4 %), the precisions of
    "cooperative" (23/25) and "uncooperative" (11/16), that uncooperative trials were
    most often judged unresponsive, and that an "unresponsive" judgment came about
    equally often from each requested state. That fixes every cell but one degree of
    freedom ``a`` = #(requested 0, judged +1) = #(requested +1, judged -1) in {0, 1, 2};
    we take ``a = 1``, which makes the "unresponsive" column 20 / 19 / 20.

    Attributes:
        confusion: Counts, rows = requested ``xi`` -1, 0, +1, columns = judged -1, 0, +1.
    """

    confusion: tuple[tuple[int, int, int], ...] = ((11, 20, 1), (4, 19, 1), (1, 20, 23))

    @property
    def matrix(self) -> NDArray[np.int64]:
        """(3, 3) counts as an array."""
        return np.array(self.confusion, dtype=np.int64)

    @property
    def accuracy(self) -> float:
        """Fraction judged correctly (0.53)."""
        return accuracy(self.matrix)

    @property
    def balanced_accuracy(self) -> float:
        """Mean of the three correct rates (0.553)."""
        return balanced_accuracy(self.matrix)


PAPER_RESULTS = PaperResults()
"""The one place the paper's numbers live."""


# --------------------------------------------------------------------------- scores and tables


def judgment_scores(
    requested: ArrayLike, judged: ArrayLike, probabilities: ArrayLike, latency_s: ArrayLike
) -> dict[str, Any]:
    """The paper's three tables and the calibration scores of a set of judged trials (JSON-ready).

    Args:
        requested: (K,) requested ``xi`` of each trial.
        judged: (K,) judged ``xi``.
        probabilities: (K, 3) ``P(xi = -1, 0, +1)`` at each judgment (normalised here).
        latency_s: (K,) time from the initial cue onset to each judgment [s].

    Returns:
        ``confusion`` (rows requested -1, 0, 1; columns judged -1, 0, 1),
        ``p_estimated_given_requested``, ``p_requested_given_estimated``, ``accuracy``,
        ``balanced_accuracy``, ``log_loss``, ``brier``, ``ece`` and ``mean_latency_s``.
    """
    labels = np.asarray(requested).ravel()
    conf = confusion_matrix(labels, judged)
    # Calibration scores from estimator.metrics (10 top-label bins on [1/3, 1] for the ECE).
    probs = np.asarray(probabilities, dtype=np.float64).reshape(-1, 3)
    probs = probs / probs.sum(axis=1, keepdims=True)
    given_req, given_est = conditional_tables(conf)
    return {
        "confusion": conf.tolist(),
        "p_estimated_given_requested": nan_to_none(given_req),
        "p_requested_given_estimated": nan_to_none(given_est),
        "accuracy": accuracy(conf),
        "balanced_accuracy": balanced_accuracy(conf),
        "log_loss": metrics.log_loss(probs, labels),
        "brier": metrics.brier_score(probs, labels),
        "ece": metrics.expected_calibration_error(probs, labels),
        "mean_latency_s": float(np.mean(np.asarray(latency_s, dtype=np.float64))),
    }


def nan_to_none(a: NDArray[np.float64]) -> list[list[float | None]]:
    """A table as nested lists with NaN (an empty row or column) as ``None``, for JSON."""
    return [[None if not math.isfinite(v) else float(v) for v in row] for row in a]


def percent(v: float | None) -> str:
    """A rate as a 6-character percentage; ``None`` or NaN (an empty row or column) as a dash."""
    return "   -  " if v is None or not math.isfinite(v) else f"{100 * v:5.1f}%"


def format_tables(
    summary: dict[str, Any], title: str, ours: str = "simulated", paper: PaperResults = PAPER_RESULTS
) -> str:
    """The paper's three tables of :func:`judgment_scores`'s ``summary``, each beside the paper's on real people.

    Args:
        summary: Holds at least the keys :func:`judgment_scores` returns.
        title: The first line (what was judged, by which estimator).
        ours: What the left-hand tables hold (``"simulated"``, ``"recorded"``).
        paper: The numbers to print beside.
    """
    conf = np.array(summary["confusion"])
    tables = [conf, *conditional_tables(conf)]
    theirs = [paper.matrix, *conditional_tables(paper.matrix)]
    titles = (
        "Table I   joint counts (rows: requested, columns: estimated)",
        "Table II  P(estimated | requested)",
        "Table III P(requested | estimated)",
    )
    head = "".join(f"{n:>8s}" for n in XI_SHORT)
    lines = [title]
    for k, table_title in enumerate(titles):
        lines += ["", f"{table_title}   [{ours} | paper]", f"{'requested':>14s}{head}   |{head}"]
        for r, name in enumerate(XI_NAMES):
            if k == 0:
                a = "".join(f"{int(v):8d}" for v in tables[0][r])
                b = "".join(f"{int(v):8d}" for v in theirs[0][r])
            else:
                a = "".join(f"{percent(v):>8s}" for v in tables[k][r])
                b = "".join(f"{percent(v):>8s}" for v in theirs[k][r])
            lines.append(f"{name:>14s}{a}   |{b}")
    lines += [
        "",
        f"accuracy           {100 * summary['accuracy']:5.1f}%   (paper {100 * paper.accuracy:5.1f}%)",
        f"balanced accuracy  {100 * summary['balanced_accuracy']:5.1f}%   "
        f"(paper {100 * paper.balanced_accuracy:5.1f}%)",
        f"log loss {summary['log_loss']:.3f} nats, Brier {summary['brier']:.3f}, ECE {summary['ece']:.3f}, "
        f"judgment {summary['mean_latency_s']:.2f} s after the initial cue onset",
    ]
    return "\n".join(lines)
