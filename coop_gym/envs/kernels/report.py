"""The report row the step kernel writes for each env, and the one rule that ends an episode."""

from __future__ import annotations

from enum import IntEnum

import numpy as np
from numba import njit
from numpy.typing import NDArray

from coop_gym.envs.actions import CMD
from coop_gym.envs.config import (
    Outcome,
)
from coop_gym.envs.observation import FEATURES
from estimator.compiled.cache import guard_kernel_cache
from estimator.compiled.schema import index_table

__all__ = [
    "REPORT",
    "REPORT_COLUMNS",
    "REWARD_TERMS",
    "TERMINATES",
    "TRUNCATES",
    "check_outcome_codes",
    "count_steps_and_end_episodes",
    "episode_end",
]


# --- the report row: everything an observation and an info need ------------------

REWARD_TERMS: tuple[str, ...] = ("success", "unsafe", "premature", "time", "force")
"""Names of the reward terms (``info["reward_terms"]``), in report-column order."""

REPORT_COLUMNS: tuple[str, ...] = (
    *FEATURES,
    *(f"reward_{name}" for name in REWARD_TERMS),
    "reward",
    "outcome",
    "push_force_n",
    "true_x_m",
    "true_xdot_m_per_s",
    "true_eta_m",
    "info_true_xi",  # the info's true xi; the oracle's feature "true_xi" is its own column
    "persona_index",
)
"""Columns of ``SitToStandCore.report``: one float row per env with everything ``info`` needs.

Kept in one row so an env reads it with a single ``tolist()``.
"""
REPORT = index_table("ReportColumns", REPORT_COLUMNS)
"""Column of each quantity in a report row: ``report[REPORT.x_hat_m]``, ``report[REPORT.outcome]``."""

# --- episode end ------------------------------------------------------------------


def check_outcome_codes(outcome: type[IntEnum]) -> None:
    """Raise ``ValueError`` unless the enum's values are ``0 .. n-1`` in order.

    The kernel writes outcome codes into a float report column and the envs index tables
    (labels, episode end) with them, so they must be small consecutive integers. An
    explicit check, not an ``assert``: it must hold under ``python -O`` too.
    """
    codes = [int(member) for member in outcome]
    if codes != list(range(len(codes))):
        raise ValueError(f"{outcome.__name__} values must be 0 .. {len(codes) - 1} in order, got {codes}")


check_outcome_codes(Outcome)

TERMINATES = np.array([o.terminates for o in Outcome])
"""Indexed by outcome code: does the episode terminate (the robot lifted)?"""
TRUNCATES = np.array([o.truncates for o in Outcome])
"""Indexed by outcome code: was the episode truncated at its length (``"timeout"``)?"""
_LIFTS: tuple[bool, ...] = tuple(o.terminates for o in Outcome)  # what the compiled rule indexes
_TIMEOUT = int(Outcome.TIMEOUT)


def episode_end(outcome: int, episode_steps: int, length: int, limit: int) -> tuple[int, bool, bool]:
    """``(outcome, terminated, truncated)`` of a step: the one rule that ends an episode, in either env.

    The step kernel judges a lift (its outcome code terminates the episode) and never ends one
    otherwise: the episode's length is counted here, in steps. A step that reaches ``length``
    without a lift times out (the outcome becomes ``TIMEOUT``, ``"timeout"`` in the info); the
    step that reaches ``length`` or ``limit`` truncates the episode -- also when it terminated it:
    a lift on the last allowed step is ``terminated`` and ``truncated``, exactly as Gymnasium's
    ``TimeLimit`` reports it. A ``limit`` under ``length`` truncates as a ``TimeLimit`` would, with
    the step's own outcome.

    Args:
        outcome: The step kernel's outcome code (:class:`~coop_gym.envs.config.Outcome`).
        episode_steps: Steps of the episode, this one included.
        length: Steps of a full episode (``Timing.max_episode_steps``).
        limit: A step limit from outside (the vector env's ``max_episode_steps``; ``length`` for
            the single env, whose ``TimeLimit`` is Gymnasium's wrapper).
    """
    terminated = _LIFTS[outcome]
    if not terminated and episode_steps >= length:
        outcome = _TIMEOUT
    return outcome, terminated, episode_steps >= min(length, limit)


# The same rule inside the vector env's compiled pass (the single env calls the Python function).
_episode_end_kernel = njit(cache=True, error_model="numpy", inline="always")(episode_end)


@njit(cache=True, error_model="numpy")
def count_steps_and_end_episodes(
    report: NDArray[np.float64],
    cmd: NDArray[np.float64],
    episode_steps: NDArray[np.int64],
    length: int,
    limit: int,
    rewards: NDArray[np.float64],
    terminated: NDArray[np.bool_],
    truncated: NDArray[np.bool_],
) -> None:
    """The episode end of a batch of envs after a step, with the step count, in one pass.

    Each env stepped (``cmd`` active) counts a step in ``episode_steps``; ``rewards`` gets the
    report's reward of stepped envs, 0 elsewhere. A stepped env ends by :func:`episode_end`, whose
    outcome (``TIMEOUT`` at the episode's length) goes back into the report; envs not stepped
    neither terminate nor truncate.
    """
    for i in range(report.shape[0]):
        if cmd[i, CMD.active] > 0.5:
            episode_steps[i] += 1
            rewards[i] = report[i, REPORT.reward]
            code, terminated[i], truncated[i] = _episode_end_kernel(
                int(report[i, REPORT.outcome]), episode_steps[i], length, limit
            )
            report[i, REPORT.outcome] = code
        else:
            rewards[i] = 0.0
            terminated[i] = False
            truncated[i] = False


guard_kernel_cache(__name__)
