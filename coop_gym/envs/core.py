"""The batched simulation shared by the single env and the vector env.

This is where model and filter meet. :class:`SitToStandCore` holds ``N`` independent
episodes as arrays and advances them one agent action at a time:

    decode action -> lift outcome | (cues -> person -> sensors -> filter -> judgment) x substeps
    -> features -> reward terms

The maths is not here: the person is :mod:`coop_gym.model.dynamics`, the filter
:mod:`estimator.kalman` / :mod:`estimator.judgment`. The single env is this core with
``N = 1``; the vector env is the same core with ``N`` envs, so the two cannot drift.

Randomness: env ``i`` draws only from its own ``numpy.random.Generator``. Step noise is
taken from a per-env block of standard normals refilled from that generator, with a
fixed number consumed per step, so env ``i`` of a vector env seeded ``s`` and a single
env seeded ``s + i`` see identical random streams.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from coop_gym.envs.config import LiftCriteria, Outcome, RewardWeights
from coop_gym.model.dynamics import (
    DELAY_LINE_LENGTH,
    NORMALS_PER_SUBSTEP,
    S_ETA,
    S_X,
    S_XDOT,
    S_XI,
    STATE_COLUMNS,
    initial_state_row,
    measure,
    pack_person,
    person_substep,
)
from coop_gym.model.params import Cues, PersonParams, Realism, Timing
from coop_gym.model.personas import Persona, sample_person
from estimator.judgment import J_JUDGMENT, J_SINCE_ONSET, JUDGMENT_COLUMNS, ThresholdJudgment, judgment_substep
from estimator.kalman import NOMINAL_COLUMNS, kalman_step, nominal_row
from estimator.nominal import STATE_DIM, NominalModel

__all__ = [
    "FEATURES",
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

# Per-env bookkeeping of the cue scheduler: the utterance playing and the clock.
E_VERBAL_VALUE, E_VERBAL_REMAINING, E_ELAPSED, E_IMPULSE = range(4)
_N_ENV_COLUMNS = 4

BLOCK_STEPS = 32
"""Agent steps of noise drawn at once per env."""


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
    """What one core step produced, for ``N`` envs (arrays are reused between steps).

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


@njit(cache=True)
def _advance(
    lift: NDArray[np.bool_],
    push_force_n: NDArray[np.float64],
    verbal_request: NDArray[np.float64],
    person: NDArray[np.float64],
    params: NDArray[np.float64],
    delay_push: NDArray[np.float64],
    delay_verbal: NDArray[np.float64],
    normals: NDArray[np.float64],
    cursor: NDArray[np.int64],
    env: NDArray[np.float64],
    m: NDArray[np.float64],
    P: NDArray[np.float64],
    nominal: NDArray[np.float64],
    judge: NDArray[np.float64],
    features: NDArray[np.float64],
    outcome: NDArray[np.int64],
    block_cp: NDArray[np.float64],
    block_cv: NDArray[np.float64],
    block_y: NDArray[np.float64],
    substeps: int,
    verbal_duration_s: float,
    judgment_delay_s: float,
    judgment_threshold: float,
    success_lean_m: float,
    upright_m: float,
    episode_s: float,
) -> None:
    for i in range(lift.shape[0]):
        s = person[i]
        p = params[i]
        dt = p[0]
        env[i, E_IMPULSE] = 0.0
        outcome[i] = 0
        if lift[i]:
            # The lift is judged on the true state at the moment it starts (§II).
            if s[S_XI] > 0.5 and s[S_X] >= success_lean_m:
                outcome[i] = 1  # Outcome.SUCCESS
            elif s[S_XI] < -0.5 or s[S_X] < upright_m:
                outcome[i] = 2  # Outcome.UNSAFE
            else:
                outcome[i] = 3  # Outcome.PREMATURE
            for k in range(substeps):
                block_cp[i, k] = 0.0
                block_cv[i, k] = 0.0
                block_y[i, k] = features[i, 0]
            continue
        # A verbal cue is an utterance of fixed length; one can't talk over oneself.
        if env[i, E_VERBAL_REMAINING] <= 0.0 and verbal_request[i] != 0.0:
            env[i, E_VERBAL_VALUE] = verbal_request[i]
            env[i, E_VERBAL_REMAINING] = verbal_duration_s
        cp = push_force_n[i]
        c = cursor[i]
        for k in range(substeps):
            cv = env[i, E_VERBAL_VALUE] if env[i, E_VERBAL_REMAINING] > 1e-9 else 0.0
            z = normals[i, c : c + NORMALS_PER_SUBSTEP]
            c += NORMALS_PER_SUBSTEP
            person_substep(s, p, delay_push[i], delay_verbal[i], cp, cv, z)
            pos, force = measure(s, p, cp, z[3], z[4])
            kalman_step(m[i], P[i], nominal[i], force, cv, pos)
            judgment_substep(judge[i], cp > 0.0 or cv != 0.0, m[i, 3], judgment_delay_s, judgment_threshold, dt)
            block_cp[i, k] = force
            block_cv[i, k] = cv
            block_y[i, k] = pos
            env[i, E_VERBAL_REMAINING] -= dt
            env[i, E_IMPULSE] += cp * dt
            features[i, 0] = pos
            features[i, 1] = force
        cursor[i] = c
        if env[i, E_VERBAL_REMAINING] <= 1e-9:
            env[i, E_VERBAL_REMAINING] = 0.0
            env[i, E_VERBAL_VALUE] = 0.0
        env[i, E_ELAPSED] += substeps * dt
        f = features[i]
        f[2] = env[i, E_VERBAL_VALUE]
        f[3] = min(judge[i, J_SINCE_ONSET], episode_s)
        f[4] = m[i, 0]
        f[5] = m[i, 1]
        f[6] = m[i, 2]
        f[7] = m[i, 3]
        f[8] = np.sqrt(max(P[i, 3, 3], 0.0))
        f[9] = judge[i, J_JUDGMENT]
        f[10] = env[i, E_ELAPSED]
        f[14] = s[S_XI]
        if env[i, E_ELAPSED] >= episode_s - 1e-9:
            outcome[i] = 4  # Outcome.TIMEOUT (TimeLimit truncates on this same step)


class SitToStandCore:
    """``N`` sit-to-stand episodes stepped together (see module docstring).

    Args:
        n_envs: Number of parallel episodes.
        personas: Personas to draw each episode's person from (uniformly).
        timing, cues, realism, lift, reward, judgment: Settings (see their classes).
        estimator: ``"kalman"``, ``"multiple_model"`` or ``"imm"``.
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
    ) -> None:
        """Allocate the arrays; every env must be reset before it is stepped."""
        self.n_envs = n_envs
        self.personas = personas
        self.timing = timing
        self.cues = cues
        self.realism = realism
        self.lift = lift
        self.reward_weights = reward
        self.judgment = judgment
        self.estimator = estimator
        # The filter's nominal model depends only on the persona: pack each once.
        self._persona_nominal = [nominal_row(nominal_model_for(p.params, timing)) for p in personas]
        self._nominal_prior = NominalModel()
        n = n_envs
        self.person = np.zeros((n, len(STATE_COLUMNS)))
        self.params = np.zeros((n, len(pack_person(PersonParams(), timing))))
        self.delay_push = np.zeros((n, DELAY_LINE_LENGTH))
        self.delay_verbal = np.zeros((n, DELAY_LINE_LENGTH))
        self.per_step = NORMALS_PER_SUBSTEP * timing.substeps
        self.normals = np.zeros((n, BLOCK_STEPS * self.per_step))
        self.cursor = np.full(n, self.normals.shape[1], dtype=np.int64)
        self.env = np.zeros((n, _N_ENV_COLUMNS))
        self.m = np.zeros((n, STATE_DIM))
        self.P = np.zeros((n, STATE_DIM, STATE_DIM))
        self.nominal = np.zeros((n, len(NOMINAL_COLUMNS)))
        self.judge = np.zeros((n, len(JUDGMENT_COLUMNS)))
        self.persona_index = np.zeros(n, dtype=np.int64)
        self.rngs: list[np.random.Generator | None] = [None] * n
        self._block_cp = np.zeros((n, timing.substeps))
        self._block_cv = np.zeros((n, timing.substeps))
        self._block_y = np.zeros((n, timing.substeps))
        self.out = StepArrays(
            features=np.zeros((n, len(FEATURES))),
            reward_terms=np.zeros((n, len(REWARD_TERMS))),
            reward=np.zeros(n),
            outcome=np.zeros(n, dtype=np.int64),
            terminated=np.zeros(n, dtype=bool),
            push_force_n=np.zeros(n),
            verbal_cue=np.zeros(n),
        )
        self.mm = self._make_multiple_model(multiple_model_options or {}) if estimator != "kalman" else None

    def _make_multiple_model(self, options: dict[str, Any]) -> Any:
        from estimator.multiple_model import IMMEstimator, MultipleModelEstimator

        cls = IMMEstimator if self.estimator == "imm" else MultipleModelEstimator
        try:
            return cls(np.tile(self._persona_nominal[0], (self.n_envs, 1)), np.zeros(self.n_envs), **options)
        except TypeError as exc:  # an unknown option name
            raise ValueError(f"estimator_options for {self.estimator!r}: {exc}") from None

    # --- episodes -------------------------------------------------------------

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
        self.rngs[i] = rng
        # The same draws happen whatever is fixed, so fixing one thing shifts nothing else.
        drawn = int(rng.integers(len(self.personas)))
        k = drawn if persona_index is None else persona_index
        persona = self.personas[k]
        person = sample_person(persona, rng, vary=self.realism.person_variation).with_realism(self.realism)
        coop = person.cooperativeness
        u = rng.random()
        xi = -1 if u < coop.initial_p_uncooperative else (1 if u > 1.0 - coop.initial_p_cooperative else 0)
        if initial_xi is not None:
            xi = initial_xi
        # People sit a little differently: a few millimetres of initial lean.
        x0 = float(rng.normal(0.0, 0.005))
        self.persona_index[i] = k
        self.params[i] = pack_person(person, self.timing)
        self.person[i] = initial_state_row(xi, x0)
        self.delay_push[i] = 0.0
        self.delay_verbal[i] = 0.0
        self.cursor[i] = self.normals.shape[1]  # discard buffered noise: a new stream follows
        self.env[i] = 0.0
        self.nominal[i] = self._persona_nominal[k]
        prior = self._nominal_prior
        self.m[i] = [x0, 0.0, x0, 0.0]
        self.P[i] = np.diag(
            [
                self.nominal[i, -1],
                prior.initial_velocity_std_m_per_s**2,
                prior.initial_intention_std_m**2,
                prior.initial_cooperativeness_std**2,
            ]
        )
        self.judge[i] = 0.0
        self.judge[i, J_SINCE_ONSET] = self.timing.episode_s
        f = self.out.features[i]
        f[:] = 0.0
        f[F_POS] = x0
        f[F_X_HAT] = x0
        f[F_ETA_HAT] = x0
        f[F_XI_STD] = prior.initial_cooperativeness_std
        f[F_SINCE_ONSET] = self.timing.episode_s
        f[F_TRUE_XI] = xi
        if self.mm is not None:
            # The persona (and so the nominal model) may change from episode to episode.
            self.mm.nominal[i] = self.nominal[i]
            self.mm.reset([i], x0)
            f[F_P_M1 : F_P_P1 + 1] = self.mm.probabilities[i]
        self.out.terminated[i] = False
        self.out.outcome[i] = Outcome.NONE

    def _refill(self) -> None:
        need = self.cursor + self.per_step > self.normals.shape[1]
        for i in np.flatnonzero(need):
            rng = self.rngs[i]
            if rng is None:
                raise RuntimeError(f"env {i} was stepped before it was reset")
            self.normals[i] = rng.standard_normal(self.normals.shape[1])
            self.cursor[i] = 0

    # --- stepping -------------------------------------------------------------

    def step(
        self, push_force_n: NDArray[np.float64], verbal_cue: NDArray[np.float64], lift: NDArray[np.bool_]
    ) -> StepArrays:
        """Advance every env by one agent action (already decoded and validated)."""
        self._refill()
        out = self.out
        _advance(
            lift,
            push_force_n,
            verbal_cue,
            self.person,
            self.params,
            self.delay_push,
            self.delay_verbal,
            self.normals,
            self.cursor,
            self.env,
            self.m,
            self.P,
            self.nominal,
            self.judge,
            out.features,
            out.outcome,
            self._block_cp,
            self._block_cv,
            self._block_y,
            self.timing.substeps,
            self.cues.verbal_duration_s,
            self.judgment.delay_s,
            self.judgment.threshold,
            self.lift.success_lean_m,
            self.lift.upright_m,
            self.timing.episode_s,
        )
        if self.mm is not None:
            probs = self.mm.run(self._block_cp, self._block_cv, self._block_y)
            out.features[:, F_P_M1 : F_P_P1 + 1] = probs[:, -1]
        w = self.reward_weights
        terms = out.reward_terms
        terms[:, 0] = np.where(out.outcome == Outcome.SUCCESS, w.success, 0.0)
        terms[:, 1] = np.where(out.outcome == Outcome.UNSAFE, -w.unsafe, 0.0)
        terms[:, 2] = np.where(out.outcome == Outcome.PREMATURE, -w.premature, 0.0)
        terms[:, 3] = np.where(lift, 0.0, -w.time_per_s * self.timing.action_period_s)
        terms[:, 4] = -w.force_per_n_s * self.env[:, E_IMPULSE]
        np.sum(terms, axis=1, out=out.reward)
        np.copyto(out.terminated, lift)
        np.copyto(out.push_force_n, np.where(lift, 0.0, push_force_n))
        np.copyto(out.verbal_cue, self.env[:, E_VERBAL_VALUE])
        return out

    def true_state(self, i: int) -> dict[str, float]:
        """The hidden truth of env ``i``, for ``info``."""
        s = self.person[i]
        return {
            "true_x_m": float(s[S_X]),
            "true_xdot_m_per_s": float(s[S_XDOT]),
            "true_eta_m": float(s[S_ETA]),
            "true_xi": int(s[S_XI]),
        }
