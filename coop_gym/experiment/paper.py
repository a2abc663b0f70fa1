"""The paper's numbers (§V-C) and the scores its tables are made of.

Every confusion table is ordered by :data:`XI_VALUES` (rows requested, columns judged).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

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
