r"""Play the caregiver: ``python -m agents.tools.play``.

A pygame window shows the env's own rendered scene (the person, your push and words,
the filter's cooperativeness gauge) with the person's true cooperativeness covered, and
a control panel beneath it. Keys (:data:`KEYS`):

========  ================================================================
1 / 2 / 3 push none / soft (10 N) / firm (30 N), held until you change it
B / F     say "lean back" / "lean forward" once (the words play for 1 s)
L         lift (ends the episode)
Space     pause (``--pace realtime``) or take one step (``--pace turns``)
Enter     next person, after an episode
Esc / Q   quit (an unfinished episode is not recorded)
========  ================================================================

Pace: ``--pace realtime`` (default) advances one env step per frame at ``--fps 10``,
the env's own control rate of 0.1 s, so the episode runs in real time; the controls
held at a frame are that step's action; each episode starts paused (Space starts the
clock). ``--pace turns`` advances only when you act: each B, F, L or Space is one step
(1/2/3 only change the held push).

After each episode the panel shows the outcome, the true mental state over time under
your cues, and what the oracle (which sees the mental state) and the prober did with the
same person (same seed). Every finished episode is appended to ``--csv`` (see
:mod:`agents.tools.play_log`); :func:`score_played` scores such a file like an agent::

    python -m agents.tools.play                        # CoopGym/SitToStandHard-v2, held-out personas
    python -m agents.tools.play --pace turns --seed 7 --csv runs/me.csv

Without ``--seed`` play starts at one past the largest seed already in the CSV for the
env (0 for a new file), so successive sessions walk the evaluation's episodes 0, 1, 2...
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

import coop_gym
from agents.base import (
    LIFT,
    PUSH_FIRM,
    PUSH_NONE,
    PUSH_SOFT,
    VERBAL_BACK,
    VERBAL_FORWARD,
    VERBAL_NONE,
    WAIT,
    action_type_of,
    encode_actions,
)
from agents.evaluate import evaluate
from agents.tools.play_log import PlayedEpisode, append_played, next_seed, read_played, score_played
from coop_gym.cli import BadArgs, exit_status, output_path_problem, parse, seed_range_problem
from coop_gym.model.personas import resolve_personas
from coop_gym.registration import HARD_ENV_ID

__all__ = [
    "DEFAULT_CSV",
    "DEFAULT_ENV_ID",
    "KEYS",
    "PROG",
    "Args",
    "Controls",
    "PlayedSteps",
    "args_problem",
    "main",
    "play",
    "score_played",
    "scripted_keys",
]

DEFAULT_ENV_ID = HARD_ENV_ID
DEFAULT_CSV = "runs/played.csv"
COMPARED = ("oracle", "prober")
"""Scripted agents replayed on each played seed for the summary."""

KEYS: dict[str, str] = {
    "1": "push none",
    "2": "push soft",
    "3": "push firm",
    "b": "say lean back",
    "f": "say lean forward",
    "l": "lift",
    "space": "pause / step",
    "return": "next episode",
    "escape": "quit",
    "q": "quit",
}
"""Key names (``pygame.key.name``) and what they do."""

_PUSH_KEYS = {"1": PUSH_NONE, "2": PUSH_SOFT, "3": PUSH_FIRM, "[1]": PUSH_NONE, "[2]": PUSH_SOFT, "[3]": PUSH_FIRM}
_WORD_KEYS = {"b": VERBAL_BACK, "f": VERBAL_FORWARD}
_WORDS = {VERBAL_BACK: "lean back", VERBAL_FORWARD: "lean forward"}

KeySource = Callable[[], Sequence[str]]
"""Returns the names of the keys pressed since its last call (``"quit"`` for a closed window)."""


@dataclass
class Controls:
    """What the player holds: a push level, and the words and lift asked for the next step."""

    push: int = PUSH_NONE
    verbal: int = VERBAL_NONE
    lift: int = WAIT
    said: str = ""

    def press(self, key: str) -> str | None:
        """Apply one key; returns ``"quit"``, ``"space"``, ``"next"`` or ``"act"`` (a one-step cue) or None."""
        key = key.lower()
        if key in ("escape", "q", "quit"):
            return "quit"
        if key in ("return", "enter", "[enter]"):
            return "next"
        if key == "space":
            return "space"
        if key in _PUSH_KEYS:
            self.push = _PUSH_KEYS[key]
            return None
        if key in _WORD_KEYS:
            self.verbal = _WORD_KEYS[key]
            self.said = _WORDS[self.verbal]
            return "act"
        if key == "l":
            self.lift = LIFT
            return "act"
        return None

    def take(self) -> tuple[int, int, int]:
        """The ``(push, verbal, lift)`` of the next step; words and lift are used once."""
        action = (self.push, self.verbal, self.lift)
        self.verbal, self.lift = VERBAL_NONE, WAIT
        return action


def pygame_keys() -> list[str]:
    """Key names pressed since the last call, from pygame's event queue."""
    import pygame

    names = []
    for event in pygame.event.get():
        if event.type == pygame.QUIT:
            names.append("quit")
        elif event.type == pygame.KEYDOWN:
            names.append(pygame.key.name(event.key))
    return names


def scripted_keys(script: Iterable[Sequence[str]]) -> KeySource:
    """A key source that gives one entry of ``script`` per call, then ``"escape"`` forever (tests, recordings)."""
    entries = iter(script)

    def keys() -> Sequence[str]:
        return next(entries, ("escape",))

    return keys


@dataclass
class PlayedSteps:
    """A running played episode's record: what the player did and what the env answered, step by step."""

    seed: int
    persona: str
    times_s: list[float] = field(default_factory=list)
    true_xi: list[int] = field(default_factory=list)
    actions: list[tuple[int, int, int]] = field(default_factory=list)
    episode_return: float = 0.0
    outcome: str = "none"
    lift_time_s: float | None = None

    def step(self, env: gym.Env[Any, Any], push: int, verbal: int, lift: int) -> tuple[bool, dict[str, Any]]:
        """One env step with the player's component action, recorded; returns ``(done, info)``."""
        action = encode_actions(np.array([push]), np.array([verbal]), np.array([lift]), action_type_of(env))[0]
        _, reward, terminated, truncated, info = env.step(action)
        self.actions.append((push, verbal, lift))
        self.episode_return += float(reward)
        self.times_s.append(float(info["elapsed_s"]))
        self.true_xi.append(int(info["true_xi"]))
        self.outcome = str(info["outcome"])
        if lift:
            self.lift_time_s = float(info["elapsed_s"])
        return bool(terminated or truncated), info

    def played(self, env_id: str, personas: str) -> PlayedEpisode:
        """The finished episode as a line of the played-episodes CSV."""
        return PlayedEpisode(
            env_id,
            self.seed,
            personas,
            self.persona,
            self.outcome,
            self.lift_time_s,
            self.episode_return,
            tuple(self.actions),
        )


@dataclass
class _Session:
    """What every episode is played with: the env, the window, the keys and the clock."""

    env_id: str
    personas: list[str]
    env: gym.Env[Any, Any]
    keys: KeySource
    pace: str
    fps: int
    window: bool
    on_frame: Callable[[NDArray[np.uint8]], None] | None
    view: Any = None  # agents.tools.play_view.PlayView, opened on the first frame (it takes the frame's size)
    clock: Any = None  # pygame.time.Clock

    def open_view(self, frame: NDArray[np.uint8]) -> None:
        """Open the window (or the off-screen surface) around the env's frame, once."""
        if self.view is None:
            import pygame

            from agents.tools.play_view import PlayView

            self.view = PlayView((frame.shape[1], frame.shape[0]), window=self.window)
            self.clock = pygame.time.Clock()

    def show(self, advanced: bool = True) -> None:
        """Put the composed image on the screen, and hand it to ``on_frame`` when something changed."""
        self.view.present()
        if self.on_frame is not None and advanced:
            self.on_frame(self.view.pixels())

    def close(self) -> None:
        """Close the env and the window."""
        self.env.close()
        if self.view is not None:
            self.view.close()


def _step(session: _Session, episode: PlayedSteps, controls: Controls) -> tuple[bool, NDArray[np.uint8]]:
    """One env step with the held controls; returns ``(done, frame)``."""
    done, _ = episode.step(session.env, *controls.take())
    return done, session.env.render()  # type: ignore[return-value]


def _compared(env_id: str, personas: list[str], seed: int) -> list[tuple[str, str, float | None]]:
    """What the scripted agents of :data:`COMPARED` did on the same seed (outcome, lift time)."""
    out = []
    for name in COMPARED:
        record = evaluate(name, env_id, personas, episodes=1, seed=seed, n_envs=1, backend="single").records[0]
        out.append((name, record.outcome, record.duration_s if record.lifted else None))
    return out


def _play_episode(session: _Session, seed: int) -> tuple[PlayedSteps, NDArray[np.uint8] | None]:
    """Reset to ``seed`` and step under the player's keys until the episode ends.

    Returns:
        The episode and its last frame; the frame is None if the player quit.
    """
    _, info = session.env.reset(seed=seed)
    frame: NDArray[np.uint8] = session.env.render()  # type: ignore[assignment]
    session.open_view(frame)
    episode = PlayedSteps(seed, str(info["persona"]), [0.0], [int(info["true_xi"])])
    # Real time waits for the first Space, so the player sees the person before the clock runs.
    controls, paused, done, stepped = Controls(), session.pace == "realtime", False, True
    while not done:
        commands = [controls.press(k) for k in session.keys()]
        if "quit" in commands:
            return episode, None
        if session.pace == "realtime":
            paused ^= commands.count("space") % 2 == 1
            advance = not paused
        else:
            advance = "space" in commands or "act" in commands
        if advance:
            done, frame = _step(session, episode, controls)
        status = ("your move" if session.pace == "turns" else "") if not paused else "PAUSED: Space to run"
        session.view.show_playing(frame, controls.push, controls.said, episode.times_s[-1], seed, status)
        session.show(advance or stepped)
        stepped = False
        session.clock.tick(session.fps if session.pace == "realtime" else 30)
    return episode, frame


def _summary(session: _Session, episode: PlayedSteps, note: str) -> Any:
    """The after-episode panel: the outcome, the mental state under the player's cues, the scripted agents' runs."""
    from agents.tools.play_view import Summary

    timing = getattr(session.env.unwrapped, "timing", None)  # the env's clock sets the summary's time axis
    return Summary(
        episode.outcome,
        episode.lift_time_s,
        episode.episode_return,
        episode.persona,
        episode.times_s,
        episode.true_xi,
        episode.actions,
        _compared(session.env_id, session.personas, episode.seed),
        float(timing.episode_s) if timing is not None else 30.0,
        note,
    )


def _wait_for_next(session: _Session, last: bool) -> bool:
    """After the summary: True when the player asks for the next person, False when they quit."""
    controls = Controls()
    while True:
        commands = [controls.press(k) for k in session.keys()]
        if "quit" in commands or (last and "next" in commands):
            return False
        if "next" in commands:
            return True
        session.view.present()
        session.clock.tick(30)


def play(
    env_id: str = DEFAULT_ENV_ID,
    seed: int | None = None,
    personas: str = "test",
    csv_path: str | Path = DEFAULT_CSV,
    *,
    pace: str = "realtime",
    fps: int = 10,
    episodes: int = 0,
    keys: KeySource | None = None,
    window: bool = True,
    on_frame: Callable[[NDArray[np.uint8]], None] | None = None,
) -> list[PlayedEpisode]:
    """Play episodes until the player quits (or ``episodes`` are done); each is appended to ``csv_path``.

    Args:
        env_id: A coop_gym env id.
        seed: Seed of the first episode (then +1 each); None: one past the CSV's largest for ``env_id``.
        personas: The persona set people are drawn from (as ``agents.evaluate --personas``).
        csv_path: The played-episodes CSV to append to.
        pace: ``"realtime"`` (one step a frame at ``fps``) or ``"turns"`` (a step per action key).
        fps: Frames a second; 10 is real time; 0 runs as fast as it can (tests, recordings).
        episodes: Stop after this many (0: until the player quits).
        keys: Where key presses come from (default: the pygame window).
        window: Open a window (False draws off-screen only).
        on_frame: Called with the composed window image after every drawn step and summary.

    Returns:
        The finished episodes, as appended.
    """
    if pace not in ("realtime", "turns"):
        raise ValueError(f"pace must be 'realtime' or 'turns', got {pace!r}")
    names = [p.name for p in resolve_personas(personas if "," not in personas else personas.split(","))]
    if Path(csv_path).exists() and Path(csv_path).stat().st_size:
        read_played(csv_path)  # a foreign or corrupt CSV is refused before anyone plays
    seed = next_seed(csv_path, env_id) if seed is None else seed
    env = gym.make(env_id, personas=names, render_mode="rgb_array")
    session = _Session(env_id, names, env, keys or pygame_keys, pace, fps, window, on_frame)
    played: list[PlayedEpisode] = []
    try:
        while True:
            episode, frame = _play_episode(session, seed)
            if frame is None:
                return played
            record = episode.played(env_id, personas)
            append_played(csv_path, record)
            played.append(record)
            last = bool(episodes and len(played) >= episodes)
            hint = "Esc: quit" if last else f"Enter: next person (seed {seed + 1})   Esc: quit"
            session.view.show_summary(frame, _summary(session, episode, f"saved to {csv_path}.   {hint}"))
            session.show()
            if not _wait_for_next(session, last):
                return played
            seed += 1
    finally:
        session.close()


PROG = "python -m agents.tools.play"
DESCRIPTION = "Play the robot caregiver: push, speak and lift by keyboard; every episode is saved to a CSV."


@dataclass
class Args:
    """The command line's arguments; each field's docstring is its ``--help``."""

    env: str = DEFAULT_ENV_ID
    """coop_gym env id"""
    seed: int | None = None
    """seed of the first episode (None: next in the CSV)"""
    personas: str = "test"
    """train, test, all, a persona or names joined by ','"""
    csv: str = DEFAULT_CSV
    """played-episodes CSV to append to"""
    pace: Literal["realtime", "turns"] = "realtime"
    """see the module help"""
    fps: int = 10
    """steps a second in realtime pace (10 = real time)"""
    episodes: int = 0
    """stop after this many episodes (0: until Esc)"""

    def __post_init__(self) -> None:
        """The first value no session can use is a usage error naming it, before the window opens."""
        if problem := args_problem(self):
            raise BadArgs(problem)


def args_problem(args: Args) -> str | None:
    """The first value of ``args`` no session can use (None if all are fine)."""
    if args.env not in coop_gym.ENV_IDS:
        return f"--env: unknown env id {args.env!r}; coop_gym ids: {', '.join(coop_gym.ENV_IDS)}"
    if args.seed is not None and (problem := seed_range_problem("--seed", args.seed)):
        return problem
    if problem := output_path_problem(args.csv):
        return f"--csv: {problem}"
    if args.fps < 1 or args.episodes < 0:
        return "--fps must be >= 1 and --episodes >= 0"
    return None


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code (usage errors exit 2)."""
    args = parse(Args, argv, PROG, DESCRIPTION + "\n\nKeys: " + ", ".join(f"{k} {v}" for k, v in KEYS.items()))
    try:
        resolve_personas(args.personas if "," not in args.personas else args.personas.split(","))
        played = play(
            args.env, args.seed, args.personas, args.csv, pace=args.pace, fps=args.fps, episodes=args.episodes
        )
    except ValueError as exc:  # a foreign or corrupt --csv, an unknown persona
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if played:
        print(f"{len(played)} episode(s) appended to {args.csv}")
    return 0


if __name__ == "__main__":
    sys.exit(exit_status(main))
