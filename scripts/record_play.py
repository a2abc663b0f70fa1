"""Record a played episode of ``python -m agents.tools.play`` as a GIF (for the docs), headless.

The player is a fixed key script: say "lean forward", push softly, say it again, lift
at 5.1 s. Every drawn step becomes a frame (0.1 s, real time); the end-of-episode summary
is held for a few seconds. Run from the repository root::

    python scripts/record_play.py                  # writes docs/img/play.gif
    python scripts/record_play.py --seed 1 --out /tmp/play.gif
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from agents.tools.play import DEFAULT_CSV, DEFAULT_ENV_ID, play, scripted_keys  # noqa: E402

# Two paused frames, then Space and "lean forward"; soft push from 1.0 s; "lean forward"
# again at 2.5 s; lift at 5.1 s; Enter closes the summary.
SCRIPT: list[list[str]] = [[], [], ["space", "f"], *[[]] * 9, ["2"], *[[]] * 14, ["f"], *[[]] * 25, ["l"], ["return"]]
SUMMARY_S = 6.0


def main() -> int:
    """Play the key script on one seed and write the GIF."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default=DEFAULT_ENV_ID)
    parser.add_argument("--seed", type=int, default=1, help="seed 1 gives a held-out person this script lifts safely")
    parser.add_argument("--out", default=str(ROOT / "docs" / "img" / "play.gif"))
    parser.add_argument("--scale", type=float, default=0.75, help="frame size relative to the 600x610 window")
    args = parser.parse_args()
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

    from PIL import Image

    frames: list[NDArray[np.uint8]] = []
    here = Path.cwd()
    with tempfile.TemporaryDirectory() as scratch:
        # The recording is not a human score: its CSV goes to a scratch folder, under the default
        # relative path, so the summary frame says what a player sees ("saved to runs/played.csv").
        os.chdir(scratch)
        try:
            (episode,) = play(
                args.env,
                args.seed,
                "test",
                DEFAULT_CSV,
                fps=0,
                episodes=1,
                keys=scripted_keys(SCRIPT),
                window=False,
                on_frame=frames.append,
            )
        finally:
            os.chdir(here)
    size = (round(frames[0].shape[1] * args.scale), round(frames[0].shape[0] * args.scale))
    images = [Image.fromarray(f).resize(size, Image.Resampling.LANCZOS) for f in frames]
    # One shared palette keeps the file small; the scene's colours are few.
    palette = images[-1].quantize(colors=64, method=Image.Quantize.MEDIANCUT)
    quantized = [im.quantize(palette=palette, dither=Image.Dither.NONE) for im in images]
    durations = [100] * (len(quantized) - 1) + [int(SUMMARY_S * 1000)]
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    quantized[0].save(out, save_all=True, append_images=quantized[1:], duration=durations, loop=0, optimize=True)
    print(
        f"{out}: {len(frames)} frames, {out.stat().st_size / 1e3:.0f} kB; seed {args.seed}, "
        f"{episode.persona}, {episode.outcome}, lift at {episode.lift_time_s:.1f} s"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
