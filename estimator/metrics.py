"""Scores for 3-class probability estimates of cooperativeness (``xi = -1, 0, +1``).

Accuracy alone hides over- and under-confidence; these report calibration beside it:

* log loss ``-mean log p(true)`` (strictly proper; uniform guessing scores ``log 3``),
* Brier score ``mean sum_k (p_k - [k = true])^2`` (uniform guessing scores ``2/3``),
* expected calibration error of the top-label confidence (Guo et al. 2017).

Probabilities are ``(M, 3)`` arrays ordered like :data:`estimator.multiple_model.MODE_VALUES`;
labels are ``(M,)`` integers in {-1, 0, +1}.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["accuracy", "brier_score", "expected_calibration_error", "log_loss"]

_N_CLASSES = 3


def _check(probs: ArrayLike, labels: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    p = np.asarray(probs, dtype=np.float64)
    y = np.asarray(labels)
    if p.ndim != 2 or p.shape[1] != _N_CLASSES:
        raise ValueError(f"probs must have shape (M, 3), got {p.shape}")
    if y.shape != (p.shape[0],):
        raise ValueError(f"labels must have shape ({p.shape[0]},), got {y.shape}")
    if p.shape[0] == 0:
        raise ValueError("need at least one sample")
    if not np.all(np.isin(y, (-1, 0, 1))):
        raise ValueError("labels must be in {-1, 0, +1}")
    if not np.all(np.isfinite(p)) or np.any(p < 0) or not np.allclose(p.sum(axis=1), 1.0, atol=1e-6):
        raise ValueError("probs must be finite, non-negative rows summing to 1")
    return p, (y.astype(np.int64) + 1)


def log_loss(probs: ArrayLike, labels: ArrayLike, *, min_probability: float = 1e-15) -> float:
    """Mean negative log-probability of the true class [nats].

    Args:
        probs: (M, 3) probabilities.
        labels: (M,) true ``xi``.
        min_probability: Probabilities are clipped from below to this, so a single
            confident mistake costs ``-log(min_probability)`` instead of infinity.
    """
    p, k = _check(probs, labels)
    return float(-np.mean(np.log(np.clip(p[np.arange(k.shape[0]), k], min_probability, 1.0))))


def brier_score(probs: ArrayLike, labels: ArrayLike) -> float:
    """Mean squared distance between the probabilities and the one-hot truth (0 best, 2 worst)."""
    p, k = _check(probs, labels)
    onehot = np.eye(_N_CLASSES)[k]
    return float(np.mean(np.sum((p - onehot) ** 2, axis=1)))


def accuracy(probs: ArrayLike, labels: ArrayLike) -> float:
    """Fraction of samples whose most probable class is the true one (ties to the first)."""
    p, k = _check(probs, labels)
    return float(np.mean(np.argmax(p, axis=1) == k))


def expected_calibration_error(probs: ArrayLike, labels: ArrayLike, n_bins: int = 10) -> float:
    """Top-label expected calibration error: ``sum_b (n_b / M) |accuracy_b - confidence_b|``.

    Samples are binned by their top probability into ``n_bins`` equal-width bins on [1/3, 1]
    (a top probability of three classes is never below 1/3).
    """
    if n_bins < 1:
        raise ValueError(f"n_bins must be >= 1, got {n_bins!r}")
    p, k = _check(probs, labels)
    confidence = p.max(axis=1)
    correct = np.argmax(p, axis=1) == k
    edges = np.linspace(1.0 / _N_CLASSES, 1.0, n_bins + 1)
    bins = np.clip(np.searchsorted(edges, confidence, side="right") - 1, 0, n_bins - 1)
    ece = 0.0
    for b in range(n_bins):
        in_bin = bins == b
        if np.any(in_bin):
            ece += in_bin.mean() * abs(correct[in_bin].mean() - confidence[in_bin].mean())
    return float(ece)
