"""The observation normaliser a learned agent was trained behind, frozen for evaluation.

One class for both frameworks: SB3's ``VecNormalize`` divides by ``sqrt(var + epsilon)``,
RLlib's ``MeanStdFilter`` by ``std + 1e-6`` (its ``SMALL_NUMBER``); both subtract the running mean and clip. The
divisor is computed once from the saved statistics (:meth:`ObsNormalizer.from_vec_normalize`,
:meth:`ObsNormalizer.from_mean_std`) and the arithmetic is the same float64 sequence the
training wrapper ran, so an evaluated agent sees exactly the observations it trained on.
Neither library is imported here: the statistics are read from the objects.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["ObsNormalizer"]


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
