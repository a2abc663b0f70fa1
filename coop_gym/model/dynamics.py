"""The three-level human model as pure, compiled functions (paper §III).

All the maths of the simulated person lives here; the envs only sequence it. The
functions work on packed float rows so that one compiled kernel serves the single env
(``N = 1``) and the batched env (``N`` people) alike:

* a *parameter row* (:data:`PARAM_COLUMNS`) packed from :class:`PersonParams` by
  :func:`pack_person` -- derived quantities such as the exact zero-order-hold matrices
  of eq. 1 are computed here, once per person;
* a *state row* (:data:`STATE_COLUMNS`): ``x, xdot, eta, xi`` and the person's memory
  of recent cues;
* a *delay line* per person holding the last cues, for the intention's reaction delay.

Randomness comes in as standard normals drawn by the caller from its own
``numpy.random.Generator`` (never global state): :data:`NORMALS_PER_SUBSTEP` per
simulation step.

Discretisation: the biomechanics (eq. 1) is integrated exactly over a step with the
input held constant (zero-order hold); the intention (eq. 6) is the paper's own
discrete-time update; the cooperativeness chain is an exact CTMC step with the rates
held over the step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from coop_gym.model.params import MAX_REACTION_DELAY_S, PersonParams, Timing
from estimator.compiled.schema import field_names, field_values, index_table
from estimator.validate import check_choice

__all__ = [
    "DELAY_LINE_LENGTH",
    "NORMALS_PER_SUBSTEP",
    "PARAM_COLUMNS",
    "PERSON",
    "PERSON_DERIVED_COLUMNS",
    "STATE",
    "STATE_COLUMNS",
    "Trajectory",
    "fill_initial_state",
    "initial_state_row",
    "measure",
    "pack_person",
    "person_substep",
    "simulate",
    "zoh_coefficients",
    "zoh_coefficients_batch",
    "zoh_matrices",
]

PERSON_DERIVED_COLUMNS: tuple[str, ...] = (
    "dt_s",
    "zoh_a00",
    "zoh_a01",
    "zoh_a10",
    "zoh_a11",
    "zoh_b0",
    "zoh_b1",
    "intention_noise_std_per_step_m",
    "delay_steps",
    "hold_xi",
)
"""Columns :func:`pack_person` computes: the step, eq. 1's exact ZOH matrices, per-step scales, the hold switch."""

PARAM_COLUMNS: tuple[str, ...] = field_names(PersonParams) + PERSON_DERIVED_COLUMNS
"""Every field of :class:`PersonParams` (levels flattened, in order), then the derived columns."""

PERSON = index_table("PersonColumns", PARAM_COLUMNS)
"""Column of each parameter in a packed row: ``p[PERSON.damping_rate_per_s]``."""

STATE_COLUMNS: tuple[str, ...] = (
    "x_m",
    "xdot_m_per_s",
    "eta_m",
    "xi",
    "since_explanation_s",
    "since_cue_s",
    "delay_index",
)
STATE = index_table("StateColumns", STATE_COLUMNS)
"""Column of each person-state quantity: ``s[STATE.x_m]``."""

NORMALS_PER_SUBSTEP = 5
"""Standard normals one simulation step consumes: accel, intention, chain, position, force."""

DELAY_LINE_LENGTH = 64
"""Slots of the reaction-delay line (must exceed the longest delay in steps)."""

_LONG_AGO_S = 1.0e6  # "never": the time since a cue that has not happened


def zoh_matrices(damping_rate_per_s: float, voluntary_gain_per_s2: float, dt_s: float) -> NDArray[np.float64]:
    """Exact discretisation of eq. 1's ``[x, xdot]`` dynamics with the input held over ``dt``.

    With ``s = [x, xdot]`` and scalar input ``u = k1*eta + k2*c_p + w_x`` [m/s^2],
    ``ds/dt = F s + G u``, ``F = [[0, 1], [-k1, -lambda1]]``, ``G = [0, 1]``. Van Loan:
    ``expm([[F, G], [0, 0]] dt) = [[Ad, Bd], [0, 1]]`` (computed by :func:`zoh_coefficients`).

    Returns:
        (2, 3) array ``[Ad | Bd]``.
    """
    a00, a01, a10, a11, b0, b1 = zoh_coefficients(float(damping_rate_per_s), float(voluntary_gain_per_s2), float(dt_s))
    return np.array([[a00, a01, b0], [a10, a11, b1]])


@njit(cache=True, error_model="numpy", inline="always")
def _van_loan_block(
    damping_rate_per_s: float, voluntary_gain_per_s2: float, dt_s: float
) -> tuple[float, float, float, float, int]:
    # The block [[0, dt, 0], [-k1 dt, -lambda1 dt, dt], [0, 0, 0]] as (a, b, c, d), halved
    # ``squarings`` times until its 1-norm (largest column sum) is at most 1/2.
    a = dt_s
    b = -voluntary_gain_per_s2 * dt_s
    c = -damping_rate_per_s * dt_s
    d = dt_s
    norm = max(abs(b), abs(a) + abs(c), abs(d))
    squarings = 0
    while norm > 0.5 and squarings < 64:  # the cap stops the loop on inf/NaN gains
        norm *= 0.5
        squarings += 1
    scale = 0.5**squarings
    return a * scale, b * scale, c * scale, d * scale, squarings


@njit(cache=True, error_model="numpy", inline="always")
def _taylor_term(
    t00: float, t01: float, t10: float, t11: float, a: float, b: float, c: float, d: float, k: int
) -> tuple[float, float, float, float, float, float]:
    # T_k = T_(k-1) M / k, the top two rows of the block's Taylor term.
    return t01 * b / k, (t00 * a + t01 * c) / k, t01 * d / k, t11 * b / k, (t10 * a + t11 * c) / k, t11 * d / k


@njit(cache=True, error_model="numpy", inline="always")
def _squared(
    e00: float, e01: float, e02: float, e10: float, e11: float, e12: float
) -> tuple[float, float, float, float, float, float]:
    # E E for E = [[e00, e01, e02], [e10, e11, e12], [0, 0, 1]], top two rows.
    return (
        e00 * e00 + e01 * e10,
        e00 * e01 + e01 * e11,
        e00 * e02 + e01 * e12 + e02,
        e10 * e00 + e11 * e10,
        e10 * e01 + e11 * e11,
        e10 * e02 + e11 * e12 + e12,
    )


@njit(cache=True, error_model="numpy")
def zoh_coefficients(
    damping_rate_per_s: float, voluntary_gain_per_s2: float, dt_s: float
) -> tuple[float, float, float, float, float, float]:
    """``(a00, a01, a10, a11, b0, b1)`` of :func:`zoh_matrices`, compiled so kernels can call it.

    ``expm`` of the (3, 3) Van Loan block by scaling and squaring a Taylor series: the
    block is halved until its 1-norm is at most 1/2, summed to 18 terms (truncation below
    1e-22 relative) and squared back. It agrees with ``scipy.linalg.expm`` to ~1e-15, without
    scipy's BLAS calls at each episode reset (and their thread contention).
    """
    # The block's powers keep a zero last row and its exponential the last row [0, 0, 1], so
    # only the top two rows (six numbers) are carried: no arrays, nothing allocated.
    a, b, c, d, squarings = _van_loan_block(damping_rate_per_s, voluntary_gain_per_s2, dt_s)
    # Taylor: E = sum_k T_k with T_0 = I and T_k = T_(k-1) M / k.
    e00, e01, e02, e10, e11, e12 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0
    t00, t01, t10, t11 = 1.0, 0.0, 0.0, 1.0
    for k in range(1, 19):
        t00, t01, t02, t10, t11, t12 = _taylor_term(t00, t01, t10, t11, a, b, c, d, k)
        e00 += t00
        e01 += t01
        e02 += t02
        e10 += t10
        e11 += t11
        e12 += t12
    for _ in range(squarings):
        e00, e01, e02, e10, e11, e12 = _squared(e00, e01, e02, e10, e11, e12)
    return e00, e01, e10, e11, e02, e12


@njit(cache=True, error_model="numpy")
def zoh_coefficients_batch(
    damping_rate_per_s: NDArray[np.float64],
    voluntary_gain_per_s2: NDArray[np.float64],
    dt_s: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:
    """:func:`zoh_coefficients` of ``m`` people at once: ``out[r] = zoh_coefficients(damping[r], gain[r], dt[r])``.

    The same operations (the same helpers) in the same order on each person's numbers, so the
    results are equal bit for bit (tests/coop_gym/test_vector.py); only the loops are turned
    around. One person's Taylor sum waits on its divisions one term after the other, while the
    people of a batch are independent: with the people in the inner loop the compiler runs
    several divisions at once (SIMD) for a batch of resets (``python bench/reset.py``).

    Args:
        damping_rate_per_s: (m,) each person's damping ``lambda1`` [1/s].
        voluntary_gain_per_s2: (m,) each person's voluntary gain ``k1`` [1/s^2].
        dt_s: (m,) each person's simulation step [s].
        out: (m, 6) ``(a00, a01, a10, a11, b0, b1)`` of each person.
    """
    m = damping_rate_per_s.shape[0]
    block = np.empty((4, m))  # a, b, c, d of every person
    squarings = np.empty(m, dtype=np.int64)
    for r in range(m):
        block[0, r], block[1, r], block[2, r], block[3, r], squarings[r] = _van_loan_block(
            damping_rate_per_s[r], voluntary_gain_per_s2[r], dt_s[r]
        )
    a, b, c, d = block[0], block[1], block[2], block[3]
    e = np.zeros((6, m))  # rows: e00, e01, e02, e10, e11, e12 of every person
    t = np.zeros((4, m))  # rows: t00, t01, t10, t11
    for r in range(m):
        e[0, r] = 1.0
        e[4, r] = 1.0
        t[0, r] = 1.0
        t[3, r] = 1.0
    e00, e01, e02, e10, e11, e12 = e[0], e[1], e[2], e[3], e[4], e[5]
    t00, t01, t10, t11 = t[0], t[1], t[2], t[3]
    for k in range(1, 19):
        for r in range(m):
            n00, n01, n02, n10, n11, n12 = _taylor_term(t00[r], t01[r], t10[r], t11[r], a[r], b[r], c[r], d[r], k)
            t00[r], t01[r], t10[r], t11[r] = n00, n01, n10, n11
            e00[r] += n00
            e01[r] += n01
            e02[r] += n02
            e10[r] += n10
            e11[r] += n11
            e12[r] += n12
    for r in range(m):
        f00, f01, f02, f10, f11, f12 = e00[r], e01[r], e02[r], e10[r], e11[r], e12[r]
        for _ in range(squarings[r]):
            f00, f01, f02, f10, f11, f12 = _squared(f00, f01, f02, f10, f11, f12)
        out[r, 0] = f00
        out[r, 1] = f01
        out[r, 2] = f10
        out[r, 3] = f11
        out[r, 4] = f02
        out[r, 5] = f12


def pack_person(person: PersonParams, timing: Timing, hold_xi: bool = False) -> NDArray[np.float64]:
    """Pack ``person`` into a parameter row (:data:`PARAM_COLUMNS`) for the kernels.

    Args:
        person: The person's parameters.
        timing: Time base (the simulation step ``dt``).
        hold_xi: Keep ``xi`` fixed (the paper's experiment requests a state per trial).
    """
    bio, intent = person.biomechanics, person.intention
    dt = timing.dt_s
    zoh = zoh_matrices(bio.damping_rate_per_s, bio.voluntary_gain_per_s2, dt)
    delay_steps = round(intent.reaction_delay_s / dt)
    if delay_steps >= DELAY_LINE_LENGTH:
        raise ValueError(
            f"Intention.reaction_delay_s={intent.reaction_delay_s} is {delay_steps} steps of {dt} s; "
            f"at most {DELAY_LINE_LENGTH - 1} are supported (<= {MAX_REACTION_DELAY_S} s at 50 Hz)"
        )
    derived = {
        "dt_s": dt,
        "zoh_a00": zoh[0, 0],
        "zoh_a01": zoh[0, 1],
        "zoh_a10": zoh[1, 0],
        "zoh_a11": zoh[1, 1],
        "zoh_b0": zoh[0, 2],
        "zoh_b1": zoh[1, 2],
        "intention_noise_std_per_step_m": intent.noise_std_m_per_sqrt_s * math.sqrt(dt),
        "delay_steps": float(delay_steps),
        "hold_xi": 1.0 if hold_xi else 0.0,
    }
    # Bools (``saturate``) and ints (``baseline``) become 1.0/0.0 and floats.
    values = {**{name: float(value) for name, value in field_values(person).items()}, **derived}
    return np.array([values[name] for name in PARAM_COLUMNS], dtype=np.float64)


@njit(cache=True, error_model="numpy")
def fill_initial_state(s: NDArray[np.float64], xi: float, x0_m: float) -> None:
    """Write a person sitting still at ``x0_m``, intending to stay there, with cooperativeness ``xi`` into ``s``."""
    for j in range(s.shape[0]):
        s[j] = 0.0
    s[STATE.x_m] = x0_m
    s[STATE.eta_m] = x0_m
    s[STATE.xi] = xi
    s[STATE.since_explanation_s] = _LONG_AGO_S
    s[STATE.since_cue_s] = _LONG_AGO_S


def initial_state_row(xi: int, x0_m: float = 0.0) -> NDArray[np.float64]:
    """A person sitting still at ``x0_m``, intending to stay there, with cooperativeness ``xi``."""
    row = np.zeros(len(STATE_COLUMNS))
    fill_initial_state(row, float(xi), float(x0_m))
    return row


@njit(cache=True, error_model="numpy")
def _normal_cdf(z: float) -> float:
    # A standard normal mapped through its CDF is uniform on (0, 1): one stream of
    # normals serves every random need.
    return 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))


@njit(cache=True, error_model="numpy")
def cooperativeness_rates(
    p: NDArray[np.float64],
    xi: float,
    push_force_n: float,
    verbal_cue: float,
    since_explain_s: float,
    since_cue_s: float,
) -> tuple[float, float]:
    """Rates [1/s] of one level up and one level down of the chain (eq. 8, handbook rules §II)."""
    up = 0.0
    down = 0.0
    hearing = p[PERSON.hearing]
    persuade = p[PERSON.persuadability]
    startle = p[PERSON.startle_sensitivity]
    # Explaining first ("lean forward") calms a resisting person; words alone rarely suffice.
    if verbal_cue > 0.5:
        up += (
            hearing * persuade * (p[PERSON.explain_calm_rate_per_s] if xi < -0.5 else p[PERSON.words_alone_rate_per_s])
        )
    # "Lean back" confuses.
    elif verbal_cue < -0.5:
        down += hearing * startle * p[PERSON.confusion_rate_per_s]
    if push_force_n >= p[PERSON.touch_threshold_n]:
        # How well a push is prepared: the part of a recent explanation that was heard.
        prepared = hearing if since_explain_s <= p[PERSON.explanation_memory_s] else 0.0
        guided = p[PERSON.guided_calm_rate_per_s] if xi < -0.5 else p[PERSON.guided_push_rate_per_s]
        alone = p[PERSON.push_alone_rate_per_s] if abs(xi) < 0.5 else 0.0
        up += persuade * (prepared * guided + (1.0 - prepared) * alone)
        if push_force_n >= p[PERSON.firm_push_threshold_n]:
            # A firm push without preparation startles.
            down += startle * (
                prepared * p[PERSON.prepared_startle_rate_per_s] + (1.0 - prepared) * p[PERSON.startle_rate_per_s]
            )
    # Long idle periods let engagement drift back to the person's baseline.
    if since_cue_s >= p[PERSON.idle_after_s]:
        if xi < p[PERSON.baseline] - 0.5:
            up += p[PERSON.drift_rate_per_s]
        elif xi > p[PERSON.baseline] + 0.5:
            down += p[PERSON.drift_rate_per_s]
    if xi > 0.5:
        up = 0.0
        # Willingness is not absorbing: it lapses (see also the refusal jump in person_substep).
        down += p[PERSON.lapse_rate_per_s]
        if push_force_n >= p[PERSON.touch_threshold_n]:
            down += p[PERSON.pushed_lapse_rate_per_s]
    if xi < -0.5:
        down = 0.0
    return up, down


@njit(cache=True, error_model="numpy")
def person_substep(
    s: NDArray[np.float64],
    p: NDArray[np.float64],
    delay_push: NDArray[np.float64],
    delay_verbal: NDArray[np.float64],
    push_force_n: float,
    verbal_cue: float,
    z: NDArray[np.float64],
) -> None:
    """Advance one person by one simulation step ``dt``, in place.

    Args:
        s: State row (:data:`STATE_COLUMNS`), updated in place.
        p: Parameter row (:data:`PARAM_COLUMNS`).
        delay_push: The person's delay line of push forces [N], updated in place.
        delay_verbal: The person's delay line of verbal cues, updated in place.
        push_force_n: Push force acting during the step ``c_p`` [N].
        verbal_cue: Verbal cue heard during the step ``c_v`` in {-1, 0, +1}.
        z: At least 3 standard normals: acceleration, intention and chain noise.
    """
    dt = p[PERSON.dt_s]
    xi = s[STATE.xi]
    # The person's memory of cues (used by the chain below).
    felt = push_force_n >= p[PERSON.touch_threshold_n]
    s[STATE.since_explanation_s] = 0.0 if verbal_cue > 0.5 else s[STATE.since_explanation_s] + dt
    s[STATE.since_cue_s] = 0.0 if (felt or verbal_cue != 0.0) else s[STATE.since_cue_s] + dt

    # Reaction delay: the intention answers the cues of `delay_steps` ago.
    k = int(s[STATE.delay_index])
    delay_push[k] = push_force_n
    delay_verbal[k] = verbal_cue
    j = (k - int(p[PERSON.delay_steps])) % DELAY_LINE_LENGTH
    push_seen = delay_push[j]
    verbal_seen = delay_verbal[j]
    s[STATE.delay_index] = float((k + 1) % DELAY_LINE_LENGTH)

    # The inlined helpers take scalars and at most the parameter row, read last outside any
    # branch, and return scalars: other array arguments, or a last read of the row inside a
    # branch, leave reference counting in the compiled step (NRT_incref in inspect_llvm()).
    s[STATE.x_m], s[STATE.xdot_m_per_s] = _move_body(
        p, s[STATE.x_m], s[STATE.xdot_m_per_s], s[STATE.eta_m], xi, push_force_n, z[0]
    )
    s[STATE.eta_m] = _move_intention(p, s[STATE.eta_m], s[STATE.x_m], xi, push_seen, verbal_seen, z[1])

    # Looking ready while not ready: an unresponsive person left waiting (idle) now and then
    # leans forward on their own. The chain's uniform decides it from the top of [0, 1) (the chain's jumps
    # come from the bottom), so the person still draws 5 normals per step.
    if p[PERSON.spontaneous_lean_rate_per_s] > 0.0 and abs(xi) < 0.5 and s[STATE.since_cue_s] >= p[PERSON.idle_after_s]:
        if _normal_cdf(z[2]) >= math.exp(-p[PERSON.spontaneous_lean_rate_per_s] * dt):
            s[STATE.eta_m] = max(s[STATE.eta_m], p[PERSON.spontaneous_lean_m])

    # eq. 8: one exact step of the cue-driven chain, rates held over dt.
    if p[PERSON.hold_xi] < 0.5:
        up, down = cooperativeness_rates(
            p, xi, push_force_n, verbal_cue, s[STATE.since_explanation_s], s[STATE.since_cue_s]
        )
        refuse = p[PERSON.refusal_rate_per_s] if xi > 0.5 else 0.0
        s[STATE.xi] = _step_cooperativeness(xi, up, down, refuse, dt, z[2])


@njit(cache=True, error_model="numpy", inline="always")
def _move_body(
    p: NDArray[np.float64], x: float, xdot: float, eta: float, xi: float, push_force_n: float, z_accel: float
) -> tuple[float, float]:
    """The body, eq. 1 by exact zero-order hold: the new ``(x, xdot)`` [m, m/s].

    ``[x, xdot] <- Ad [x, xdot] + Bd u``, ``u = k1*eta + k2_eff*c_p + w_x``; an uncooperative
    person stiffens (``k2_eff < k2``).
    """
    k2 = p[PERSON.push_compliance_m_per_s2_n]
    if xi < -0.5:
        k2 *= p[PERSON.stiffness_factor_uncooperative]
    elif xi < 0.5:
        k2 *= p[PERSON.stiffness_factor_unresponsive]
    u = p[PERSON.voluntary_gain_per_s2] * eta + k2 * push_force_n + p[PERSON.accel_noise_std_m_per_s2] * z_accel
    return (
        p[PERSON.zoh_a00] * x + p[PERSON.zoh_a01] * xdot + p[PERSON.zoh_b0] * u,
        p[PERSON.zoh_a10] * x + p[PERSON.zoh_a11] * xdot + p[PERSON.zoh_b1] * u,
    )


@njit(cache=True, error_model="numpy", inline="always")
def _move_intention(
    p: NDArray[np.float64], eta: float, x: float, xi: float, push_seen: float, verbal_seen: float, z_intent: float
) -> float:
    """The intention, eq. 6: the new ``eta`` [m] from the cues as perceived (delayed) and the body's ``x``.

    ``eta[t+1] = eta[t] + xi*(k3*c_p + k4*c_v)*dt + w_eta``; with no cue acting the intention
    relaxes toward upright.
    """
    dt = p[PERSON.dt_s]
    if push_seen >= p[PERSON.touch_threshold_n] or verbal_seen != 0.0:
        eta += xi * (p[PERSON.push_gain_m_per_s_n] * push_seen + p[PERSON.verbal_gain_m_per_s] * verbal_seen) * dt
    else:
        # Euler step, capped: with rate*dt > 2 it would overshoot and diverge (relaxation
        # 100/s at dt 0.1 s is valid); a full relaxation in one step is the stable limit.
        eta -= min(p[PERSON.relaxation_rate_per_s] * dt, 1.0) * eta
    eta += p[PERSON.intention_noise_std_per_step_m] * z_intent
    if p[PERSON.passive_follow_rate_per_s] > 0.0 and abs(xi) < 0.5:
        # A passive (unresponsive) person's intention follows the body: bent forward by a
        # push, a weak trunk stays bent instead of pulling back upright (capped as above).
        eta += min(p[PERSON.passive_follow_rate_per_s] * dt, 1.0) * (x - eta)
    # The bounds read before the branch: the row's last use then comes after every other branch,
    # and Numba drops the inlined argument's reference counting.
    min_m, max_m = p[PERSON.min_m], p[PERSON.max_m]
    if p[PERSON.saturate] > 0.5:
        eta = min(max(eta, min_m), max_m)
    return eta


@njit(cache=True, error_model="numpy", inline="always")
def _step_cooperativeness(xi: float, up: float, down: float, refuse: float, dt: float, z_chain: float) -> float:
    """The cooperativeness after one exact step of the chain (eq. 8) from ``xi`` [-1, 0, +1].

    Args:
        xi: Cooperativeness before the step.
        up: Rate [1/s] of the jump up, held over ``dt``.
        down: Rate [1/s] of the jump down.
        refuse: Rate [1/s] of the jump from +1 straight to -1.
        dt: Step [s].
        z_chain: Standard normal giving the chain's uniform (jumps from its bottom, the lean from its top).
    """
    total = up + down + refuse
    if total > 0.0:
        leave = 1.0 - math.exp(-total * dt)
        uniform = _normal_cdf(z_chain)
        if uniform < leave * up / total:
            return xi + 1.0
        if uniform < leave:
            # A sudden refusal jumps from +1 straight to -1.
            if refuse > 0.0 and uniform >= leave * (up + down) / total:
                return -1.0
            return xi - 1.0
    return xi


@njit(cache=True, error_model="numpy")
def measure(
    s: NDArray[np.float64], p: NDArray[np.float64], push_force_n: float, z_position: float, z_force: float
) -> tuple[float, float]:
    """The robot's readings: shoulder position [m] (camera) and push force [N] (force sensor)."""
    return s[STATE.x_m] + p[PERSON.position_noise_std_m] * z_position, push_force_n + p[
        PERSON.force_noise_std_n
    ] * z_force


@njit(cache=True, error_model="numpy")
def _simulate_kernel(
    s: NDArray[np.float64],
    p: NDArray[np.float64],
    push_force_n: NDArray[np.float64],
    verbal_cue: NDArray[np.float64],
    normals: NDArray[np.float64],
    states: NDArray[np.float64],
    measurements: NDArray[np.float64],
) -> None:
    delay_push = np.zeros(DELAY_LINE_LENGTH)
    delay_verbal = np.zeros(DELAY_LINE_LENGTH)
    for t in range(push_force_n.shape[0]):
        z = normals[t]
        person_substep(s, p, delay_push, delay_verbal, push_force_n[t], verbal_cue[t], z)
        pos, force = measure(s, p, push_force_n[t], z[3], z[4])
        states[t] = s[:4]
        measurements[t, 0] = pos
        measurements[t, 1] = force


@dataclass(frozen=True)
class Trajectory:
    """A simulated run, one row per simulation step ``dt``.

    Attributes:
        time_s: (T,) time at the end of each step [s].
        true_state: (T, 4) ``x [m], xdot [m/s], eta [m], xi`` after each step.
        measured_position_m: (T,) camera reading of the shoulder [m].
        measured_force_n: (T,) force-sensor reading [N].
        push_force_n: (T,) push applied [N].
        verbal_cue: (T,) verbal cue heard.
    """

    time_s: NDArray[np.float64]
    true_state: NDArray[np.float64]
    measured_position_m: NDArray[np.float64]
    measured_force_n: NDArray[np.float64]
    push_force_n: NDArray[np.float64]
    verbal_cue: NDArray[np.float64]


def simulate(
    person: PersonParams,
    push_force_n: NDArray[np.float64],
    verbal_cue: NDArray[np.float64],
    rng: np.random.Generator,
    *,
    initial_xi: int = 0,
    x0_m: float = 0.0,
    hold_xi: bool = False,
    timing: Timing | None = None,
) -> Trajectory:
    """Simulate one person under given per-step cue sequences (one entry per ``dt``).

    Args:
        person: Parameters of the person.
        push_force_n: (T,) push force per simulation step [N].
        verbal_cue: (T,) verbal cue per simulation step in {-1, 0, 1}.
        rng: Source of all randomness.
        initial_xi: Cooperativeness at the start.
        x0_m: Initial shoulder displacement [m].
        hold_xi: Keep ``xi`` at ``initial_xi`` (the paper's experiment).
        timing: Time base; default :class:`Timing`.

    Example:
        >>> traj = simulate(PersonParams(), np.full(50, 10.0), np.zeros(50), np.random.default_rng(0), initial_xi=1)
        >>> traj.true_state.shape
        (50, 4)
    """
    timing = timing or Timing()
    cp = np.ascontiguousarray(push_force_n, dtype=np.float64)
    cv = np.ascontiguousarray(verbal_cue, dtype=np.float64)
    if cp.ndim != 1 or cv.shape != cp.shape:
        raise ValueError(f"push_force_n and verbal_cue must be 1-D of equal length, got {cp.shape} and {cv.shape}")
    initial_xi = check_choice("initial_xi", initial_xi, (-1, 0, 1))
    p = pack_person(person, timing, hold_xi=hold_xi)
    s = initial_state_row(initial_xi, x0_m)
    n = cp.shape[0]
    normals = rng.standard_normal((n, NORMALS_PER_SUBSTEP))
    states = np.empty((n, 4))
    measurements = np.empty((n, 2))
    _simulate_kernel(s, p, cp, cv, normals, states, measurements)
    return Trajectory(
        time_s=np.arange(1, n + 1, dtype=np.float64) * timing.dt_s,
        true_state=states,
        measured_position_m=measurements[:, 0].copy(),
        measured_force_n=measurements[:, 1].copy(),
        push_force_n=cp.copy(),
        verbal_cue=cv.copy(),
    )
