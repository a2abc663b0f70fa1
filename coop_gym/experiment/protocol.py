"""The paper's experiment (§V) as a reproducible protocol, and better estimators on it.

``python -m coop_gym.experiment.protocol --help``. The parts: the trial design and the simulated
subjects (:mod:`coop_gym.experiment.simulation`), the registry of estimators
(:mod:`coop_gym.experiment.estimators`) and the subject models they read
(:mod:`coop_gym.experiment.banks`), scores and the paper's tables (:mod:`coop_gym.experiment.tables`),
figures (:mod:`coop_gym.experiment.plots`); this module runs them from the command line and
re-exports their public names.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from typing import Any, Literal

from coop_gym.cli import output_path_problem, seed_range_problem
from coop_gym.cli import positive_int as _positive_int
from coop_gym.cli import seed as _seed
from coop_gym.experiment.banks import identified_banks, intention_drive
from coop_gym.experiment.estimators import (
    ESTIMATORS,
    NEEDS_CALIBRATION,
    EstimateResult,
    estimate,
    fit_recalibration,
    gaussian_xi_probabilities,
)
from coop_gym.experiment.paper import PAPER_RESULTS, accuracy, balanced_accuracy, conditional_tables, confusion_matrix
from coop_gym.experiment.plots import plot_confusion, plot_trial
from coop_gym.experiment.simulation import ExperimentData, ProtocolConfig, TrialSpec, draw_trials, run_experiment
from coop_gym.experiment.tables import aggregate, format_aggregate, format_tables, summarize
from coop_gym.model.difficulty import DIFFICULTIES

__all__ = [
    "ESTIMATORS",
    "NEEDS_CALIBRATION",
    "PAPER_RESULTS",
    "EstimateResult",
    "ExperimentData",
    "ProtocolConfig",
    "TrialSpec",
    "accuracy",
    "aggregate",
    "balanced_accuracy",
    "build_parser",
    "conditional_tables",
    "confusion_matrix",
    "draw_trials",
    "estimate",
    "fit_recalibration",
    "format_aggregate",
    "format_tables",
    "gaussian_xi_probabilities",
    "identified_banks",
    "intention_drive",
    "main",
    "plot_confusion",
    "plot_trial",
    "run_experiment",
    "run_protocol",
    "summarize",
]


def run_protocol(
    config: ProtocolConfig,
    seed: int,
    estimator: str = "kalman",
    *,
    decision: Literal["map", "sequential"] = "map",
) -> dict[str, Any]:
    """Simulate the experiment with ``seed`` and score ``estimator`` on it (see :func:`summarize`).

    Example:
        >>> out = run_protocol(ProtocolConfig(n_subjects=1, n_trials=6), seed=0)
        >>> sum(map(sum, out["confusion"]))
        6
    """
    if estimator not in ESTIMATORS:
        raise ValueError(f"unknown estimator {estimator!r}; choose from {', '.join(ESTIMATORS)}")
    data = run_experiment(config, seed, with_calibration=estimator in NEEDS_CALIBRATION)
    return summarize(data, estimate(data, estimator, decision=decision))


def build_parser() -> argparse.ArgumentParser:
    """The ``python -m coop_gym.experiment.protocol`` argument parser."""
    parser = argparse.ArgumentParser(
        prog="python -m coop_gym.experiment.protocol",
        description="Bell & Asada's cooperativeness-judgment experiment on simulated subjects: the paper's "
        "three tables side by side with its numbers on real people.",
    )
    parser.add_argument("--subjects", type=_positive_int, default=4, help="simulated subjects (paper: 4)")
    parser.add_argument("--trials", type=_positive_int, default=25, help="trials per subject (paper: 25)")
    parser.add_argument("--seed", type=_seed, default=0, help="seed of trials, subjects and noise")
    parser.add_argument("--seeds", type=_positive_int, default=1, help="run seeds seed..seed+K-1, report mean +/- std")
    parser.add_argument("--estimator", choices=ESTIMATORS, default="kalman", help="estimator to score")
    parser.add_argument(
        "--decision", choices=("map", "sequential"), default="map",
        help="multiple-model judgment: MAP at the paper's 0.75 s, or the earliest confident step up to it",
    )  # fmt: skip
    parser.add_argument("--personas", default="all", help="persona set of the subjects: all, train, test or a name")
    parser.add_argument(
        "--difficulty",
        choices=tuple(DIFFICULTIES),
        default=None,
        help="subjects at this difficulty level of the -v1 envs (default: the -v0 model)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of tables")
    parser.add_argument("--plot", metavar="PATH", help="write a Fig. 6 style trace of one trial (PNG)")
    parser.add_argument("--plot-confusion", metavar="PATH", help="write the confusion matrix beside the paper's (PNG)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point; usage errors exit with status 2."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        config = ProtocolConfig(
            n_subjects=args.subjects, n_trials=args.trials, personas=args.personas, difficulty=args.difficulty
        )
    except ValueError as err:
        parser.error(str(err))
    problem = seed_range_problem("--seed", args.seed, args.seeds)  # runs seed .. seed + seeds - 1
    if problem:
        parser.error(problem)
    for path in (args.plot, args.plot_confusion):
        if path is not None and not path.lower().endswith(".png"):
            parser.error(f"plot paths must end in .png, got {path!r}")
        # Checked before the experiment runs, so a bad path fails at once, not after the work.
        problem = output_path_problem(path) if path is not None else None
        if problem:
            parser.error(problem)
    summaries = []
    first: tuple[ExperimentData, EstimateResult] | None = None
    for seed in range(args.seed, args.seed + args.seeds):
        data = run_experiment(config, seed, with_calibration=args.estimator in NEEDS_CALIBRATION)
        result = estimate(data, args.estimator, decision=args.decision)
        summaries.append(summarize(data, result))
        if first is None:
            first = (data, result)
    assert first is not None
    if args.seeds == 1:
        out = summaries[0]
        text = format_tables(out)
    else:
        out = aggregate(summaries)
        text = format_aggregate(out)
    out["paper"] = {
        "confusion": PAPER_RESULTS.matrix.tolist(),
        "accuracy": PAPER_RESULTS.accuracy,
        "balanced_accuracy": PAPER_RESULTS.balanced_accuracy,
    }
    try:
        if args.plot:
            plot_trial(first[0], args.plot, estimator=first[1])
        if args.plot_confusion:
            plot_confusion(out, args.plot_confusion)
    except OSError as exc:  # e.g. a full disk: the file is not there (never half-written)
        print(f"error: could not write {exc.filename or 'output'}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    print(json.dumps(out) if args.json else text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
