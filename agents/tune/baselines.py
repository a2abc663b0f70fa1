"""Searches behind the headroom baselines: the blind family and the probing caregiver.

Every headline figure (value of reading the mind, achieved insight, mind-reading score) is
measured against the best mental-state-blind policy, so the blind search must be wide.

**The blind family** (:class:`agents.caregivers.scripted.BlindSettings`): a fixed schedule of cue
phases (each a push, words, a duration and whether a lift may come in it), played in order and
then repeated or followed by a final phase held to the end, and a lift rule on the shoulder
estimate and the clock. It reads ``elapsed_s``, ``verbal_cue`` (its own utterance) and
``x_hat_m``, never a mind feature. ``python -m agents.tune.baselines blind --level LEVEL``
searches :func:`blind_grid`: the schedules of :func:`schedule_grid` (1,605; "lean back" is in
the family but not searched: while it is heard every level moves the person one level down)
under the lift rules of :func:`lift_rules` (up to 336 each), 486,024 settings, with the 648
one-routine settings of :func:`original_blind_grid` beside them. :func:`search_blind` scores
them coarse to fine by successive halving, every round on the same seeded episodes of the
*training* personas from :data:`TUNING_SEED` (common random numbers: candidates meet identical
people), and keeps the best on the final 1000 episodes (success, then fewer unsafe lifts).
Candidates are scored many at a time in one natively batched vector env
(:func:`play_population`: slot ``i`` plays candidate ``i // episodes`` on episode
``i % episodes``, the episodes :func:`agents.evaluate.evaluate` would play).

``python -m agents.tune.baselines prober --level LEVEL`` scores
:class:`agents.caregivers.scripted.ProbingCaregiver`'s 36 settings on 300 training episodes
each. The winners are kept in :data:`agents.caregivers.scripted.TUNED_BLIND` and
:data:`agents.caregivers.scripted.TUNED_PROBER`, and scored by :mod:`agents.evaluate` on the
held-out personas with fresh seeds (``--personas test``, seeds from 0).
"""

from __future__ import annotations

import dataclasses
import itertools
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Annotated, Any, Literal

import gymnasium as gym
import numpy as np
import tyro
from numpy.typing import NDArray

import coop_gym  # noqa: F401 -- registers the env ids
from agents.base import action_type_of, features_of
from agents.caregivers.scripted import (
    BlindAgent,
    BlindSettings,
    CuePhase,
    ProbingCaregiver,
    ProbingSettings,
    ScriptedAgent,
)
from agents.evaluate import evaluate
from coop_gym.cli import exit_status, one_of, parse
from coop_gym.envs.config import Outcome
from coop_gym.registration import LEVEL_ENV_IDS

__all__ = [
    "ORIGINAL_BLIND_WINNERS",
    "PROG",
    "TUNING_SEED",
    "Args",
    "blind_grid",
    "lift_rules",
    "main",
    "original_blind_grid",
    "play_population",
    "prober_grid",
    "schedule_grid",
    "search_blind",
    "tune",
]


TUNING_SEED = 1_000_000
"""Seed of the first tuning episode: far from the evaluation seeds (0, 1, ...)."""

# The cues a searched phase may hold: (push, verbal).
CUES: dict[str, tuple[str, str]] = {
    "silence": ("none", "none"),
    "words": ("none", "forward"),
    "push": ("soft", "none"),
    "guided": ("soft", "forward"),
    "firm": ("firm", "forward"),
}
# Final (held) phases: what the original family's push x words can hold.
FINALS = ("silence", "words", "push", "guided")
DURATIONS_S = (0.5, 1.0, 2.0, 4.0)

LEANS_M = (0.12, 0.16, 0.2, 0.25, 0.3, 0.35, 0.4)
MIN_TIMES_S = (0.0, 4.0, 10.0, 20.0)
HOLDS_S = (0.0, 1.0, 2.0)
LAST_CALLS: tuple[tuple[float, float] | None, ...] = (None, (25.0, 0.16), (28.0, 0.16))
"""Last-call choices tried on the finalists: None, or (from time [s], on lean [m])."""


ORIGINAL_ROUTINES: tuple[tuple[str, bool], ...] = (
    ("none", True),
    ("soft", False),
    ("soft", True),
    ("firm", False),
    ("firm", True),
)
"""(push, words) of the original family's one routine held from the start (no cue at all is left out)."""


ORIGINAL_BLIND_WINNERS: dict[str, BlindSettings] = {
    "v0": BlindSettings(push="soft", words=True, lean_m=0.16, min_time_s=0.0),
    "easy": BlindSettings(push="soft", words=True, lean_m=0.16, min_time_s=0.0),
    "medium": BlindSettings(push="soft", words=True, lean_m=0.3, min_time_s=4.0),
    "hard": BlindSettings(push="soft", words=True, lean_m=0.3, min_time_s=0.0),
    "hard-v2": BlindSettings(push="soft", words=True, lean_m=0.16, min_time_s=0.0),
}
"""Each level's winner of the original family (:func:`original_blind_grid`, 300 training episodes each)."""


def original_blind_grid() -> Iterator[BlindSettings]:
    """The 648 settings of the original family: one routine from the start, lift rule on the lean."""
    for (push, words), release in itertools.product(ORIGINAL_ROUTINES, (False, True)):
        if push == "none" and release:
            continue  # nothing to release
        for lean_m, min_time_s, hold_s in itertools.product(
            (0.12, 0.16, 0.2, 0.25, 0.3, 0.35), (0.0, 4.0, 10.0, 20.0), (0.0, 1.0, 2.0)
        ):
            yield BlindSettings(push, words, lean_m, min_time_s, release, hold_s)


def _phase(cue: str, duration_s: float) -> CuePhase:
    push, verbal = CUES[cue]
    return CuePhase(push, verbal, duration_s)


def _held(opening: tuple[CuePhase, ...], final: str) -> BlindSettings:
    push, verbal = CUES[final]
    return BlindSettings(push=push, words=verbal == "forward", schedule=opening)


def schedule_grid() -> Iterator[BlindSettings]:
    """The cue schedules the search tries, each with the default lift rule (see the module docstring)."""
    for push, words in ORIGINAL_ROUTINES:
        yield BlindSettings(push=push, words=words)
    timed = [(cue, d) for cue in CUES for d in DURATIONS_S]
    for first in timed:  # one opening phase, then a held final phase
        for final in FINALS:
            if final != first[0]:
                yield _held((_phase(*first),), final)
    for first, second in itertools.product(timed, timed):  # two opening phases
        if first[0] != second[0]:
            for final in FINALS:
                if final != second[0]:
                    yield _held((_phase(*first), _phase(*second)), final)
    for first, second in itertools.product(timed, timed):  # a repeated cycle of two phases
        if first[0] != second[0]:
            yield BlindSettings(schedule=(_phase(*first), _phase(*second)), repeat=True)
    for d0, push, d1, rest, d2 in itertools.product(
        (1.0, 2.0), ("push", "guided", "firm"), DURATIONS_S, ("words", "silence"), DURATIONS_S
    ):  # explain, push, then words or silence: repeated
        yield BlindSettings(schedule=(_phase("words", d0), _phase(push, d1), _phase(rest, d2)), repeat=True)


def _lift_only_unpushed(settings: BlindSettings) -> BlindSettings | None:
    """``settings`` lifting only in its phases without a push; None when that changes nothing or never lifts."""
    flags = [p.push == "none" for p in settings.phases]
    if all(flags) or not any(flags):
        return None
    return dataclasses.replace(
        settings,
        schedule=tuple(dataclasses.replace(p, lift=p.push == "none") for p in settings.schedule),
        final_lift=settings.push == "none",
    )


def lift_rules(
    schedule: BlindSettings,
    leans_m: Sequence[float] = LEANS_M,
    min_times_s: Sequence[float] = MIN_TIMES_S,
    holds_s: Sequence[float] = HOLDS_S,
    releases: Sequence[bool] = (False, True),
) -> Iterator[BlindSettings]:
    """``schedule`` under every lift rule of the grid (any phase, then only unpushed phases)."""
    variants = [schedule]
    unpushed = _lift_only_unpushed(schedule)
    if unpushed is not None:
        variants.append(unpushed)
    for variant in variants:
        for lean_m, min_time_s, hold_s, release in itertools.product(leans_m, min_times_s, holds_s, releases):
            yield dataclasses.replace(
                variant, lean_m=lean_m, min_time_s=min_time_s, hold_s=hold_s, release_on_lean=release
            )


def blind_grid() -> Iterator[BlindSettings]:
    """Every schedule x lift rule of the searched grid (last calls aside): 486,024 settings."""
    for schedule in schedule_grid():
        yield from lift_rules(schedule)


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


# --- scoring many blind candidates at once ------------------------------------


def play_population(
    candidates: Sequence[BlindSettings],
    env_id: str,
    personas: str = "train",
    episodes: int = 100,
    seed: int = TUNING_SEED,
    batch: int = 8192,
    threads: int | None = 1,
) -> NDArray[np.int64]:
    """Outcome of every candidate on episodes ``seed, ..., seed + episodes - 1`` (one batched env).

    Slot ``i`` of a batch plays candidate ``i // episodes`` on episode ``i % episodes``
    (seeded as :func:`agents.evaluate.evaluate` seeds it), so every candidate meets the
    same people. Episodes that end are reset by the env and no longer recorded.

    Returns:
        (len(candidates), episodes) :class:`~coop_gym.envs.config.Outcome` codes.
    """
    total = len(candidates) * episodes
    n = min(batch, total)
    env = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", personas=personas, threads=threads)
    features, action_type = features_of(env), action_type_of(env)
    outcomes = np.zeros(total, dtype=np.int64)
    try:
        for start in range(0, total, n):
            # The last batch is filled up with copies of its first slots (played, not recorded).
            slots = ((start + np.arange(n)) % total).tolist()
            chunk = min(n, total - start)
            agent = BlindAgent(features, action_type, settings=[candidates[i // episodes] for i in slots])
            obs, _ = env.reset(seed=[seed + i % episodes for i in slots])  # type: ignore[arg-type]  # a seed each
            recorded = np.zeros(n, dtype=bool)
            state, episode_start = None, np.ones(n, dtype=bool)
            while not recorded[:chunk].all():
                actions, state = agent.predict(obs, state=state, episode_start=episode_start)
                obs, _, terminated, truncated, info = env.step(actions)
                done = terminated | truncated
                fresh = done & ~recorded
                outcomes[start + np.flatnonzero(fresh[:chunk])] = np.asarray(info["outcome_code"])[:chunk][
                    fresh[:chunk]
                ]
                recorded |= done
                episode_start = done
    finally:
        env.close()
    codes = outcomes.reshape(len(candidates), episodes)
    return np.where(codes == Outcome.NONE, int(Outcome.TIMEOUT), codes)


def _ranked(outcomes: NDArray[np.int64]) -> NDArray[np.int64]:
    """Candidate indices best first: success rate, then fewer unsafe lifts (stable)."""
    success = (outcomes == Outcome.SUCCESS).mean(axis=1)
    unsafe = (outcomes == Outcome.UNSAFE).mean(axis=1)
    return np.lexsort((unsafe, -success))


def _halve(
    candidates: list[BlindSettings],
    env_id: str,
    rounds: Sequence[tuple[int, float | int]],
    log: Any,
    **play: Any,
) -> tuple[list[BlindSettings], NDArray[np.int64]]:
    """Successive halving: each round scores the survivors on more episodes and keeps the best.

    ``rounds``: ``(episodes, keep)`` with ``keep`` a fraction (< 1) or a count. Returns the
    survivors of the last round, best first, and their outcomes on its episodes.
    """
    outcomes = np.zeros((0, 0), dtype=np.int64)
    for episodes, keep in rounds:
        t0 = time.perf_counter()
        outcomes = play_population(candidates, env_id, episodes=episodes, **play)
        order = _ranked(outcomes)
        count = max(1, round(keep * len(candidates)) if keep < 1 else int(keep))
        best = (outcomes[order[0]] == Outcome.SUCCESS).mean()
        log(
            f"  {len(candidates)} candidates x {episodes} episodes ({time.perf_counter() - t0:.0f} s): "
            f"best {100 * best:.1f} %, keep {min(count, len(candidates))}"
        )
        candidates = [candidates[i] for i in order[:count]]
        outcomes = outcomes[order[:count]]
    return candidates, outcomes


def search_blind(
    env_id: str,
    incumbent: BlindSettings | None = None,
    top_schedules: int = 10,
    finalists: int = 10,
    final_episodes: int = 1000,
    log: Any = print,
    **play: Any,
) -> list[tuple[BlindSettings, float, float]]:
    """The blind family's coarse-to-fine successive-halving search, on the training personas.

    ``incumbent`` (e.g. the original family's winner) joins the final round whatever its
    earlier scores.

    Returns:
        The finalists best first: ``[(settings, success_rate, unsafe_rate), ...]`` on the
        ``final_episodes`` training episodes from :data:`TUNING_SEED`.
    """
    schedules = list(schedule_grid())
    coarse = [c for s in schedules for c in lift_rules(s, (0.2, 0.3), (0.0,), (0.0,), (False,))]
    log(f"stage 1: {len(schedules)} schedules under coarse lift rules")
    survivors, _ = _halve(coarse, env_id, [(30, 0.1), (100, 0.1), (300, 0.5)], log, **play)
    best_schedules: list[BlindSettings] = []
    for settings in survivors:  # distinct schedules, in rank order
        template = dataclasses.replace(
            settings, lean_m=0.16, schedule=tuple(dataclasses.replace(p, lift=True) for p in settings.schedule)
        )
        template = dataclasses.replace(template, final_lift=True)
        if template not in best_schedules:
            best_schedules.append(template)
    best_schedules = best_schedules[:top_schedules]
    fine = list(dict.fromkeys([*original_blind_grid(), *(c for s in best_schedules for c in lift_rules(s))]))
    log(f"stage 2: {len(best_schedules)} schedules x lift rules + the original family = {len(fine)} settings")
    survivors, _ = _halve(fine, env_id, [(40, 0.1), (200, finalists)], log, **play)
    final = [
        s if call is None else dataclasses.replace(s, last_call_s=call[0], last_call_lean_m=call[1])
        for s in survivors
        for call in LAST_CALLS
    ]
    if incumbent is not None and incumbent not in final:
        final.append(incumbent)
    log(f"stage 3: {len(final)} finalists (with last calls and the incumbent)")
    survivors, outcomes = _halve(final, env_id, [(final_episodes, len(final))], log, **play)
    return [
        (s, float((o == Outcome.SUCCESS).mean()), float((o == Outcome.UNSAFE).mean()))
        for s, o in zip(survivors, outcomes, strict=True)
    ]


def describe(settings: BlindSettings) -> str:
    """A one-line summary of a blind setting: the final phase and lift rule, and every other field set."""
    always = ("push", "words", "lean_m", "min_time_s", "hold_s", "release_on_lean")
    fields = {
        f.name: getattr(settings, f.name)
        for f in dataclasses.fields(settings)
        if f.name in always or getattr(settings, f.name) != f.default
    }
    return f"BlindSettings({', '.join(f'{k}={v!r}' for k, v in fields.items())})"


PROG = "python -m agents.tune.baselines"


@dataclass
class Args:
    """The command line's arguments; each field's docstring is its ``--help``."""

    family: tyro.conf.Positional[Literal["blind", "prober"]]
    """the caregivers searched: the blind family or the probing caregiver"""
    level: Annotated[str, one_of(tuple(LEVEL_ENV_IDS))] = "hard"
    """the level searched on"""
    episodes: int | None = None
    """episodes per finalist (blind; None: 1000) or setting (prober; None: 300)"""
    threads: int = 1
    """threads of the batched env's compiled step"""
    top: int = 10
    """rows to print"""


def main(argv: Sequence[str] | None = None) -> int:
    """Run a search and print the best settings."""
    args = parse(Args, argv, PROG, (__doc__ or "").split("\n")[0])
    env_id = LEVEL_ENV_IDS[args.level]
    if args.family == "blind":
        t0 = time.perf_counter()
        rows = search_blind(
            env_id, ORIGINAL_BLIND_WINNERS[args.level], final_episodes=args.episodes or 1000, threads=args.threads
        )
        print(f"search took {time.perf_counter() - t0:.0f} s")
        for settings, success, unsafe in rows[: args.top]:
            print(f"success {100 * success:5.1f} %  unsafe {100 * unsafe:4.1f} %  {describe(settings)}")
        return 0
    rows = tune(lambda s: ProbingCaregiver(settings=s), list(prober_grid()), env_id, episodes=args.episodes or 300)
    for settings, success, unsafe in rows[: args.top]:
        print(f"success {100 * success:5.1f} %  unsafe {100 * unsafe:4.1f} %  {dataclasses.asdict(settings)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(exit_status(main))
