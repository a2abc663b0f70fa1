"""The batched simulation shared by the single env and the vector env.

This is where model and filter meet. :class:`SitToStandCore` holds ``N`` independent
episodes as arrays and advances them one agent action at a time:

    decode action -> lift outcome | (cues -> person -> sensors -> filter -> judgment) x substeps
    -> features -> reward terms -> observation

The maths is not here: the person is :mod:`coop_gym.model.dynamics`, the filter
:mod:`estimator.kalman` / :mod:`estimator.judgment`. The single env is this core with
``N = 1``; the vector env is the same core with ``N`` envs, so the two cannot drift.

Speed: one compiled call steps every env, writing the reward terms, the info values
(:data:`REPORT_COLUMNS`) and the clipped float32 observation into preallocated arrays;
another resets any set of envs. Per-env state lives in one packed float row
(:attr:`SitToStandCore.state`; ``m``, ``P``, ``params`` ... are views into it) so a call
passes few arrays.

Randomness: env ``i`` draws only from its own ``numpy.random.Generator``, in a fixed
order -- at reset ``integers(n_personas)``, the person's variation normals, ``random()``
for the initial ``xi`` and ``normal(0, 5 mm)`` for the initial lean; then
``substeps x NORMALS_PER_SUBSTEP`` standard normals per non-lift step. So env ``i`` of a
vector env seeded ``s`` and a single env seeded ``s + i`` see identical streams. The
compiled kernels draw these through the generator's own C functions with NumPy's
algorithms (:mod:`compiled.rng`), so the numbers are exactly those the ``Generator``
methods return and the ``Generator`` object stays the single source of truth.

Numba caches the kernels on disk, keyed by every project source they compile in
(:func:`compiled.cache.guard_kernel_cache`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from compiled.cache import guard_kernel_cache
from compiled.rng import G_STATE, bit_generator_row, integers, random, standard_normal
from coop_gym.envs.config import LiftCriteria, Outcome, RewardWeights
from coop_gym.model.dynamics import (
    DELAY_LINE_LENGTH,
    NORMALS_PER_SUBSTEP,
    PARAM_COLUMNS,
    PERSON,
    STATE,
    STATE_COLUMNS,
    initial_state_row,
    measure,
    pack_person,
    person_substep,
    zoh_coefficients,
)
from coop_gym.model.params import Cues, PersonParams, Realism, Timing
from coop_gym.model.personas import VARIED_PARAMETERS, Persona
from estimator.judgment import J_JUDGMENT, J_SINCE_ONSET, JUDGMENT_COLUMNS, ThresholdJudgment, judgment_substep
from estimator.kalman import NOMINAL, NOMINAL_COLUMNS, kalman_step, nominal_row
from estimator.nominal import STATE_DIM, NominalModel

__all__ = [
    "FEATURES",
    "REPORT_COLUMNS",
    "REWARD_TERMS",
    "SitToStandCore",
    "StepArrays",
    "nominal_model_for",
]

FEATURES: tuple[str, ...] = (
    "measured_position_m",
    "measured_force_n",
    "verbal_cue",
    "time_since_cue_onset_s",
    "x_hat_m",
    "xdot_hat_m_per_s",
    "eta_hat_m",
    "xi_hat",
    "xi_std",
    "judgment",
    "elapsed_s",
    "p_uncooperative",
    "p_unresponsive",
    "p_cooperative",
    "true_xi",
)
"""Every quantity an observation can hold; each observation mode selects some of them."""
(
    F_POS,
    F_FORCE,
    F_VERBAL,
    F_SINCE_ONSET,
    F_X_HAT,
    F_XDOT_HAT,
    F_ETA_HAT,
    F_XI_HAT,
    F_XI_STD,
    F_JUDGMENT,
    F_ELAPSED,
    F_P_M1,
    F_P_0,
    F_P_P1,
    F_TRUE_XI,
) = range(len(FEATURES))

REWARD_TERMS: tuple[str, ...] = ("success", "unsafe", "premature", "time", "force")
"""Names of the reward terms, in the column order of :attr:`StepArrays.reward_terms`."""

REPORT_COLUMNS: tuple[str, ...] = (
    *FEATURES,
    *(f"reward_{name}" for name in REWARD_TERMS),
    "reward",
    "outcome",
    "push_force_n",
    "true_x_m",
    "true_xdot_m_per_s",
    "true_eta_m",
    "true_xi",
    "persona_index",
)
"""Columns of :attr:`SitToStandCore.report`: one float row per env with everything ``info`` needs.

Kept in one row so an env reads it with a single ``tolist()``.
"""
R_TERMS = len(FEATURES)
R_REWARD = R_TERMS + len(REWARD_TERMS)
R_OUTCOME, R_PUSH, R_TRUE_X, R_TRUE_XDOT, R_TRUE_ETA, R_TRUE_XI, R_PERSONA = range(R_REWARD + 1, len(REPORT_COLUMNS))

# Per-env bookkeeping of the cue scheduler: the utterance playing and the clock.
E_VERBAL_VALUE, E_VERBAL_REMAINING, E_ELAPSED, E_IMPULSE = range(4)
_N_ENV_COLUMNS = 4

# Column blocks of the packed per-env state row (SitToStandCore.state).
_ST_PERSON = 0
_ST_CUES = _ST_PERSON + len(STATE_COLUMNS)
_ST_MEAN = _ST_CUES + _N_ENV_COLUMNS
_ST_COV = _ST_MEAN + STATE_DIM
_ST_JUDGE = _ST_COV + STATE_DIM * STATE_DIM
_ST_NOMINAL = _ST_JUDGE + len(JUDGMENT_COLUMNS)
_ST_PARAMS = _ST_NOMINAL + len(NOMINAL_COLUMNS)
_ST_DELAY_PUSH = _ST_PARAMS + len(PARAM_COLUMNS)
_ST_DELAY_VERBAL = _ST_DELAY_PUSH + DELAY_LINE_LENGTH
_ST_REPORT = _ST_DELAY_VERBAL + DELAY_LINE_LENGTH
_ST_BLOCKS = _ST_REPORT + len(REPORT_COLUMNS)  # then 3 x substeps: measured force, verbal cue, position

# Scalars the kernels read, packed in one float array (SitToStandCore.consts).
(
    _C_SUBSTEPS,
    _C_VERBAL_S,
    _C_JUDGE_DELAY_S,
    _C_JUDGE_THRESHOLD,
    _C_SUCCESS_LEAN_M,
    _C_UPRIGHT_M,
    _C_EPISODE_S,
    _C_W_SUCCESS,
    _C_W_UNSAFE,
    _C_W_PREMATURE,
    _C_TIME_TERM,
    _C_W_FORCE,
    _C_BUILD_OBS,
    _C_VARY,
    _C_XDOT_VAR,
    _C_ETA_VAR,
    _C_XI_VAR,
    _C_XI_STD,
    _C_N_OBS,
    _C_N_VARIED,
    _C_OBS_AT,
    _C_VARIED_AT,
    _C_TEMPLATE_AT,
    _N_CONSTS,
) = range(24)
# After the scalars come the observation spec (feature index, low, high; n_obs each), the
# columns sample_person varies, and the person's initial state row.

# Columns of the command row: push [N], verbal request {-1, 0, 1}, lift {0, 1}, active {0, 1}
# (an inactive env is not stepped).
CMD_PUSH, CMD_VERBAL, CMD_LIFT, CMD_ACTIVE = range(4)
CMD_COLUMNS = 4

# Columns of the scratch rows of a reset: the draws, then the variation normals (turned into factors).
_D_PERSONA, _D_UNIFORM, _D_LEAN, _D_NORMALS = range(4)

# Columns of a persona-table row: the packed person, the filter's nominal row, the initial-xi cuts.
_PT_PARAMS = 0
_PT_NOMINAL = _PT_PARAMS + len(PARAM_COLUMNS)
_PT_XI_CUTS = _PT_NOMINAL + len(NOMINAL_COLUMNS)
_PT_WIDTH = _PT_XI_CUTS + 2


def check_outcome_codes(outcome: type[IntEnum]) -> None:
    """Raise ``ValueError`` unless the enum's values are ``0 .. n-1`` in order.

    The kernel writes outcome codes into a float report column and the envs index label
    tables with them, so they must be small consecutive integers. An explicit check, not
    an ``assert``: it must hold under ``python -O`` too.
    """
    codes = [int(member) for member in outcome]
    if codes != list(range(len(codes))):
        raise ValueError(f"{outcome.__name__} values must be 0 .. {len(codes) - 1} in order, got {codes}")


check_outcome_codes(Outcome)
# Outcome codes the kernel writes, from the enum (Numba freezes them into the machine code).
_NONE = int(Outcome.NONE)
_SUCCESS = int(Outcome.SUCCESS)
_UNSAFE = int(Outcome.UNSAFE)
_PREMATURE = int(Outcome.PREMATURE)
_TIMEOUT = int(Outcome.TIMEOUT)
_ENDED_BY_LIFT = np.array([member in (Outcome.SUCCESS, Outcome.UNSAFE, Outcome.PREMATURE) for member in Outcome])
"""Indexed by outcome code: does the episode terminate (the robot lifted)?"""

INITIAL_LEAN_STD_M = 0.005
"""People sit a little differently: std of the initial forward lean [m]."""

_NO_OVERRIDE = -99  # "draw it" for the persona / initial-xi overrides of a reset


def nominal_model_for(person: PersonParams, timing: Timing, base: NominalModel | None = None) -> NominalModel:
    """The filter's nominal model for a persona: its typical gains, the paper's linear form.

    The filter sees the persona's *typical* parameters, not the episode's varied person,
    and none of the realism knobs -- the gap real people leave.
    """
    base = base or NominalModel()
    bio, intent, sensors = person.biomechanics, person.intention, person.sensors
    return base.replace(
        dt_s=timing.dt_s,
        damping_rate_per_s=bio.damping_rate_per_s,
        voluntary_gain_per_s2=bio.voluntary_gain_per_s2,
        push_compliance_m_per_s2_n=bio.push_compliance_m_per_s2_n,
        push_gain_m_per_s_n=intent.push_gain_m_per_s_n,
        verbal_gain_m_per_s=intent.verbal_gain_m_per_s,
        # A noiseless camera still needs R > 0 for the filter to be well posed.
        position_noise_std_m=max(sensors.position_noise_std_m, 1e-4),
    )


@dataclass
class StepArrays:
    """What one core step produced, for ``N`` envs (views into the core's arrays, reused between steps).

    Attributes:
        features: (N, len(FEATURES)) float64, see :data:`FEATURES`.
        reward_terms: (N, len(REWARD_TERMS)) signed contributions to the reward.
        reward: (N,) sum of the terms.
        outcome: (N,) int, an :class:`Outcome` (``NONE`` while the episode runs).
        terminated: (N,) bool, True when the robot lifted.
        push_force_n: (N,) the push commanded this step [N].
        verbal_cue: (N,) the utterance playing at the end of the step.
    """

    features: NDArray[np.float64]
    reward_terms: NDArray[np.float64]
    reward: NDArray[np.float64]
    outcome: NDArray[np.int64]
    terminated: NDArray[np.bool_]
    push_force_n: NDArray[np.float64]
    verbal_cue: NDArray[np.float64]


# --- kernels --------------------------------------------------------------------
# Few, packed arguments: dispatching a compiled call costs ~0.1 us per argument, as much
# as a whole env step's arithmetic.


@njit(cache=True)
def _observe_row(row: NDArray[np.float64], obs_row: NDArray[np.float32], consts: NDArray[np.float64]) -> None:
    # Select the features and clip in float64, then round: as np.clip(f, low, high).astype(float32).
    n_obs = int(consts[_C_N_OBS])
    at = int(consts[_C_OBS_AT])
    for k in range(n_obs):
        value = row[_ST_REPORT + int(consts[at + k])]
        obs_row[k] = min(max(value, consts[at + n_obs + k]), consts[at + 2 * n_obs + k])


@njit(cache=True)
def _observe(
    indices: NDArray[np.int64], state: NDArray[np.float64], obs: NDArray[np.float32], consts: NDArray[np.float64]
) -> None:
    for i in indices:
        _observe_row(state[i], obs[i], consts)


@njit(cache=True)
def _draw_reset(
    indices: NDArray[np.int64],
    generators: NDArray[np.uint64],
    n_personas: int,
    persona_override: int,
    draws: NDArray[np.float64],
) -> int:
    # The random draws of a reset in the documented order (draws row r is env indices[r]).
    # Returns -1, or the index of an env without a generator (nothing is drawn then).
    for r in range(indices.shape[0]):
        if generators[indices[r], G_STATE] == 0:
            return indices[r]
    for r in range(indices.shape[0]):
        g = generators[indices[r]]
        drawn = integers(g, n_personas)
        draws[r, _D_PERSONA] = drawn if persona_override == _NO_OVERRIDE else persona_override
        for j in range(_D_NORMALS, draws.shape[1]):
            draws[r, j] = standard_normal(g)
        draws[r, _D_UNIFORM] = random(g)
        draws[r, _D_LEAN] = 0.0 + INITIAL_LEAN_STD_M * standard_normal(g)
    return -1


@njit(cache=True)
def _reset_rows(
    indices: NDArray[np.int64],
    xi_override: int,
    draws: NDArray[np.float64],
    persona_table: NDArray[np.float64],
    state: NDArray[np.float64],
    obs: NDArray[np.float32],
    consts: NDArray[np.float64],
) -> None:
    # Start episodes from the draws (their normals columns already turned into variation factors).
    episode_s = consts[_C_EPISODE_S]
    n_varied = int(consts[_C_N_VARIED])
    varied_at = int(consts[_C_VARIED_AT])
    template_at = int(consts[_C_TEMPLATE_AT])
    for r in range(indices.shape[0]):
        i = indices[r]
        k = int(draws[r, _D_PERSONA])
        persona = persona_table[k]
        row = state[i]
        row[:] = 0.0
        # The person: the persona's packed row with the varied gains scaled (= sample_person + pack_person).
        p = row[_ST_PARAMS : _ST_PARAMS + len(PARAM_COLUMNS)]
        p[:] = persona[_PT_PARAMS : _PT_PARAMS + len(PARAM_COLUMNS)]
        if consts[_C_VARY] > 0.5:
            for j in range(n_varied):
                column = int(consts[varied_at + j])
                p[column] = persona[_PT_PARAMS + column] * draws[r, _D_NORMALS + j]
        a00, a01, a10, a11, b0, b1 = zoh_coefficients(
            p[PERSON.damping_rate_per_s], p[PERSON.voluntary_gain_per_s2], p[PERSON.dt_s]
        )
        p[PERSON.zoh_a00] = a00
        p[PERSON.zoh_a01] = a01
        p[PERSON.zoh_a10] = a10
        p[PERSON.zoh_a11] = a11
        p[PERSON.zoh_b0] = b0
        p[PERSON.zoh_b1] = b1
        u = draws[r, _D_UNIFORM]
        xi = -1.0 if u < persona[_PT_XI_CUTS] else (1.0 if u > persona[_PT_XI_CUTS + 1] else 0.0)
        if xi_override != _NO_OVERRIDE:
            xi = float(xi_override)
        x0 = draws[r, _D_LEAN]
        # initial_state_row(xi, x0): at rest at x0, intending to stay.
        s = row[_ST_PERSON : _ST_PERSON + len(STATE_COLUMNS)]
        s[:] = consts[template_at : template_at + len(STATE_COLUMNS)]
        s[STATE.x_m] = x0
        s[STATE.eta_m] = x0
        s[STATE.xi] = xi
        # The filter, centred on the first reading with the nominal model's prior.
        nominal_width = len(NOMINAL_COLUMNS)
        row[_ST_NOMINAL : _ST_NOMINAL + nominal_width] = persona[_PT_NOMINAL : _PT_NOMINAL + nominal_width]
        row[_ST_MEAN] = x0
        row[_ST_MEAN + 2] = x0
        row[_ST_COV] = persona[_PT_NOMINAL + NOMINAL.r_position]  # P[0, 0] = R
        row[_ST_COV + STATE_DIM + 1] = consts[_C_XDOT_VAR]
        row[_ST_COV + 2 * (STATE_DIM + 1)] = consts[_C_ETA_VAR]
        row[_ST_COV + 3 * (STATE_DIM + 1)] = consts[_C_XI_VAR]
        row[_ST_JUDGE + J_SINCE_ONSET] = episode_s
        rep = row[_ST_REPORT : _ST_REPORT + len(REPORT_COLUMNS)]
        rep[F_POS] = x0
        rep[F_X_HAT] = x0
        rep[F_ETA_HAT] = x0
        rep[F_XI_STD] = consts[_C_XI_STD]
        rep[F_SINCE_ONSET] = episode_s
        rep[F_TRUE_XI] = xi
        rep[R_TRUE_X] = x0
        rep[R_TRUE_ETA] = x0
        rep[R_TRUE_XI] = xi
        rep[R_PERSONA] = k
        if consts[_C_BUILD_OBS] > 0.5:
            _observe_row(row, obs[i], consts)


@njit(cache=True)
def _lift_outcome(s: NDArray[np.float64], consts: NDArray[np.float64]) -> int:
    # The lift is judged on the true state at the moment it starts (§II).
    if s[STATE.xi] > 0.5 and s[STATE.x_m] >= consts[_C_SUCCESS_LEAN_M]:
        return _SUCCESS
    if s[STATE.xi] < -0.5 or s[STATE.x_m] < consts[_C_UPRIGHT_M]:
        return _UNSAFE
    return _PREMATURE


@njit(cache=True)
def _simulate_action(
    row: NDArray[np.float64],
    cp: float,
    verbal_request: float,
    g: NDArray[np.uint64],
    z: NDArray[np.float64],
    consts: NDArray[np.float64],
) -> int:
    # One non-lift action of one env: cues -> person -> sensors -> filter -> judgment, x substeps,
    # then the features. Returns the outcome: TIMEOUT at the end of the episode, else NONE.
    substeps = int(consts[_C_SUBSTEPS])
    episode_s = consts[_C_EPISODE_S]
    s = row[_ST_PERSON : _ST_PERSON + len(STATE_COLUMNS)]
    env = row[_ST_CUES : _ST_CUES + _N_ENV_COLUMNS]
    m = row[_ST_MEAN : _ST_MEAN + STATE_DIM]
    P = row[_ST_COV : _ST_COV + STATE_DIM * STATE_DIM].reshape((STATE_DIM, STATE_DIM))
    judge = row[_ST_JUDGE : _ST_JUDGE + len(JUDGMENT_COLUMNS)]
    nominal = row[_ST_NOMINAL : _ST_NOMINAL + len(NOMINAL_COLUMNS)]
    p = row[_ST_PARAMS : _ST_PARAMS + len(PARAM_COLUMNS)]
    delay_push = row[_ST_DELAY_PUSH : _ST_DELAY_PUSH + DELAY_LINE_LENGTH]
    delay_verbal = row[_ST_DELAY_VERBAL : _ST_DELAY_VERBAL + DELAY_LINE_LENGTH]
    f = row[_ST_REPORT : _ST_REPORT + len(REPORT_COLUMNS)]
    block = row[_ST_BLOCKS : _ST_BLOCKS + 3 * substeps]
    dt = p[PERSON.dt_s]
    # A verbal cue is an utterance of fixed length; one can't talk over oneself.
    if env[E_VERBAL_REMAINING] <= 0.0 and verbal_request != 0.0:
        env[E_VERBAL_VALUE] = verbal_request
        env[E_VERBAL_REMAINING] = consts[_C_VERBAL_S]
    for k in range(substeps):
        cv = env[E_VERBAL_VALUE] if env[E_VERBAL_REMAINING] > 1e-9 else 0.0
        for j in range(NORMALS_PER_SUBSTEP):
            z[j] = standard_normal(g)
        person_substep(s, p, delay_push, delay_verbal, cp, cv, z)
        pos, force = measure(s, p, cp, z[3], z[4])
        kalman_step(m, P, nominal, force, cv, pos)
        judgment_substep(judge, cp > 0.0 or cv != 0.0, m[3], consts[_C_JUDGE_DELAY_S], consts[_C_JUDGE_THRESHOLD], dt)
        block[k] = force
        block[substeps + k] = cv
        block[2 * substeps + k] = pos
        env[E_VERBAL_REMAINING] -= dt
        env[E_IMPULSE] += cp * dt
        f[F_POS] = pos
        f[F_FORCE] = force
    if env[E_VERBAL_REMAINING] <= 1e-9:
        env[E_VERBAL_REMAINING] = 0.0
        env[E_VERBAL_VALUE] = 0.0
    env[E_ELAPSED] += substeps * dt
    f[F_VERBAL] = env[E_VERBAL_VALUE]
    f[F_SINCE_ONSET] = min(judge[J_SINCE_ONSET], episode_s)
    f[F_X_HAT] = m[0]
    f[F_XDOT_HAT] = m[1]
    f[F_ETA_HAT] = m[2]
    f[F_XI_HAT] = m[3]
    f[F_XI_STD] = np.sqrt(max(P[3, 3], 0.0))
    f[F_JUDGMENT] = judge[J_JUDGMENT]
    f[F_ELAPSED] = env[E_ELAPSED]
    f[F_TRUE_XI] = s[STATE.xi]
    if env[E_ELAPSED] >= episode_s - 1e-9:
        return _TIMEOUT  # truncation happens on this same step
    return _NONE


@njit(cache=True)
def _write_reward_and_truth(
    row: NDArray[np.float64], result: int, lift: bool, cp: float, consts: NDArray[np.float64]
) -> None:
    # Named reward terms (RewardWeights), then their sum; the outcome, the push and the true state.
    s = row[_ST_PERSON : _ST_PERSON + len(STATE_COLUMNS)]
    f = row[_ST_REPORT : _ST_REPORT + len(REPORT_COLUMNS)]
    t_success = consts[_C_W_SUCCESS] if result == _SUCCESS else 0.0
    t_unsafe = -consts[_C_W_UNSAFE] if result == _UNSAFE else 0.0
    t_premature = -consts[_C_W_PREMATURE] if result == _PREMATURE else 0.0
    t_time = 0.0 if lift else consts[_C_TIME_TERM]
    t_force = -consts[_C_W_FORCE] * row[_ST_CUES + E_IMPULSE]
    f[R_TERMS] = t_success
    f[R_TERMS + 1] = t_unsafe
    f[R_TERMS + 2] = t_premature
    f[R_TERMS + 3] = t_time
    f[R_TERMS + 4] = t_force
    f[R_REWARD] = t_success + t_unsafe + t_premature + t_time + t_force
    f[R_OUTCOME] = result
    f[R_PUSH] = 0.0 if lift else cp
    f[R_TRUE_X] = s[STATE.x_m]
    f[R_TRUE_XDOT] = s[STATE.xdot_m_per_s]
    f[R_TRUE_ETA] = s[STATE.eta_m]
    f[R_TRUE_XI] = s[STATE.xi]


@njit(cache=True)
def _advance(
    cmd: NDArray[np.float64],
    state: NDArray[np.float64],
    generators: NDArray[np.uint64],
    obs: NDArray[np.float32],
    consts: NDArray[np.float64],
) -> int:
    # Returns -1, or the index of an active env that was never reset (nothing is stepped then).
    n_envs = cmd.shape[0]
    for i in range(n_envs):
        if cmd[i, CMD_ACTIVE] > 0.5 and generators[i, G_STATE] == 0:
            return i
    substeps = int(consts[_C_SUBSTEPS])
    z = np.empty(NORMALS_PER_SUBSTEP)
    for i in range(n_envs):
        if cmd[i, CMD_ACTIVE] < 0.5:
            continue
        row = state[i]
        cp = cmd[i, CMD_PUSH]
        lift = cmd[i, CMD_LIFT] > 0.5
        row[_ST_CUES + E_IMPULSE] = 0.0
        if lift:
            result = _lift_outcome(row[_ST_PERSON : _ST_PERSON + len(STATE_COLUMNS)], consts)
            # The filter's input blocks hold still: no push, no cue, the last reading.
            block = row[_ST_BLOCKS : _ST_BLOCKS + 3 * substeps]
            for k in range(substeps):
                block[k] = 0.0
                block[substeps + k] = 0.0
                block[2 * substeps + k] = row[_ST_REPORT + F_POS]
        else:
            result = _simulate_action(row, cp, cmd[i, CMD_VERBAL], generators[i], z, consts)
        _write_reward_and_truth(row, result, lift, cp, consts)
        if consts[_C_BUILD_OBS] > 0.5:
            _observe_row(row, obs[i], consts)
    return -1


class SitToStandCore:
    """``N`` sit-to-stand episodes stepped together (see module docstring).

    Args:
        n_envs: Number of parallel episodes.
        personas: Personas to draw each episode's person from (uniformly).
        timing, cues, realism, lift, reward, judgment: Settings (see their classes).
        estimator: ``"kalman"``, ``"multiple_model"`` or ``"imm"``.
        multiple_model_options: Keyword arguments of the multiple-model estimator.
        observation_index: Indices into :data:`FEATURES` that make the observation
            (default: all of them, unclipped).
        observation_low, observation_high: Bounds the observation is clipped into.

    Attributes:
        state: (N, W) packed per-env state; ``person``, ``m``, ``P``, ``judge``, ``nominal``,
            ``params``, ``delay_push``, ``delay_verbal`` and ``report`` are views into it.
        report: (N, len(REPORT_COLUMNS)) what the last step or reset of each env produced.
        obs: (N, len(observation_index)) float32 observation of the last step or reset.
        cmd: (N, 4) command rows (:data:`CMD_PUSH` ...) for :meth:`step_commands`.
        generators: (N, 4) uint64 addresses of each env's bit generator (0: none yet).
    """

    def __init__(
        self,
        n_envs: int,
        personas: tuple[Persona, ...],
        timing: Timing,
        cues: Cues,
        realism: Realism,
        lift: LiftCriteria,
        reward: RewardWeights,
        judgment: ThresholdJudgment,
        estimator: str = "kalman",
        multiple_model_options: dict[str, Any] | None = None,
        observation_index: tuple[int, ...] | None = None,
        observation_low: NDArray[np.float64] | None = None,
        observation_high: NDArray[np.float64] | None = None,
    ) -> None:
        """Allocate the arrays; every env must be reset before it is stepped."""
        # Kept to rebuild the arrays and their views when unpickled (see __setstate__).
        self._init_args = (n_envs, personas, timing, cues, realism, lift, reward, judgment, estimator,
                           multiple_model_options, observation_index, observation_low, observation_high)  # fmt: skip
        if isinstance(n_envs, bool) or not isinstance(n_envs, (int, np.integer)) or n_envs < 1:
            raise ValueError(f"n_envs must be a positive int, got {n_envs!r}")
        n = int(n_envs)
        self.n_envs = n
        self.personas = personas
        self.timing = timing
        self.cues = cues
        self.realism = realism
        self.lift = lift
        self.reward_weights = reward
        self.judgment = judgment
        self.estimator = estimator
        self._nominal_prior = NominalModel()
        varied = self._pack_personas()
        index = tuple(range(len(FEATURES))) if observation_index is None else tuple(observation_index)
        self.consts = _pack_consts(self, index, observation_low, observation_high, varied)
        self._allocate(n, len(index), len(varied))
        self.mm = self._make_multiple_model(multiple_model_options or {}) if estimator != "kalman" else None
        # With a multiple-model estimator the observation waits for its probabilities.
        self.consts[_C_BUILD_OBS] = 1.0 if self.mm is None else 0.0

    def _pack_personas(self) -> list[int]:
        """Fill ``persona_table`` and the variation stds; return the varied columns of a packed person."""
        personas, timing, realism = self.personas, self.timing, self.realism
        # The filter's nominal model depends only on the persona: pack each once.
        self._persona_nominal = [nominal_row(nominal_model_for(p.params, timing)) for p in personas]
        # Each persona packed once; a reset scales the varied gains (as sample_person does) and
        # recomputes the zero-order hold, instead of building and validating dataclasses.
        table = np.zeros((len(personas), _PT_WIDTH))
        for k, persona in enumerate(personas):
            coop = persona.params.cooperativeness
            table[k, _PT_PARAMS:_PT_NOMINAL] = pack_person(persona.params.with_realism(realism), timing)
            table[k, _PT_NOMINAL:_PT_XI_CUTS] = self._persona_nominal[k]
            table[k, _PT_XI_CUTS] = coop.initial_p_uncooperative
            table[k, _PT_XI_CUTS + 1] = 1.0 - coop.initial_p_cooperative
        self.persona_table = table
        stds = {p.variation_relative_std for p in personas}
        # One shared std (the usual case) broadcasts from a 1-element array (cheaper for a ufunc
        # than a Python float); else each reset env takes its persona's.
        self._variation_std = np.array([stds.pop()]) if len(stds) == 1 else None
        self._persona_variation_std = np.array([p.variation_relative_std for p in personas])
        return [PARAM_COLUMNS.index(name) for names in VARIED_PARAMETERS.values() for name in names]

    def _allocate(self, n: int, n_obs: int, n_varied: int) -> None:
        """The packed per-env state with its views, the command rows and the output buffers."""
        substeps = self.timing.substeps
        self.state = st = np.zeros((n, _ST_BLOCKS + 3 * substeps))
        self.person = st[:, _ST_PERSON : _ST_PERSON + len(STATE_COLUMNS)]
        self.env = st[:, _ST_CUES : _ST_CUES + _N_ENV_COLUMNS]
        self.m = st[:, _ST_MEAN : _ST_MEAN + STATE_DIM]
        self.P = st[:, _ST_COV : _ST_COV + STATE_DIM * STATE_DIM].reshape(n, STATE_DIM, STATE_DIM)
        self.judge = st[:, _ST_JUDGE : _ST_JUDGE + len(JUDGMENT_COLUMNS)]
        self.nominal = st[:, _ST_NOMINAL : _ST_NOMINAL + len(NOMINAL_COLUMNS)]
        self.params = st[:, _ST_PARAMS : _ST_PARAMS + len(PARAM_COLUMNS)]
        self.delay_push = st[:, _ST_DELAY_PUSH : _ST_DELAY_PUSH + DELAY_LINE_LENGTH]
        self.delay_verbal = st[:, _ST_DELAY_VERBAL : _ST_DELAY_VERBAL + DELAY_LINE_LENGTH]
        self.report = st[:, _ST_REPORT : _ST_REPORT + len(REPORT_COLUMNS)]
        self._block_cp = st[:, _ST_BLOCKS : _ST_BLOCKS + substeps]
        self._block_cv = st[:, _ST_BLOCKS + substeps : _ST_BLOCKS + 2 * substeps]
        self._block_y = st[:, _ST_BLOCKS + 2 * substeps : _ST_BLOCKS + 3 * substeps]
        self.rngs: list[np.random.Generator | None] = [None] * n
        self.generators = np.zeros((n, 4), dtype=np.uint64)
        self.cmd = np.zeros((n, CMD_COLUMNS))
        self.cmd[:, CMD_ACTIVE] = 1.0
        self.obs = np.zeros((n, n_obs), dtype=np.float32)
        self._outcome = np.zeros(n, dtype=np.int64)
        self._terminated = np.zeros(n, dtype=bool)
        self._out = StepArrays(
            features=self.report[:, : len(FEATURES)],
            reward_terms=self.report[:, R_TERMS:R_REWARD],
            reward=self.report[:, R_REWARD],
            outcome=self._outcome,
            terminated=self._terminated,
            push_force_n=self.report[:, R_PUSH],
            verbal_cue=self.report[:, F_VERBAL],
        )
        self._all = np.arange(n, dtype=np.int64)
        self._draws = np.zeros((n, _D_NORMALS + n_varied))

    def _make_multiple_model(self, options: dict[str, Any]) -> Any:
        from estimator.multiple_model import IMMEstimator, MultipleModelEstimator

        cls = IMMEstimator if self.estimator == "imm" else MultipleModelEstimator
        try:
            return cls(np.tile(self._persona_nominal[0], (self.n_envs, 1)), np.zeros(self.n_envs), **options)
        except TypeError as exc:  # an unknown option name
            raise ValueError(f"estimator_options for {self.estimator!r}: {exc}") from None

    @property
    def out(self) -> StepArrays:
        """What the last step or reset produced, as :class:`StepArrays` (views; outcome and terminated refreshed)."""
        np.copyto(self._outcome, self.report[:, R_OUTCOME], casting="unsafe")
        np.take(_ENDED_BY_LIFT, self._outcome, out=self._terminated)
        return self._out

    @property
    def persona_index(self) -> NDArray[np.int64]:
        """(N,) index into ``personas`` of each env's current persona."""
        return self.report[:, R_PERSONA].astype(np.int64)

    # --- episodes -------------------------------------------------------------

    def set_rng(self, i: int, rng: np.random.Generator) -> None:
        """Make ``rng`` env ``i``'s source of randomness (kept for its following episodes)."""
        if self.rngs[i] is not rng:
            self.generators[i] = bit_generator_row(rng)
            self.rngs[i] = rng

    def reset_env(
        self, i: int, rng: np.random.Generator, persona_index: int | None = None, initial_xi: int | None = None
    ) -> None:
        """Start a new episode in env ``i``, drawing its person from ``rng``.

        Args:
            i: Env index.
            rng: The env's generator; kept for the episode's step noise.
            persona_index: Use this persona (index into ``personas``) instead of drawing one.
            initial_xi: Start at this cooperativeness instead of drawing it.
        """
        self.set_rng(i, rng)
        self.reset_envs(self._all[i : i + 1], persona_index, initial_xi)

    def reset_envs(
        self, indices: NDArray[np.int64], persona_index: int | None = None, initial_xi: int | None = None
    ) -> None:
        """Start new episodes in envs ``indices`` (int64 array), each drawing from its own generator.

        The same draws happen whatever is fixed, so fixing the persona or ``initial_xi``
        shifts nothing else in the random stream.
        """
        count = indices.shape[0]
        if count == 0:
            return
        draws = self._draws[:count]
        override = _NO_OVERRIDE if persona_index is None else persona_index
        failed = _draw_reset(indices, self.generators, len(self.personas), override, draws)
        if failed >= 0:
            raise RuntimeError(f"env {failed} has no random generator; call reset_env(i, rng) or set_rng first")
        # The variation factors exp(std * z) with NumPy's exp, not a compiled one: NumPy's SIMD
        # exp can differ in the last bit, and the person must equal sample_person's exactly.
        factors = draws[:, _D_NORMALS:]
        std = self._variation_std
        if std is None:
            std = self._persona_variation_std[draws[:, _D_PERSONA].astype(np.int64)][:, None]
        np.multiply(factors, std, out=factors)
        np.exp(factors, out=factors)
        _reset_rows(
            indices,
            _NO_OVERRIDE if initial_xi is None else initial_xi,
            draws,
            self.persona_table,
            self.state,
            self.obs,
            self.consts,
        )
        if self.mm is not None:
            # The persona (and so the nominal model) may change from episode to episode.
            self.mm.nominal[indices] = self.nominal[indices]
            self.mm.reset(indices, draws[:, _D_LEAN])
            self.report[indices, F_P_M1 : F_P_P1 + 1] = self.mm.probabilities[indices]
            _observe(indices, self.state, self.obs, self.consts)

    # --- stepping -------------------------------------------------------------

    def step(
        self, push_force_n: NDArray[np.float64], verbal_cue: NDArray[np.float64], lift: NDArray[np.bool_]
    ) -> StepArrays:
        """Advance every env by one agent action (already decoded and validated)."""
        cmd = self.cmd
        cmd[:, CMD_PUSH] = push_force_n
        cmd[:, CMD_VERBAL] = verbal_cue
        cmd[:, CMD_LIFT] = lift
        cmd[:, CMD_ACTIVE] = 1.0
        self.step_commands(cmd)
        return self.out

    def step_commands(self, cmd: NDArray[np.float64]) -> None:
        """Advance the active envs by one agent action; results land in ``report`` and ``obs``.

        Args:
            cmd: (N, 4) float64 C-contiguous rows ``[push_force_n, verbal_cue, lift, active]``
                (decoded and validated); envs with ``active == 0`` are left untouched.
        """
        failed = _advance(cmd, self.state, self.generators, self.obs, self.consts)
        if failed >= 0:
            raise RuntimeError(f"env {failed} was stepped before it was reset")
        if self.mm is not None:
            probs = self.mm.run(self._block_cp, self._block_cv, self._block_y)
            self.report[:, F_P_M1 : F_P_P1 + 1] = probs[:, -1]
            _observe(self._all, self.state, self.obs, self.consts)

    # --- pickling -----------------------------------------------------------------
    # ``generators`` holds raw addresses of the generators' C states and ``person``, ``P``,
    # ``report`` ... are views into ``state``: a pickled copy would go on drawing from (and
    # advancing) the original's generators -- or freed memory in another process -- and its
    # views would no longer alias ``state``. So a copy is rebuilt by the constructor and
    # refilled with the saved values (tests/coop_gym/test_determinism.py).

    def __getstate__(self) -> dict[str, Any]:
        """The saved values; ``generators`` is left out (rebuilt from ``rngs``)."""
        return {k: v for k, v in self.__dict__.items() if k != "generators"}

    def __setstate__(self, saved: dict[str, Any]) -> None:
        """Rebuild the arrays and their views, then copy the saved values into them."""
        self.__init__(*saved["_init_args"])  # type: ignore[misc]
        for name, value in saved.items():
            current = self.__dict__.get(name)
            if isinstance(value, np.ndarray) and isinstance(current, np.ndarray) and current.shape == value.shape:
                np.copyto(current, value)
            elif not (dataclasses.is_dataclass(current) and not isinstance(current, type)):
                self.__dict__[name] = value  # keep rebuilt holders of views (e.g. ``out``)
        for i, rng in enumerate(self.rngs):
            if rng is not None:
                self.generators[i] = bit_generator_row(rng)


def _pack_consts(
    core: SitToStandCore,
    index: tuple[int, ...],
    observation_low: NDArray[np.float64] | None,
    observation_high: NDArray[np.float64] | None,
    varied: list[int],
) -> NDArray[np.float64]:
    """The scalars the kernels read (``_C_*``), then the observation spec, varied columns and initial state row."""
    timing, reward, prior = core.timing, core.reward_weights, core._nominal_prior
    n_obs = len(index)
    template = initial_state_row(0, 0.0)
    consts = np.zeros(_N_CONSTS + 3 * n_obs + len(varied) + len(template))
    consts[_C_SUBSTEPS] = timing.substeps
    consts[_C_VERBAL_S] = core.cues.verbal_duration_s
    consts[_C_JUDGE_DELAY_S] = core.judgment.delay_s
    consts[_C_JUDGE_THRESHOLD] = core.judgment.threshold
    consts[_C_SUCCESS_LEAN_M] = core.lift.success_lean_m
    consts[_C_UPRIGHT_M] = core.lift.upright_m
    consts[_C_EPISODE_S] = timing.episode_s
    consts[_C_W_SUCCESS] = reward.success
    consts[_C_W_UNSAFE] = reward.unsafe
    consts[_C_W_PREMATURE] = reward.premature
    consts[_C_TIME_TERM] = -reward.time_per_s * timing.action_period_s
    consts[_C_W_FORCE] = reward.force_per_n_s
    consts[_C_VARY] = 1.0 if core.realism.person_variation else 0.0
    consts[_C_XDOT_VAR] = prior.initial_velocity_std_m_per_s**2
    consts[_C_ETA_VAR] = prior.initial_intention_std_m**2
    consts[_C_XI_VAR] = prior.initial_cooperativeness_std**2
    consts[_C_XI_STD] = prior.initial_cooperativeness_std
    consts[_C_N_OBS] = n_obs
    consts[_C_N_VARIED] = len(varied)
    at = _N_CONSTS
    consts[_C_OBS_AT] = at
    consts[at : at + n_obs] = index
    consts[at + n_obs : at + 2 * n_obs] = -np.inf if observation_low is None else observation_low
    consts[at + 2 * n_obs : at + 3 * n_obs] = np.inf if observation_high is None else observation_high
    consts[_C_VARIED_AT] = at = at + 3 * n_obs
    consts[at : at + len(varied)] = varied
    consts[_C_TEMPLATE_AT] = at = at + len(varied)
    consts[at : at + len(template)] = template
    return consts


guard_kernel_cache(__name__)
