"""The paper's estimator run offline over recorded trials: ``python -m estimator.estimate RECORDING...``.

Reads recordings (:mod:`estimator.recording`; a folder stands for its ``*.csv`` files), runs
the chosen filter over each on its recorded nominal model, judges each trial on the paper's
rule (:class:`~estimator.judgment.ThresholdJudgment` 0.75 s after the initial cue onset, on
the judgment tracker's step) and prints the estimates and judgments; where the recordings
hold the requested ``xi`` it prints the paper's three tables and the balanced accuracy.

* ``kalman`` -- the paper's thresholded filter (:class:`~estimator.kalman.FastKalmanFilter`);
* ``multiple_model`` / ``imm`` -- MMAE and IMM (:mod:`estimator.multiple_model`), MAP at the
  same step.

The same estimators of ``python -m coop_gym.experiment.protocol`` judge the simulated trials
that ``--export`` writes the same way: both give the same tables on the same seed. The
switching particle filter is not offered here: its person model is the simulator's
(:mod:`coop_gym.envs.switching`), which this package sits below.

Example:
    >>> rec = Recording(np.arange(100) * 0.02, np.zeros(100), np.zeros(100), np.r_[np.zeros(10), np.ones(90)])
    >>> estimate_recordings([rec])[0].judgment
    0
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import tyro
from numpy.typing import NDArray

from estimator.judgment import ThresholdJudgment, first_judgment_step, gaussian_xi_probabilities
from estimator.kalman import FastKalmanFilter, nominal_row
from estimator.multiple_model import (
    TRIAL_PROBABILITY_FLOOR,
    TRIAL_SWITCHING_RATE_PER_S,
    IMMEstimator,
    MultipleModelEstimator,
    map_judgment,
)
from estimator.paper import format_tables, judgment_scores
from estimator.recording import Recording, RecordingError, read_recording, recordings_in

__all__ = ["OFFLINE_ESTIMATORS", "Args", "TrialEstimate", "estimate_recordings", "main", "summarize_recordings"]

OFFLINE_ESTIMATORS: tuple[str, ...] = ("kalman", "multiple_model", "imm")
"""The estimators :func:`estimate_recordings` runs."""


@dataclass(frozen=True, eq=False)
class TrialEstimate:
    """What an estimator made of one recording.

    Attributes:
        name: The recording's name (its path).
        judgment: Judged ``xi`` in {-1, 0, +1}.
        probabilities: (3,) ``P(xi = -1, 0, +1)`` at the judgment (the KF's from its Gaussian marginal).
        judgment_step: Sample index of the judgment.
        latency_s: Time from the initial cue onset to the judgment [s].
        xi_trace: (T,) running ``xi`` estimate (KF mean, or ``P(+1) - P(-1)``).
        position_trace: (T,) running shoulder-position estimate [m] (NaN for the multiple-model ones).
    """

    name: str
    judgment: int
    probabilities: NDArray[np.float64]
    judgment_step: int
    latency_s: float
    xi_trace: NDArray[np.float64]
    position_trace: NDArray[np.float64]


def _xi_sequence(rec: Recording, estimator: str) -> tuple[NDArray[np.float64], NDArray[np.float64], Any]:
    """(T,) xi estimate, (T,) position estimate, and what the judgment reads: the KF's (mean, std) or (T, 3) P."""
    model = rec.nominal_model
    row = nominal_row(model)[None, :]
    force, verbal, y = (a[None, :] for a in (rec.force_n, rec.verbal_cue, rec.shoulder_position_m))
    if estimator == "kalman":
        means, covs, _ = FastKalmanFilter(row, y[:, 0], prior=model).run(force, verbal, y)
        std = np.sqrt(np.maximum(covs[0, :, 3, 3], 0.0))
        return means[0, :, 3], means[0, :, 0], (means[0, :, 3], std)
    if estimator == "multiple_model":
        mm: MultipleModelEstimator | IMMEstimator = MultipleModelEstimator(
            row, y[:, 0], prior=model, probability_floor=TRIAL_PROBABILITY_FLOOR
        )
    else:
        mm = IMMEstimator(
            row, y[:, 0], prior=model, probability_floor=TRIAL_PROBABILITY_FLOOR,
            switching_rate_per_s=TRIAL_SWITCHING_RATE_PER_S,
        )  # fmt: skip
    probs = mm.run(force, verbal, y)[0]
    return probs[:, 2] - probs[:, 0], np.full(probs.shape[0], np.nan), probs


def estimate_recordings(
    recordings: Sequence[Recording], estimator: str = "kalman", judgment: ThresholdJudgment | None = None
) -> list[TrialEstimate]:
    """Run ``estimator`` over each recording and judge it at the paper's step.

    Raises:
        ValueError: An unknown estimator, or a recording with no cue (nothing to judge).
    """
    if estimator not in OFFLINE_ESTIMATORS:
        raise ValueError(f"unknown estimator {estimator!r}; choose from {', '.join(OFFLINE_ESTIMATORS)}")
    judgment = judgment if judgment is not None else ThresholdJudgment()
    out = []
    for rec in recordings:
        active = rec.cue_active
        try:
            step = first_judgment_step(active, judgment, rec.dt_s)
        except ValueError as exc:
            raise ValueError(f"{rec.name}: {exc}") from None
        xi, position, evidence = _xi_sequence(rec, estimator)
        if estimator == "kalman":
            mean, std = evidence
            judged = int(judgment.judge(mean[step]))
            probs = gaussian_xi_probabilities(mean[step], std[step])
        else:
            probs = evidence[step]
            judged = int(map_judgment(probs))
        # On the judgment tracker's clock, as the protocol reports it (0.74 s at 50 Hz).
        latency = (step - int(np.argmax(active))) * rec.dt_s
        out.append(TrialEstimate(rec.name, judged, np.asarray(probs), step, latency, xi, position))
    return out


def summarize_recordings(recordings: Sequence[Recording], estimates: Sequence[TrialEstimate]) -> dict[str, Any]:
    """Per-trial judgments and, over the trials with a requested ``xi``, the paper's scores (JSON-ready)."""
    trials = [
        {
            "recording": e.name,
            "requested_xi": r.requested,
            "judgment": e.judgment,
            "probabilities": e.probabilities.tolist(),
            "xi_estimate": float(e.xi_trace[e.judgment_step]),
            "judgment_time_s": float(r.time_s[e.judgment_step]),
            "latency_s": e.latency_s,
        }
        for r, e in zip(recordings, estimates, strict=True)
    ]
    out: dict[str, Any] = {"n_trials": len(trials), "trials": trials}
    labelled = [(r.requested, e) for r, e in zip(recordings, estimates, strict=True) if r.requested is not None]
    if labelled:
        out["n_labelled"] = len(labelled)
        out.update(
            judgment_scores(
                [k for k, _ in labelled],
                [e.judgment for _, e in labelled],
                np.stack([e.probabilities for _, e in labelled]),
                [e.latency_s for _, e in labelled],
            )
        )
    return out


def plot_estimate(recording: Recording, estimate: TrialEstimate, judgment: ThresholdJudgment, path: str) -> None:
    """A Fig. 6 style trace of one recording: shoulder position and the ``xi`` estimate with the band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = recording.time_s
    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(7, 5))
    top.plot(t, recording.shoulder_position_m, ".", ms=2, label="measured")
    top.plot(t, estimate.position_trace, label="estimate")
    top.set_ylabel("shoulder position [m]")
    top.legend(loc="upper left")
    bottom.plot(t, estimate.xi_trace, label="xi estimate")
    if recording.true_xi is not None:
        bottom.plot(t, recording.true_xi, "k--", label="true xi")
    bottom.axhspan(-judgment.threshold, judgment.threshold, color="0.9", label="unresponsive band")
    bottom.axvline(t[estimate.judgment_step], color="r", label=f"judgment {estimate.judgment:+d}")
    bottom.set_xlabel("time [s]")
    bottom.set_ylabel("xi")
    bottom.legend(loc="upper left")
    fig.suptitle(recording.name)
    fig.savefig(path, dpi=100)
    plt.close(fig)


PROG = "python -m estimator.estimate"
DESCRIPTION = (
    "The paper's filter run offline over recorded sit-to-stand trials (CSV, see estimator.recording): "
    "estimates, judgments and, where the requested xi is recorded, the paper's three tables."
)


@dataclass
class Args:
    """The command line's arguments; each field's docstring is its ``--help``."""

    recordings: Annotated[tuple[str, ...], tyro.conf.Positional, tyro.conf.arg(metavar="RECORDING...")]
    """recording files (CSV, see estimator.recording), or folders of them"""
    estimator: Literal["kalman", "multiple_model", "imm"] = "kalman"
    """estimator to run"""
    json: bool = False
    """print one JSON object instead of text"""
    plot: Annotated[str | None, tyro.conf.arg(metavar="PATH")] = None
    """write a trace of the first recording (PNG)"""


def _text(summary: dict[str, Any], estimator: str) -> str:
    lines = [f"{'recording':40s} requested  judged  P(-1)  P(0)  P(+1)  xi_hat  at [s]"]
    for t in summary["trials"]:
        req = "-" if t["requested_xi"] is None else f"{t['requested_xi']:+d}"
        p = t["probabilities"]
        lines.append(
            f"{t['recording'][-40:]:40s} {req:>9s}  {t['judgment']:+6d}  {p[0]:5.2f} {p[1]:5.2f} {p[2]:5.2f}"
            f"  {t['xi_estimate']:+6.2f}  {t['judgment_time_s']:6.2f}"
        )
    if "confusion" in summary:
        title = (
            f"estimator: {estimator}, {summary['n_labelled']} recorded trials with a requested xi  |  "
            "paper: 4 real subjects x 25 trials"
        )
        lines += ["", format_tables(summary, title, ours="recorded")]
    return "\n".join(lines)


PLOT_SUFFIXES = (".png", ".pdf", ".svg")
"""The figure formats ``--plot`` writes (matplotlib's, by the file's suffix)."""


def _plot_problem(plot: str | None) -> str | None:
    """Why ``--plot`` cannot be written, before any recording is read (None if it can, or is not asked for)."""
    if plot is None:
        return None
    path = Path(plot)
    if path.suffix.lower() not in PLOT_SUFFIXES:
        return f"--plot: unsupported file type {path.suffix or '(none)'!r}; use {', '.join(PLOT_SUFFIXES)}"
    folder = path.parent
    if path.is_dir() or not folder.is_dir() or not os.access(folder, os.W_OK | os.X_OK):
        return f"--plot: cannot write {path} ({folder} is not a writable folder)"
    return None


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point: exit 0, 1 on a bad recording (the message names line and column), 2 on usage."""
    args = tyro.cli(Args, args=list(sys.argv[1:] if argv is None else argv), prog=PROG, description=DESCRIPTION)
    problem = "give at least one recording" if not args.recordings else _plot_problem(args.plot)
    if problem:
        print(f"usage: {PROG} [-h] [OPTIONS] RECORDING...\n{PROG}: error: {problem}", file=sys.stderr)
        return 2
    try:
        paths = recordings_in(args.recordings)
        if not paths:
            raise RecordingError("no recordings (an empty folder?)")
        recordings = [read_recording(p) for p in paths]
        estimates = estimate_recordings(recordings, args.estimator)
    except ValueError as exc:  # RecordingError included
        print(f"error: {exc}", file=sys.stderr)
        return 1
    summary = summarize_recordings(recordings, estimates)
    summary["estimator"] = args.estimator
    if args.plot:
        plot_estimate(recordings[0], estimates[0], ThresholdJudgment(), args.plot)
    print(json.dumps(summary) if args.json else _text(summary, args.estimator))
    return 0


if __name__ == "__main__":
    try:
        status = main()
        sys.stdout.flush()
    except BrokenPipeError:  # a reader that closed the pipe early (... --json | head): a quiet stop, status 1
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        status = 1
    sys.exit(status)
