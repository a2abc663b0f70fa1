"""Figures of the experiment: the paper's Fig. 6 for one trial, and the confusion matrix beside the paper's."""

from __future__ import annotations

from typing import Any

import numpy as np

from coop_gym.experiment.estimators import EstimateResult, estimate
from coop_gym.experiment.simulation import ExperimentData
from coop_gym.io import save_figure
from estimator.paper import (
    PAPER_RESULTS,
    XI_NAMES,
    XI_SHORT,
    PaperResults,
    balanced_accuracy,
    conditional_tables,
    percent,
)

__all__ = ["plot_confusion", "plot_trial"]

# --------------------------------------------------------------------------- figures


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")  # files only; never open a window
    import matplotlib.pyplot as plt

    return plt


def _default_trial(data: ExperimentData) -> int:
    """The first trial with both cues and a cooperative request (the paper's example), else 0."""
    both = [
        k for k, t in enumerate(data.trials)
        if t.requested_xi == 1 and t.physical_cue != "none" and t.verbal_cue != "none"
    ]  # fmt: skip
    return both[0] if both else 0


def _plot_states(ax: Any, time_s: Any, data: ExperimentData, subject: int, trial: int, est: Any) -> None:
    """Panels 0-2: x, xdot, eta (truth and KF estimate), with the measurements on x."""
    truth = data.true_state[subject, trial]
    ax[0].plot(time_s, 100 * data.measured_position_m[subject, trial], ".", ms=2, color="0.6", label="measured")
    panels = (("x [cm]", 0, 100.0), ("xdot [cm/s]", 1, 100.0), ("eta [cm]", 2, 100.0))
    for k, (label, col, scale) in enumerate(panels):
        ax[k].plot(time_s, scale * truth[:, col], "k-", lw=1.2, label="true")
        ax[k].plot(time_s, scale * est[:, col], "C0-", lw=1.2, label="KF estimate")
        ax[k].set_ylabel(label)
    ax[0].legend(loc="upper left", fontsize=8)


def _plot_cues(ax: Any, time_s: Any, data: ExperimentData, subject: int, trial: int) -> None:
    """Panel 3: the push (commanded and measured) and the verbal cue."""
    ax[3].plot(time_s, data.push_force_n[trial], "C3-", label="push c_p [N]")
    ax[3].plot(time_s, data.measured_force_n[subject, trial], "C3.", ms=1, alpha=0.4)
    ax3b = ax[3].twinx()
    ax3b.plot(time_s, data.verbal_cue[trial], "C2-", label="verbal c_v")
    ax3b.set_ylim(-1.5, 1.5)
    ax3b.set_ylabel("verbal cue c_v")
    ax[3].set_ylabel("push [N]")
    ax[3].legend(loc="upper left", fontsize=8)


def _plot_xi(
    xi_ax: Any,
    time_s: Any,
    data: ExperimentData,
    subject: int,
    trial: int,
    kf: EstimateResult,
    estimator: EstimateResult | None,
) -> None:
    """Panel 4: the xi estimate, the threshold band and the judgment window (and another estimator's)."""
    config = data.config
    threshold = config.judgment.threshold
    xi_ax.axhspan(-threshold, threshold, color="0.9", label=f"unresponsive band +/-{threshold}")
    xi_ax.axhline(threshold, color="0.5", lw=0.8, ls="--")
    xi_ax.axhline(-threshold, color="0.5", lw=0.8, ls="--")
    onset_s = config.onset_step * config.timing.dt_s
    judge_s = time_s[data.judgment_step[trial]]
    xi_ax.axvspan(onset_s, judge_s, color="C1", alpha=0.15, label="judgment window")
    xi_ax.axvline(judge_s, color="C1", lw=1.0)
    xi_ax.plot(time_s, data.true_state[subject, trial][:, 3], "k-", lw=1.2, label="requested (true)")
    xi_ax.plot(time_s, kf.xi_trace[subject, trial], "C0-", lw=1.2, label="KF estimate")
    if estimator is not None and estimator.estimator != "kalman":
        xi_ax.plot(
            time_s, estimator.xi_trace[subject, trial], "C4-", lw=1.2, label=f"{estimator.estimator} P(+1)-P(-1)"
        )
    judged = int(kf.judgment[subject, trial])
    xi_ax.set_title(f"KF judgment: {XI_NAMES[judged + 1]}", fontsize=9)
    xi_ax.set_ylabel("xi")
    xi_ax.set_ylim(-2.0, 2.0)
    xi_ax.legend(loc="lower left", fontsize=7)


def plot_trial(
    data: ExperimentData,
    path: str,
    *,
    subject: int = 0,
    trial: int | None = None,
    estimator: EstimateResult | None = None,
) -> str:
    """Write the paper's Fig. 6 for one trial as a PNG: ``x, xdot, eta, xi`` estimates and truth.

    The x, xdot and eta panels show the paper filter's estimates; the xi panel shows its
    estimate with the +/- threshold band and the judgment window (and, if given, another
    estimator's posterior mean ``P(+1) - P(-1)``). By default the first trial with both cues
    and a cooperative request (the paper's example), else trial 0.

    Returns:
        ``path``.
    """
    plt = _pyplot()
    config = data.config
    if not 0 <= subject < len(data.subjects):
        raise ValueError(f"subject must be in [0, {len(data.subjects)}), got {subject}")
    trial = _default_trial(data) if trial is None else trial
    if not 0 <= trial < len(data.trials):
        raise ValueError(f"trial must be in [0, {len(data.trials)}), got {trial}")
    kf = estimate(data, "kalman")
    spec = data.trials[trial]
    time_s = (np.arange(config.n_steps) + 1) * config.timing.dt_s
    fig, axes = plt.subplots(3, 2, figsize=(10, 8), sharex=True)
    ax = axes.ravel()
    _plot_states(ax, time_s, data, subject, trial, kf.state_trace[subject, trial])
    _plot_cues(ax, time_s, data, subject, trial)
    _plot_xi(ax[4], time_s, data, subject, trial, kf, estimator)
    ax[5].axis("off")
    ax[5].text(
        0.0, 0.9,
        f"subject {subject} ({data.personas[subject].name}), trial {trial}\n"
        f"requested xi = {spec.requested_xi:+d}\nphysical cue: {spec.physical_cue}\n"
        f"verbal cue: {spec.verbal_cue}\nrelative timing: {spec.relative_timing_s:+d} s\n"
        f"judged {config.judgment.delay_s} s after the initial cue onset",
        va="top", fontsize=9,
    )  # fmt: skip
    for a in (ax[3], ax[4]):
        a.set_xlabel("time [s]")
    fig.suptitle("Fig. 6 style: paper Kalman filter on one simulated trial")
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path


def plot_confusion(summary: dict[str, Any], path: str, paper: PaperResults = PAPER_RESULTS) -> str:
    """Write the confusion matrix beside the paper's as a PNG (``P(estimated | requested)`` shading, counts)."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(9, 4))
    panels = (
        (np.array(summary["confusion"]), f"{summary['estimator']} (simulated)"),
        (paper.matrix, "paper (real people)"),
    )
    for ax, (conf, title) in zip(axes, panels, strict=True):
        rates = conditional_tables(conf)[0]
        ax.imshow(np.nan_to_num(rates), vmin=0.0, vmax=1.0, cmap="Blues")
        for r in range(3):
            for c in range(3):
                v = rates[r, c]
                txt = f"{int(conf[r, c])}\n{percent(v)}"
                ax.text(c, r, txt, ha="center", va="center", color="white" if v > 0.5 else "black", fontsize=9)
        ax.set_xticks(range(3), list(XI_SHORT))
        ax.set_yticks(range(3), list(XI_SHORT))
        ax.set_xlabel("estimated")
        ax.set_ylabel("requested")
        ax.set_title(f"{title}\nBA {100 * balanced_accuracy(conf):.1f}%", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path
