"""Speed of an ``rgb_array`` frame, measured against CartPole's in the same run (a ratio).

    python bench/render.py [--repeats N] [--frames N]

Each repeat draws ``--frames`` frames of ``gymnasium.make("CoopGym/SitToStand-v0",
render_mode="rgb_array")`` and of ``gymnasium.make("CartPole-v1", render_mode="rgb_array")``
(both pygame, both a fresh state every frame: one env step, then ``render()``; the step's
own time is measured apart and taken out) in alternating blocks of 10, so a change of
machine load hits both. Reports each renderer's milliseconds per frame and the ratio
ours / CartPole's: the median over repeats with its min..max. Our frame is 600 x 400 with
the person, the robot, the cue, the gauge and the face; CartPole's 600 x 400 with a cart and
a pole. ``--save`` also writes the report to ``bench/results/render.json``
(``bench/result_files.py``).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/result_files.py, however this runs
from result_files import add_save_argument, save, summary

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # no screen needed for rgb_array frames
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")

import gymnasium as gym

import coop_gym  # noqa: F401  (registers the ids)
from coop_gym.cli import positive_int

ENV_ID = "CoopGym/SitToStand-v0"
CARTPOLE_ID = "CartPole-v1"
BLOCK = 10


class FrameTimer:
    """Steps one env under a fixed action sequence and times ``render()`` apart from the steps."""

    def __init__(self, env_id: str, seed: int) -> None:
        """Make the env, reset it and draw a first frame (fonts and surfaces created)."""
        self.env = gym.make(env_id, render_mode="rgb_array")
        self.env.action_space.seed(seed)
        self.env.reset(seed=seed)
        self.env.render()
        self.seconds = 0.0
        self.frames = 0

    def block(self, frames: int) -> None:
        """Draw ``frames`` frames, each after one step (a reset when the episode ends)."""
        env = self.env
        for _ in range(frames):
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                env.reset()
            start = time.perf_counter()
            frame: Any = env.render()
            self.seconds += time.perf_counter() - start
            self.frames += 1
            if frame is None or frame.ndim != 3:
                raise RuntimeError(f"{env.spec.id if env.spec else env} returned no rgb_array frame")

    def close(self) -> None:
        """Close the env and its window surface."""
        self.env.close()


def measure(repeats: int, frames: int) -> dict[str, Any]:
    """``repeats`` interleaved measurements; the report as a dict."""
    ours_ms: list[float] = []
    cartpole_ms: list[float] = []
    for r in range(repeats):
        timers = [FrameTimer(ENV_ID, r), FrameTimer(CARTPOLE_ID, r)]
        for _ in range(max(1, frames // BLOCK)):
            for timer in timers:
                timer.block(BLOCK)
        ours_ms.append(1e3 * timers[0].seconds / timers[0].frames)
        cartpole_ms.append(1e3 * timers[1].seconds / timers[1].frames)
        for timer in timers:
            timer.close()
        print(f"  [{r + 1}/{repeats}] ours {ours_ms[-1]:.2f} ms  CartPole {cartpole_ms[-1]:.2f} ms", file=sys.stderr)
    ratios = [a / b for a, b in zip(ours_ms, cartpole_ms, strict=True)]
    return {
        "repeats": repeats,
        "frames_per_repeat": frames,
        "ours_ms_per_frame": summary(ours_ms),
        "cartpole_ms_per_frame": summary(cartpole_ms),
        "ratio": summary(ratios),
    }


def main(argv: list[str] | None = None) -> None:
    """Command line: print the report."""
    parser = argparse.ArgumentParser(prog="python bench/render.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=positive_int, default=5, help="repeats (default 5)")
    parser.add_argument("--frames", type=positive_int, default=200, help="frames per renderer per repeat (default 200)")
    add_save_argument(parser, "render.json")
    args = parser.parse_args(argv)
    report = measure(args.repeats, args.frames)
    ours, cartpole, ratio = report["ours_ms_per_frame"], report["cartpole_ms_per_frame"], report["ratio"]
    print(
        f"rgb_array frame: ours {ours['median']:.2f} ms ({ours['min']:.2f}..{ours['max']:.2f}), "
        f"CartPole {cartpole['median']:.2f} ms ({cartpole['min']:.2f}..{cartpole['max']:.2f}); "
        f"ratio {ratio['median']:.2f}x ({ratio['min']:.2f}..{ratio['max']:.2f})"
    )
    if args.save:
        save(args.save, "render", argv, report)


if __name__ == "__main__":
    main()
