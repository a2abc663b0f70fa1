"""The search behind :class:`agents.belief.BeliefCaregiver`'s settings, on the training personas.

``python -m agents.tune_belief`` plays every setting of :func:`settings_grid` on the same
seeded episodes of the TRAINING personas (from :data:`agents.tune_baselines.TUNING_SEED`, far
from the evaluation seeds), with the switching particle filter in the observation, and prints
each one's success and unsafe rates and the best (most successes, then fewest unsafe lifts).
The winner is :class:`agents.belief.BeliefSettings`' default; it is scored on the held-out
personas by ``python -m agents.evaluate --compare belief,...``.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from agents.belief import BeliefCaregiver, BeliefSettings
from agents.evaluate import evaluate
from agents.tune_baselines import TUNING_SEED
from coop_gym.envs.contract import observation_features

__all__ = ["main", "settings_grid"]


def settings_grid() -> list[BeliefSettings]:
    """The settings ``python -m agents.tune_belief`` tries: lift gate x recruiting burst x probe window.

    (An earlier grid over the lean and re-probe gates found them tied; they keep their defaults.)
    """
    return [
        BeliefSettings(lift_p=lift_p, burst_s=burst_s, window_s=window_s)
        for lift_p in (0.8, 0.85)
        for burst_s in (0.5, 1.0)
        for window_s in (1.0, 1.5, 2.0)
    ]


def main(argv: Sequence[str] | None = None) -> int:
    """Score :func:`settings_grid` on the TRAINING personas and print the best."""
    parser = argparse.ArgumentParser(prog="python -m agents.tune_belief", description=main.__doc__)
    parser.add_argument("--env", default="CoopGym/SitToStandHard-v1")
    parser.add_argument("--episodes", type=int, default=200)
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error(f"--episodes must be positive, got {args.episodes}")
    rows = []
    for settings in settings_grid():
        result = evaluate(
            BeliefCaregiver(observation_features("belief", "switching"), settings=settings),
            args.env, "train", args.episodes, TUNING_SEED, env_kwargs={"estimator": "switching"},
        )  # fmt: skip
        rows.append((result.success_rate, -result.unsafe_rate, settings))
        print(f"{result.success_rate:.3f} success, {result.unsafe_rate:.3f} unsafe: {settings}", flush=True)
    best = max(rows, key=lambda row: row[:2])
    print(f"best on the training personas: {best[2]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
