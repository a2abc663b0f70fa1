"""What an evaluation measured: one record per episode, and the metrics summed over them.

:class:`EpisodeRecord` is one episode (its seed, persona, outcome, return, time, force and
cues); :class:`EvaluationResult` holds the records of one agent on one env and derives every
reported metric from them: outcome rates with 95 % Wilson intervals, mean time to lift,
mean and peak push force, cues and return. Plain data: no env, no torch.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from coop_gym.envs.config import Outcome

__all__ = [
    "DEFAULT_ENV_ID",
    "OUTCOMES",
    "PLOT_SUFFIXES",
    "EpisodeRecord",
    "EvaluationResult",
    "persona_rates_over_runs",
    "wilson_interval",
]

DEFAULT_ENV_ID = "CoopGym/SitToStand-v0"
PLOT_SUFFIXES: tuple[str, ...] = (".png", ".pdf", ".svg")
"""File types ``--plot`` writes (matplotlib picks the format from the suffix)."""
OUTCOMES: tuple[str, ...] = tuple(o.label for o in Outcome if o is not Outcome.NONE)
"""Episode outcomes (labels of :class:`~coop_gym.envs.config.Outcome`), in report order."""

LIFT_OUTCOMES = {o.label for o in Outcome if o.terminates}


def wilson_interval(successes: int, trials: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95 % by default).

    Args:
        successes: Number of events.
        trials: Number of trials (0 gives ``(0, 1)``).
        z: Standard normal quantile of the interval.

    Returns:
        ``(low, high)``, clipped to [0, 1].

    Example:
        >>> low, high = wilson_interval(50, 100)
        >>> round(low, 3), round(high, 3)
        (0.404, 0.596)
    """
    if trials <= 0:
        return 0.0, 1.0
    p = successes / trials
    denom = 1.0 + z * z / trials
    centre = (p + z * z / (2 * trials)) / denom
    half = z * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials)) / denom
    # The bounds at 0 and n events are exactly 0 and 1 (the formula leaves rounding dust).
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    high = 1.0 if successes == trials else min(1.0, centre + half)
    return low, high


@dataclass(frozen=True)
class EpisodeRecord:
    """What happened in one evaluation episode.

    Attributes:
        episode: Index ``k`` of the episode (its seed is ``seed + k``).
        seed: The env seed of the episode.
        persona: Name of the persona the person was drawn from.
        outcome: ``"success"``, ``"unsafe"``, ``"premature"`` or ``"timeout"``.
        episode_return: Sum of rewards.
        steps: Agent steps taken (the lift included).
        duration_s: Episode time at the end (at the lift, or the time limit) [s].
        mean_force_n: Push force averaged over the guiding steps (0 if none) [N].
        peak_force_n: Largest push force commanded [N].
        impulse_n_s: Total push impulse [N s].
        verbal_cues: Utterances started.
        push_onsets: Pushes started (a push after a step without one).
    """

    episode: int
    seed: int
    persona: str
    outcome: str
    episode_return: float
    steps: int
    duration_s: float
    mean_force_n: float
    peak_force_n: float
    impulse_n_s: float
    verbal_cues: int
    push_onsets: int

    @property
    def cues(self) -> int:
        """Cues given: utterances plus push onsets."""
        return self.verbal_cues + self.push_onsets

    @property
    def lifted(self) -> bool:
        """True when the episode ended with a lift (of any outcome)."""
        return self.outcome in LIFT_OUTCOMES


@dataclass(frozen=True)
class EvaluationResult:
    """The episodes of one agent on one env, and their summary metrics.

    Attributes:
        agent: Name of the agent.
        env_id: The env id evaluated on.
        personas: Persona names the people were drawn from.
        seed: Seed of episode 0 (episode ``k`` uses ``seed + k``).
        records: One :class:`EpisodeRecord` per episode, in episode order.
        wall_time_s: Time the evaluation took [s].
        backend: ``"vector"`` (batched env) or ``"single"`` (one env per slot).
    """

    agent: str
    env_id: str
    personas: tuple[str, ...]
    seed: int
    records: tuple[EpisodeRecord, ...]
    wall_time_s: float = 0.0
    backend: str = "single"
    env_kwargs: dict[str, Any] = field(default_factory=dict)

    @property
    def episodes(self) -> int:
        """Number of episodes."""
        return len(self.records)

    def count(self, outcome: str) -> int:
        """Episodes that ended with ``outcome``."""
        if outcome not in OUTCOMES:
            raise ValueError(f"unknown outcome {outcome!r}; known: {list(OUTCOMES)}")
        return sum(r.outcome == outcome for r in self.records)

    def rate(self, outcome: str) -> float:
        """Fraction of episodes that ended with ``outcome``."""
        return self.count(outcome) / self.episodes if self.episodes else float("nan")

    def interval(self, outcome: str) -> tuple[float, float]:
        """95 % Wilson interval of :meth:`rate`."""
        return wilson_interval(self.count(outcome), self.episodes)

    @property
    def success_rate(self) -> float:
        """Fraction of successful lifts."""
        return self.rate("success")

    @property
    def unsafe_rate(self) -> float:
        """Fraction of unsafe lifts (resisting or upright person)."""
        return self.rate("unsafe")

    @property
    def premature_rate(self) -> float:
        """Fraction of premature lifts."""
        return self.rate("premature")

    @property
    def timeout_rate(self) -> float:
        """Fraction of episodes that reached the time limit without a lift."""
        return self.rate("timeout")

    def _mean(self, values: Sequence[float]) -> float:
        return float(np.mean(values)) if len(values) else float("nan")

    @property
    def mean_time_to_lift_s(self) -> float:
        """Mean episode time at the lift, over the episodes that lifted (NaN if none) [s]."""
        return self._mean([r.duration_s for r in self.records if r.lifted])

    @property
    def mean_time_to_success_s(self) -> float:
        """Mean episode time at a successful lift (NaN if none) [s]."""
        return self._mean([r.duration_s for r in self.records if r.outcome == "success"])

    @property
    def mean_force_n(self) -> float:
        """Push force averaged over guiding steps, then over episodes [N]."""
        return self._mean([r.mean_force_n for r in self.records])

    @property
    def peak_force_n(self) -> float:
        """Per-episode peak push force, averaged over episodes [N]."""
        return self._mean([r.peak_force_n for r in self.records])

    @property
    def max_force_n(self) -> float:
        """Largest push force commanded in any episode [N]."""
        return max((r.peak_force_n for r in self.records), default=float("nan"))

    @property
    def mean_impulse_n_s(self) -> float:
        """Push impulse per episode, averaged [N s]."""
        return self._mean([r.impulse_n_s for r in self.records])

    @property
    def mean_cues(self) -> float:
        """Cues (utterances + push onsets) per episode, averaged."""
        return self._mean([r.cues for r in self.records])

    @property
    def mean_return(self) -> float:
        """Mean episode return."""
        return self._mean([r.episode_return for r in self.records])

    @property
    def std_return(self) -> float:
        """Standard deviation of the episode return."""
        return float(np.std([r.episode_return for r in self.records])) if self.records else float("nan")

    def by_persona(self) -> dict[str, EvaluationResult]:
        """The same result split by persona (each keeps its episodes' records)."""
        names = sorted({r.persona for r in self.records})
        return {
            name: EvaluationResult(
                self.agent,
                self.env_id,
                (name,),
                self.seed,
                tuple(r for r in self.records if r.persona == name),
                self.wall_time_s,
                self.backend,
                self.env_kwargs,
            )
            for name in names
        }

    def persona_rates(self) -> dict[str, dict[str, Any]]:
        """Each persona's episode count and outcome rates: ``{persona: {"episodes": n, "success_rate": ..., ...}}``."""
        return {
            name: {"episodes": sub.episodes, **{f"{o}_rate": sub.rate(o) for o in OUTCOMES}}
            for name, sub in self.by_persona().items()
        }

    def summary(self) -> dict[str, Any]:
        """The metrics as a flat JSON-ready dict (NaN becomes None)."""
        out: dict[str, Any] = {
            "agent": self.agent,
            "env_id": self.env_id,
            "personas": list(self.personas),
            "episodes": self.episodes,
            "seed": self.seed,
        }
        for outcome in OUTCOMES:
            low, high = self.interval(outcome)
            out[f"{outcome}_rate"] = self.rate(outcome)
            out[f"{outcome}_rate_ci95"] = [low, high]
            out[f"{outcome}_count"] = self.count(outcome)
        out |= {
            "mean_time_to_lift_s": self.mean_time_to_lift_s,
            "mean_time_to_success_s": self.mean_time_to_success_s,
            "mean_force_n": self.mean_force_n,
            "peak_force_n": self.peak_force_n,
            "max_force_n": self.max_force_n,
            "mean_impulse_n_s": self.mean_impulse_n_s,
            "mean_cues": self.mean_cues,
            "mean_return": self.mean_return,
            "std_return": self.std_return,
            "wall_time_s": self.wall_time_s,
            "backend": self.backend,
        }
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in out.items()}


def persona_rates_over_runs(runs: Sequence[dict[str, dict[str, Any]]]) -> dict[str, dict[str, Any]]:
    """Each persona's mean rates over several runs' :meth:`EvaluationResult.persona_rates`, with its range of success.

    ``runs``: one per training seed, on the same episodes; ``success_rate_range`` is the lowest and highest.
    """
    out = {}
    for persona in runs[0]:
        found = [run[persona] for run in runs]
        out[persona] = {
            "episodes": found[0]["episodes"],
            **{f"{o}_rate": float(np.mean([f[f"{o}_rate"] for f in found])) for o in OUTCOMES},
            "success_rate_range": [min(f["success_rate"] for f in found), max(f["success_rate"] for f in found)],
        }
    return out
