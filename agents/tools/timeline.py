"""One episode as a timeline: what the robot did, what the body did, what the filter believed.

:class:`TraceBuilder` collects one row per 0.1 s agent step (plus the reset) from the
env's ``info`` (the true state, cues, judgment, outcome) and the observation's features
(measurement and Kalman estimates, found by name in ``env.unwrapped.features``) into a
:class:`Trace`. :func:`plot_timeline` draws a trace as a PNG with four panels on one
time axis:

1. **cues** -- the push on the upper back [N] and the verbal cue playing ("lean forward"
   / "lean back" as shaded spans);
2. **shoulder x** [m] -- true, measured (camera) and the filter's estimate, with the lean
   needed for a safe lift;
3. **intention eta** [m] -- true and estimated;
4. **cooperativeness xi** -- the filter's estimate with its ±1 std band, the ±threshold
   band of the thresholded judgment, the true ``xi``, and each judgment as a marker at the
   moment it was made (a cue's onset + the judgment delay).

A vertical line marks the lift, coloured by its outcome. Plotting uses matplotlib's
object API on an Agg canvas (no pyplot, no display), so it runs headless.

Example:
    >>> import gymnasium as gym
    >>> import coop_gym
    >>> env = gym.make("CoopGym/SitToStand-v0")
    >>> obs, info = env.reset(seed=0)
    >>> builder = TraceBuilder.for_env(env)
    >>> builder.append(obs, info)
    >>> obs, reward, terminated, truncated, info = env.step([1, 2, 0])
    >>> builder.append(obs, info, reward)
    >>> trace = builder.build(agent="manual", env_id="CoopGym/SitToStand-v0", seed=0)
    >>> trace.n_steps, trace.time_s.tolist()
    (1, [0.0, 0.1])
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from coop_gym.envs.config import LiftCriteria
from coop_gym.io import save_figure
from estimator.judgment import ThresholdJudgment

__all__ = ["OUTCOME_COLOURS", "Trace", "TraceBuilder", "judgment_events", "plot_timeline"]

# Per-step series read from ``info`` (name in the trace -> info key).
_INFO_SERIES = {
    "time_s": "elapsed_s",
    "push_force_n": "push_force_n",
    "verbal_cue": "verbal_cue",
    "true_x_m": "true_x_m",
    "true_eta_m": "true_eta_m",
    "true_xi": "true_xi",
    "judgment": "judgment",
}
# Per-step series read from the observation's features (name in the trace -> feature name).
_FEATURE_SERIES = {
    "measured_position_m": "measured_position_m",
    "x_hat_m": "x_hat_m",
    "eta_hat_m": "eta_hat_m",
    "xi_hat": "xi_hat",
    "xi_std": "xi_std",
    "time_since_cue_onset_s": "time_since_cue_onset_s",
}

OUTCOME_COLOURS: dict[str, str] = {
    "success": "#2ea043",
    "unsafe": "#cf3434",
    "premature": "#e08214",
    "timeout": "#6e7480",
    "none": "#6e7480",
}
"""Colour of each episode outcome (the renderer's banner colours)."""

_XI_COLOURS = {-1: "#cf3434", 0: "#8c8c8c", 1: "#2ea043"}
_XI_NAMES = {-1: "uncooperative", 0: "unresponsive", 1: "cooperative"}
_PUSH_COLOUR = "#d66014"  # the renderer's push arrow
_ESTIMATE_COLOUR = "#2858c8"  # the renderer's estimate marker
_VERBAL_COLOURS = {1: "#2ea043", -1: "#8a4fc4"}
_VERBAL_NAMES = {1: '"lean forward"', -1: '"lean back"'}


@dataclass(frozen=True)
class Trace:
    """One recorded episode, one entry per agent step (index 0 is the state after reset).

    Every array has shape ``(n_steps + 1,)``. Cues (``push_force_n``, ``verbal_cue``) at
    index ``k`` are those in force during the step that ended at ``time_s[k]``.

    Attributes:
        time_s: Elapsed episode time [s].
        push_force_n: Push on the upper back [N].
        verbal_cue: Verbal cue playing (-1 "lean back", 0 none, +1 "lean forward").
        true_x_m: True shoulder displacement ``x`` [m].
        measured_position_m: Camera measurement of the shoulder [m].
        x_hat_m: Kalman estimate of ``x`` [m].
        true_eta_m: True intended position ``eta`` [m].
        eta_hat_m: Kalman estimate of ``eta`` [m].
        true_xi: True cooperativeness in {-1, 0, +1}.
        xi_hat: Kalman estimate of ``xi``.
        xi_std: Standard deviation of the ``xi`` estimate.
        judgment: Latest thresholded judgment in {-1, 0, +1} (0 until the first).
        time_since_cue_onset_s: Time since the last cue onset [s] (episode length if none yet).
        reward: Reward of the step that ended at ``time_s[k]`` (0 at index 0).
        outcome: ``"success"``, ``"unsafe"``, ``"premature"``, ``"timeout"``, or ``"none"`` when
            the recording stopped before the episode ended.
        threshold: Judgment threshold (paper: 0.3).
        judgment_delay_s: Judgment sampling delay after a cue's onset (paper: 0.75 s).
        success_lean_m: Lean needed for a safe lift [m].
        agent: Name of the agent.
        env_id: Env id.
        seed: Reset seed.
        persona: Persona of the simulated person.
    """

    time_s: NDArray[np.float64]
    push_force_n: NDArray[np.float64]
    verbal_cue: NDArray[np.float64]
    true_x_m: NDArray[np.float64]
    measured_position_m: NDArray[np.float64]
    x_hat_m: NDArray[np.float64]
    true_eta_m: NDArray[np.float64]
    eta_hat_m: NDArray[np.float64]
    true_xi: NDArray[np.float64]
    xi_hat: NDArray[np.float64]
    xi_std: NDArray[np.float64]
    judgment: NDArray[np.float64]
    time_since_cue_onset_s: NDArray[np.float64]
    reward: NDArray[np.float64]
    outcome: str = "none"
    threshold: float = ThresholdJudgment().threshold
    judgment_delay_s: float = ThresholdJudgment().delay_s
    success_lean_m: float = LiftCriteria().success_lean_m
    agent: str = ""
    env_id: str = ""
    seed: int | None = None
    persona: str = ""

    def __post_init__(self) -> None:
        """Check that every series has the same length (at least the reset row)."""
        lengths = {
            f.name: len(getattr(self, f.name)) for f in fields(self) if isinstance(getattr(self, f.name), np.ndarray)
        }
        if len(set(lengths.values())) != 1 or lengths["time_s"] < 1:
            raise ValueError(f"Trace series must have one common, non-zero length; got {lengths}")

    @property
    def n_steps(self) -> int:
        """Number of agent steps (rows after the reset row)."""
        return len(self.time_s) - 1

    @property
    def episode_return(self) -> float:
        """Sum of the rewards."""
        return float(self.reward.sum())

    @property
    def lifted(self) -> bool:
        """Whether the episode ended with a lift (success, unsafe or premature)."""
        return self.outcome in ("success", "unsafe", "premature")


class TraceBuilder:
    """Collects :class:`Trace` rows from ``(obs, info)`` pairs of a single coop_gym env.

    Args:
        features: Names of the observation's features, in order (``env.unwrapped.features``).
        fallback: Optional callable returning a mapping ``feature name -> value`` for features
            the observation lacks (e.g. the filter's estimates under the ``raw`` observation
            mode); missing features without a fallback are recorded as NaN and not drawn.
        threshold: Judgment threshold drawn as a band.
        judgment_delay_s: Delay between a cue's onset and its judgment [s].
        success_lean_m: Lean needed for a safe lift [m].
    """

    def __init__(
        self,
        features: Sequence[str],
        fallback: Any = None,
        threshold: float = ThresholdJudgment().threshold,
        judgment_delay_s: float = ThresholdJudgment().delay_s,
        success_lean_m: float = LiftCriteria().success_lean_m,
    ) -> None:
        """Remember where each feature sits in the observation."""
        self.features = tuple(features)
        self.fallback = fallback
        self.threshold = float(threshold)
        self.judgment_delay_s = float(judgment_delay_s)
        self.success_lean_m = float(success_lean_m)
        self._rows: dict[str, list[float]] = {name: [] for name in (*_INFO_SERIES, *_FEATURE_SERIES, "reward")}
        self.outcome = "none"
        self.persona = ""

    @classmethod
    def for_env(cls, env: Any) -> TraceBuilder:
        """A builder for a (possibly wrapped) single coop_gym env, with its settings."""
        base = getattr(env, "unwrapped", env)
        core = getattr(base, "core", None)
        kwargs: dict[str, Any] = {}
        fallback = None
        if core is not None:
            kwargs["threshold"] = core.judgment.threshold
            kwargs["judgment_delay_s"] = core.judgment.delay_s
            kwargs["success_lean_m"] = core.lift.success_lean_m
            from coop_gym.envs.contract import FEATURES

            # The core computes every feature whatever the observation mode selects.
            def fallback() -> dict[str, float]:
                row = core.report[0, : len(FEATURES)]  # the report row starts with the features
                return {name: float(row[k]) for k, name in enumerate(FEATURES)}

        features = getattr(base, "features", None)
        if features is None:
            raise ValueError(f"{type(base).__name__} has no `features` attribute; is it a coop_gym env?")
        return cls(features, fallback=fallback, **kwargs)

    def append(self, observation: Any, info: Mapping[str, Any], reward: float = 0.0) -> None:
        """Add the row of one ``reset`` or ``step`` result."""
        obs = np.asarray(observation, dtype=np.float64).reshape(-1)
        if obs.shape[0] != len(self.features):
            raise ValueError(f"observation has {obs.shape[0]} entries, expected {len(self.features)} {self.features}")
        extra: Mapping[str, float] | None = None
        for name, key in _INFO_SERIES.items():
            self._rows[name].append(float(info[key]))
        for name, feature in _FEATURE_SERIES.items():
            if feature in self.features:
                value = float(obs[self.features.index(feature)])
            else:
                if extra is None:
                    extra = self.fallback() if self.fallback is not None else {}
                value = float(extra.get(feature, math.nan))
            self._rows[name].append(value)
        self._rows["reward"].append(float(reward))
        self.outcome = str(info.get("outcome", "none"))
        self.persona = str(info.get("persona", self.persona))

    def build(self, agent: str = "", env_id: str = "", seed: int | None = None) -> Trace:
        """The trace collected so far."""
        arrays = {name: np.asarray(values, dtype=np.float64) for name, values in self._rows.items()}
        return Trace(
            **arrays,
            outcome=self.outcome,
            threshold=self.threshold,
            judgment_delay_s=self.judgment_delay_s,
            success_lean_m=self.success_lean_m,
            agent=agent,
            env_id=env_id,
            seed=seed,
            persona=self.persona,
        )


def judgment_events(trace: Trace) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Times [s] and values of the judgments made during the episode.

    A judgment is made ``judgment_delay_s`` after a cue's onset; it shows as the time
    since the onset crossing the delay within a step. (The judgment series alone cannot
    show a repeated judgment of the same value.)

    Returns:
        ``(times_s, judgments)``: when each judgment was made and its value in {-1, 0, +1}.
    """
    since = trace.time_since_cue_onset_s
    step_s = np.diff(trace.time_s)
    # Half a filter step of slack, as in the judgment tracker itself.
    due = trace.judgment_delay_s - 0.01
    made = (since[1:] >= due) & (since[1:] - step_s < due)
    index = np.flatnonzero(made) + 1
    times = trace.time_s[index] - (since[index] - trace.judgment_delay_s)
    return times, trace.judgment[index].astype(np.int64)


def _spans(mask: NDArray[np.bool_], time_s: NDArray[np.float64]) -> list[tuple[float, float]]:
    """Intervals where ``mask`` holds; row ``k`` covers ``(time_s[k-1], time_s[k]]``."""
    spans = []
    k = 1
    while k < len(mask):
        if mask[k]:
            start = k
            while k + 1 < len(mask) and mask[k + 1]:
                k += 1
            spans.append((float(time_s[start - 1]), float(time_s[k])))
        k += 1
    return spans


def plot_timeline(
    trace: Trace,
    path: str | Path,
    *,
    width_px: int = 900,
    height_px: int = 760,
    dpi: int = 100,
    title: str | None = None,
) -> Path:
    """Draw ``trace`` as a four-panel timeline PNG (see the module docstring).

    Args:
        trace: The episode.
        path: Where to write the PNG (parent folders are created).
        width_px: Image width [px].
        height_px: Image height [px].
        dpi: Resolution; the figure is ``width_px / dpi`` by ``height_px / dpi`` inches.
        title: Figure title; default names the agent, env, seed, persona and outcome.

    Returns:
        The path written.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    for name, value in (("width_px", width_px), ("height_px", height_px), ("dpi", dpi)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 10:
            raise ValueError(f"plot_timeline {name} must be an int >= 10, got {value!r}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)

    fig = Figure(figsize=(width_px / dpi, height_px / dpi), dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(4, 1, sharex=True, height_ratios=[0.8, 1.1, 1.0, 1.5])
    ax_cue, ax_x, ax_eta, ax_xi = axes
    _draw_cues(ax_cue, trace)
    _draw_shoulder(ax_x, trace)
    _draw_intention(ax_eta, trace)
    for ax in (ax_x, ax_eta):
        low, high = ax.get_ylim()
        ax.set_ylim(low, high + 0.35 * (high - low))  # room for the legend
    _draw_cooperativeness(ax_xi, trace)
    _mark_episode_end(axes, trace)
    for ax in axes:
        ax.grid(True, color="#e4e6ea", lw=0.6)
        ax.tick_params(labelsize=8)
    fig.suptitle(title if title is not None else _default_title(trace), fontsize=10)
    save_figure(fig, path, dpi=dpi, facecolor="white")
    return path


_SMALL = {"fontsize": 8}
"""Panel titles and legends."""


def _draw_cues(ax: Any, trace: Trace) -> None:
    """Panel 1: the push as a filled step, the verbal cue as shaded spans behind it."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    t = trace.time_s
    ax.fill_between(t, trace.push_force_n, step="pre", color=_PUSH_COLOUR, alpha=0.35, lw=0)
    ax.step(t, trace.push_force_n, where="pre", color=_PUSH_COLOUR, lw=1.5, label="push [N]")
    for value in (1, -1):
        for start, stop in _spans(trace.verbal_cue == value, t):
            ax.axvspan(start, stop, color=_VERBAL_COLOURS[value], alpha=0.18, lw=0)
    ax.set_ylabel("push [N]")
    ax.set_ylim(0.0, max(45.0, float(np.nanmax(trace.push_force_n)) * 1.5))  # room for the legend
    ax.set_title("robot's cues", loc="left", **_SMALL)
    handles: list[Any] = [Line2D([], [], color=_PUSH_COLOUR, lw=1.5, label="push force")]
    handles += [
        Patch(color=_VERBAL_COLOURS[v], alpha=0.3, label=f"says {_VERBAL_NAMES[v]}")
        for v in (1, -1)
        if np.any(trace.verbal_cue == v)
    ]
    ax.legend(handles=handles, loc="upper left", ncols=3, **_SMALL)


def _draw_shoulder(ax: Any, trace: Trace) -> None:
    """Panel 2: the shoulder's truth, camera and filter; the lean a safe lift needs."""
    t = trace.time_s
    ax.plot(t, trace.measured_position_m, ".", color="#9aa0aa", ms=2.5, label="measured (camera)")
    ax.plot(t, trace.true_x_m, color="black", lw=1.6, label="true")
    ax.plot(t, trace.x_hat_m, "--", color=_ESTIMATE_COLOUR, lw=1.2, label="Kalman estimate")
    ax.axhline(trace.success_lean_m, color=OUTCOME_COLOURS["success"], ls=":", lw=1.2, label="lean for a safe lift")
    ax.set_ylabel("shoulder x [m]")
    ax.set_title("body: shoulder displacement (forward +)", loc="left", **_SMALL)
    ax.legend(loc="upper left", ncols=4, **_SMALL)


def _draw_intention(ax: Any, trace: Trace) -> None:
    """Panel 3: the intention, true and estimated."""
    t = trace.time_s
    ax.plot(t, trace.true_eta_m, color="black", lw=1.6, label="true")
    ax.plot(t, trace.eta_hat_m, "--", color=_ESTIMATE_COLOUR, lw=1.2, label="Kalman estimate")
    ax.set_ylabel("eta [m]")
    ax.set_title("intention: where the person means to be", loc="left", **_SMALL)
    ax.legend(loc="upper left", ncols=2, **_SMALL)


def _draw_cooperativeness(ax: Any, trace: Trace) -> None:
    """Panel 4: the estimate +/- its std, the threshold band, the truth and each judgment."""
    t = trace.time_s
    t_max = max(float(t[-1]), 1.0)
    band = trace.threshold
    ax.axhspan(-band, band, color="#8c8c8c", alpha=0.15, lw=0, label=f"±{band:g} threshold band")
    xi_hat = np.clip(trace.xi_hat, -1.9, 1.9)
    ax.fill_between(
        t,
        np.clip(trace.xi_hat - trace.xi_std, -1.9, 1.9),
        np.clip(trace.xi_hat + trace.xi_std, -1.9, 1.9),
        color=_ESTIMATE_COLOUR,
        alpha=0.18,
        lw=0,
        label="estimate ±1 std",
    )
    ax.plot(t, xi_hat, color=_ESTIMATE_COLOUR, lw=1.4, label="Kalman estimate")
    ax.step(t, trace.true_xi, where="pre", color="black", lw=2.0, label="true xi")
    times, values = judgment_events(trace)
    for value in (-1, 0, 1):
        chosen = values == value
        if np.any(chosen):
            ax.plot(
                times[chosen],
                np.full(int(chosen.sum()), float(value)),
                "D",
                color=_XI_COLOURS[value],
                mec="white",
                ms=7,
                label=f"judged {_XI_NAMES[value]}",
            )
    ax.set_ylim(-1.9, 2.3)
    ax.set_yticks([-1, 0, 1], ["-1 uncoop.", "0 unresp.", "+1 coop."])
    ax.set_ylabel("xi")
    ax.set_title("mind: cooperativeness and the filter's judgment", loc="left", **_SMALL)
    ax.legend(loc="upper left", ncols=4, **_SMALL)
    ax.set_xlabel("time [s]")
    ax.set_xlim(0.0, t_max + max(0.2, 0.02 * t_max))  # keep the lift line off the frame


def _mark_episode_end(axes: Sequence[Any], trace: Trace) -> None:
    """The lift (or the end) as a line across every panel, labelled over the first."""
    if trace.outcome == "none":
        return
    end_s = float(trace.time_s[-1])
    colour = OUTCOME_COLOURS.get(trace.outcome, OUTCOME_COLOURS["none"])
    for ax in axes:
        ax.axvline(end_s, color=colour, lw=2.0, alpha=0.85)
    label = f"lift at {end_s:.1f} s: {trace.outcome}" if trace.lifted else f"{trace.outcome} at {end_s:.1f} s"
    # Top right of the first panel, clear of its title whatever the lift time; the line marks the time.
    axes[0].annotate(
        label,
        (1.0, 1.0),
        xycoords="axes fraction",
        xytext=(0, 3),
        textcoords="offset points",
        ha="right",
        va="bottom",
        color="white",
        fontsize=9,
        fontweight="bold",
        bbox={"boxstyle": "round,pad=0.25", "fc": colour, "ec": "none"},
    )


def _default_title(trace: Trace) -> str:
    """The agent, env, seed, persona, outcome and return of ``trace`` in one line."""
    end_s = float(trace.time_s[-1])
    who = trace.agent or "agent"
    where = f" on {trace.env_id}" if trace.env_id else ""
    seed = f", seed {trace.seed}" if trace.seed is not None else ""
    persona = f", persona {trace.persona}" if trace.persona else ""
    return f"{who}{where}{seed}{persona}: {trace.outcome} after {end_s:.1f} s, return {trace.episode_return:+.2f}"
