r"""One env step, compiled: :func:`step_env` takes one agent action from command row to reward and observation.

The maths it sequences lives elsewhere -- the person in :mod:`coop_gym.model.dynamics`, the
filter in :mod:`estimator.kalman`, the judgment in :mod:`estimator.judgment`; the layout of the
rows it reads in :mod:`coop_gym.envs.kernels.layout`. :func:`step_envs` runs it over a range of envs;
the core calls that on one thread or, through :mod:`coop_gym.envs.kernels.threads`, on several.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from coop_gym.envs.actions import CMD
from coop_gym.envs.config import Outcome
from coop_gym.envs.kernels.layout import BLOCKS, CONSTS, CUE_COLUMNS, CUES
from coop_gym.envs.kernels.report import REPORT, REPORT_COLUMNS
from coop_gym.model.dynamics import (
    DELAY_LINE_LENGTH,
    NORMALS_PER_SUBSTEP,
    PARAM_COLUMNS,
    PERSON,
    STATE,
    STATE_COLUMNS,
    measure,
    person_substep,
)
from estimator.compiled.cache import guard_kernel_cache
from estimator.compiled.rng import G_STATE, standard_normal
from estimator.judgment import JUDGE, JUDGMENT_COLUMNS, judgment_substep
from estimator.kalman import NOMINAL_COLUMNS, kalman_step
from estimator.nominal import STATE_DIM

__all__ = ["first_unready", "observe", "observe_row", "step_all", "step_env", "step_envs"]

# Outcome codes the kernel writes, from the enum (Numba freezes them into the machine code).
_NONE = int(Outcome.NONE)
_SUCCESS = int(Outcome.SUCCESS)
_UNSAFE = int(Outcome.UNSAFE)
_PREMATURE = int(Outcome.PREMATURE)


@njit(cache=True, error_model="numpy", nogil=True)
def step_env(
    row: NDArray[np.float64],
    command: NDArray[np.float64],
    generator: NDArray[np.uint64],
    normals: NDArray[np.float64],
    obs_row: NDArray[np.float32],
    consts: NDArray[np.float64],
) -> None:
    r"""One agent action of one env: cues -> (person -> sensors -> filter -> judgment) x substeps -> outcome -> reward.

    A lift ends the episode, judged on the true state (§II); else the cues play for ``substeps`` filter
    steps (the episode's length: :func:`~coop_gym.envs.kernels.report.episode_end`). The reward sums the named
    terms (:func:`_write_reward`); ``row`` is the env's packed state (:data:`~coop_gym.envs.kernels.layout.BLOCKS`).
    """
    substeps = int(consts[CONSTS.substeps])
    person = row[BLOCKS.person : BLOCKS.person + len(STATE_COLUMNS)]
    cue = row[BLOCKS.cues : BLOCKS.cues + len(CUE_COLUMNS)]
    push_force_n = command[CMD.push_force_n]
    lift = command[CMD.lift] > 0.5
    cue[CUES.impulse_n_s] = 0.0
    if lift:
        outcome = _lift_outcome(person, consts)
        _hold_bank_inputs(row, substeps)
    else:
        params = row[BLOCKS.params : BLOCKS.params + len(PARAM_COLUMNS)]
        delay_push = row[BLOCKS.delay_push : BLOCKS.delay_push + DELAY_LINE_LENGTH]
        delay_verbal = row[BLOCKS.delay_verbal : BLOCKS.delay_verbal + DELAY_LINE_LENGTH]
        mean = row[BLOCKS.mean : BLOCKS.mean + STATE_DIM]
        covariance = row[BLOCKS.cov : BLOCKS.cov + STATE_DIM * STATE_DIM].reshape((STATE_DIM, STATE_DIM))
        nominal = row[BLOCKS.nominal : BLOCKS.nominal + len(NOMINAL_COLUMNS)]
        judge = row[BLOCKS.judge : BLOCKS.judge + len(JUDGMENT_COLUMNS)]
        dt = params[PERSON.dt_s]
        # A verbal cue is an utterance of fixed length; one can't talk over oneself.
        if cue[CUES.verbal_remaining_s] <= 0.0 and command[CMD.verbal_cue] != 0.0:
            cue[CUES.verbal_value] = command[CMD.verbal_cue]
            cue[CUES.verbal_remaining_s] = consts[CONSTS.verbal_duration_s]
        for k in range(substeps):
            verbal_cue = cue[CUES.verbal_value] if cue[CUES.verbal_remaining_s] > 1e-9 else 0.0
            for j in range(NORMALS_PER_SUBSTEP):
                normals[j] = standard_normal(generator)
            person_substep(person, params, delay_push, delay_verbal, push_force_n, verbal_cue, normals)
            position_m, force_n = measure(person, params, push_force_n, normals[3], normals[4])
            kalman_step(mean, covariance, nominal, force_n, verbal_cue, position_m)
            cue_active = push_force_n > 0.0 or verbal_cue != 0.0
            judgment_substep(judge, cue_active, mean[3], consts[CONSTS.judgment_delay_s],
                             consts[CONSTS.judgment_threshold], dt)  # fmt: skip
            _record_readings(row, k, substeps, force_n, verbal_cue, position_m)
            cue[CUES.verbal_remaining_s] -= dt
            cue[CUES.impulse_n_s] += push_force_n * dt
        if cue[CUES.verbal_remaining_s] <= 1e-9:
            cue[CUES.verbal_remaining_s] = cue[CUES.verbal_value] = 0.0
        cue[CUES.elapsed_s] += substeps * dt
        _report_belief(row, consts[CONSTS.episode_s])
        # Only a lift ends an episode here; its length is counted in steps (report.episode_end).
        outcome = _NONE
    report = row[BLOCKS.report : BLOCKS.report + len(REPORT_COLUMNS)]
    _write_reward(report, outcome, lift, cue[CUES.impulse_n_s], consts)
    _report_truth(report, person, outcome, 0.0 if lift else push_force_n)
    if consts[CONSTS.build_obs] > 0.5:
        observe_row(row, obs_row, consts)


@njit(cache=True, error_model="numpy", nogil=True, inline="always")
def _write_reward(
    report: NDArray[np.float64], outcome: int, lift: bool, impulse_n_s: float, consts: NDArray[np.float64]
) -> None:
    r"""The named reward terms of a step and their sum, into the report.

    :math:`r = w_\text{success}[\text{success}] - w_\text{unsafe}[\text{unsafe}]
    - w_\text{premature}[\text{premature}] - w_\text{time} \Delta t_\text{action} [\text{no lift}]
    - w_\text{force} \int F_\text{push} dt`, the weights those of
    :class:`~coop_gym.envs.config.RewardWeights` (``time_term`` is ``-w_time dt_action``).
    """
    report[REPORT.reward_success] = consts[CONSTS.reward_success] if outcome == _SUCCESS else 0.0
    report[REPORT.reward_unsafe] = -consts[CONSTS.reward_unsafe] if outcome == _UNSAFE else 0.0
    report[REPORT.reward_premature] = -consts[CONSTS.reward_premature] if outcome == _PREMATURE else 0.0
    report[REPORT.reward_time] = 0.0 if lift else consts[CONSTS.time_term]
    report[REPORT.reward_force] = -consts[CONSTS.force_per_n_s] * impulse_n_s
    report[REPORT.reward] = (report[REPORT.reward_success] + report[REPORT.reward_unsafe]
                             + report[REPORT.reward_premature] + report[REPORT.reward_time]
                             + report[REPORT.reward_force])  # fmt: skip


@njit(cache=True, error_model="numpy", nogil=True, inline="always")
def _lift_outcome(person: NDArray[np.float64], consts: NDArray[np.float64]) -> int:
    # Success if the person is cooperative and leans past success_lean_m; unsafe if uncooperative
    # or not yet past upright_m; else premature.
    if person[STATE.xi] > 0.5 and person[STATE.x_m] >= consts[CONSTS.success_lean_m]:
        return _SUCCESS
    if person[STATE.xi] < -0.5 or person[STATE.x_m] < consts[CONSTS.upright_m]:
        return _UNSAFE
    return _PREMATURE


@njit(cache=True, error_model="numpy", nogil=True, inline="always")
def _hold_bank_inputs(row: NDArray[np.float64], substeps: int) -> None:
    # A lift's multiple-model bank inputs hold still: no push, no cue, the last reading.
    for k in range(substeps):
        row[BLOCKS.end + k] = 0.0
        row[BLOCKS.end + substeps + k] = 0.0
        row[BLOCKS.end + 2 * substeps + k] = row[BLOCKS.report + REPORT.measured_position_m]


@njit(cache=True, error_model="numpy", nogil=True, inline="always")
def _record_readings(
    row: NDArray[np.float64], k: int, substeps: int, force_n: float, verbal_cue: float, position_m: float
) -> None:
    # Substep k's readings: the multiple-model bank's inputs (measured force, verbal cue, position)
    # and the report's last readings.
    row[BLOCKS.end + k] = force_n
    row[BLOCKS.end + substeps + k] = verbal_cue
    row[BLOCKS.end + 2 * substeps + k] = position_m
    row[BLOCKS.report + REPORT.measured_position_m] = position_m
    row[BLOCKS.report + REPORT.measured_force_n] = force_n


@njit(cache=True, error_model="numpy", nogil=True, inline="always")
def _report_belief(row: NDArray[np.float64], episode_s: float) -> None:
    # The features after a non-lift step: the cue, the filter's belief, the judgment, the clocks.
    # Read and written at their offsets in the row, as _record_readings does: a view made here (and
    # the covariance's reshape) would cost reference counting and a reshape call on every env step.
    at = BLOCKS.report
    row[at + REPORT.verbal_cue] = row[BLOCKS.cues + CUES.verbal_value]
    row[at + REPORT.time_since_cue_onset_s] = min(row[BLOCKS.judge + JUDGE.since_onset_s], episode_s)
    row[at + REPORT.x_hat_m] = row[BLOCKS.mean + 0]
    row[at + REPORT.xdot_hat_m_per_s] = row[BLOCKS.mean + 1]
    row[at + REPORT.eta_hat_m] = row[BLOCKS.mean + 2]
    row[at + REPORT.xi_hat] = row[BLOCKS.mean + 3]
    row[at + REPORT.xi_std] = np.sqrt(max(row[BLOCKS.cov + 3 * STATE_DIM + 3], 0.0))  # covariance[3, 3]
    row[at + REPORT.judgment] = row[BLOCKS.judge + JUDGE.judgment]
    row[at + REPORT.elapsed_s] = row[BLOCKS.cues + CUES.elapsed_s]
    row[at + REPORT.true_xi] = row[BLOCKS.person + STATE.xi]


@njit(cache=True, error_model="numpy", nogil=True, inline="always")
def _report_truth(report: NDArray[np.float64], person: NDArray[np.float64], outcome: int, push_force_n: float) -> None:
    # What the info tells and the agent never sees: the outcome, the push and the true state.
    report[REPORT.outcome] = outcome
    report[REPORT.push_force_n] = push_force_n
    report[REPORT.true_x_m] = person[STATE.x_m]
    report[REPORT.true_xdot_m_per_s] = person[STATE.xdot_m_per_s]
    report[REPORT.true_eta_m] = person[STATE.eta_m]
    report[REPORT.info_true_xi] = person[STATE.xi]


@njit(cache=True, error_model="numpy", nogil=True)
def observe_row(row: NDArray[np.float64], obs_row: NDArray[np.float32], consts: NDArray[np.float64]) -> None:
    """The env's observation from its report: the selected features clipped into their bounds, float32."""
    n_obs = int(consts[CONSTS.n_obs])
    at = int(consts[CONSTS.obs_at])
    select_and_clip(
        row[BLOCKS.report :],
        consts[at : at + n_obs],
        consts[at + n_obs : at + 2 * n_obs],
        consts[at + 2 * n_obs : at + 3 * n_obs],
        obs_row,
    )


@njit(cache=True, error_model="numpy", nogil=True, inline="always")
def select_and_clip(
    report_row: NDArray[np.float64],
    columns: NDArray[np.float64],
    low: NDArray[np.float64],
    high: NDArray[np.float64],
    obs_row: NDArray[np.float32],
) -> None:
    """The physical observation of a report row: column ``columns[k]`` clipped into ``[low[k], high[k]]``.

    The one selection of the observation: the step's (:func:`observe_row`) and the info's
    ``unscaled_obs`` (:class:`~coop_gym.envs.info.InfoBuilder`). Clipped in float64, then rounded
    into ``obs_row``'s float32: as ``np.clip(f, low, high).astype(np.float32)``.
    """
    for k in range(obs_row.shape[0]):
        obs_row[k] = min(max(report_row[int(columns[k])], low[k]), high[k])


@njit(cache=True, error_model="numpy")
def observe(
    indices: NDArray[np.int64], state: NDArray[np.float64], obs: NDArray[np.float32], consts: NDArray[np.float64]
) -> None:
    """:func:`observe_row` of envs ``indices``."""
    for i in indices:
        observe_row(state[i], obs[i], consts)


@njit(cache=True, error_model="numpy", nogil=True)
def step_envs(
    start: int,
    stop: int,
    cmd: NDArray[np.float64],
    state: NDArray[np.float64],
    generators: NDArray[np.uint64],
    obs: NDArray[np.float32],
    consts: NDArray[np.float64],
) -> None:
    """:func:`step_env` of the active envs ``start .. stop - 1``.

    Each env touches only its own rows and its own generator, so disjoint ranges can run on
    different threads.
    """
    normals = np.empty(NORMALS_PER_SUBSTEP)  # this call's scratch
    for i in range(start, stop):
        if cmd[i, CMD.active] < 0.5:
            continue
        step_env(state[i], cmd[i], generators[i], normals, obs[i], consts)


@njit(cache=True, error_model="numpy")
def first_unready(cmd: NDArray[np.float64], generators: NDArray[np.uint64]) -> int:
    """The first active env that was never reset (has no generator), or -1.

    Checked before any env is stepped, in order, so a failed call changes nothing and names the
    lowest such env.
    """
    for i in range(cmd.shape[0]):
        if cmd[i, CMD.active] > 0.5 and generators[i, G_STATE] == 0:
            return i
    return -1


@njit(cache=True, error_model="numpy")
def step_all(
    cmd: NDArray[np.float64],
    state: NDArray[np.float64],
    generators: NDArray[np.uint64],
    obs: NDArray[np.float32],
    consts: NDArray[np.float64],
) -> int:
    """Step every active env on this thread; returns -1, or an active env never reset (nothing stepped then)."""
    failed = first_unready(cmd, generators)
    if failed < 0:
        step_envs(0, cmd.shape[0], cmd, state, generators, obs, consts)
    return failed


guard_kernel_cache(__name__)
