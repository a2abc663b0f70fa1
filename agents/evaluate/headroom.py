r"""What a comparison says about reading the mind: headroom, insight and the mind-reading score.

On one level (one env id) and the same seeded episodes, three success rates anchor it:

* the oracle's (it sees the true ``xi``: the upper bound),
* the best mental-state-blind policy's (:data:`BLIND_AGENTS`; the tuned ``blind`` of
  ``agents.caregivers.scripted.make_scripted("blind", level=LEVEL)`` is the family's best),
* and every other agent's.

From them: the **value of reading the mind** = oracle - best blind (what knowing ``xi`` is
worth on this level), the **achieved insight** = best non-oracle - best blind (how much of
it a policy obtains from the cue answers), and per agent the **mind-reading score**

.. math:: s = \frac{\text{success} - \text{best blind}}{\text{oracle} - \text{best blind}},

0 for a policy that ignores the mind, 1 for the oracle. Its 95 % interval is a paired
percentile bootstrap: episodes are resampled, and the agent, the best blind policy and the
oracle are scored on the same resampled episodes (they played the same seeds), so the
interval reflects the episodes drawn, not three independent samples.

A person's row (:data:`HUMAN_AGENTS`, the episodes played with ``python -m agents.tools.play``)
is never the best non-oracle: a person plays a handful of seeds of their own choosing, not
the comparison's episodes, so their success rate is not comparable with the agents' and
would silently become the "achieved insight". The headroom is computed from the other rows;
the person still gets a mind-reading score, against the best blind policy and the oracle on
exactly the episodes they played (matched by seed; ``-`` when the comparison did not play
them all, on the same persona set).

Across training seeds (one score per run and level), :func:`iqm_across_runs` reports the
interquartile mean with a stratified bootstrap interval: runs are resampled within each
level, as rliable does (Agarwal et al., "Deep RL at the Edge of the Statistical Precipice",
NeurIPS 2021). Both intervals come from :func:`scipy.stats.bootstrap`.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from agents.evaluate.results import EvaluationResult

__all__ = [
    "BLIND_AGENTS",
    "HUMAN_AGENTS",
    "ORACLE_AGENTS",
    "AggregateScore",
    "Headroom",
    "MindReadingScore",
    "headroom",
    "iqm_across_runs",
    "selection_study",
]

ORACLE_AGENTS = ("oracle",)
"""Agents that see the true mental state: upper bounds, never the "best non-oracle"."""
BLIND_AGENTS = ("blind", "push_then_lift", "lift_at_once", "random")
"""Scripted agents that never use the cue-response evidence (lean, timers and pushes only)."""
HUMAN_AGENTS = ("human",)
"""Rows of episodes people played (:func:`agents.tools.play_log.score_played`): scored on their own
episodes, never the "best non-oracle"."""
N_RESAMPLES = 2000
"""Bootstrap resamples: the percentile interval's ends move by well under a point beyond this."""
BOOTSTRAP_SEED = 0
"""The resampling is seeded: the same results give the same intervals."""

Interval = tuple[float, float]


@dataclass(frozen=True)
class MindReadingScore:
    """One agent's mind-reading score on one level.

    Attributes:
        agent: The agent's name in the comparison.
        score: ``(success - best blind) / (oracle - best blind)``; NaN when the oracle does not
            beat the best blind policy (nothing to read on this level).
        ci95: Paired percentile bootstrap 95 % interval (NaN ends when undefined, e.g. when in some
            resample of a small comparison the oracle does not beat the best blind policy).
    """

    agent: str
    score: float
    ci95: Interval

    def text(self) -> str:
        """``0.78 [0.74, 0.82]`` (``-`` when undefined; no interval when it is, e.g. for one episode)."""
        if not math.isfinite(self.score):
            return "-"
        if not all(math.isfinite(end) for end in self.ci95):
            return f"{self.score:.2f}"
        return f"{self.score:.2f} [{self.ci95[0]:.2f}, {self.ci95[1]:.2f}]"


@dataclass(frozen=True)
class Headroom:
    """What a comparison says about reading the mind (success rates in [0, 1]).

    Attributes:
        oracle: Best success of the agents that see the true ``xi``.
        best_blind: Best success of the mental-state-blind agents (:data:`BLIND_AGENTS`).
        best_reader: Best success of every other agent (learned or scripted, no oracle).
        best_blind_agent, best_reader_agent: Their names.
        value_ci95, insight_ci95: Paired bootstrap 95 % intervals of the two differences.
        scores: The mind-reading score of every agent in the comparison, in its order.
    """

    oracle: float
    best_blind: float
    best_reader: float
    best_blind_agent: str
    best_reader_agent: str
    oracle_agent: str = "oracle"
    value_ci95: Interval = (math.nan, math.nan)
    insight_ci95: Interval = (math.nan, math.nan)
    scores: tuple[MindReadingScore, ...] = field(default=())

    @property
    def value_of_reading_the_mind(self) -> float:
        """Oracle minus best blind: what knowing the mental state is worth on this env."""
        return self.oracle - self.best_blind

    @property
    def achieved_insight(self) -> float:
        """Best non-oracle minus best blind: how much of it the non-oracle agents obtain."""
        return self.best_reader - self.best_blind

    def score_of(self, agent: str) -> MindReadingScore | None:
        """The mind-reading score of ``agent`` (None if it is not in the comparison)."""
        return next((s for s in self.scores if s.agent == agent), None)

    def lines(self) -> list[str]:
        """Human-readable lines for the report: value, insight, the best reader's score."""

        def points(value: float, ci: Interval) -> str:
            return f"{100 * value:+.1f} points [{100 * ci[0]:+.1f}, {100 * ci[1]:+.1f}]"

        out = [
            f"value of reading the mind = oracle {100 * self.oracle:.1f} % - best blind ({self.best_blind_agent}) "
            f"{100 * self.best_blind:.1f} % = {points(self.value_of_reading_the_mind, self.value_ci95)}",
            f"achieved insight = best non-oracle ({self.best_reader_agent}) {100 * self.best_reader:.1f} % - best "
            f"blind {100 * self.best_blind:.1f} % = {points(self.achieved_insight, self.insight_ci95)}",
        ]
        best = self.score_of(self.best_reader_agent)
        if best is not None:
            out.append(
                f"mind-reading score = (success - best blind) / (oracle - best blind): "
                f"{self.best_reader_agent} {best.text()} (0: ignores the mind, 1: the oracle)"
            )
        for person in (s for s in self.scores if _kind(s.agent) == "human"):
            out.append(
                f"{person.agent}: mind-reading score {person.text()} on the episodes played "
                "(against the best blind and the oracle on the same seeds; not a candidate for best non-oracle)"
            )
        return out

    def as_json(self) -> dict[str, Any]:
        """A JSON-ready dict (NaN becomes None)."""
        return _finite(
            {
                "oracle": self.oracle,
                "best_blind": self.best_blind,
                "best_reader": self.best_reader,
                "oracle_agent": self.oracle_agent,
                "best_blind_agent": self.best_blind_agent,
                "best_reader_agent": self.best_reader_agent,
                "value_of_reading_the_mind": self.value_of_reading_the_mind,
                "value_of_reading_the_mind_ci95": list(self.value_ci95),
                "achieved_insight": self.achieved_insight,
                "achieved_insight_ci95": list(self.insight_ci95),
                "mind_reading_score": {s.agent: {"score": s.score, "ci95": list(s.ci95)} for s in self.scores},
            }
        )


def _finite(value: Any) -> Any:
    """``value`` with every non-finite float replaced by None (JSON has no NaN)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def _kind(name: str) -> str:
    """``"oracle"``, ``"blind"``, ``"human"`` or ``"reader"`` from an agent's name in a comparison."""
    base = name.split(":")[0].split(" ")[0]
    for kind, names in (("oracle", ORACLE_AGENTS), ("blind", BLIND_AGENTS), ("human", HUMAN_AGENTS)):
        if base in names:
            return kind
    return "reader"


def _paired(results: Sequence[EvaluationResult]) -> bool:
    """True when every result played the same seeded episodes (the bootstrap resamples them together)."""
    seeds = [tuple(r.seed for r in result.records) for result in results]
    return bool(seeds) and all(s == seeds[0] for s in seeds) and len(seeds[0]) > 0


def _successes(result: EvaluationResult) -> NDArray[np.float64]:
    return np.array([r.outcome == "success" for r in result.records], dtype=np.float64)


def _paired_interval(statistic: Any, samples: Sequence[NDArray[np.float64]]) -> Interval:
    """95 % percentile interval of ``statistic(*samples)`` with the episodes resampled together."""
    if len(samples[0]) < 2:
        return math.nan, math.nan
    # A resample in which the oracle does not beat the best blind policy has no score: the
    # interval is then NaN (scipy warns; said here instead, in the docstring of MindReadingScore).
    with np.errstate(divide="ignore", invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", stats.DegenerateDataWarning)
        found = stats.bootstrap(
            tuple(samples),
            statistic,
            paired=True,
            vectorized=True,
            axis=-1,
            n_resamples=N_RESAMPLES,
            batch=500,
            method="percentile",
            rng=np.random.default_rng(BOOTSTRAP_SEED),
        )
    return float(found.confidence_interval.low), float(found.confidence_interval.high)


def _difference(a: NDArray[np.float64], b: NDArray[np.float64], axis: int = -1) -> Any:
    return np.mean(a, axis=axis) - np.mean(b, axis=axis)


def _score(agent: Any, blind: Any, oracle: Any, axis: int = -1) -> Any:
    """The mind-reading score of success indicators (NaN where the oracle does not beat blind)."""
    blind_rate = np.mean(blind, axis=axis)
    room = np.mean(oracle, axis=axis) - blind_rate
    gained = np.mean(agent, axis=axis) - blind_rate
    return np.where(room > 0, gained / np.where(room > 0, room, 1.0), np.nan)


def mind_reading_score(result: EvaluationResult, blind: EvaluationResult, oracle: EvaluationResult) -> MindReadingScore:
    """The mind-reading score of ``result`` against ``blind`` and ``oracle`` on the same episodes."""
    samples = (_successes(result), _successes(blind), _successes(oracle))
    point = float(_score(*samples))
    ci = _paired_interval(_score, samples) if math.isfinite(point) else (math.nan, math.nan)
    return MindReadingScore(result.agent, point, ci)


def _on_episodes_of(person: EvaluationResult, result: EvaluationResult) -> EvaluationResult | None:
    """``result`` cut to the episodes ``person`` played, in their order (None unless it played them all).

    The same seed is the same person only on the same env and persona set.
    """
    if (person.env_id, set(person.personas)) != (result.env_id, set(result.personas)):
        return None
    by_seed = {r.seed: r for r in result.records}
    if any(r.seed not in by_seed for r in person.records):
        return None
    return dataclasses.replace(result, records=tuple(by_seed[r.seed] for r in person.records))


def _person_score(person: EvaluationResult, blind: EvaluationResult, oracle: EvaluationResult) -> MindReadingScore:
    """A person's mind-reading score on the episodes they played (NaN when the comparison lacks some)."""
    blind_there, oracle_there = _on_episodes_of(person, blind), _on_episodes_of(person, oracle)
    if blind_there is None or oracle_there is None:
        return MindReadingScore(person.agent, math.nan, (math.nan, math.nan))
    return mind_reading_score(person, blind_there, oracle_there)


def headroom(results: Sequence[EvaluationResult]) -> Headroom | None:
    """:class:`Headroom` of a comparison on the same episodes.

    None without an oracle and a blind agent, or when the results did not play the same seeded
    episodes (e.g. rows split by persona). Rows of :data:`HUMAN_AGENTS` are left out of the
    anchors and of the best non-oracle; each is scored on the episodes it played.
    """
    agents = [r for r in results if _kind(r.agent) != "human"]
    if not _paired(agents):
        return None
    best: dict[str, EvaluationResult] = {}
    for result in agents:
        k = _kind(result.agent)
        if k not in best or result.success_rate > best[k].success_rate:
            best[k] = result
    if "oracle" not in best or "blind" not in best:
        return None
    oracle, blind = best["oracle"], best["blind"]
    reader = best.get("reader", blind)
    return Headroom(
        oracle.success_rate,
        blind.success_rate,
        reader.success_rate,
        blind.agent,
        reader.agent,
        oracle_agent=oracle.agent,
        value_ci95=_paired_interval(_difference, (_successes(oracle), _successes(blind))),
        insight_ci95=_paired_interval(_difference, (_successes(reader), _successes(blind))),
        scores=tuple(
            _person_score(r, blind, oracle) if _kind(r.agent) == "human" else mind_reading_score(r, blind, oracle)
            for r in results
        ),
    )


@dataclass(frozen=True)
class AggregateScore:
    """The interquartile mean of per-run scores, with its stratified bootstrap interval.

    Attributes:
        iqm: Mean of the middle 50 % of all the per-run scores (every level pooled).
        ci95: 95 % percentile interval, runs resampled within each level (NaN ends when a
            level has fewer than two runs: nothing to resample).
        runs: Scores per level that went into it.
    """

    iqm: float
    ci95: Interval
    runs: dict[str, int]

    def as_json(self) -> dict[str, Any]:
        """A JSON-ready dict (NaN becomes None)."""
        return _finite({"iqm": self.iqm, "ci95": list(self.ci95), "runs": dict(self.runs)})

    def text(self) -> str:
        """``IQM 0.81 [0.77, 0.85] over 3 runs``."""
        ci = "" if not math.isfinite(self.ci95[0]) else f" [{self.ci95[0]:.2f}, {self.ci95[1]:.2f}]"
        n = sum(self.runs.values())
        return f"IQM {self.iqm:.2f}{ci} over {n} run{'' if n == 1 else 's'}"


def _iqm(*samples: Any, axis: int = -1) -> Any:
    return stats.trim_mean(np.concatenate(samples, axis=axis), 0.25, axis=axis)


def iqm_across_runs(scores_by_level: Mapping[str, Sequence[float]]) -> AggregateScore:
    """Interquartile mean of per-run scores across training seeds, stratified by level (rliable's method).

    Args:
        scores_by_level: For each level (env id), one score per training run (NaN scores are dropped).

    Returns:
        The :class:`AggregateScore`.

    Raises:
        ValueError: no finite score at all.

    Example:
        >>> agg = iqm_across_runs({"hard": [0.7, 0.8, 0.9, 1.0], "medium": [0.5, 0.6]})
        >>> round(agg.iqm, 3), agg.runs
        (0.75, {'hard': 4, 'medium': 2})
    """
    finite = {level: [s for s in v if math.isfinite(s)] for level, v in scores_by_level.items()}
    samples = {level: np.asarray(v, dtype=np.float64) for level, v in finite.items() if v}
    if not samples:
        raise ValueError("no finite mind-reading score to aggregate")
    point = float(_iqm(*samples.values()))
    ci: Interval = (math.nan, math.nan)
    if all(len(v) >= 2 for v in samples.values()):
        # paired=False resamples each level's runs on their own: rliable's stratified bootstrap.
        found = stats.bootstrap(
            tuple(samples.values()),
            _iqm,
            paired=False,
            vectorized=True,
            axis=-1,
            n_resamples=N_RESAMPLES,
            method="percentile",
            rng=np.random.default_rng(BOOTSTRAP_SEED),
        )
        ci = float(found.confidence_interval.low), float(found.confidence_interval.high)
    return AggregateScore(point, ci, {level: len(v) for level, v in samples.items()})


def selection_study(
    candidates: Sequence[Sequence[Mapping[str, Any]]], rules: Sequence[str], target: str = "test"
) -> dict[str, Any]:
    """How well each selecting set predicts ``target`` across training runs, and what it keeps.

    Args:
        candidates: Per run, its scored policies in order (``SelectionCallback``'s scores with
            ``recorded`` sets): each maps a set name to ``{"success_rate": ...}``.
        rules: Set names a policy may be selected on (e.g. ``"train"``, ``"validation"``).
        target: The set the choice is judged on (the held-out people), never a rule.

    Returns:
        Per rule: the policy each run keeps (its best on the rule, ties to the later), the
        Pearson ``r`` (with its 95 % interval) and Spearman ``rho`` between the kept policies'
        rule and ``target`` success over runs, the same over every candidate of every run,
        the kept ``target`` success per run, and, runs paired ``k`` and ``k + n/2``, the
        ``target`` success of the better-scored run of each pair.
    """
    if target in rules or len(candidates) < 3:
        raise ValueError(f"selection_study needs >= 3 runs and a target not among the rules, got {len(candidates)}")
    out: dict[str, Any] = {"runs": len(candidates), "target": target}
    half = len(candidates) // 2
    for rule in rules:
        kept = [max(reversed(run), key=lambda p: p[rule]["success_rate"]) for run in candidates]
        x = [k[rule]["success_rate"] for k in kept]
        y = [k[target]["success_rate"] for k in kept]
        every = [(p[rule]["success_rate"], p[target]["success_rate"]) for run in candidates for p in run]
        pearson = stats.pearsonr(x, y)
        scored = list(zip(x, y, strict=True))
        pairs = [max(scored[k], scored[k + half], key=lambda s: s[0]) for k in range(half)]
        out[rule] = _finite(
            {
                "pearson_r": float(pearson.statistic),
                "pearson_r_ci95": list(pearson.confidence_interval()),
                "spearman_rho": float(stats.spearmanr(x, y).statistic),
                "candidates_pearson_r": float(stats.pearsonr(*zip(*every, strict=True)).statistic),
                "kept_timesteps": [k["timesteps"] for k in kept],
                "kept_rule_success": x,
                "kept_target_success": y,
                "kept_target_unsafe": [k[target]["unsafe_rate"] for k in kept],
                "best_of_pairs_target_success": [t for _, t in pairs],
            }
        )
    return out
