"""Observations scaled by their running statistics, as SB3's ``VecNormalize`` scales them."""

from __future__ import annotations

import numpy as np

__all__ = ["ObsNormalizer"]


class ObsNormalizer:
    """Observations scaled by their running mean and standard deviation, clipped (SB3's ``VecNormalize``).

    The statistics start at mean 0 and variance 1 with a weight of 1e-4 observations and
    take every observation the envs return, as sums of ``x`` and ``x**2`` in float64.
    """

    def __init__(self, shape: tuple[int, ...], clip: float = 10.0, epsilon: float = 1e-8) -> None:
        """Mean 0, variance 1, a count of 1e-4."""
        self.count, self.sum, self.sum_sq = 1e-4, np.zeros(shape), np.full(shape, 1e-4)
        self.clip, self.epsilon = clip, epsilon
        self.mean, self.var = np.zeros(shape), np.ones(shape)
        self._scale = 1.0 / np.sqrt(self.var + epsilon)

    def restore(self, count: float, mean: np.ndarray, var: np.ndarray) -> None:
        """Take the statistics of ``count`` observations of mean ``mean`` and variance ``var``."""
        self.count = float(count)
        self.sum = np.asarray(mean, np.float64) * self.count
        self.sum_sq = (np.asarray(var, np.float64) + np.square(mean)) * self.count
        self.update(np.zeros((0, *self.sum.shape)))

    def update(self, batch: np.ndarray) -> None:
        """Fold a batch of observations (one per row) into the statistics."""
        self.count += batch.shape[0]
        self.sum += batch.sum(axis=0, dtype=np.float64)
        self.sum_sq += np.square(batch, dtype=np.float64).sum(axis=0)
        self.mean = self.sum / self.count
        self.var = np.maximum(self.sum_sq / self.count - self.mean * self.mean, 0.0)
        self._scale = (self.var + self.epsilon) ** -0.5

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """``obs`` scaled and clipped."""
        scaled = (obs - self.mean) * self._scale
        return np.clip(scaled, -self.clip, self.clip, out=scaled).astype(np.float32)
