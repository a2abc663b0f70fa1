"""Regenerate the README figures under ``docs/img/`` (small, optimised PNGs).

Usage::

    python scripts/make_readme_figures.py                       # every figure
    python scripts/make_readme_figures.py --only scene,timeline  # a subset
    python scripts/make_readme_figures.py --out /tmp/img --episodes 100

Figures (each deterministic given the seeds below, each kept under ``--max-kb``, 150 KB):

* ``scene.png`` -- one rendered frame (``render_mode="rgb_array"``) from the middle of a
  handbook-caregiver episode: the person leaning forward under the soft push (arrow) while
  the robot says "lean forward" (speech bubble), the estimator's gauge with the ±threshold
  band and the judgment, and the true cooperativeness as a face.
* ``timeline_handbook.png`` -- :func:`agents.tools.timeline.plot_timeline` of that episode on
  ``CoopGym/SitToStand-v0``: the first seed (from 0) whose person starts uncooperative, is
  judged so, and is guided to cooperation and a safe lift. The script prints the seed and
  the ``python -m agents.tools.record`` command that writes the same figure (and the video).
* ``timeline_push_then_lift.png`` -- the paper's failure scenario: the push-then-lift caregiver
  on a frail person whom the push moves past the lean threshold although they resist
  (``xi = -1``), so the lift is unsafe (the first such seed from 0; the script prints the
  ``python -m agents.tools.record --agent push_then_lift --persona frail`` command).
* ``outcomes.png`` -- outcome rates (95 % Wilson intervals) of every scripted caregiver on
  the held-out personas (:func:`agents.evaluate.evaluate`, ``--episodes`` each, seeds from 0;
  :func:`agents.tools.plots.plot_outcome_rates`), as
  ``python -m agents.evaluate --compare random,lift_at_once,push_then_lift,handbook,oracle
  --personas test --episodes N --plot FILE`` draws it.
* ``protocol_trace.png`` and ``protocol_confusion.png`` -- the paper's experiment
  (:mod:`coop_gym.experiment.protocol`): a Fig. 6-style trace of one trial and the confusion matrix of
  requested vs judged cooperativeness beside the paper's (:func:`coop_gym.experiment.protocol.plot_trial`,
  :func:`coop_gym.experiment.protocol.plot_confusion`; seed 0, 4 subjects x 25 trials, the paper's
  thresholded Kalman filter), as ``python -m coop_gym.experiment.protocol --seed 0 --plot FILE
  --plot-confusion FILE`` draws them.

Every figure is rendered headless (pygame off-screen, matplotlib Agg) and then shrunk: scaled
down to at most ``--max-width`` pixels, PNG-optimised, and reduced to a 256-colour palette only
if it is still above ``--max-kb``.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # never open a window
os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import gymnasium as gym
import numpy as np
from PIL import Image

import coop_gym  # noqa: F401  (registers the ids)
from agents.base import action_type_of, features_of
from agents.caregivers.scripted import SCRIPTED_AGENTS, make_scripted
from agents.tools.record import play_episode
from agents.tools.timeline import Trace, judgment_events, plot_timeline
from coop_gym.cli import output_path_problem
from coop_gym.io import save_with

REPO = Path(__file__).resolve().parents[1]
ENV_ID = "CoopGym/SitToStand-v0"
SEED_SEARCH_LIMIT = 500
FIGURES = ("scene", "timeline", "failure", "outcomes", "protocol")


def shrink_png(path: Path, max_width: int, max_kb: int) -> Path:
    """Scale ``path`` down to ``max_width`` px, optimise it, and palettise it if still too big."""
    with Image.open(path) as opened:
        image = opened.convert("RGB")
    if image.width > max_width:
        height = round(image.height * max_width / image.width)
        image = image.resize((max_width, height), Image.Resampling.LANCZOS)
    save_with(path, lambda temp: image.save(temp, optimize=True))
    if path.stat().st_size > max_kb * 1024:
        palette = image.quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
        save_with(path, lambda temp: palette.save(temp, optimize=True))
    return path


def scripted_episode(name: str, seed: int, **env_kwargs: Any) -> tuple[Trace, list[np.ndarray]]:
    """A scripted caregiver's episode with ``seed``: its trace and every rendered frame."""
    env = gym.make(ENV_ID, render_mode="rgb_array", **env_kwargs)
    agent = make_scripted(name, features_of(env), action_type_of(env), seed=seed)
    frames: list[np.ndarray] = []
    trace = play_episode(
        env, agent, seed, agent_name=name, env_id=ENV_ID, on_step=lambda e, _: frames.append(np.asarray(e.render()))
    )
    env.close()
    return trace, frames


def find_seed(name: str, wanted: Callable[[Trace], bool], **env_kwargs: Any) -> int:
    """The first seed from 0 whose episode of scripted agent ``name`` shows what ``wanted`` asks for.

    Searching (rather than hard-coding a seed) keeps the figures telling their story when
    the simulation is recalibrated.
    """
    env = gym.make(ENV_ID, **env_kwargs)
    try:
        for seed in range(SEED_SEARCH_LIMIT):
            agent = make_scripted(name, features_of(env), action_type_of(env), seed=seed)
            if wanted(play_episode(env, agent, seed)):
                return seed
    finally:
        env.close()
    raise RuntimeError(f"no seed below {SEED_SEARCH_LIMIT} gives the wanted {name} episode")


def guided_to_cooperation(trace: Trace) -> bool:
    """Starts uncooperative, is judged so, and ends in a safe lift after some guiding."""
    _, judgments = judgment_events(trace)
    return trace.true_xi[0] == -1 and -1 in judgments and trace.outcome == "success" and trace.n_steps >= 60


def lifted_while_resisting(trace: Trace) -> bool:
    """Pushed past the safe-lift lean while resisting, then lifted: unsafe."""
    return trace.outcome == "unsafe" and trace.true_xi[-1] == -1 and trace.true_x_m[-1] >= trace.success_lean_m


def pick_scene_frame(trace: Trace) -> int:
    """The step that shows the most: pushing, saying "lean forward", clearly leaning (about 2/3 of the way)."""
    showing = (trace.push_force_n > 0) & (trace.verbal_cue == 1)
    if not np.any(showing):
        showing = trace.push_force_n > 0
    candidates = np.flatnonzero(showing)
    if not len(candidates):
        return len(trace.time_s) // 2
    return int(candidates[np.argmin(np.abs(trace.true_x_m[candidates] - 0.65 * trace.success_lean_m))])


def make_scene(out: Path, trace: Trace, frames: list[np.ndarray]) -> list[Path]:
    """``scene.png``: one frame from the middle of the handbook episode."""
    k = pick_scene_frame(trace)
    path = out / "scene.png"
    save_with(path, Image.fromarray(frames[k]).save)
    print(f"  scene: frame of t = {trace.time_s[k]:.1f} s, shoulder x = {trace.true_x_m[k]:.3f} m")
    return [path]


def make_timeline(out: Path, trace: Trace) -> list[Path]:
    """``timeline_handbook.png``: the handbook episode's timeline."""
    path = plot_timeline(trace, out / "timeline_handbook.png", width_px=900, height_px=760, dpi=100)
    return [path]


def make_failure(out: Path) -> list[Path]:
    """``timeline_push_then_lift.png``: the paper's failure scenario on a frail person."""
    seed = find_seed("push_then_lift", lifted_while_resisting, personas="frail")
    trace, _ = scripted_episode("push_then_lift", seed, personas="frail")
    print(f"  push_then_lift, frail, seed {seed}: {trace.outcome} at {trace.time_s[-1]:.1f} s")
    print(
        "  same episode with its video: python -m agents.tools.record --agent push_then_lift --persona frail "
        f"--seed {seed} --out DIR"
    )
    return [plot_timeline(trace, out / "timeline_push_then_lift.png", width_px=900, height_px=760, dpi=100)]


def make_outcomes(out: Path, episodes: int) -> list[Path]:
    """``outcomes.png``: outcome rates of the scripted caregivers on held-out personas."""
    from agents.evaluate import evaluate
    from agents.tools.plots import plot_outcome_rates

    results = []
    for name in ("random", "lift_at_once", "push_then_lift", "handbook", "oracle"):
        if name not in SCRIPTED_AGENTS:
            continue
        result = evaluate(name, ENV_ID, personas="test", episodes=episodes, seed=0)
        results.append(result)
        print(
            f"  {name:15s} success {result.rate('success'):6.1%}  unsafe {result.rate('unsafe'):6.1%}  "
            f"premature {result.rate('premature'):6.1%}  timeout {result.rate('timeout'):6.1%}"
        )
    title = f"scripted caregivers on held-out personas ({episodes} episodes each)"
    return [plot_outcome_rates(results, out / "outcomes.png", title=title)]


def make_protocol(out: Path) -> list[Path]:
    """``protocol_trace.png``, ``protocol_confusion.png`` from :mod:`coop_gym.experiment.protocol`, if it can plot."""
    from coop_gym.experiment import protocol

    plot_trial = getattr(protocol, "plot_trial", None)
    plot_confusion = getattr(protocol, "plot_confusion", None)
    if plot_trial is None or plot_confusion is None:
        print("  skipped: coop_gym.experiment.protocol has no plot_trial/plot_confusion")
        return []
    # The paper's experiment, seed 0: 4 subjects x 25 trials, the paper's thresholded filter.
    data = protocol.run_experiment(protocol.ProtocolConfig(), 0)
    result = protocol.estimate(data, "kalman")
    summary = protocol.summarize(data, result)
    print(
        f"  kalman: accuracy {summary['accuracy']:.1%}, balanced accuracy {summary['balanced_accuracy']:.1%} "
        f"(paper on real people: {protocol.PAPER_RESULTS.accuracy:.1%}, {protocol.PAPER_RESULTS.balanced_accuracy:.1%})"
    )
    return [
        Path(plot_trial(data, str(out / "protocol_trace.png"), estimator=result)),
        Path(plot_confusion(summary, str(out / "protocol_confusion.png"))),
    ]


def main(argv: Sequence[str] | None = None) -> int:
    """Make the figures; usage errors exit 2."""
    parser = argparse.ArgumentParser(prog="python scripts/make_readme_figures.py", description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "img", help="output folder (default docs/img)")
    parser.add_argument("--only", default=",".join(FIGURES), help=f"comma-separated subset of {','.join(FIGURES)}")
    parser.add_argument("--episodes", type=int, default=200, help="episodes per agent for outcomes.png (default 200)")
    parser.add_argument("--max-kb", type=int, default=150, help="size budget per PNG [KB] (default 150)")
    parser.add_argument("--max-width", type=int, default=900, help="maximum PNG width [px] (default 900)")
    args = parser.parse_args(argv)
    wanted = [name.strip() for name in args.only.split(",") if name.strip()]
    unknown = sorted(set(wanted) - set(FIGURES))
    if unknown or not wanted:
        parser.error(f"--only: unknown figure(s) {unknown or wanted}; choose from {','.join(FIGURES)}")
    for flag, value, low in (
        ("--episodes", args.episodes, 1),
        ("--max-kb", args.max_kb, 10),
        ("--max-width", args.max_width, 100),
    ):
        if value < low:
            parser.error(f"{flag} must be >= {low}, got {value}")
    problem = output_path_problem(args.out, folder=True)
    if problem:
        parser.error(f"--out: {problem}")
    args.out.mkdir(parents=True, exist_ok=True)

    episode: tuple[Trace, list[np.ndarray]] | None = None
    if "scene" in wanted or "timeline" in wanted:
        seed = find_seed("handbook", guided_to_cooperation)
        episode = scripted_episode("handbook", seed)
        trace = episode[0]
        print(f"handbook episode: seed {seed}, persona {trace.persona}, {trace.outcome} at {trace.time_s[-1]:.1f} s")
        print(f"  same episode with its video: python -m agents.tools.record --agent handbook --seed {seed} --out DIR")
    makers: dict[str, Callable[[], list[Path]]] = {
        "scene": lambda: make_scene(args.out, *episode),  # type: ignore[misc]
        "timeline": lambda: make_timeline(args.out, episode[0]),  # type: ignore[index]
        "failure": lambda: make_failure(args.out),
        "outcomes": lambda: make_outcomes(args.out, args.episodes),
        "protocol": lambda: make_protocol(args.out),
    }
    written: list[Path] = []
    for name in FIGURES:
        if name in wanted:
            print(f"{name}:")
            written += makers[name]()
    for path in written:
        shrink_png(path, args.max_width, args.max_kb)
        with Image.open(path) as image:
            size = image.size
        kb = path.stat().st_size / 1024
        flag = "" if kb <= args.max_kb else f"  (over the {args.max_kb} KB budget)"
        print(f"wrote {path} ({size[0]}x{size[1]}, {kb:.0f} KB){flag}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
