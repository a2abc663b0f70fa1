"""The paper's experiment (§V) as a reproducible protocol, and better estimators on it.

``python -m coop_gym.experiment.protocol --help``. The parts: the trial design and the simulated
subjects (:mod:`coop_gym.experiment.simulation`), the registry of estimators
(:mod:`coop_gym.experiment.estimators`) and the subject models they read
(:mod:`coop_gym.experiment.banks`), scores and the paper's tables (:mod:`coop_gym.experiment.tables`),
figures (:mod:`coop_gym.experiment.plots`); this module runs them from the command line and
re-exports their public names.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import tyro

from coop_gym.cli import BadArgs, PositiveInt, Seed, exit_status, one_of, output_path_problem, parse, seed_range_problem
from coop_gym.experiment.banks import identified_banks, intention_drive, subject_models
from coop_gym.experiment.estimators import (
    ESTIMATORS,
    NEEDS_CALIBRATION,
    EstimateResult,
    estimate,
    fit_recalibration,
    gaussian_xi_probabilities,
)
from coop_gym.experiment.plots import plot_confusion, plot_trial
from coop_gym.experiment.simulation import ExperimentData, ProtocolConfig, TrialSpec, draw_trials, run_experiment
from coop_gym.experiment.tables import aggregate, format_aggregate, format_tables, summarize
from coop_gym.io import write_text
from coop_gym.model.difficulty import DIFFICULTIES
from estimator.paper import PAPER_RESULTS, accuracy, balanced_accuracy, conditional_tables, confusion_matrix
from estimator.recording import Recording, format_recording

__all__ = [
    "ESTIMATORS",
    "NEEDS_CALIBRATION",
    "PAPER_RESULTS",
    "PROG",
    "Args",
    "EstimateResult",
    "ExperimentData",
    "ProtocolConfig",
    "TrialSpec",
    "accuracy",
    "aggregate",
    "args_problem",
    "balanced_accuracy",
    "conditional_tables",
    "confusion_matrix",
    "draw_trials",
    "estimate",
    "export_recordings",
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


def export_recordings(data: ExperimentData, folder: str | Path) -> list[Path]:
    """Write every trial of ``data`` as a recording file (:mod:`estimator.recording`); returns the paths.

    Each file ``seed{seed}_s{subject}_t{trial}.csv`` holds the measured position and force, the
    verbal and commanded physical cues, the requested and true ``xi``, and the subject's nominal
    model (the one the protocol's filters run on), so ``python -m estimator.estimate`` judges
    the files exactly as the protocol judged the trials.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    models = subject_models(data)
    time_s = np.arange(data.config.n_steps, dtype=np.float64) * data.config.timing.dt_s
    paths = []
    for i, persona in enumerate(data.personas):
        for k, spec in enumerate(data.trials):
            recording = Recording(
                time_s=time_s,
                shoulder_position_m=data.measured_position_m[i, k],
                force_n=data.measured_force_n[i, k],
                verbal_cue=data.verbal_cue[k],
                cue_force_n=data.push_force_n[k],
                requested_xi=np.full(time_s.shape, spec.requested_xi),
                true_xi=data.true_state[i, k, :, 3],
                model=models[i],
                meta={
                    "source": f"{PROG} --seed {data.seed}",
                    "subject": f"s{i:02d}",
                    "persona": persona.name,
                    "trial": f"t{k:02d}",
                    "cues": f"physical {spec.physical_cue}, verbal {spec.verbal_cue}, "
                    f"verbal minus physical onset {spec.relative_timing_s} s",
                },
            )
            path = folder / f"seed{data.seed}_s{i:02d}_t{k:02d}.csv"
            paths.append(write_text(path, format_recording(recording)))
    return paths


PROG = "python -m coop_gym.experiment.protocol"
DESCRIPTION = (
    "Bell & Asada's cooperativeness-judgment experiment on simulated subjects: the paper's "
    "three tables side by side with its numbers on real people."
)


@dataclass
class Args:
    """The command line's arguments; each field's docstring is its ``--help``."""

    subjects: PositiveInt = 4
    """simulated subjects (paper: 4)"""
    trials: PositiveInt = 25
    """trials per subject (paper: 25)"""
    seed: Seed = 0
    """seed of trials, subjects and noise"""
    seeds: PositiveInt = 1
    """run seeds seed..seed+K-1, report mean +/- std"""
    estimator: Annotated[str, one_of(ESTIMATORS)] = "kalman"
    """estimator to score"""
    decision: Literal["map", "sequential"] = "map"
    """multiple-model judgment: MAP at the paper's 0.75 s, or the earliest confident step up to it"""
    personas: str = "all"
    """persona set of the subjects: all, train, test or a name"""
    difficulty: Annotated[str | None, one_of(tuple(DIFFICULTIES))] = None
    """subjects at this difficulty level of the -v1 envs; None: the -v0 model"""
    json: bool = False
    """print one JSON object instead of tables"""
    plot: Annotated[str | None, tyro.conf.arg(metavar="PATH")] = None
    """write a Fig. 6 style trace of one trial (PNG)"""
    plot_confusion: Annotated[str | None, tyro.conf.arg(metavar="PATH")] = None
    """write the confusion matrix beside the paper's (PNG)"""
    export: Annotated[str | None, tyro.conf.arg(metavar="DIR")] = None
    """write every simulated trial as a recording (estimator.recording) into this folder"""

    def __post_init__(self) -> None:
        """The first value no run can use is a usage error naming it."""
        if problem := args_problem(self):
            raise BadArgs(problem)

    def config(self) -> ProtocolConfig:
        """The experiment these arguments ask for."""
        return ProtocolConfig(
            n_subjects=self.subjects, n_trials=self.trials, personas=self.personas, difficulty=self.difficulty
        )


def args_problem(args: Args) -> str | None:
    """The first value of ``args`` no run can use (None if all are fine); checked before the experiment runs."""
    try:
        args.config()
    except ValueError as err:
        return str(err)
    problem = seed_range_problem("--seed", args.seed, args.seeds)  # runs seed .. seed + seeds - 1
    if problem:
        return problem
    for path in (args.plot, args.plot_confusion):
        if path is not None and not path.lower().endswith(".png"):
            return f"plot paths must end in .png, got {path!r}"
        # Checked before the experiment runs, so a bad path fails at once, not after the work.
        problem = output_path_problem(path) if path is not None else None
        if problem:
            return problem
    problem = output_path_problem(args.export, folder=True) if args.export is not None else None
    return f"--export: {problem}" if problem else None


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point; usage errors exit with status 2."""
    args = parse(Args, argv, PROG, DESCRIPTION)
    config = args.config()
    summaries = []
    first: tuple[ExperimentData, EstimateResult] | None = None
    for seed in range(args.seed, args.seed + args.seeds):
        data = run_experiment(config, seed, with_calibration=args.estimator in NEEDS_CALIBRATION)
        result = estimate(data, args.estimator, decision=args.decision)
        summaries.append(summarize(data, result))
        if args.export is not None:
            export_recordings(data, args.export)
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
    sys.exit(exit_status(main))
