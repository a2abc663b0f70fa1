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

Threads: a batch of at least 2 x :data:`MIN_ENVS_PER_THREAD` envs steps on up to
:attr:`SitToStandCore.threads` threads (:meth:`SitToStandCore.set_threads`), each running the
compiled step, without the GIL, on blocks of envs it claims from an atomic counter. Env ``i``'s
numbers depend only on its own row and generator, so the results are bit-identical whatever
the thread count (tests/coop_gym/test_threads.py).

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
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from compiled.atomics import atomic_add, atomic_cas, atomic_load
from compiled.cache import guard_kernel_cache
from compiled.rng import G_STATE, bit_generator_row, integers, random, standard_normal
from compiled.schema import field_values, index_table, offset_table
from coop_gym.envs.config import LiftCriteria, Outcome, RewardWeights
from coop_gym.envs.contract import (
    CMD,
    CMD_COLUMNS,
    FEATURES,
    REPORT,
    REPORT_COLUMNS,
    REWARD_TERMS,
    TERMINATES,
)
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
    zoh_coefficients_batch,
)
from coop_gym.model.params import Cues, PersonParams, Realism, Timing
from coop_gym.model.personas import VARIED_PARAMETERS, Persona
from estimator.judgment import JUDGE, JUDGMENT_COLUMNS, ThresholdJudgment, judgment_substep
from estimator.kalman import NOMINAL, NOMINAL_COLUMNS, kalman_step, nominal_row
from estimator.nominal import STATE_DIM, NominalModel

__all__ = [
    "FEATURES",  # the env contract's (coop_gym.envs.contract), for the importers of this module
    "REPORT",
    "REPORT_COLUMNS",
    "REWARD_TERMS",
    "SitToStandCore",
    "StepArrays",
    "nominal_model_for",
]

CUE_COLUMNS: tuple[str, ...] = ("verbal_value", "verbal_remaining_s", "elapsed_s", "impulse_n_s")
"""Per-env bookkeeping of the cue scheduler: the utterance playing, the clock, the step's push impulse."""
CUES = index_table("CueColumns", CUE_COLUMNS)

BLOCKS = offset_table(
    "StateBlocks",
    {
        "person": len(STATE_COLUMNS),
        "cues": len(CUE_COLUMNS),
        "mean": STATE_DIM,
        "cov": STATE_DIM * STATE_DIM,
        "judge": len(JUDGMENT_COLUMNS),
        "nominal": len(NOMINAL_COLUMNS),
        "params": len(PARAM_COLUMNS),
        "delay_push": DELAY_LINE_LENGTH,
        "delay_verbal": DELAY_LINE_LENGTH,
        "report": len(REPORT_COLUMNS),
    },
)
"""Start of each block of the packed per-env state row (SitToStandCore.state); after ``end`` come
3 x substeps scratch columns: measured force, verbal cue, position."""

CONST_COLUMNS: tuple[str, ...] = (
    "substeps",
    "verbal_duration_s",
    "judgment_delay_s",
    "judgment_threshold",
    "success_lean_m",
    "upright_m",
    "episode_s",
    "reward_success",
    "reward_unsafe",
    "reward_premature",
    "time_term",
    "force_per_n_s",
    "build_obs",
    "vary",
    "xdot_var",
    "eta_var",
    "xi_var",
    "xi_std",
    "n_obs",
    "n_varied",
    "obs_at",
    "varied_at",
    "template_at",
)
"""Scalars the kernels read, packed in one float array (SitToStandCore.consts)."""
CONSTS = index_table("ConstColumns", CONST_COLUMNS)
# After the scalars come the observation spec (feature index, low, high; n_obs each), the
# columns sample_person varies, and the person's initial state row.

# Columns of the scratch rows of a reset: the draws, then (from ``normals`` on) the variation
# normals, turned into factors.
DRAW_COLUMNS: tuple[str, ...] = ("persona", "uniform", "lean", "normals")
DRAWS = index_table("DrawColumns", DRAW_COLUMNS)

# Columns of a persona-table row: the packed person, the filter's nominal row, the initial-xi cuts.
PERSONA_BLOCKS = offset_table(
    "PersonaBlocks", {"params": len(PARAM_COLUMNS), "nominal": len(NOMINAL_COLUMNS), "xi_cuts": 2}
)


# Outcome codes the kernel writes, from the enum (Numba freezes them into the machine code).
_NONE = int(Outcome.NONE)
_SUCCESS = int(Outcome.SUCCESS)
_UNSAFE = int(Outcome.UNSAFE)
_PREMATURE = int(Outcome.PREMATURE)
_TIMEOUT = int(Outcome.TIMEOUT)

INITIAL_LEAN_STD_M = 0.005
"""People sit a little differently: std of the initial forward lean [m]."""

_NO_OVERRIDE = -99  # "draw it" for the persona / initial-xi overrides of a reset

MIN_ENVS_PER_THREAD = 512
"""Fewer envs per thread than this step on one thread. Measured on the quiet 2-core VM (the vector
env under random actions, 20 alternating runs of 100 steps, 2 threads over 1, three sessions):
256 envs 0.75-0.88x, 512 envs 0.89-1.08x, 1024 envs 1.04-1.29x. A threaded step costs a worker's
wake-up (~0.1 ms on that VM) and moves the envs' rows between the cores' caches (~2 KB per env),
so two threads pay only from ~1024 envs; the single env and SB3-sized batches step on one."""


ENVS_PER_BLOCK = 64
"""Envs per block a thread claims at a time in a threaded step (~50 us of work: small enough that
the threads finish together, large enough that claiming costs little)."""


def available_threads() -> int:
    """The threads a batched core uses by default: the cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def check_threads(threads: Any) -> int:
    """``threads`` validated: ``None`` (:func:`available_threads`) or a positive int."""
    if threads is None:
        return available_threads()
    if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1:
        raise ValueError(f"threads must be None or a positive int, got {threads!r}")
    return int(threads)


# The worker threads of threaded steps, shared by every core of the process and started at
# the first threaded step. Python threads calling a ``nogil`` kernel, not Numba's OpenMP
# ``parallel=True``: OpenMP's threads spin between steps, and once torch has loaded its own
# OpenMP runtime (Numba then uses that one, whose wait policy is already fixed) a 2-thread
# step of 1024 envs took 18 ms instead of 2 ms on the loaded dev machine. GNU OpenMP also
# aborts children forked after a parallel region; these threads are simply gone in a child.
_workers: ThreadPoolExecutor | None = None
_workers_lock = threading.Lock()


def _worker_pool(count: int) -> ThreadPoolExecutor:
    """A pool of at least ``count`` worker threads."""
    global _workers
    with _workers_lock:
        if _workers is None or _workers._max_workers < count:
            if _workers is not None:
                _workers.shutdown(wait=False)
            _workers = ThreadPoolExecutor(count, thread_name_prefix="coop_gym-step")
        return _workers


def _forget_workers() -> None:
    # In a forked child the parent's threads do not exist: start new ones when needed.
    global _workers, _workers_lock
    _workers = None
    _workers_lock = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_workers)


def _no_generator_message(i: int) -> str:
    return f"env {i} has no random generator; call reset_env(i, rng) or set_rng first"


def nominal_model_for(person: PersonParams, timing: Timing, base: NominalModel | None = None) -> NominalModel:
    """The filter's nominal model for a persona: its typical gains, the paper's linear form.

    The filter sees the persona's *typical* parameters, not the episode's varied person,
    and none of the realism knobs -- the gap real people leave.
    """
    base = base or NominalModel()
    # The nominal model shares its gains' names with the person's fields: copy every shared one.
    person_values = {**field_values(person), "dt_s": timing.dt_s}
    shared = {f.name: person_values[f.name] for f in dataclasses.fields(NominalModel) if f.name in person_values}
    # A noiseless camera still needs R > 0 for the filter to be well posed.
    shared["position_noise_std_m"] = max(shared["position_noise_std_m"], 1e-4)
    return base.replace(**shared)


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


@njit(cache=True, error_model="numpy")
def _observe_row(row: NDArray[np.float64], obs_row: NDArray[np.float32], consts: NDArray[np.float64]) -> None:
    # Select the features and clip in float64, then round: as np.clip(f, low, high).astype(float32).
    n_obs = int(consts[CONSTS.n_obs])
    at = int(consts[CONSTS.obs_at])
    for k in range(n_obs):
        value = row[BLOCKS.report + int(consts[at + k])]
        obs_row[k] = min(max(value, consts[at + n_obs + k]), consts[at + 2 * n_obs + k])


@njit(cache=True, error_model="numpy")
def _observe(
    indices: NDArray[np.int64], state: NDArray[np.float64], obs: NDArray[np.float32], consts: NDArray[np.float64]
) -> None:
    for i in indices:
        _observe_row(state[i], obs[i], consts)


@njit(cache=True, error_model="numpy", nogil=True)
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
        draws[r, DRAWS.persona] = drawn if persona_override == _NO_OVERRIDE else persona_override
        for j in range(DRAWS.normals, draws.shape[1]):
            draws[r, j] = standard_normal(g)
        draws[r, DRAWS.uniform] = random(g)
        draws[r, DRAWS.lean] = 0.0 + INITIAL_LEAN_STD_M * standard_normal(g)
    return -1


@njit(cache=True, error_model="numpy", nogil=True)
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
    episode_s = consts[CONSTS.episode_s]
    n_varied = int(consts[CONSTS.n_varied])
    varied_at = int(consts[CONSTS.varied_at])
    template_at = int(consts[CONSTS.template_at])
    count = indices.shape[0]
    damping = np.empty(count)
    gain = np.empty(count)
    dt = np.empty(count)
    for r in range(count):
        i = indices[r]
        persona = persona_table[int(draws[r, DRAWS.persona])]
        row = state[i]
        # Element loops, not slice assignments: those compile numba's shape-mismatch error
        # formatting (~4 s of every cold start); the copies are the same.
        for j in range(row.shape[0]):
            row[j] = 0.0
        # The person: the persona's packed row with the varied gains scaled (= sample_person + pack_person).
        p = row[BLOCKS.params : BLOCKS.params + len(PARAM_COLUMNS)]
        for j in range(len(PARAM_COLUMNS)):
            p[j] = persona[PERSONA_BLOCKS.params + j]
        if consts[CONSTS.vary] > 0.5:
            for j in range(n_varied):
                column = int(consts[varied_at + j])
                p[column] = persona[PERSONA_BLOCKS.params + column] * draws[r, DRAWS.normals + j]
        damping[r] = p[PERSON.damping_rate_per_s]
        gain[r] = p[PERSON.voluntary_gain_per_s2]
        dt[r] = p[PERSON.dt_s]
    # eq. 1's zero-order hold of every reset person in one batch (zoh_coefficients, bit for bit).
    zoh = np.empty((count, 6))
    zoh_coefficients_batch(damping, gain, dt, zoh)
    for r in range(count):
        i = indices[r]
        k = int(draws[r, DRAWS.persona])
        persona = persona_table[k]
        row = state[i]
        p = row[BLOCKS.params : BLOCKS.params + len(PARAM_COLUMNS)]
        p[PERSON.zoh_a00] = zoh[r, 0]
        p[PERSON.zoh_a01] = zoh[r, 1]
        p[PERSON.zoh_a10] = zoh[r, 2]
        p[PERSON.zoh_a11] = zoh[r, 3]
        p[PERSON.zoh_b0] = zoh[r, 4]
        p[PERSON.zoh_b1] = zoh[r, 5]
        u = draws[r, DRAWS.uniform]
        xi = -1.0 if u < persona[PERSONA_BLOCKS.xi_cuts] else (1.0 if u > persona[PERSONA_BLOCKS.xi_cuts + 1] else 0.0)
        if xi_override != _NO_OVERRIDE:
            xi = float(xi_override)
        x0 = draws[r, DRAWS.lean]
        # initial_state_row(xi, x0): at rest at x0, intending to stay.
        s = row[BLOCKS.person : BLOCKS.person + len(STATE_COLUMNS)]
        for j in range(len(STATE_COLUMNS)):
            s[j] = consts[template_at + j]
        s[STATE.x_m] = x0
        s[STATE.eta_m] = x0
        s[STATE.xi] = xi
        # The filter, centred on the first reading with the nominal model's prior.
        nominal_width = len(NOMINAL_COLUMNS)
        for j in range(nominal_width):
            row[BLOCKS.nominal + j] = persona[PERSONA_BLOCKS.nominal + j]
        row[BLOCKS.mean] = x0
        row[BLOCKS.mean + 2] = x0
        row[BLOCKS.cov] = persona[PERSONA_BLOCKS.nominal + NOMINAL.r_position]  # P[0, 0] = R
        row[BLOCKS.cov + STATE_DIM + 1] = consts[CONSTS.xdot_var]
        row[BLOCKS.cov + 2 * (STATE_DIM + 1)] = consts[CONSTS.eta_var]
        row[BLOCKS.cov + 3 * (STATE_DIM + 1)] = consts[CONSTS.xi_var]
        row[BLOCKS.judge + JUDGE.since_onset_s] = episode_s
        rep = row[BLOCKS.report : BLOCKS.report + len(REPORT_COLUMNS)]
        rep[REPORT.measured_position_m] = x0
        rep[REPORT.x_hat_m] = x0
        rep[REPORT.eta_hat_m] = x0
        rep[REPORT.xi_std] = consts[CONSTS.xi_std]
        rep[REPORT.time_since_cue_onset_s] = episode_s
        rep[REPORT.true_xi] = xi
        rep[REPORT.true_x_m] = x0
        rep[REPORT.true_eta_m] = x0
        rep[REPORT.info_true_xi] = xi
        rep[REPORT.persona_index] = k
        if consts[CONSTS.build_obs] > 0.5:
            _observe_row(row, obs[i], consts)


@njit(cache=True, error_model="numpy")
def _lift_outcome(s: NDArray[np.float64], consts: NDArray[np.float64]) -> int:
    # The lift is judged on the true state at the moment it starts (§II).
    if s[STATE.xi] > 0.5 and s[STATE.x_m] >= consts[CONSTS.success_lean_m]:
        return _SUCCESS
    if s[STATE.xi] < -0.5 or s[STATE.x_m] < consts[CONSTS.upright_m]:
        return _UNSAFE
    return _PREMATURE


@njit(cache=True, error_model="numpy")
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
    substeps = int(consts[CONSTS.substeps])
    episode_s = consts[CONSTS.episode_s]
    s = row[BLOCKS.person : BLOCKS.person + len(STATE_COLUMNS)]
    env = row[BLOCKS.cues : BLOCKS.cues + len(CUE_COLUMNS)]
    m = row[BLOCKS.mean : BLOCKS.mean + STATE_DIM]
    P = row[BLOCKS.cov : BLOCKS.cov + STATE_DIM * STATE_DIM].reshape((STATE_DIM, STATE_DIM))
    judge = row[BLOCKS.judge : BLOCKS.judge + len(JUDGMENT_COLUMNS)]
    nominal = row[BLOCKS.nominal : BLOCKS.nominal + len(NOMINAL_COLUMNS)]
    p = row[BLOCKS.params : BLOCKS.params + len(PARAM_COLUMNS)]
    delay_push = row[BLOCKS.delay_push : BLOCKS.delay_push + DELAY_LINE_LENGTH]
    delay_verbal = row[BLOCKS.delay_verbal : BLOCKS.delay_verbal + DELAY_LINE_LENGTH]
    f = row[BLOCKS.report : BLOCKS.report + len(REPORT_COLUMNS)]
    block = row[BLOCKS.end : BLOCKS.end + 3 * substeps]
    dt = p[PERSON.dt_s]
    # A verbal cue is an utterance of fixed length; one can't talk over oneself.
    if env[CUES.verbal_remaining_s] <= 0.0 and verbal_request != 0.0:
        env[CUES.verbal_value] = verbal_request
        env[CUES.verbal_remaining_s] = consts[CONSTS.verbal_duration_s]
    for k in range(substeps):
        cv = env[CUES.verbal_value] if env[CUES.verbal_remaining_s] > 1e-9 else 0.0
        for j in range(NORMALS_PER_SUBSTEP):
            z[j] = standard_normal(g)
        person_substep(s, p, delay_push, delay_verbal, cp, cv, z)
        pos, force = measure(s, p, cp, z[3], z[4])
        kalman_step(m, P, nominal, force, cv, pos)
        judgment_substep(
            judge, cp > 0.0 or cv != 0.0, m[3], consts[CONSTS.judgment_delay_s], consts[CONSTS.judgment_threshold], dt
        )
        block[k] = force
        block[substeps + k] = cv
        block[2 * substeps + k] = pos
        env[CUES.verbal_remaining_s] -= dt
        env[CUES.impulse_n_s] += cp * dt
        f[REPORT.measured_position_m] = pos
        f[REPORT.measured_force_n] = force
    if env[CUES.verbal_remaining_s] <= 1e-9:
        env[CUES.verbal_remaining_s] = 0.0
        env[CUES.verbal_value] = 0.0
    env[CUES.elapsed_s] += substeps * dt
    f[REPORT.verbal_cue] = env[CUES.verbal_value]
    f[REPORT.time_since_cue_onset_s] = min(judge[JUDGE.since_onset_s], episode_s)
    f[REPORT.x_hat_m] = m[0]
    f[REPORT.xdot_hat_m_per_s] = m[1]
    f[REPORT.eta_hat_m] = m[2]
    f[REPORT.xi_hat] = m[3]
    f[REPORT.xi_std] = np.sqrt(max(P[3, 3], 0.0))
    f[REPORT.judgment] = judge[JUDGE.judgment]
    f[REPORT.elapsed_s] = env[CUES.elapsed_s]
    f[REPORT.true_xi] = s[STATE.xi]
    if env[CUES.elapsed_s] >= episode_s - 1e-9:
        return _TIMEOUT  # truncation happens on this same step
    return _NONE


@njit(cache=True, error_model="numpy")
def _write_reward_and_truth(
    row: NDArray[np.float64], result: int, lift: bool, cp: float, consts: NDArray[np.float64]
) -> None:
    # Named reward terms (RewardWeights), then their sum; the outcome, the push and the true state.
    s = row[BLOCKS.person : BLOCKS.person + len(STATE_COLUMNS)]
    f = row[BLOCKS.report : BLOCKS.report + len(REPORT_COLUMNS)]
    t_success = consts[CONSTS.reward_success] if result == _SUCCESS else 0.0
    t_unsafe = -consts[CONSTS.reward_unsafe] if result == _UNSAFE else 0.0
    t_premature = -consts[CONSTS.reward_premature] if result == _PREMATURE else 0.0
    t_time = 0.0 if lift else consts[CONSTS.time_term]
    t_force = -consts[CONSTS.force_per_n_s] * row[BLOCKS.cues + CUES.impulse_n_s]
    f[REPORT.reward_success] = t_success
    f[REPORT.reward_unsafe] = t_unsafe
    f[REPORT.reward_premature] = t_premature
    f[REPORT.reward_time] = t_time
    f[REPORT.reward_force] = t_force
    f[REPORT.reward] = t_success + t_unsafe + t_premature + t_time + t_force
    f[REPORT.outcome] = result
    f[REPORT.push_force_n] = 0.0 if lift else cp
    f[REPORT.true_x_m] = s[STATE.x_m]
    f[REPORT.true_xdot_m_per_s] = s[STATE.xdot_m_per_s]
    f[REPORT.true_eta_m] = s[STATE.eta_m]
    f[REPORT.info_true_xi] = s[STATE.xi]


@njit(cache=True, error_model="numpy")
def _unready(cmd: NDArray[np.float64], generators: NDArray[np.uint64]) -> int:
    # The first active env that was never reset (has no generator), or -1. Checked before any
    # env is stepped, in order, so a failed call changes nothing and names the lowest such env.
    for i in range(cmd.shape[0]):
        if cmd[i, CMD.active] > 0.5 and generators[i, G_STATE] == 0:
            return i
    return -1


@njit(cache=True, error_model="numpy", nogil=True)
def _advance_rows(
    start: int,
    stop: int,
    cmd: NDArray[np.float64],
    state: NDArray[np.float64],
    generators: NDArray[np.uint64],
    obs: NDArray[np.float32],
    consts: NDArray[np.float64],
) -> None:
    # Step the active envs start..stop-1. Each env touches only its own rows and its own
    # generator, so disjoint ranges can run on different threads; ``z`` is this call's scratch.
    substeps = int(consts[CONSTS.substeps])
    z = np.empty(NORMALS_PER_SUBSTEP)
    for i in range(start, stop):
        if cmd[i, CMD.active] < 0.5:
            continue
        row = state[i]
        cp = cmd[i, CMD.push_force_n]
        lift = cmd[i, CMD.lift] > 0.5
        row[BLOCKS.cues + CUES.impulse_n_s] = 0.0
        if lift:
            result = _lift_outcome(row[BLOCKS.person : BLOCKS.person + len(STATE_COLUMNS)], consts)
            # The filter's input blocks hold still: no push, no cue, the last reading.
            block = row[BLOCKS.end : BLOCKS.end + 3 * substeps]
            for k in range(substeps):
                block[k] = 0.0
                block[substeps + k] = 0.0
                block[2 * substeps + k] = row[BLOCKS.report + REPORT.measured_position_m]
        else:
            result = _simulate_action(row, cp, cmd[i, CMD.verbal_cue], generators[i], z, consts)
        _write_reward_and_truth(row, result, lift, cp, consts)
        if consts[CONSTS.build_obs] > 0.5:
            _observe_row(row, obs[i], consts)


# The threaded step's control words (an int64 array per core): the claim word -- the step's
# number in the high bits, the next unclaimed block in the low 32 -- and the blocks done. Step
# numbers wrap at 2**31, so the claim word stays a non-negative int64.
_CLAIM, _DONE = 0, 1
_LOW32 = (1 << 32) - 1
_STEP_NUMBERS = 1 << 31


@njit(cache=True, error_model="numpy", nogil=True)
def _advance_claimed(
    step: int,
    blocks: int,
    control: NDArray[np.int64],
    cmd: NDArray[np.float64],
    state: NDArray[np.float64],
    generators: NDArray[np.uint64],
    obs: NDArray[np.float32],
    consts: NDArray[np.float64],
) -> None:
    # Step blocks of envs, claimed one at a time, until step ``step`` has none left. A worker that
    # starts after its step is over finds another step's number in the claim word and does nothing.
    n = cmd.shape[0]
    while True:
        word = atomic_load(control, _CLAIM)
        block = word & _LOW32
        if word >> 32 != step or block >= blocks:
            return
        if atomic_cas(control, _CLAIM, word, word + 1) == word:
            _advance_rows(block * n // blocks, (block + 1) * n // blocks, cmd, state, generators, obs, consts)
            atomic_add(control, _DONE, 1)


def _yield_core() -> None:
    # The scheduler may run another thread on this core now (the GIL is released meanwhile).
    if hasattr(os, "sched_yield"):
        os.sched_yield()
    else:  # Windows
        time.sleep(0)


_WAIT_SPINS = 20_000
"""Reads of the done count before the waiting thread yields its core (tens of microseconds: about
one block's work, the usual wait; on a busy machine a worker holding a block gets the core)."""


@njit(cache=True, error_model="numpy", nogil=True)
def _close_step(control: NDArray[np.int64], blocks: int) -> int:
    # Leave no block of the current step to claim; returns how many were claimed (all of them,
    # unless the calling thread was interrupted before it had claimed the rest).
    while True:
        word = atomic_load(control, _CLAIM)
        claimed = word & _LOW32
        if claimed >= blocks:
            return blocks
        if atomic_cas(control, _CLAIM, word, word - claimed + blocks) == word:
            return claimed


@njit(cache=True, error_model="numpy", nogil=True)
def _blocks_done(control: NDArray[np.int64], blocks: int, spins: int) -> bool:
    # Whether every block is done, read up to ``spins`` times: a wait too short to sleep through.
    for _ in range(spins):
        if atomic_load(control, _DONE) >= blocks:
            return True
    return False


@njit(cache=True, error_model="numpy")
def _advance(
    cmd: NDArray[np.float64],
    state: NDArray[np.float64],
    generators: NDArray[np.uint64],
    obs: NDArray[np.float32],
    consts: NDArray[np.float64],
) -> int:
    # Returns -1, or the index of an active env that was never reset (nothing is stepped then).
    failed = _unready(cmd, generators)
    if failed < 0:
        _advance_rows(0, cmd.shape[0], cmd, state, generators, obs, consts)
    return failed


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
        cmd: (N, 4) command rows (columns :data:`~coop_gym.envs.contract.CMD`) for :meth:`step_commands`.
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
        self.threads = available_threads()
        self._chunks = 0  # threads a step uses; 0: plan again (see _plan_chunks)
        self._control = np.zeros(2, dtype=np.int64)  # a threaded step's claim word and blocks done
        # With a multiple-model estimator the observation waits for its probabilities.
        self.consts[CONSTS.build_obs] = 1.0 if self.mm is None else 0.0

    def _pack_personas(self) -> list[int]:
        """Fill ``persona_table`` and the variation stds; return the varied columns of a packed person."""
        personas, timing, realism = self.personas, self.timing, self.realism
        # The filter's nominal model depends only on the persona: pack each once.
        self._persona_nominal = [nominal_row(nominal_model_for(p.params, timing)) for p in personas]
        # Each persona packed once; a reset scales the varied gains (as sample_person does) and
        # recomputes the zero-order hold, instead of building and validating dataclasses.
        table = np.zeros((len(personas), PERSONA_BLOCKS.end))
        for k, persona in enumerate(personas):
            coop = persona.params.cooperativeness
            table[k, PERSONA_BLOCKS.params : PERSONA_BLOCKS.nominal] = pack_person(
                persona.params.with_realism(realism), timing
            )
            table[k, PERSONA_BLOCKS.nominal : PERSONA_BLOCKS.xi_cuts] = self._persona_nominal[k]
            table[k, PERSONA_BLOCKS.xi_cuts] = coop.initial_p_uncooperative
            table[k, PERSONA_BLOCKS.xi_cuts + 1] = 1.0 - coop.initial_p_cooperative
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
        self.state = st = np.zeros((n, BLOCKS.end + 3 * substeps))
        self.person = st[:, BLOCKS.person : BLOCKS.person + len(STATE_COLUMNS)]
        self.env = st[:, BLOCKS.cues : BLOCKS.cues + len(CUE_COLUMNS)]
        self.m = st[:, BLOCKS.mean : BLOCKS.mean + STATE_DIM]
        self.P = st[:, BLOCKS.cov : BLOCKS.cov + STATE_DIM * STATE_DIM].reshape(n, STATE_DIM, STATE_DIM)
        self.judge = st[:, BLOCKS.judge : BLOCKS.judge + len(JUDGMENT_COLUMNS)]
        self.nominal = st[:, BLOCKS.nominal : BLOCKS.nominal + len(NOMINAL_COLUMNS)]
        self.params = st[:, BLOCKS.params : BLOCKS.params + len(PARAM_COLUMNS)]
        self.delay_push = st[:, BLOCKS.delay_push : BLOCKS.delay_push + DELAY_LINE_LENGTH]
        self.delay_verbal = st[:, BLOCKS.delay_verbal : BLOCKS.delay_verbal + DELAY_LINE_LENGTH]
        self.report = st[:, BLOCKS.report : BLOCKS.report + len(REPORT_COLUMNS)]
        self._block_cp = st[:, BLOCKS.end : BLOCKS.end + substeps]
        self._block_cv = st[:, BLOCKS.end + substeps : BLOCKS.end + 2 * substeps]
        self._block_y = st[:, BLOCKS.end + 2 * substeps : BLOCKS.end + 3 * substeps]
        self.rngs: list[np.random.Generator | None] = [None] * n
        self.generators = np.zeros((n, 4), dtype=np.uint64)
        self.cmd = np.zeros((n, len(CMD_COLUMNS)))
        self.cmd[:, CMD.active] = 1.0
        self.obs = np.zeros((n, n_obs), dtype=np.float32)
        self._outcome = np.zeros(n, dtype=np.int64)
        self._terminated = np.zeros(n, dtype=bool)
        self._out = StepArrays(
            features=self.report[:, : len(FEATURES)],
            reward_terms=self.report[:, REPORT.reward_success : REPORT.reward],
            reward=self.report[:, REPORT.reward],
            outcome=self._outcome,
            terminated=self._terminated,
            push_force_n=self.report[:, REPORT.push_force_n],
            verbal_cue=self.report[:, REPORT.verbal_cue],
        )
        self._all = np.arange(n, dtype=np.int64)
        self._draws = np.zeros((n, DRAWS.normals + n_varied))

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
        np.copyto(self._outcome, self.report[:, REPORT.outcome], casting="unsafe")
        np.take(TERMINATES, self._outcome, out=self._terminated)
        return self._out

    @property
    def persona_index(self) -> NDArray[np.int64]:
        """(N,) index into ``personas`` of each env's current persona."""
        return self.report[:, REPORT.persona_index].astype(np.int64)

    # --- episodes -------------------------------------------------------------

    def set_threads(self, threads: int | None) -> None:
        """Step on up to ``threads`` threads (``None``: :func:`available_threads`); results do not depend on it."""
        self.threads = check_threads(threads)
        self._chunks = 0

    def _plan_chunks(self) -> int:
        """How many threads (contiguous ranges of envs) a step uses: 1 unless it pays and is safe."""
        chunks = min(self.threads, self.n_envs // MIN_ENVS_PER_THREAD)
        if chunks > 1:
            # Two envs drawing from one generator must draw in env order: one thread.
            drawing = self.generators[:, G_STATE]
            drawing = drawing[drawing != 0]
            if np.unique(drawing).shape[0] != drawing.shape[0]:
                chunks = 1
        self._chunks = max(chunks, 1)
        return self._chunks

    def set_rng(self, i: int, rng: np.random.Generator) -> None:
        """Make ``rng`` env ``i``'s source of randomness (kept for its following episodes)."""
        if self.rngs[i] is not rng:
            self.generators[i] = bit_generator_row(rng)
            self.rngs[i] = rng
            self._chunks = 0

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
            raise RuntimeError(_no_generator_message(failed))
        # The variation factors exp(std * z) with NumPy's exp, not a compiled one: NumPy's SIMD
        # exp can differ in the last bit, and the person must equal sample_person's exactly.
        factors = draws[:, DRAWS.normals :]
        std = self._variation_std
        if std is None:
            std = self._persona_variation_std[draws[:, DRAWS.persona].astype(np.int64)][:, None]
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
            self.mm.reset(indices, draws[:, DRAWS.lean])
            self.report[indices, REPORT.p_uncooperative : REPORT.p_cooperative + 1] = self.mm.probabilities[indices]
            _observe(indices, self.state, self.obs, self.consts)

    # --- stepping -------------------------------------------------------------

    def step(
        self, push_force_n: NDArray[np.float64], verbal_cue: NDArray[np.float64], lift: NDArray[np.bool_]
    ) -> StepArrays:
        """Advance every env by one agent action (already decoded and validated)."""
        cmd = self.cmd
        cmd[:, CMD.push_force_n] = push_force_n
        cmd[:, CMD.verbal_cue] = verbal_cue
        cmd[:, CMD.lift] = lift
        cmd[:, CMD.active] = 1.0
        self.step_commands(cmd)
        return self.out

    def _advance_threaded(self, cmd: NDArray[np.float64], chunks: int, reset: NDArray[np.int64] | None) -> None:
        """Step the envs on up to ``chunks`` threads (this one and ``chunks - 1`` workers).

        The envs are cut into blocks of about :data:`ENVS_PER_BLOCK`, and each thread claims the
        next unclaimed block (an atomic counter in a ``nogil`` kernel) until none is left: on a
        busy machine a worker that is not scheduled in time finds the step over and does
        nothing, and this thread steps every block (one thread's speed, not a wait for the
        slowest); with a free core the blocks are shared. The envs of ``reset`` (not active in
        ``cmd``) are reset by this thread first, while the workers wake up (~0.1 ms on the
        2-core VM). This thread then waits for the workers' last blocks in a kernel, not on a
        lock: a lock's wake-up would cost as much again (after :data:`_WAIT_SPINS` reads it yields the
        core between reads).
        """
        n = self.n_envs
        blocks = max(chunks, n // ENVS_PER_BLOCK)
        control = self._control
        step = (int(control[_CLAIM] >> 32) + 1) % _STEP_NUMBERS  # the last step's number, plus one
        control[_DONE] = 0
        control[_CLAIM] = step << 32  # after the done count: a worker may claim as soon as it sees this
        args = (step, blocks, control, cmd, self.state, self.generators, self.obs, self.consts)
        pool = _worker_pool(chunks - 1)
        for _ in range(chunks - 1):
            pool.submit(_advance_claimed, *args)
        try:
            if reset is not None:
                self.reset_envs(reset)
            _advance_claimed(*args)
        finally:
            # Every block is claimed -- or, if this thread was interrupted (Ctrl-C), none will be
            # from now on: no worker goes on changing the envs once this call has returned.
            claimed = _close_step(control, blocks)
            while not _blocks_done(control, claimed, _WAIT_SPINS):
                _yield_core()

    def step_commands(self, cmd: NDArray[np.float64], reset: NDArray[np.int64] | None = None) -> None:
        """Advance the active envs by one agent action; results land in ``report`` and ``obs``.

        Args:
            cmd: (N, 4) float64 C-contiguous rows ``[push_force_n, verbal_cue, lift, active]``
                (decoded and validated); envs with ``active == 0`` are left untouched.
            reset: Envs to start new episodes in during the same call (int64 indices, none of
                them active in ``cmd``): the same as :meth:`reset_envs` after the step, since the
                two touch different envs and each env draws from its own generator, but on a
                threaded step the reset overlaps the workers' stepping.
        """
        chunks = self._chunks or self._plan_chunks()
        if reset is not None:
            # Checked before anything changes.
            if (cmd[reset, CMD.active] > 0.5).any():
                raise ValueError("step_commands: an env can't be both stepped and reset in one call")
            missing = reset[self.generators[reset, G_STATE] == 0]
            if missing.shape[0]:
                raise RuntimeError(_no_generator_message(int(missing[0])))
            if reset.shape[0] == 0:
                reset = None
            elif self.mm is not None:
                chunks = 1  # the bank's reset must follow its run over the stepped envs' inputs
        if chunks > 1:
            failed = _unready(cmd, self.generators)
            if failed < 0:
                self._advance_threaded(cmd, chunks, reset)
                reset = None
        else:
            failed = _advance(cmd, self.state, self.generators, self.obs, self.consts)
        if failed >= 0:
            raise RuntimeError(f"env {failed} was stepped before it was reset")
        if self.mm is not None:
            probs = self.mm.run(self._block_cp, self._block_cv, self._block_y)
            self.report[:, REPORT.p_uncooperative : REPORT.p_cooperative + 1] = probs[:, -1]
            _observe(self._all, self.state, self.obs, self.consts)
        if reset is not None:
            self.reset_envs(reset)

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
        self._chunks = 0


def _pack_consts(
    core: SitToStandCore,
    index: tuple[int, ...],
    observation_low: NDArray[np.float64] | None,
    observation_high: NDArray[np.float64] | None,
    varied: list[int],
) -> NDArray[np.float64]:
    """The scalars the kernels read (:data:`CONST_COLUMNS`), then observation spec, varied columns, initial state."""
    timing, reward, prior = core.timing, core.reward_weights, core._nominal_prior
    n_obs = len(index)
    template = initial_state_row(0, 0.0)
    obs_at = len(CONST_COLUMNS)
    varied_at = obs_at + 3 * n_obs
    template_at = varied_at + len(varied)
    scalars = {
        "substeps": timing.substeps,
        "verbal_duration_s": core.cues.verbal_duration_s,
        "judgment_delay_s": core.judgment.delay_s,
        "judgment_threshold": core.judgment.threshold,
        "success_lean_m": core.lift.success_lean_m,
        "upright_m": core.lift.upright_m,
        "episode_s": timing.episode_s,
        "reward_success": reward.success,
        "reward_unsafe": reward.unsafe,
        "reward_premature": reward.premature,
        "time_term": -reward.time_per_s * timing.action_period_s,
        "force_per_n_s": reward.force_per_n_s,
        "build_obs": 0.0,  # set by the core once its estimator exists
        "vary": 1.0 if core.realism.person_variation else 0.0,
        "xdot_var": prior.initial_velocity_std_m_per_s**2,
        "eta_var": prior.initial_intention_std_m**2,
        "xi_var": prior.initial_cooperativeness_std**2,
        "xi_std": prior.initial_cooperativeness_std,
        "n_obs": n_obs,
        "n_varied": len(varied),
        "obs_at": obs_at,
        "varied_at": varied_at,
        "template_at": template_at,
    }
    consts = np.zeros(template_at + len(template))
    consts[:obs_at] = [scalars[name] for name in CONST_COLUMNS]
    consts[obs_at : obs_at + n_obs] = index
    consts[obs_at + n_obs : obs_at + 2 * n_obs] = -np.inf if observation_low is None else observation_low
    consts[obs_at + 2 * n_obs : varied_at] = np.inf if observation_high is None else observation_high
    consts[varied_at:template_at] = varied
    consts[template_at:] = template
    return consts


guard_kernel_cache(__name__)
