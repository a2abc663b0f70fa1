"""Searches behind the headroom baselines: the blind family and the probing caregiver.

``python -m agents.tune_baselines blind --level hard`` scores every setting of the
mental-state-blind family (:func:`blind_grid`: push x words x push-until-lean x lean
threshold x timer x hold, 648 settings) on the *training* personas, 300 episodes from seed
1,000,000 each, and prints the best; the winners are kept in
:data:`agents.scripted.TUNED_BLIND` and scored by :mod:`agents.evaluate` on the held-out
personas with fresh seeds. ``python -m agents.tune_baselines prober`` does the same for
:class:`agents.scripted.ProbingCaregiver` (36 settings). Rerun both after a model change.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
from collections.abc import Iterator, Sequence
from typing import Any

from agents.evaluate import evaluate
from agents.scripted import BlindAgent, BlindSettings, ProbingCaregiver, ProbingSettings, ScriptedAgent

__all__ = ["LEVEL_ENV_IDS", "blind_grid", "main", "prober_grid", "tune"]

LEVEL_ENV_IDS: dict[str, str] = {
    "v0": "CoopGym/SitToStand-v0",
    "easy": "CoopGym/SitToStandEasy-v1",
    "medium": "CoopGym/SitToStandMedium-v1",
    "hard": "CoopGym/SitToStandHard-v1",
}
"""The env id each level is tuned on."""

TUNING_SEED = 1_000_000
"""Seed of the first tuning episode: far from the evaluation seeds (0, 1, ...)."""


def blind_grid() -> Iterator[BlindSettings]:
    """Every setting of the blind family that the search tries."""
    for push, words, release in itertools.product(("none", "soft", "firm"), (False, True), (False, True)):
        if push == "none" and (not words or release):
            continue  # no cue at all, or nothing to release
        for lean_m, min_time_s, hold_s in itertools.product(
            (0.12, 0.16, 0.2, 0.25, 0.3, 0.35), (0.0, 4.0, 10.0, 20.0), (0.0, 1.0, 2.0)
        ):
            yield BlindSettings(push, words, lean_m, min_time_s, release, hold_s)


def prober_grid() -> Iterator[ProbingSettings]:
    """The settings of the probing caregiver that the search tries."""
    for burst_s, settle_s, answer_m, push_below_m in itertools.product(
        (0.3, 0.5, 1.0), (0.1, 0.3), (0.012, 0.02, 0.03), (0.25, 0.32)
    ):
        yield ProbingSettings(burst_s=burst_s, settle_s=settle_s, answer_m=answer_m, push_below_m=push_below_m)


def tune(
    make: Any,
    candidates: Sequence[Any],
    env_id: str,
    personas: str = "train",
    episodes: int = 300,
    seed: int = TUNING_SEED,
) -> list[tuple[Any, float, float]]:
    """Score ``make(settings)`` for every candidate on the same seeded episodes; best first.

    Ranked by success rate, then by fewer unsafe lifts.

    Returns:
        ``[(settings, success_rate, unsafe_rate), ...]``.
    """
    scored = []
    for settings in candidates:
        agent: ScriptedAgent = make(settings)
        result = evaluate(agent, env_id, personas, episodes, seed)
        scored.append((settings, result.success_rate, result.unsafe_rate))
    scored.sort(key=lambda row: (-row[1], row[2]))
    return scored


def main(argv: Sequence[str] | None = None) -> int:
    """Run a search and print the best settings."""
    parser = argparse.ArgumentParser(prog="python -m agents.tune_baselines", description=__doc__.split("\n")[0])
    parser.add_argument("family", choices=("blind", "prober"))
    parser.add_argument("--level", choices=tuple(LEVEL_ENV_IDS), default="hard")
    parser.add_argument("--episodes", type=int, default=300, help="episodes per setting")
    parser.add_argument("--top", type=int, default=10, help="rows to print")
    args = parser.parse_args(argv)
    if args.family == "blind":
        rows = tune(
            lambda s: BlindAgent(settings=s), list(blind_grid()), LEVEL_ENV_IDS[args.level], episodes=args.episodes
        )
    else:
        rows = tune(
            lambda s: ProbingCaregiver(settings=s),
            list(prober_grid()),
            LEVEL_ENV_IDS[args.level],
            episodes=args.episodes,
        )
    for settings, success, unsafe in rows[: args.top]:
        print(f"success {100 * success:5.1f} %  unsafe {100 * unsafe:4.1f} %  {dataclasses.asdict(settings)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
