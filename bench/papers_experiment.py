"""The paper's experiment: each estimator's judgment of simulated subjects, beside the paper's table.

    python bench/papers_experiment.py [--seeds 20] [--estimators kalman,...] [--save [PATH]]

Runs ``python -m coop_gym.experiment.protocol --seeds N --json`` (Bell & Asada's protocol:
4 subjects x 25 trials, judged at the paper's 0.75 s) once per estimator on the ``-v0``
model's personas, and the paper's thresholded Kalman filter and the switching particle filter
once per difficulty level of the ``-v1`` envs. Each run's report holds the confusion matrix,
P(judged | requested), accuracy, balanced accuracy, log loss, Brier score and ECE as mean and
std over the seeds; the paper's own table on real people (``coop_gym.experiment.PAPER_RESULTS``) comes with it, the
reference the simulated figures are read against. The ``oracle`` estimator (the subject's
true parameters) bounds what any estimator can judge from the same trials.

``--save`` also writes the report to ``bench/results/papers_experiment.json``
(``bench/result_files.py``).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/result_files.py, however this runs
from result_files import add_save_argument, save

from coop_gym.cli import positive_int

ESTIMATORS = ("kalman", "multiple_model", "imm", "delay_aware", "persona_bank", "calibrated", "switching", "oracle")
LEVEL_ESTIMATORS = ("kalman", "switching")
"""Run on every level: the paper's filter, and the switching particle filter of the level's person."""
DIFFICULTIES = ("easy", "medium", "hard", "hard-v2")


def protocol(flags: list[str]) -> dict[str, Any]:
    """The JSON report of ``python -m coop_gym.experiment.protocol FLAGS --json``, run in this process."""
    from coop_gym.experiment.protocol import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        status = main([*flags, "--json"])
    if status != 0:
        raise RuntimeError(f"coop_gym.experiment.protocol {' '.join(flags)} exited with {status}")
    return json.loads(out.getvalue().strip().splitlines()[-1])  # type: ignore[no-any-return]


def main(argv: list[str] | None = None) -> int:
    """Parse the flags, run the protocol for every estimator and level (and save with ``--save``)."""
    parser = argparse.ArgumentParser(prog="python bench/papers_experiment.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=positive_int, default=20, help="seeds 0..N-1 of each run (default 20)")
    parser.add_argument("--estimators", default=",".join(ESTIMATORS), help="comma-separated estimators")
    parser.add_argument("--difficulties", default=",".join(DIFFICULTIES), help="comma-separated levels ('' for none)")
    add_save_argument(parser, "papers_experiment.json")
    args = parser.parse_args(argv)
    if args.seeds < 2:
        parser.error(f"--seeds: mean and std need at least 2 seeds, got {args.seeds}")
    estimators = [e for e in args.estimators.split(",") if e]
    difficulties = [d for d in args.difficulties.split(",") if d]
    bad = [e for e in estimators if e not in ESTIMATORS] + [d for d in difficulties if d not in DIFFICULTIES]
    if bad or not estimators:
        parser.error(f"unknown or no estimators/difficulties: {bad or args.estimators!r}")
    seeds = ["--seeds", str(args.seeds)]
    report: dict[str, Any] = {"seeds": args.seeds, "estimators": {}, "difficulties": {}, "difficulties_switching": {}}
    for estimator in estimators:
        report["estimators"][estimator] = run = protocol([*seeds, "--estimator", estimator])
        print(f"{estimator:>15}: balanced accuracy {run['balanced_accuracy']:.3f}", file=sys.stderr)
    for level in difficulties:
        for estimator, key in zip(LEVEL_ESTIMATORS, ("difficulties", "difficulties_switching"), strict=True):
            report[key][level] = run = protocol([*seeds, "--difficulty", level, "--estimator", estimator])
            print(f"{level:>15}: balanced accuracy {run['balanced_accuracy']:.3f} ({estimator})", file=sys.stderr)
    if args.save:
        save(args.save, "papers_experiment", argv, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
