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

__all__ = [
    "DELAY_LINE_LENGTH",
    "NORMALS_PER_SUBSTEP",
    "PARAM_COLUMNS",
    "STATE_COLUMNS",
    "Trajectory",
    "initial_state_row",
    "measure",
    "pack_person",
    "person_substep",
    "simulate",
    "zoh_coefficients",
    "zoh_matrices",
]

PARAM_COLUMNS: tuple[str, ...] = (
    "dt_s",
    "damping_rate_per_s",
    "voluntary_gain_per_s2",
    "push_compliance_m_per_s2_n",
    "accel_noise_std_m_per_s2",
    "stiffness_factor_uncooperative",
    "stiffness_factor_unresponsive",
    "zoh_a00",
    "zoh_a01",
    "zoh_a10",
    "zoh_a11",
    "zoh_b0",
    "zoh_b1",
    "push_gain_m_per_s_n",
    "verbal_gain_m_per_s",
    "intention_noise_std_per_step_m",
    "delay_steps",
    "saturate",
    "eta_min_m",
    "eta_max_m",
    "relaxation_rate_per_s",
    "explain_calm_rate_per_s",
    "words_alone_rate_per_s",
    "guided_push_rate_per_s",
    "guided_calm_rate_per_s",
    "push_alone_rate_per_s",
    "startle_rate_per_s",
    "prepared_startle_rate_per_s",
    "confusion_rate_per_s",
    "drift_rate_per_s",
    "explanation_memory_s",
    "idle_after_s",
    "touch_threshold_n",
    "firm_push_threshold_n",
    "persuadability",
    "startle_sensitivity",
    "hearing",
    "baseline",
    "position_noise_std_m",
    "force_noise_std_n",
    "hold_xi",
    "passive_follow_rate_per_s",
    "lapse_rate_per_s",
    "refusal_rate_per_s",
    "spontaneous_lean_rate_per_s",
    "spontaneous_lean_m",
    "pushed_lapse_rate_per_s",
)
(
    P_DT,
    P_LAMBDA1,
    P_K1,
    P_K2,
    P_ACCEL_STD,
    P_STIFF_UNCOOP,
    P_STIFF_UNRESP,
    P_A00,
    P_A01,
    P_A10,
    P_A11,
    P_B0,
    P_B1,
    P_K3,
    P_K4,
    P_ETA_STD,
    P_DELAY,
    P_SATURATE,
    P_ETA_MIN,
    P_ETA_MAX,
    P_RELAX,
    P_R_EXPLAIN_CALM,
    P_R_WORDS,
    P_R_GUIDED,
    P_R_GUIDED_CALM,
    P_R_PUSH_ALONE,
    P_R_STARTLE,
    P_R_PREP_STARTLE,
    P_R_CONFUSION,
    P_R_DRIFT,
    P_EXPLAIN_MEMORY,
    P_IDLE_AFTER,
    P_TOUCH,
    P_FIRM,
    P_PERSUADE,
    P_STARTLE_SENS,
    P_HEARING,
    P_BASELINE,
    P_POS_STD,
    P_FORCE_STD,
    P_HOLD_XI,
    P_FOLLOW,
    P_R_LAPSE,
    P_R_REFUSAL,
    P_R_SPONTANEOUS,
    P_SPONTANEOUS_M,
    P_R_PUSHED_LAPSE,
) = range(len(PARAM_COLUMNS))

STATE_COLUMNS: tuple[str, ...] = (
    "x_m",
    "xdot_m_per_s",
    "eta_m",
    "xi",
    "since_explanation_s",
    "since_cue_s",
    "delay_index",
)
S_X, S_XDOT, S_ETA, S_XI, S_SINCE_EXPLAIN, S_SINCE_CUE, S_DELAY_INDEX = range(len(STATE_COLUMNS))

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


@njit(cache=True)
def zoh_coefficients(
    damping_rate_per_s: float, voluntary_gain_per_s2: float, dt_s: float
) -> tuple[float, float, float, float, float, float]:
    """``(a00, a01, a10, a11, b0, b1)`` of :func:`zoh_matrices`, compiled so kernels can call it.

    ``expm`` of the (3, 3) Van Loan block by scaling and squaring a Taylor series: the
    block is halved until its 1-norm is at most 1/2, summed to 18 terms (truncation below
    1e-22 relative) and squared back. It agrees with ``scipy.linalg.expm`` to ~1e-15;
    scipy's BLAS calls cost 10 us to milliseconds (thread contention) per episode reset.
    """
    # The block is [[0, dt, 0], [-k1 dt, -lambda1 dt, dt], [0, 0, 0]]. Its powers keep a zero
    # last row and its exponential the last row [0, 0, 1], so only the top two rows (six
    # numbers) are carried: no arrays, nothing allocated.
    a = dt_s
    b = -voluntary_gain_per_s2 * dt_s
    c = -damping_rate_per_s * dt_s
    d = dt_s
    norm = max(abs(b), abs(a) + abs(c), abs(d))  # largest column sum
    squarings = 0
    while norm > 0.5 and squarings < 64:  # the cap stops the loop on inf/NaN gains
        norm *= 0.5
        squarings += 1
    scale = 0.5**squarings
    a *= scale
    b *= scale
    c *= scale
    d *= scale
    # Taylor: E = sum_k T_k with T_0 = I and T_k = T_(k-1) M / k.
    e00, e01, e02, e10, e11, e12 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0
    t00, t01, t02, t10, t11, t12 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0
    for k in range(1, 19):
        t00, t01, t02 = t01 * b / k, (t00 * a + t01 * c) / k, t01 * d / k
        t10, t11, t12 = t11 * b / k, (t10 * a + t11 * c) / k, t11 * d / k
        e00 += t00
        e01 += t01
        e02 += t02
        e10 += t10
        e11 += t11
        e12 += t12
    for _ in range(squarings):
        e00, e01, e02, e10, e11, e12 = (
            e00 * e00 + e01 * e10,
            e00 * e01 + e01 * e11,
            e00 * e02 + e01 * e12 + e02,
            e10 * e00 + e11 * e10,
            e10 * e01 + e11 * e11,
            e10 * e02 + e11 * e12 + e12,
        )
    return e00, e01, e10, e11, e02, e12


def pack_person(person: PersonParams, timing: Timing, hold_xi: bool = False) -> NDArray[np.float64]:
    """Pack ``person`` into a parameter row (:data:`PARAM_COLUMNS`) for the kernels.

    Args:
        person: The person's parameters.
        timing: Time base (the simulation step ``dt``).
        hold_xi: Keep ``xi`` fixed (the paper's experiment requests a state per trial).
    """
    bio, intent, coop, sensors = person.biomechanics, person.intention, person.cooperativeness, person.sensors
    dt = timing.dt_s
    zoh = zoh_matrices(bio.damping_rate_per_s, bio.voluntary_gain_per_s2, dt)
    delay_steps = round(intent.reaction_delay_s / dt)
    if delay_steps >= DELAY_LINE_LENGTH:
        raise ValueError(
            f"Intention.reaction_delay_s={intent.reaction_delay_s} is {delay_steps} steps of {dt} s; "
            f"at most {DELAY_LINE_LENGTH - 1} are supported (<= {MAX_REACTION_DELAY_S} s at 50 Hz)"
        )
    values = {
        "dt_s": dt,
        "damping_rate_per_s": bio.damping_rate_per_s,
        "voluntary_gain_per_s2": bio.voluntary_gain_per_s2,
        "push_compliance_m_per_s2_n": bio.push_compliance_m_per_s2_n,
        "accel_noise_std_m_per_s2": bio.accel_noise_std_m_per_s2,
        "stiffness_factor_uncooperative": bio.stiffness_factor_uncooperative,
        "stiffness_factor_unresponsive": bio.stiffness_factor_unresponsive,
        "zoh_a00": zoh[0, 0],
        "zoh_a01": zoh[0, 1],
        "zoh_a10": zoh[1, 0],
        "zoh_a11": zoh[1, 1],
        "zoh_b0": zoh[0, 2],
        "zoh_b1": zoh[1, 2],
        "push_gain_m_per_s_n": intent.push_gain_m_per_s_n,
        "verbal_gain_m_per_s": intent.verbal_gain_m_per_s,
        "intention_noise_std_per_step_m": intent.noise_std_m_per_sqrt_s * math.sqrt(dt),
        "delay_steps": float(delay_steps),
        "saturate": 1.0 if intent.saturate else 0.0,
        "eta_min_m": intent.min_m,
        "eta_max_m": intent.max_m,
        "relaxation_rate_per_s": intent.relaxation_rate_per_s,
        "explain_calm_rate_per_s": coop.explain_calm_rate_per_s,
        "words_alone_rate_per_s": coop.words_alone_rate_per_s,
        "guided_push_rate_per_s": coop.guided_push_rate_per_s,
        "guided_calm_rate_per_s": coop.guided_calm_rate_per_s,
        "push_alone_rate_per_s": coop.push_alone_rate_per_s,
        "startle_rate_per_s": coop.startle_rate_per_s,
        "prepared_startle_rate_per_s": coop.prepared_startle_rate_per_s,
        "confusion_rate_per_s": coop.confusion_rate_per_s,
        "drift_rate_per_s": coop.drift_rate_per_s,
        "explanation_memory_s": coop.explanation_memory_s,
        "idle_after_s": coop.idle_after_s,
        "touch_threshold_n": coop.touch_threshold_n,
        "firm_push_threshold_n": coop.firm_push_threshold_n,
        "persuadability": coop.persuadability,
        "startle_sensitivity": coop.startle_sensitivity,
        "hearing": coop.hearing,
        "baseline": float(coop.baseline),
        "position_noise_std_m": sensors.position_noise_std_m,
        "force_noise_std_n": sensors.force_noise_std_n,
        "hold_xi": 1.0 if hold_xi else 0.0,
        "passive_follow_rate_per_s": intent.passive_follow_rate_per_s,
        "lapse_rate_per_s": coop.lapse_rate_per_s,
        "refusal_rate_per_s": coop.refusal_rate_per_s,
        "spontaneous_lean_rate_per_s": intent.spontaneous_lean_rate_per_s,
        "spontaneous_lean_m": intent.spontaneous_lean_m,
        "pushed_lapse_rate_per_s": coop.pushed_lapse_rate_per_s,
    }
    return np.array([values[name] for name in PARAM_COLUMNS], dtype=np.float64)


def initial_state_row(xi: int, x0_m: float = 0.0) -> NDArray[np.float64]:
    """A person sitting still at ``x0_m``, intending to stay there, with cooperativeness ``xi``."""
    row = np.zeros(len(STATE_COLUMNS))
    row[S_X] = x0_m
    row[S_ETA] = x0_m
    row[S_XI] = float(xi)
    row[S_SINCE_EXPLAIN] = _LONG_AGO_S
    row[S_SINCE_CUE] = _LONG_AGO_S
    return row


@njit(cache=True)
def _normal_cdf(z: float) -> float:
    # A standard normal mapped through its CDF is uniform on (0, 1): one stream of
    # normals serves every random need.
    return 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))


@njit(cache=True)
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
    hearing = p[P_HEARING]
    persuade = p[P_PERSUADE]
    startle = p[P_STARTLE_SENS]
    # Explaining first ("lean forward") calms a resisting person; words alone rarely suffice.
    if verbal_cue > 0.5:
        up += hearing * persuade * (p[P_R_EXPLAIN_CALM] if xi < -0.5 else p[P_R_WORDS])
    # "Lean back" confuses.
    elif verbal_cue < -0.5:
        down += hearing * startle * p[P_R_CONFUSION]
    if push_force_n >= p[P_TOUCH]:
        # How well a push is prepared: the part of a recent explanation that was heard.
        prepared = hearing if since_explain_s <= p[P_EXPLAIN_MEMORY] else 0.0
        guided = p[P_R_GUIDED_CALM] if xi < -0.5 else p[P_R_GUIDED]
        alone = p[P_R_PUSH_ALONE] if abs(xi) < 0.5 else 0.0
        up += persuade * (prepared * guided + (1.0 - prepared) * alone)
        if push_force_n >= p[P_FIRM]:
            # A firm push without preparation startles.
            down += startle * (prepared * p[P_R_PREP_STARTLE] + (1.0 - prepared) * p[P_R_STARTLE])
    # Long idle periods let engagement drift back to the person's baseline.
    if since_cue_s >= p[P_IDLE_AFTER]:
        if xi < p[P_BASELINE] - 0.5:
            up += p[P_R_DRIFT]
        elif xi > p[P_BASELINE] + 0.5:
            down += p[P_R_DRIFT]
    if xi > 0.5:
        up = 0.0
        # Willingness is not absorbing: it lapses (see also the refusal jump in person_substep).
        down += p[P_R_LAPSE]
        if push_force_n >= p[P_TOUCH]:
            down += p[P_R_PUSHED_LAPSE]
    if xi < -0.5:
        down = 0.0
    return up, down


@njit(cache=True)
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
    dt = p[P_DT]
    xi = s[S_XI]
    # The person's memory of cues (used by the chain below).
    felt = push_force_n >= p[P_TOUCH]
    s[S_SINCE_EXPLAIN] = 0.0 if verbal_cue > 0.5 else s[S_SINCE_EXPLAIN] + dt
    s[S_SINCE_CUE] = 0.0 if (felt or verbal_cue != 0.0) else s[S_SINCE_CUE] + dt

    # Reaction delay: the intention answers the cues of `delay_steps` ago.
    k = int(s[S_DELAY_INDEX])
    delay_push[k] = push_force_n
    delay_verbal[k] = verbal_cue
    j = (k - int(p[P_DELAY])) % DELAY_LINE_LENGTH
    push_seen = delay_push[j]
    verbal_seen = delay_verbal[j]
    s[S_DELAY_INDEX] = float((k + 1) % DELAY_LINE_LENGTH)

    # eq. 1, exact zero-order hold: [x, xdot] <- Ad [x, xdot] + Bd u,
    # u = k1*eta + k2_eff*c_p + w_x; an uncooperative person stiffens (k2_eff < k2).
    k2 = p[P_K2]
    if xi < -0.5:
        k2 *= p[P_STIFF_UNCOOP]
    elif xi < 0.5:
        k2 *= p[P_STIFF_UNRESP]
    u = p[P_K1] * s[S_ETA] + k2 * push_force_n + p[P_ACCEL_STD] * z[0]
    x, xdot = s[S_X], s[S_XDOT]
    s[S_X] = p[P_A00] * x + p[P_A01] * xdot + p[P_B0] * u
    s[S_XDOT] = p[P_A10] * x + p[P_A11] * xdot + p[P_B1] * u

    # eq. 6: eta[t+1] = eta[t] + xi*(k3*c_p + k4*c_v)*dt + w_eta (cues as perceived, delayed);
    # with no cue acting the intention relaxes toward upright.
    eta = s[S_ETA]
    if push_seen >= p[P_TOUCH] or verbal_seen != 0.0:
        eta += xi * (p[P_K3] * push_seen + p[P_K4] * verbal_seen) * dt
    else:
        # Euler step, capped: with rate*dt > 2 it would overshoot and diverge (relaxation
        # 100/s at dt 0.1 s is valid); a full relaxation in one step is the stable limit.
        eta -= min(p[P_RELAX] * dt, 1.0) * eta
    eta += p[P_ETA_STD] * z[1]
    if p[P_FOLLOW] > 0.0 and abs(xi) < 0.5:
        # A passive (unresponsive) person's intention follows the body: bent forward by a
        # push, a weak trunk stays bent instead of pulling back upright (capped as above).
        eta += min(p[P_FOLLOW] * dt, 1.0) * (s[S_X] - eta)
    if p[P_SATURATE] > 0.5:
        eta = min(max(eta, p[P_ETA_MIN]), p[P_ETA_MAX])
    s[S_ETA] = eta

    # Looking ready while not ready: an unresponsive person left waiting (idle) now and then
    # leans forward on their own. The chain's uniform decides it from the top of [0, 1) (the chain's jumps
    # come from the bottom), so the person still draws 5 normals per step.
    if p[P_R_SPONTANEOUS] > 0.0 and abs(xi) < 0.5 and s[S_SINCE_CUE] >= p[P_IDLE_AFTER]:
        if _normal_cdf(z[2]) >= math.exp(-p[P_R_SPONTANEOUS] * dt):
            s[S_ETA] = max(s[S_ETA], p[P_SPONTANEOUS_M])

    # eq. 8: one exact step of the cue-driven chain, rates held over dt.
    if p[P_HOLD_XI] < 0.5:
        up, down = cooperativeness_rates(p, xi, push_force_n, verbal_cue, s[S_SINCE_EXPLAIN], s[S_SINCE_CUE])
        refuse = p[P_R_REFUSAL] if xi > 0.5 else 0.0
        total = up + down + refuse
        if total > 0.0:
            leave = 1.0 - math.exp(-total * dt)
            uniform = _normal_cdf(z[2])
            if uniform < leave * up / total:
                s[S_XI] = xi + 1.0
            elif uniform < leave:
                # A sudden refusal jumps from +1 straight to -1.
                if refuse > 0.0 and uniform >= leave * (up + down) / total:
                    s[S_XI] = -1.0
                else:
                    s[S_XI] = xi - 1.0


@njit(cache=True)
def measure(
    s: NDArray[np.float64], p: NDArray[np.float64], push_force_n: float, z_position: float, z_force: float
) -> tuple[float, float]:
    """The robot's readings: shoulder position [m] (camera) and push force [N] (force sensor)."""
    return s[S_X] + p[P_POS_STD] * z_position, push_force_n + p[P_FORCE_STD] * z_force


@njit(cache=True)
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
    if initial_xi not in (-1, 0, 1):
        raise ValueError(f"initial_xi must be -1, 0 or 1, got {initial_xi!r}")
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
