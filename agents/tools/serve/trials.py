"""The two trials a browser plays, advanced one request at a time: the caregiver's episode and the person's cue trial.

Each trial lives in the server's memory while it runs and is handed to the store whole when it
ends. Every step a browser asks for is checked first (:class:`BadInput` names the field), so a
malformed or out-of-range request changes nothing.

* :class:`CaregiverTrial` -- one episode of the env id ``agents.evaluate`` scores, on a seed and
  persona set of the evaluation; the true mental state is sent only once the episode has ended,
  beside what the oracle, the prober and the belief caregiver did with the same person.
* :class:`PersonTrial` -- one of the paper's cue trials (:mod:`coop_gym.experiment.simulation`)
  with the player as the person: their input is the intention ``eta``; the body answers through
  eq. 1 (the simulator's exact zero-order hold of the typical persona's biomechanics), is sensed
  with the simulator's camera and force noise, and is judged live by the paper's filter (the IMM's
  ``P(xi)`` shown beside it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from agents.evaluate import evaluate
from agents.tools.play import PlayedSteps
from agents.tools.play_log import PlayedEpisode, personas_arg
from coop_gym.envs.actions import ACTION_SHAPE
from coop_gym.envs.core import nominal_model_for
from coop_gym.experiment.simulation import ProtocolConfig, TrialSpec, draw_trials
from coop_gym.model.dynamics import zoh_matrices
from coop_gym.model.personas import get_persona, resolve_personas
from estimator.judgment import JUDGE, JUDGMENT_COLUMNS, judgment_substep
from estimator.kalman import PaperKalmanFilter, nominal_row
from estimator.multiple_model import TRIAL_PROBABILITY_FLOOR, TRIAL_SWITCHING_RATE_PER_S, IMMEstimator
from estimator.recording import Recording, format_recording

__all__ = ["COMPARED", "BadInput", "CaregiverTrial", "PersonTrial", "person_design"]

COMPARED = ("oracle", "prober", "belief")
"""Caregivers replayed on the seed of each played episode for its summary."""

PERSON_BODY = "typical"
"""The persona whose body (eq. 1), sensors and nominal model answer the person role's intention."""


class BadInput(ValueError):
    """A request the trial refuses; the message names the field and what it must be."""


def _integer(payload: dict[str, Any], name: str, high: int) -> int:
    value = payload.get(name)
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < high:
        raise BadInput(f"{name} must be an integer in 0..{high - 1}, got {value!r}")
    return value


@dataclass
class CaregiverTrial:
    """One caregiver episode being played.

    Args:
        env_id: The env id (that of ``agents.evaluate``).
        personas: The persona set, as ``agents.evaluate --personas`` takes it.
        seed: The episode's seed (the person and all noise follow from it).
    """

    env_id: str
    personas: str
    seed: int
    done: bool = False

    def __post_init__(self) -> None:
        """Make the env and reset it to the seed."""
        self.env = gym.make(self.env_id, personas=[p.name for p in resolve_personas(personas_arg(self.personas))])
        _, info = self.env.reset(seed=self.seed)
        self.log = PlayedSteps(self.seed, str(info["persona"]), [0.0], [int(info["true_xi"])])
        self.last_info = info

    def step(self, payload: dict[str, Any]) -> dict[str, Any]:
        """One env step (0.1 s) with ``push`` 0-2, ``verbal`` 0-2 and ``lift`` 0-1; returns the scene."""
        names = ("push", "verbal", "lift")
        push, verbal, lift = (_integer(payload, name, n) for name, n in zip(names, ACTION_SHAPE, strict=True))
        if self.done:
            raise BadInput("the episode has ended")
        self.done, self.last_info = self.log.step(self.env, push, verbal, lift)
        return self.scene()

    def scene(self) -> dict[str, Any]:
        """What the page draws: the body, the cues, the filter's reading; the true state only after the end."""
        info = self.last_info
        out: dict[str, Any] = {
            "role": "caregiver",
            "seed": self.seed,
            "elapsed_s": float(info["elapsed_s"]),
            "x_m": float(info["true_x_m"]),
            "push_force_n": float(info["push_force_n"]),
            "verbal_cue": int(info["verbal_cue"]),
            "xi_estimate": float(info["xi_estimate"]),
            "judgment": int(info["judgment"]),
            "done": self.done,
        }
        if self.done:
            log = self.log
            out.update(outcome=log.outcome, lift_time_s=log.lift_time_s, episode_return=log.episode_return,
                       persona=log.persona, times_s=log.times_s, true_xi=log.true_xi)  # fmt: skip
        return out

    def compared(self) -> list[dict[str, Any]]:
        """What the caregivers of :data:`COMPARED` did with the same person (same env, seed, persona set)."""
        out = []
        for name in COMPARED:
            personas = personas_arg(self.personas)
            result = evaluate(name, self.env_id, personas, episodes=1, seed=self.seed, n_envs=1, backend="single")
            record = result.records[0]
            lift_s = record.duration_s if record.lifted else None
            out.append({"agent": name, "outcome": record.outcome, "lift_time_s": lift_s})
        return out

    def played(self) -> PlayedEpisode:
        """The finished episode as a line of the played-episodes CSV."""
        return self.log.played(self.env_id, self.personas)

    def close(self) -> None:
        """Close the env."""
        self.env.close()


def person_design(design_seed: int, n_trials: int) -> tuple[ProtocolConfig, tuple[TrialSpec, ...]]:
    """The protocol's settings and the session's trials: the paper's design (requested mix, cues, timings)."""
    config = ProtocolConfig(n_subjects=1, n_trials=n_trials)
    return config, draw_trials(config, np.random.default_rng(design_seed))


class PersonTrial:
    """One of the paper's cue trials with the player as the person.

    Args:
        session_id: The person session it belongs to.
        trial_index: Its place in the session's design.
        config: The protocol's settings (time base, cue sizes, judgment rule).
        spec: The trial: requested ``xi`` and cues.
        seed: Seed of the body's noise and the sensors.
    """

    def __init__(  # noqa: D107  (the class docstring gives the arguments)
        self, session_id: int, trial_index: int, config: ProtocolConfig, spec: TrialSpec, seed: int
    ) -> None:
        self.session_id, self.trial_index, self.config, self.spec = session_id, trial_index, config, spec
        self.person = get_persona(PERSON_BODY).params.with_realism(config.realism)
        self.model = nominal_model_for(self.person, config.timing)
        self.push, self.verbal = spec.cues(config)
        self.rng = np.random.default_rng(seed)
        bio = self.person.biomechanics
        self.zoh = zoh_matrices(bio.damping_rate_per_s, bio.voluntary_gain_per_s2, config.timing.dt_s)
        # An acted uncooperative (or unresponsive) person stiffens against a push, as the simulator's does.
        stiffness = {-1: bio.stiffness_factor_uncooperative, 0: bio.stiffness_factor_unresponsive, 1: 1.0}
        self.compliance = bio.push_compliance_m_per_s2_n * stiffness[spec.requested_xi]
        self.body = np.zeros(2)  # x [m], xdot [m/s]
        self.t = 0
        n = config.n_steps
        self.position_m, self.force_n, self.intention_m = np.zeros(n), np.zeros(n), np.zeros(n)
        self.xi_hat = np.zeros(n)
        self._sense(0, 0.0)
        self.kf = PaperKalmanFilter(self.model, float(self.position_m[0]))
        # Beside the paper's filter, the package's IMM reads the same samples: P(xi) live.
        self.imm = IMMEstimator(
            nominal_row(self.model)[None, :], self.position_m[:1], prior=self.model,
            probability_floor=TRIAL_PROBABILITY_FLOOR, switching_rate_per_s=TRIAL_SWITCHING_RATE_PER_S,
        )  # fmt: skip
        self.p_xi = np.full(3, 1.0 / 3.0)
        self.tracker = np.zeros(len(JUDGMENT_COLUMNS))
        self.judgment: int | None = None

    @property
    def done(self) -> bool:
        """Whether every sample of the trial has been taken."""
        return self.t >= self.config.n_steps - 1

    def _sense(self, t: int, eta: float) -> None:
        sensors = self.person.sensors
        self.position_m[t] = self.body[0] + sensors.position_noise_std_m * self.rng.standard_normal()
        self.force_n[t] = self.push[t] + sensors.force_noise_std_n * self.rng.standard_normal()
        self.intention_m[t] = eta

    def step(self, payload: dict[str, Any]) -> dict[str, Any]:
        """One control step (``timing.substeps`` samples) with the player's ``intention_m``; returns the scene."""
        eta: Any = payload.get("intention_m")
        low, high = self.person.intention.min_m, self.person.intention.max_m
        number = not isinstance(eta, bool) and isinstance(eta, (int, float)) and math.isfinite(eta)
        if not number or not low <= eta <= high:
            raise BadInput(f"intention_m must be a number in [{low}, {high}] m, got {eta!r}")
        if self.done:
            raise BadInput("the trial has ended")
        for _ in range(self.config.timing.substeps):
            if self.done:
                break
            self._advance(float(eta))
        return self.scene()

    def _advance(self, eta: float) -> None:
        """One sample: eq. 1 moves the body, the sensors read it, the paper's filter and judgment follow."""
        t = self.t + 1
        bio = self.person.biomechanics
        # eq. 1 by exact zero-order hold: [x, xdot] <- Ad [x, xdot] + Bd u, u = k1 eta + k2 c_p + w_x
        u = bio.voluntary_gain_per_s2 * eta + self.compliance * self.push[t]
        u += bio.accel_noise_std_m_per_s2 * self.rng.standard_normal()
        self.body = self.zoh[:, :2] @ self.body + self.zoh[:, 2] * u
        self._sense(t, eta)
        mean = self.kf.step(self.force_n[t], self.verbal[t], self.position_m[t])
        self.xi_hat[t] = float(mean[3])
        self.p_xi = self.imm.step(self.force_n[t : t + 1], self.verbal[t : t + 1], self.position_m[t : t + 1])[0]
        active = bool(self.push[t] > 0.0 or self.verbal[t] != 0.0)
        judgment = self.config.judgment
        if judgment_substep(self.tracker, active, self.xi_hat[t], judgment.delay_s, judgment.threshold,
                            self.config.timing.dt_s) and self.judgment is None:  # fmt: skip
            self.judgment = int(self.tracker[JUDGE.judgment])
        self.t = t

    def scene(self) -> dict[str, Any]:
        """What the page draws: the body, the robot's cues, the filter's ``xi`` and its judgment once made."""
        t = self.t
        return {
            "role": "person",
            "trial_index": self.trial_index,
            "elapsed_s": t * self.config.timing.dt_s,
            "trial_s": self.config.trial_s,
            "x_m": float(self.body[0]),
            "push_force_n": float(self.push[t]),
            "verbal_cue": int(self.verbal[t]),
            "xi_estimate": float(self.xi_hat[t]),
            "judgment": self.judgment,
            "p_xi_imm": [float(p) for p in self.p_xi],
            "done": self.done,
        }

    def recording(self) -> str:
        """The trial as a recording (:mod:`estimator.recording`), the text the store keeps."""
        n = self.config.n_steps
        spec = self.spec
        return format_recording(
            Recording(
                time_s=np.arange(n, dtype=np.float64) * self.config.timing.dt_s,
                shoulder_position_m=self.position_m,
                force_n=self.force_n,
                verbal_cue=self.verbal,
                cue_force_n=self.push,
                requested_xi=np.full(n, float(spec.requested_xi)),
                model=self.model,
                meta={
                    "source": "python -m agents.tools.serve (person role)",
                    "subject": f"web{self.session_id:04d}",
                    "trial": f"t{self.trial_index:02d}",
                    "cues": f"physical {spec.physical_cue}, verbal {spec.verbal_cue}, "
                    f"verbal minus physical onset {spec.relative_timing_s} s",
                },
            )
        )
