"""The observation normaliser a learned agent was trained behind, frozen for evaluation.

One class for both frameworks: SB3's ``VecNormalize`` divides by ``sqrt(var + epsilon)``,
RLlib's ``MeanStdFilter`` by ``std + 1e-6`` (its ``SMALL_NUMBER``); both subtract the running mean and clip. The
divisor is computed once from the saved statistics (:meth:`ObsNormalizer.from_vec_normalize`,
:meth:`ObsNormalizer.from_mean_std`) and the arithmetic is the same float64 sequence the
training wrapper ran, so an evaluated agent sees exactly the observations it trained on.
Neither library is imported here: the statistics are read from the objects.

:func:`update_and_normalize` is the training side: ``VecNormalize``'s running-statistics update
and normalisation of one batch in one compiled call, with the same numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from estimator.compiled import guard_kernel_cache

__all__ = ["ObsNormalizer", "update_and_normalize"]


@dataclass(frozen=True)
class ObsNormalizer:
    """``clip((obs - mean) / scale, -clip, clip)``, as float32.

    Attributes:
        mean: Running mean of each observation feature, shape ``(n_features,)``.
        scale: What each centred feature is divided by (same shape).
        clip: Bound of the normalised values (``inf``: no clipping).

    Example:
        >>> norm = ObsNormalizer.from_mean_std(np.zeros(2), np.array([1.0, 2.0]), clip=1.5, epsilon=0.0)
        >>> norm(np.array([1.0, 4.0])).tolist()
        [1.0, 1.5]
    """

    mean: NDArray[np.float64]
    scale: NDArray[np.float64]
    clip: float = math.inf

    @classmethod
    def from_vec_normalize(cls, vec_normalize: Any) -> ObsNormalizer | None:
        """SB3 ``VecNormalize``'s statistics (None when it does not normalise observations)."""
        if vec_normalize is None or not vec_normalize.norm_obs:
            return None
        rms: Any = vec_normalize.obs_rms  # a RunningMeanStd for Box observations
        scale = np.sqrt(np.asarray(rms.var, dtype=np.float64) + float(vec_normalize.epsilon))
        return cls(np.array(rms.mean, dtype=np.float64), scale, float(vec_normalize.clip_obs))

    @classmethod
    def from_mean_std(
        cls, mean: NDArray[Any], std: NDArray[Any], clip: float | None = None, epsilon: float = 1e-6
    ) -> ObsNormalizer:
        """A running mean and standard deviation, divided by ``std + epsilon`` (RLlib's ``MeanStdFilter``)."""
        scale = np.asarray(std, dtype=np.float64) + epsilon
        return cls(np.asarray(mean, dtype=np.float64), scale, float(clip) if clip else math.inf)

    def __call__(self, observation: NDArray[Any]) -> NDArray[np.float32]:
        """Normalise one observation or a batch (no update of the statistics)."""
        scaled = (np.asarray(observation, dtype=np.float64) - self.mean) / self.scale
        return np.clip(scaled, -self.clip, self.clip).astype(np.float32)


@njit(cache=True, error_model="numpy")
def _update_and_normalize(
    obs: NDArray[np.float32],
    mean: NDArray[np.float64],
    var: NDArray[np.float64],
    count: float,
    epsilon: float,
    clip: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], float, NDArray[np.float32]]:
    n, width = obs.shape
    # np.mean and np.var over axis 0 of a float32 batch: float32 sums from the first row, row after row.
    batch_mean = obs[0].copy()
    for i in range(1, n):
        for j in range(width):
            batch_mean[j] += obs[i, j]
    batch_var = np.empty(width, dtype=np.float32)
    for j in range(width):
        batch_mean[j] = batch_mean[j] / np.float32(n)
        centred = obs[0, j] - batch_mean[j]
        batch_var[j] = centred * centred
    for i in range(1, n):
        for j in range(width):
            centred = obs[i, j] - batch_mean[j]
            batch_var[j] += centred * centred
    new_mean = np.empty(width)
    new_var = np.empty(width)
    total = count + n
    for j in range(width):
        batch_var[j] = batch_var[j] / np.float32(n)
        # RunningMeanStd.update_from_moments, term by term (m_b is float32 * int: float32).
        delta = np.float64(batch_mean[j]) - mean[j]
        new_mean[j] = mean[j] + delta * n / total
        m_a = var[j] * count
        m_b = np.float32(batch_var[j] * np.float32(n))
        m_2 = m_a + np.float64(m_b) + delta * delta * count * n / (count + n)
        new_var[j] = m_2 / (count + n)
    normalized = np.empty((n, width), dtype=np.float32)
    for j in range(width):
        scale = np.sqrt(new_var[j] + epsilon)
        for i in range(n):
            value = (np.float64(obs[i, j]) - new_mean[j]) / scale
            normalized[i, j] = np.float32(min(max(value, -clip), clip))
    return new_mean, new_var, n + count, normalized


def update_and_normalize(vec_normalize: Any, obs: NDArray[np.float32]) -> NDArray[np.float32]:
    """``VecNormalize``'s training step on a batch of observations: update ``obs_rms``, return it normalised.

    The numbers of ``obs_rms.update(obs)`` then ``normalize_obs(obs)`` (float32 batch moments,
    float64 running moments, ``clip((obs - mean) / sqrt(var + epsilon))`` as float32) in one
    compiled call; ``tests/agents/test_sb3_vec.py`` holds them equal bit for bit.
    """
    rms = vec_normalize.obs_rms
    if obs.ndim != 2 or obs.shape[1] < 2 or obs.dtype != np.float32 or not obs.flags.c_contiguous:
        # NumPy sums a contiguous column pairwise (one feature, a column-major batch) and promotes
        # another dtype otherwise: those batches take NumPy's own steps.
        rms.update(obs)
        return vec_normalize.normalize_obs(obs)  # type: ignore[no-any-return]
    rms.mean, rms.var, rms.count, normalized = _update_and_normalize(
        obs, rms.mean, rms.var, float(rms.count), float(vec_normalize.epsilon), float(vec_normalize.clip_obs)
    )
    return normalized  # type: ignore[no-any-return]


guard_kernel_cache(__name__)
