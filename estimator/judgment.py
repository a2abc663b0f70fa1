"""The paper's thresholded judgment of cooperativeness (§IV-A).

At a fixed delay after the initial onset of a cue the filter's ``xi`` estimate is
sampled and compared with a threshold: ``xi_hat >= +t`` judges cooperative (+1),
``xi_hat <= -t`` uncooperative (-1), anything between unresponsive (0). The paper used
a delay of 0.75 s and ``t = 0.3``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray
from scipy.special import ndtr

from estimator.compiled.cache import guard_kernel_cache
from estimator.compiled.schema import index_table
from estimator.validate import is_number, python_scalar

__all__ = [
    "JUDGE",
    "JUDGMENT_COLUMNS",
    "ThresholdJudgment",
    "first_judgment_step",
    "gaussian_xi_probabilities",
    "judgment_substep",
    "threshold_judgment",
]


@dataclass(frozen=True)
class ThresholdJudgment:
    """Settings of the thresholded judgment.

    Attributes:
        delay_s: Time after a cue's initial onset at which ``xi_hat`` is sampled [s].
        threshold: Half-width of the "unresponsive" band around 0.
    """

    delay_s: float = 0.75
    threshold: float = 0.3

    def __post_init__(self) -> None:
        """Validate ranges."""
        if not (is_number(self.delay_s) and math.isfinite(self.delay_s) and 0.0 <= self.delay_s <= 30.0):
            raise ValueError(f"ThresholdJudgment.delay_s must be in [0, 30] s, got {self.delay_s!r}")
        if not (is_number(self.threshold) and math.isfinite(self.threshold) and self.threshold > 0.0):
            raise ValueError(f"ThresholdJudgment.threshold must be > 0, got {self.threshold!r}")
        # A NumPy scalar is kept as the Python number of the same value (frozen: object.__setattr__).
        object.__setattr__(self, "delay_s", python_scalar(self.delay_s))
        object.__setattr__(self, "threshold", python_scalar(self.threshold))

    def judge(self, xi_estimate: NDArray[np.float64] | float) -> NDArray[np.int64]:
        """Threshold one or many ``xi`` estimates into {-1, 0, +1}."""
        return threshold_judgment(np.asarray(xi_estimate, dtype=np.float64), self.threshold)


def threshold_judgment(xi_estimate: NDArray[np.float64], threshold: float) -> NDArray[np.int64]:
    """``+1`` where ``xi_hat >= t``, ``-1`` where ``xi_hat <= -t``, else ``0``."""
    est = np.asarray(xi_estimate, dtype=np.float64)
    return np.where(est >= threshold, 1, np.where(est <= -threshold, -1, 0)).astype(np.int64)


JUDGMENT_COLUMNS = ("since_onset_s", "pending", "judgment", "cue_was_active")
"""Layout of a judgment-tracker row (one per env)."""
JUDGE = index_table("JudgmentColumns", JUDGMENT_COLUMNS)


@njit(cache=True, error_model="numpy")
def judgment_substep(
    row: NDArray[np.float64], cue_active: bool, xi_estimate: float, delay_s: float, threshold: float, dt_s: float
) -> bool:
    """Advance a judgment tracker by one filter step, in place; True when a judgment is made.

    A cue's *initial onset* is a step with a cue active after a step with none. The
    window then runs ``delay_s``; at its end the current estimate is thresholded.
    """
    if cue_active and row[JUDGE.cue_was_active] < 0.5:
        row[JUDGE.since_onset_s] = 0.0
        row[JUDGE.pending] = 1.0
    else:
        row[JUDGE.since_onset_s] += dt_s
    row[JUDGE.cue_was_active] = 1.0 if cue_active else 0.0
    # Compare with half a step of slack so a 0.75 s delay at 50 Hz lands on step 37/38
    # deterministically despite floating-point sums.
    if row[JUDGE.pending] > 0.5 and row[JUDGE.since_onset_s] >= delay_s - 0.5 * dt_s:
        row[JUDGE.pending] = 0.0
        if xi_estimate >= threshold:
            row[JUDGE.judgment] = 1.0
        elif xi_estimate <= -threshold:
            row[JUDGE.judgment] = -1.0
        else:
            row[JUDGE.judgment] = 0.0
        return True
    return False


def first_judgment_step(cue_active: NDArray[np.bool_], judgment: ThresholdJudgment, dt_s: float) -> int:
    """Index of the step at which the judgment tracker judges a trial's initial cue onset.

    Runs :func:`judgment_substep` over ``cue_active`` (one flag per filter step), so the
    protocol, the environments and the offline estimator of recordings sample ``xi_hat`` on
    exactly the same step.

    Example:
        >>> first_judgment_step(np.arange(100) >= 10, ThresholdJudgment(), 0.02)
        47
    """
    row = np.zeros(len(JUDGMENT_COLUMNS))
    # Long since any onset: the first active step is an onset even at index 0.
    row[JUDGE.since_onset_s] = 1e9
    for t, active in enumerate(np.asarray(cue_active, dtype=bool)):
        if judgment_substep(row, bool(active), 0.0, judgment.delay_s, judgment.threshold, dt_s):
            return t
    raise ValueError("no judgment inside the trial: no cue, or the judgment delay exceeds the trial")


def gaussian_xi_probabilities(mean: ArrayLike, std: ArrayLike) -> NDArray[np.float64]:
    """Map the KF's Gaussian ``xi`` marginal ``N(mean, std^2)`` to probabilities over {-1, 0, +1}.

    ``P(xi = k)`` is the Gaussian mass of ``k``'s cell ``(-inf, -0.5]``, ``(-0.5, 0.5)``,
    ``[0.5, inf)``: the probability that ``k`` is the nearest value. The KF has no
    probabilities of its own; this is the documented mapping behind its log loss, Brier
    score and ECE.

    Example:
        >>> gaussian_xi_probabilities(0.0, 1e-9).round(3).tolist()
        [0.0, 1.0, 0.0]
    """
    m = np.asarray(mean, dtype=np.float64)
    sd = np.maximum(np.asarray(std, dtype=np.float64), 1e-12)
    lo = ndtr((-0.5 - m) / sd)
    hi = ndtr((0.5 - m) / sd)
    return np.stack([lo, hi - lo, 1.0 - hi], axis=-1)


guard_kernel_cache(__name__)
