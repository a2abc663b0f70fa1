"""Calibration report: the simulated experiment against the paper, and the estimators against each other.

``python -m coop_gym.experiment.calibrate [--seeds 20] [--seed 0] [--estimators ...] [--json]``

1. **Calibration to the paper.** The paper's thresholded Kalman filter on the paper's
   protocol (:mod:`coop_gym.experiment.protocol`), every cell of Tables I-III as mean +/- std over
   seeds, beside the paper's numbers on real people (:data:`coop_gym.experiment.protocol.PAPER_RESULTS`).
   The simulator's realism defaults and the filter's noise defaults were chosen with this
   report so that the simulated people are not easier than real ones.
2. **Better estimators, same trials.** Balanced accuracy, accuracy, log loss, Brier
   score, ECE and judgment latency of every estimator (mean +/- std over seeds), and
   the per-seed paired gain in balanced accuracy over the thresholded KF.
3. **How much the 0.75 s deadline costs.** Balanced accuracy of the KF, the persona
   bank and the oracle bank (the subject's *true* parameters: an information bound for
   linear delay-aware filters) when the judgment is taken later.

Every number comes from seeded simulations; re-running with the same arguments
reproduces it exactly.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
import tyro

from coop_gym.cli import BadArgs, PositiveInt, Seed, exit_status, parse
from coop_gym.experiment.protocol import (
    ESTIMATORS,
    NEEDS_CALIBRATION,
    PAPER_RESULTS,
    ProtocolConfig,
    aggregate,
    estimate,
    format_aggregate,
    run_experiment,
    summarize,
)
from estimator.judgment import ThresholdJudgment

__all__ = ["PROG", "Args", "compare_estimators", "delay_sweep", "main"]

DEFAULT_ESTIMATORS: tuple[str, ...] = ESTIMATORS
"""Estimators compared by default (all of them)."""

SWEEP_DELAYS_S: tuple[float, ...] = (0.5, 0.75, 1.0, 1.5, 2.0)
"""Judgment delays [s] of the deadline sweep."""

SWEEP_ESTIMATORS: tuple[str, ...] = ("kalman", "persona_bank", "oracle")


def compare_estimators(
    config: ProtocolConfig,
    seeds: Sequence[int],
    estimators: Sequence[str],
    *,
    sequential: bool = True,
) -> dict[str, dict[str, Any]]:
    """Score every estimator on the same simulated experiments, one per seed.

    Args:
        config: Protocol settings.
        seeds: Seeds of the experiments.
        estimators: Names from :data:`coop_gym.experiment.protocol.ESTIMATORS`.
        sequential: Also score the multiple-model estimators with the early (sequential) decision rule.

    Returns:
        Per estimator label: :func:`~coop_gym.experiment.protocol.aggregate` of its per-seed summaries,
        plus ``per_seed_balanced_accuracy`` and ``seconds`` (compute time).
    """
    unknown = [e for e in estimators if e not in ESTIMATORS]
    if unknown:
        raise ValueError(f"unknown estimator(s) {unknown}; choose from {', '.join(ESTIMATORS)}")
    runs: dict[str, list[dict[str, Any]]] = {}
    seconds: dict[str, float] = {}
    need_calibration = any(e in NEEDS_CALIBRATION for e in estimators)
    for seed in seeds:
        data = run_experiment(config, seed, with_calibration=need_calibration)
        for name in estimators:
            variants = [("map", name)]
            if sequential and name not in ("kalman", "oracle"):
                variants.append(("sequential", f"{name}+early"))
            for decision, label in variants:
                start = time.perf_counter()
                result = estimate(data, name, decision=decision)  # type: ignore[arg-type]
                seconds[label] = seconds.get(label, 0.0) + time.perf_counter() - start
                summary = summarize(data, result)
                summary["estimator"] = label
                runs.setdefault(label, []).append(summary)
    out = {}
    for label, summaries in runs.items():
        agg = aggregate(summaries)
        agg["per_seed_balanced_accuracy"] = [s["balanced_accuracy"] for s in summaries]
        agg["seconds"] = seconds[label]
        out[label] = agg
    return out


def delay_sweep(
    config: ProtocolConfig,
    seeds: Sequence[int],
    delays_s: Sequence[float] = SWEEP_DELAYS_S,
    estimators: Sequence[str] = SWEEP_ESTIMATORS,
) -> dict[str, dict[str, list[float]]]:
    """Balanced accuracy (mean, std over seeds) of some estimators against the judgment delay.

    The simulated data do not depend on the judgment delay, so every delay sees the same trials.
    """
    out: dict[str, dict[str, list[float]]] = {e: {"mean": [], "std": []} for e in estimators}
    for delay in delays_s:
        cfg = dataclasses.replace(config, judgment=dataclasses.replace(config.judgment, delay_s=float(delay)))
        scores: dict[str, list[float]] = {e: [] for e in estimators}
        for seed in seeds:
            data = run_experiment(cfg, seed)
            for name in estimators:
                scores[name].append(summarize(data, estimate(data, name))["balanced_accuracy"])
        for name in estimators:
            out[name]["mean"].append(float(np.mean(scores[name])))
            out[name]["std"].append(float(np.std(scores[name])))
    return out


def format_comparison(comparison: dict[str, dict[str, Any]]) -> str:
    """One line per estimator: scores as mean +/- std over seeds and the paired gain over the KF."""
    base = np.array(comparison["kalman"]["per_seed_balanced_accuracy"]) if "kalman" in comparison else None
    lines = [
        f"{'estimator':>22s} {'balanced acc.':>15s} {'gain vs KF':>14s} {'accuracy':>13s} {'log loss':>13s} "
        f"{'Brier':>13s} {'ECE':>13s} {'latency':>8s} {'time':>7s}"
    ]
    for label, agg in comparison.items():
        gain = ""
        if base is not None:
            diff = np.array(agg["per_seed_balanced_accuracy"]) - base
            gain = f"{100 * diff.mean():+5.1f} +/-{100 * diff.std():4.1f}"
        lines.append(
            f"{label:>22s} {100 * agg['balanced_accuracy']:6.1f} +/-{100 * agg['balanced_accuracy_std']:4.1f} "
            f"{gain:>14s} {100 * agg['accuracy']:5.1f} +/-{100 * agg['accuracy_std']:4.1f} "
            f"{agg['log_loss']:5.3f} +/-{agg['log_loss_std']:5.3f} {agg['brier']:5.3f} +/-{agg['brier_std']:5.3f} "
            f"{agg['ece']:5.3f} +/-{agg['ece_std']:5.3f} {agg['mean_latency_s']:6.2f} s {agg['seconds']:6.1f}s"
        )
    return "\n".join(lines)


def format_sweep(sweep: dict[str, dict[str, list[float]]], delays_s: Sequence[float] = SWEEP_DELAYS_S) -> str:
    """Balanced accuracy against judgment delay, one row per estimator."""
    lines = [f"{'judgment delay':>14s}" + "".join(f"{d:>15.2f}s" for d in delays_s)]
    for name, row in sweep.items():
        cells = "".join(f"{100 * m:8.1f} +/-{100 * s:4.1f}" for m, s in zip(row["mean"], row["std"], strict=True))
        lines.append(f"{name:>14s}{cells}")
    return "\n".join(lines)


PROG = "python -m coop_gym.experiment.calibrate"


@dataclass
class Args:
    """The command line's arguments; each field's docstring is its ``--help``."""

    seeds: PositiveInt = 20
    """number of seeds (>= 20 for the report)"""
    seed: Seed = 0
    """first seed"""
    estimators: Annotated[
        str, tyro.conf.arg(help=f"comma-separated subset of {','.join(ESTIMATORS)} (identified: the slowest)")
    ] = ",".join(DEFAULT_ESTIMATORS)
    sweep: bool = True
    """run the judgment-delay sweep (--no-sweep: skip it)"""
    json: bool = False
    """print one JSON object"""

    def __post_init__(self) -> None:
        """An unknown estimator is a usage error naming the flag."""
        if not self.names() or any(e not in ESTIMATORS for e in self.names()):
            raise BadArgs(f"--estimators must name some of {', '.join(ESTIMATORS)}, got {self.estimators!r}")

    def names(self) -> list[str]:
        """The estimators named by ``--estimators``."""
        return [e for e in self.estimators.split(",") if e]


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point; usage errors exit with status 2."""
    args = parse(Args, argv, PROG, __doc__.splitlines()[0])
    names = args.names()
    if "kalman" not in names:
        names.insert(0, "kalman")
    config = ProtocolConfig()
    seeds = list(range(args.seed, args.seed + args.seeds))
    comparison = compare_estimators(config, seeds, names)
    sweep = delay_sweep(config, seeds) if args.sweep else None
    if args.json:
        out: dict[str, Any] = {
            "seeds": seeds,
            "paper": {
                "confusion": PAPER_RESULTS.matrix.tolist(),
                "accuracy": PAPER_RESULTS.accuracy,
                "balanced_accuracy": PAPER_RESULTS.balanced_accuracy,
            },
            "estimators": comparison,
        }
        if sweep is not None:
            out["delay_sweep"] = {"delays_s": list(SWEEP_DELAYS_S), **sweep}
        print(json.dumps(out))
        return 0
    judgment = ThresholdJudgment()
    print(f"== 1. Calibration: the paper's thresholded KF ({judgment.delay_s} s, +/-{judgment.threshold}) vs the paper")
    print(format_aggregate(comparison["kalman"]))
    print("\n== 2. Estimators on the same trials (mean +/- std over seeds; gain = paired per-seed difference)")
    print(format_comparison(comparison))
    if sweep is not None:
        print("\n== 3. Balanced accuracy [%] against the judgment delay (paper: 0.75 s)")
        print(format_sweep(sweep))
    return 0


if __name__ == "__main__":
    sys.exit(exit_status(main))
