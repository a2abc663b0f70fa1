"""The observation normaliser a learned agent was trained behind, frozen for evaluation.

One class for both frameworks: SB3's ``VecNormalize`` divides by ``sqrt(var + epsilon)``,
RLlib's ``MeanStdFilter`` by ``std + 1e-6`` (its ``SMALL_NUMBER``); both subtract the running mean and clip. The
divisor is computed once from the saved statistics (:meth:`ObsNormalizer.from_vec_normalize`,
:meth:`ObsNormalizer.from_mean_std`) and the arithmetic is the same float64 sequence the
training wrapper ran, so an evaluated agent sees exactly the observations it trained on.
Neither library is imported here: the statistics are read from the objects.

:func:`update_and_normalize` is the training side: ``VecNormalize``'s running-statistics update
and normalisation of one batch in one compiled call, with the same numbers; :func:`update_returns`
its discounted returns' statistics.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from estimator.compiled import guard_kernel_cache

__all__ = ["PAIRWISE_BLOCK", "ObsNormalizer", "numpy_sum", "update_and_normalize", "update_returns"]


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


PAIRWISE_BLOCK = 128
"""NumPy sums up to this many values in one block (``PW_BLOCKSIZE``); more, it splits them in two."""


@njit(cache=True, error_model="numpy")
def numpy_sum(values: NDArray[Any], zero: Any) -> Any:
    """NumPy's sum of a contiguous vector of at most :data:`PAIRWISE_BLOCK` values, in its order and dtype.

    ``zero`` is 0 of the values' dtype (the sum stays in it). 0 plus ``pairwise_sum`` (NumPy's
    ``loops_utils``): under 8 values one by one, else eight running sums over the whole groups
    of eight, added as a tree, then the rest one by one.
    """
    n = values.shape[0]
    if n < 8:
        total = zero
        for i in range(n):
            total += values[i]
        return zero + total
    running = values[:8].copy()
    i = 8
    while i < n - n % 8:
        for j in range(8):
            running[j] += values[i + j]
        i += 8
    total = ((running[0] + running[1]) + (running[2] + running[3])) + (
        (running[4] + running[5]) + (running[6] + running[7])
    )
    while i < n:
        total += values[i]
        i += 1
    return zero + total


@njit(cache=True, error_model="numpy")
def _update_returns(
    returns: NDArray[np.float64], rewards: NDArray[Any], gamma: float, mean: float, var: float, count: float
) -> tuple[NDArray[np.float64], float, float, float]:
    n = returns.shape[0]
    new_returns = np.empty(n)
    for i in range(n):
        new_returns[i] = returns[i] * gamma + np.float64(rewards[i])
    # np.mean and np.var of a contiguous float64 vector: its sum divided by n.
    batch_mean = numpy_sum(new_returns, 0.0) / n
    squares = np.empty(n)
    for i in range(n):
        squares[i] = (new_returns[i] - batch_mean) * (new_returns[i] - batch_mean)
    batch_var = numpy_sum(squares, 0.0) / n
    # RunningMeanStd.update_from_moments, term by term.
    delta = batch_mean - mean
    total = count + n
    new_mean = mean + delta * n / total
    m_2 = var * count + batch_var * n + delta * delta * count * n / (count + n)
    return new_returns, new_mean, m_2 / (count + n), n + count


def update_returns(vec_normalize: Any, rewards: NDArray[Any]) -> None:
    """``VecNormalize._update_reward``: the discounted returns and their running statistics, in one compiled call.

    ``returns = returns * gamma + rewards``, then ``ret_rms.update(returns)`` with the same numbers
    (``tests/agents/test_sb3_vec.py``); SB3 keeps them even when rewards are not normalised.
    """
    rms, returns = vec_normalize.ret_rms, vec_normalize.returns
    if (
        np.shape(rms.mean) != ()
        or not isinstance(returns, np.ndarray)
        or returns.ndim != 1
        or not 0 < returns.shape[0] <= PAIRWISE_BLOCK
        or returns.dtype != np.float64
        or np.shape(rewards) != returns.shape
        or np.asarray(rewards).dtype not in (np.float32, np.float64)
    ):
        vec_normalize._update_reward(rewards)
        return
    vec_normalize.returns, mean, var, count = _update_returns(
        returns, np.asarray(rewards), float(vec_normalize.gamma), float(rms.mean), float(rms.var), float(rms.count)
    )
    rms.mean, rms.var, rms.count = np.float64(mean), np.float64(var), count


guard_kernel_cache(__name__)
