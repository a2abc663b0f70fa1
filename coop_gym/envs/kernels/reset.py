"""The start of an episode, compiled: the draws of a reset in their documented order, then the rows they fill.

Env ``i`` draws only from its own generator, in a fixed order: ``integers(n_personas)``, the
person's variation normals, ``random()`` for the initial ``xi`` and ``normal(0, 5 mm)`` for the
initial lean (:func:`draw_reset`). Between the two kernels the core turns the normals into
variation factors with NumPy's ``exp`` (see :meth:`~coop_gym.envs.core.SitToStandCore.reset_envs`);
:func:`start_episodes` then builds each env's person, filter and first report from them.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from coop_gym.envs.kernels.layout import BLOCKS, CONSTS, DRAWS, NO_OVERRIDE, PERSONA_BLOCKS
from coop_gym.envs.kernels.report import REPORT, REPORT_COLUMNS
from coop_gym.envs.kernels.step import observe_row
from coop_gym.model.dynamics import (
    PARAM_COLUMNS,
    PERSON,
    STATE_COLUMNS,
    fill_initial_state,
    zoh_coefficients_batch,
)
from estimator.compiled.cache import guard_kernel_cache
from estimator.compiled.rng import G_STATE, integers, random, standard_normal
from estimator.judgment import JUDGE
from estimator.kalman import NOMINAL, NOMINAL_COLUMNS
from estimator.nominal import STATE_DIM

__all__ = ["INITIAL_LEAN_STD_M", "draw_reset", "start_episodes"]

INITIAL_LEAN_STD_M = 0.005
"""People sit a little differently: std of the initial forward lean [m]."""


@njit(cache=True, error_model="numpy", nogil=True)
def draw_reset(
    indices: NDArray[np.int64],
    generators: NDArray[np.uint64],
    n_personas: int,
    persona_override: int,
    draws: NDArray[np.float64],
) -> int:
    """The random draws of a reset in the documented order (draws row ``r`` is env ``indices[r]``).

    Returns -1, or the index of an env without a generator (nothing is drawn then).
    """
    for r in range(indices.shape[0]):
        if generators[indices[r], G_STATE] == 0:
            return indices[r]
    for r in range(indices.shape[0]):
        generator = generators[indices[r]]
        drawn = integers(generator, n_personas)
        draws[r, DRAWS.persona] = drawn if persona_override == NO_OVERRIDE else persona_override
        for j in range(DRAWS.normals, draws.shape[1]):
            draws[r, j] = standard_normal(generator)
        draws[r, DRAWS.uniform] = random(generator)
        draws[r, DRAWS.lean] = 0.0 + INITIAL_LEAN_STD_M * standard_normal(generator)
    return -1


@njit(cache=True, error_model="numpy", nogil=True)
def _vary_people(
    indices: NDArray[np.int64], draws: NDArray[np.float64], persona_table: NDArray[np.float64],
    state: NDArray[np.float64], consts: NDArray[np.float64],
) -> None:  # fmt: skip
    # Each env's person: its persona's packed row with the varied gains scaled by their factors
    # (sample_person + pack_person), and eq. 1's zero-order hold of every one in one batch
    # (zoh_coefficients, bit for bit).
    n_varied = int(consts[CONSTS.n_varied])
    varied_at = int(consts[CONSTS.varied_at])
    count = indices.shape[0]
    damping, gain, dt = np.empty(count), np.empty(count), np.empty(count)
    for r in range(count):
        persona = persona_table[int(draws[r, DRAWS.persona])]
        params = state[indices[r], BLOCKS.params : BLOCKS.params + len(PARAM_COLUMNS)]
        # Element loops, not slice assignments: those compile numba's shape-mismatch error
        # formatting into every cold start (python bench/cold_start.py); the copies are the same.
        for j in range(len(PARAM_COLUMNS)):
            params[j] = persona[PERSONA_BLOCKS.params + j]
        if consts[CONSTS.vary] > 0.5:
            for j in range(n_varied):
                column = int(consts[varied_at + j])
                params[column] = persona[PERSONA_BLOCKS.params + column] * draws[r, DRAWS.normals + j]
        damping[r] = params[PERSON.damping_rate_per_s]
        gain[r] = params[PERSON.voluntary_gain_per_s2]
        dt[r] = params[PERSON.dt_s]
    zoh = np.empty((count, 6))
    zoh_coefficients_batch(damping, gain, dt, zoh)
    for r in range(count):
        params = state[indices[r], BLOCKS.params : BLOCKS.params + len(PARAM_COLUMNS)]
        params[PERSON.zoh_a00] = zoh[r, 0]
        params[PERSON.zoh_a01] = zoh[r, 1]
        params[PERSON.zoh_a10] = zoh[r, 2]
        params[PERSON.zoh_a11] = zoh[r, 3]
        params[PERSON.zoh_b0] = zoh[r, 4]
        params[PERSON.zoh_b1] = zoh[r, 5]


@njit(cache=True, error_model="numpy", nogil=True)
def start_episodes(
    indices: NDArray[np.int64],
    xi_override: int,
    draws: NDArray[np.float64],
    persona_table: NDArray[np.float64],
    state: NDArray[np.float64],
    obs: NDArray[np.float32],
    consts: NDArray[np.float64],
) -> None:
    """Start episodes in envs ``indices`` from the draws (their normals already variation factors)."""
    episode_s = consts[CONSTS.episode_s]
    for r in range(indices.shape[0]):
        row = state[indices[r]]
        for j in range(row.shape[0]):
            row[j] = 0.0
    _vary_people(indices, draws, persona_table, state, consts)
    for r in range(indices.shape[0]):
        i = indices[r]
        persona_index = int(draws[r, DRAWS.persona])
        persona = persona_table[persona_index]
        row = state[i]
        uniform = draws[r, DRAWS.uniform]
        cuts = PERSONA_BLOCKS.xi_cuts
        xi = -1.0 if uniform < persona[cuts] else (1.0 if uniform > persona[cuts + 1] else 0.0)
        if xi_override != NO_OVERRIDE:
            xi = float(xi_override)
        lean_m = draws[r, DRAWS.lean]
        fill_initial_state(row[BLOCKS.person : BLOCKS.person + len(STATE_COLUMNS)], xi, lean_m)
        # The filter, centred on the first reading with the nominal model's prior.
        for j in range(len(NOMINAL_COLUMNS)):
            row[BLOCKS.nominal + j] = persona[PERSONA_BLOCKS.nominal + j]
        mean = row[BLOCKS.mean : BLOCKS.mean + STATE_DIM]
        covariance = row[BLOCKS.cov : BLOCKS.cov + STATE_DIM * STATE_DIM].reshape((STATE_DIM, STATE_DIM))
        mean[0] = lean_m
        mean[2] = lean_m
        covariance[0, 0] = persona[PERSONA_BLOCKS.nominal + NOMINAL.r_position]  # R
        covariance[1, 1] = consts[CONSTS.xdot_var]
        covariance[2, 2] = consts[CONSTS.eta_var]
        covariance[3, 3] = consts[CONSTS.xi_var]
        row[BLOCKS.judge + JUDGE.since_onset_s] = episode_s
        report = row[BLOCKS.report : BLOCKS.report + len(REPORT_COLUMNS)]
        report[REPORT.measured_position_m] = lean_m
        report[REPORT.x_hat_m] = lean_m
        report[REPORT.eta_hat_m] = lean_m
        report[REPORT.xi_std] = consts[CONSTS.xi_std]
        report[REPORT.time_since_cue_onset_s] = episode_s
        report[REPORT.true_xi] = xi
        report[REPORT.true_x_m] = lean_m
        report[REPORT.true_eta_m] = lean_m
        report[REPORT.info_true_xi] = xi
        report[REPORT.persona_index] = persona_index
        if consts[CONSTS.build_obs] > 0.5:
            observe_row(row, obs[i], consts)


guard_kernel_cache(__name__)
