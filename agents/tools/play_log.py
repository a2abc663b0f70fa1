r"""The played-episodes CSV of :mod:`agents.tools.play`, and its score as the "human" row.

One line per episode a person played, appended as it ends::

    played_at_utc,env_id,seed,personas,persona,outcome,lift_time_s,steps,episode_return,actions

``actions`` holds one ``push verbal lift`` triple of digits per env step, space-separated
(``"200 220 001"``: firm push; firm push and "lean forward"; lift), in the component
encoding of :mod:`coop_gym.envs.contract` (push 0 none, 1 soft, 2 firm; verbal 0 none,
1 "lean back", 2 "lean forward"; lift 0 wait, 1 lift), so a line replays on any action
type of its env id.

:func:`score_played` replays every line of one env id through :func:`agents.evaluate.evaluate`
(the same env, seed and persona set, the recorded actions as the agent), so a person's
episodes get exactly the records and metrics an agent gets; a line whose replay ends
differently from what it recorded is refused (the env changed since it was played).

Nothing here imports pygame, torch or SB3.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.base import encode_actions
from agents.evaluate import OUTCOMES, EvaluationResult, evaluate
from coop_gym.cli import SEED_LIMIT
from coop_gym.envs.contract import ACTION_SHAPE
from coop_gym.model.personas import resolve_personas

__all__ = [
    "PLAYED_COLUMNS",
    "PlayedEpisode",
    "append_played",
    "next_seed",
    "parse_played",
    "personas_arg",
    "played_csv",
    "read_played",
    "score_played",
]

PLAYED_COLUMNS: tuple[str, ...] = (
    "played_at_utc",
    "env_id",
    "seed",
    "personas",
    "persona",
    "outcome",
    "lift_time_s",
    "steps",
    "episode_return",
    "actions",
)
"""The header of a played-episodes CSV, in column order."""

Triple = tuple[int, int, int]


@dataclass(frozen=True)
class PlayedEpisode:
    """One episode a person played.

    Attributes:
        env_id: The env id played.
        seed: The env seed of the episode (the person and all noise follow from it).
        personas: The persona set the person was drawn from, as given (``"test"``, ``"a,b"``).
        persona: The persona drawn.
        outcome: ``"success"``, ``"unsafe"``, ``"premature"`` or ``"timeout"``.
        lift_time_s: Episode time of the lift, None without a lift [s].
        episode_return: Sum of rewards.
        actions: One ``(push, verbal, lift)`` component triple per env step.
        played_at_utc: When the episode ended (ISO 8601, UTC).
    """

    env_id: str
    seed: int
    personas: str
    persona: str
    outcome: str
    lift_time_s: float | None
    episode_return: float
    actions: tuple[Triple, ...]
    played_at_utc: str = ""

    @property
    def steps(self) -> int:
        """Env steps taken (the lift included)."""
        return len(self.actions)

    def csv_line(self) -> str:
        """The episode as one complete CSV line (newline included)."""
        stamp = self.played_at_utc or datetime.now(timezone.utc).isoformat(timespec="seconds")
        row = [
            stamp,
            self.env_id,
            str(self.seed),
            self.personas,
            self.persona,
            self.outcome,
            "" if self.lift_time_s is None else f"{self.lift_time_s:.3f}",
            str(self.steps),
            repr(float(self.episode_return)),
            " ".join(f"{p}{v}{lift}" for p, v, lift in self.actions),
        ]
        buffer = io.StringIO()
        csv.writer(buffer, lineterminator="\n").writerow(row)
        return buffer.getvalue()


def _header_line() -> str:
    return ",".join(PLAYED_COLUMNS) + "\n"


def _check_existing(path: Path, data: bytes) -> None:
    """Refuse to append to a file that is not a complete played-episodes CSV (naming why)."""
    if not data:
        return
    first = data.split(b"\n", 1)[0].decode("utf-8", errors="replace").strip("\r")
    if first != _header_line().strip():
        raise ValueError(
            f"{path} is not a played-episodes CSV: its header is {first[:120]!r}, expected "
            f"{','.join(PLAYED_COLUMNS)!r}; give another --csv path"
        )
    if not data.endswith(b"\n"):
        raise ValueError(f"{path} ends in an incomplete line (an interrupted write?); repair or move it first")


def append_played(path: str | Path, episode: PlayedEpisode) -> Path:
    """Append ``episode`` to the CSV at ``path`` (created with its header if absent).

    The line is written with one ``write`` on a file opened for appending, under an
    exclusive lock where the platform has one, so concurrent players and crashes leave
    either the whole line or none of it; the file's existing lines are never rewritten.

    Raises:
        ValueError: If the file exists but is not a complete played-episodes CSV.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    line = episode.csv_line().encode("utf-8")
    fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_APPEND, 0o644)
    try:
        try:
            import fcntl

            fcntl.flock(fd, fcntl.LOCK_EX)
        except ImportError:  # pragma: no cover - no flock on Windows; the single write remains
            pass
        size = os.fstat(fd).st_size
        existing = os.pread(fd, size, 0) if size else b""
        _check_existing(path, existing)
        payload = (b"" if existing else _header_line().encode("utf-8")) + line
        written = os.write(fd, payload)
        if written != len(payload):  # pragma: no cover - a full disk
            raise OSError(f"short write to {path}: {written} of {len(payload)} bytes")
        os.fsync(fd)
    finally:
        os.close(fd)
    return path


def _parse_actions(text: str, where: str) -> tuple[Triple, ...]:
    triples = []
    for token in text.split():
        if len(token) != 3 or not token.isdigit() or any(int(d) >= n for d, n in zip(token, ACTION_SHAPE, strict=True)):
            raise ValueError(f"{where}: bad action {token!r} (want push 0-2, verbal 0-2, lift 0-1, e.g. '201')")
        triples.append((int(token[0]), int(token[1]), int(token[2])))
    if not triples:
        raise ValueError(f"{where}: no actions")
    return tuple(triples)


def _parse_row(row: dict[str, str], where: str) -> PlayedEpisode:
    try:
        seed = int(row["seed"])
        lift_text = row["lift_time_s"]
        lift = float(lift_text) if lift_text else None
        ret = float(row["episode_return"])
        steps = int(row["steps"])
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None
    if not 0 <= seed < SEED_LIMIT:
        raise ValueError(f"{where}: seed {seed} outside [0, 2**32)")
    if row["outcome"] not in OUTCOMES:
        raise ValueError(f"{where}: unknown outcome {row['outcome']!r}; known: {list(OUTCOMES)}")
    if not math.isfinite(ret) or (lift is not None and not math.isfinite(lift)):
        raise ValueError(f"{where}: episode_return and lift_time_s must be finite")
    actions = _parse_actions(row["actions"], where)
    if steps != len(actions):
        raise ValueError(f"{where}: steps is {steps} but {len(actions)} actions are recorded")
    return PlayedEpisode(
        row["env_id"], seed, row["personas"], row["persona"], row["outcome"], lift, ret, actions, row["played_at_utc"]
    )


def read_played(path: str | Path) -> list[PlayedEpisode]:
    """Every episode of a played-episodes CSV, in file order.

    Raises:
        FileNotFoundError: If there is no file at ``path``.
        ValueError: If the file is not a played-episodes CSV or a line is malformed
            (the message names the file and line).
    """
    path = Path(path)
    data = path.read_bytes()
    if not data:
        raise ValueError(f"{path} is empty: not a played-episodes CSV")
    _check_existing(path, data)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path} is not UTF-8 text: {exc}") from None
    return parse_played(text, str(path))


def played_csv(lines: Sequence[str]) -> str:
    """A played-episodes CSV of complete lines (:meth:`PlayedEpisode.csv_line`): the header, then the lines."""
    return _header_line() + "".join(lines)


def parse_played(text: str, path: str = "<played>") -> list[PlayedEpisode]:
    """Every episode of the text of a played-episodes CSV (header first); errors name ``path`` and the line."""
    reader = csv.DictReader(io.StringIO(text), strict=True)
    episodes = []
    try:
        for row in reader:
            where = f"{path}:{reader.line_num}"
            if None in row or any(v is None for v in row.values()):
                raise ValueError(f"{where}: expected {len(PLAYED_COLUMNS)} columns")
            episodes.append(_parse_row(row, where))
    except csv.Error as exc:
        raise ValueError(f"{path}:{reader.line_num}: {exc}") from None
    return episodes


def next_seed(path: str | Path, env_id: str, default: int = 0) -> int:
    """One past the largest seed played on ``env_id`` in the CSV (``default`` without one).

    So a player who does not choose a seed walks the evaluation's episodes ``0, 1, 2, ...``.
    """
    path = Path(path)
    if not path.exists() or path.stat().st_size == 0:
        return default
    seeds = [e.seed for e in read_played(path) if e.env_id == env_id]
    return max(seeds) + 1 if seeds else default


class _Replay:
    """An agent that plays one recorded action sequence (the ``predict`` protocol, one env)."""

    def __init__(self, actions: Sequence[Triple], action_type: str) -> None:
        self.action_type = action_type
        self.actions = list(actions)
        self.step = 0

    def predict(
        self,
        observation: NDArray[np.floating[Any]],
        state: Any = None,
        episode_start: NDArray[np.bool_] | None = None,
        deterministic: bool = True,
    ) -> tuple[NDArray[Any], Any]:
        # Past the recorded end (the episode should be over) the person waits.
        push, verbal, lift = self.actions[self.step] if self.step < len(self.actions) else (0, 0, 0)
        self.step += 1
        return encode_actions(np.array([push]), np.array([verbal]), np.array([lift]), self.action_type), state


def personas_arg(text: str) -> str | list[str]:
    """A persona set as given on a command line (``"test"``, ``"a,b"``) as ``resolve_personas`` takes it."""
    return text if "," not in text else [p.strip() for p in text.split(",") if p.strip()]


def score_played(csv_path: str | Path, env_id: str, name: str = "human") -> EvaluationResult:
    """The played episodes of ``env_id`` in ``csv_path`` as one :class:`~agents.evaluate.EvaluationResult`.

    Each line is replayed by :func:`agents.evaluate.evaluate` on its seed and persona set,
    so the records (outcome, time to lift, forces, cues, return) come from the one
    evaluation path every agent is scored by. ``records[k].episode`` is the line's
    index among the env's lines; ``seed`` is the first line's seed.

    Args:
        csv_path: A CSV written by ``python -m agents.tools.play``.
        env_id: The env id whose lines are scored (other ids are left out).
        name: The agent name of the result row.

    Raises:
        ValueError: A foreign or corrupt CSV, no line for ``env_id``, or a line whose
            replay ends differently from what it recorded.
    """
    import gymnasium as gym

    from agents.base import action_type_of

    played = [e for e in read_played(csv_path) if e.env_id == env_id]
    if not played:
        raise ValueError(f"{csv_path} holds no played episode of {env_id}")
    probe = gym.make(env_id)
    action_type = action_type_of(probe)
    probe.close()
    records = []
    personas: list[str] = []
    wall = 0.0
    for k, episode in enumerate(played):
        result = evaluate(
            _Replay(episode.actions, action_type),
            env_id,
            personas_arg(episode.personas),
            episodes=1,
            seed=episode.seed,
            n_envs=1,
            backend="single",
            name=name,
        )
        record = result.records[0]
        if record.outcome != episode.outcome or record.steps != episode.steps:
            raise ValueError(
                f"{csv_path}: the episode of {env_id} seed {episode.seed} recorded {episode.outcome} after "
                f"{episode.steps} steps but replays as {record.outcome} after {record.steps}: "
                "the env changed since it was played"
            )
        records.append(replace(record, episode=k))
        personas += [p.name for p in resolve_personas(personas_arg(episode.personas)) if p.name not in personas]
        wall += result.wall_time_s
    return EvaluationResult(name, env_id, tuple(personas), played[0].seed, tuple(records), wall, "single")
