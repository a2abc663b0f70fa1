"""Where the web app keeps its trials: a SQL database through SQLAlchemy, one transaction per finished trial.

A trial lives in the server's memory while it is played and is written in one transaction
when it ends, so a closed tab or a killed server leaves it out whole, never half. SQLite (the
default, a file) runs in WAL mode with ``synchronous=FULL``: a committed trial survives a
killed process and a power cut, and the exporter may read while the server writes. Any other
SQLAlchemy URL (``postgresql://...``) works the same way.

Tables: ``caregiver_trials`` (one played episode, the columns of the played-episodes CSV of
:mod:`agents.tools.play_log`), ``person_sessions`` (a player of the person role and the seed of
their trial design) and ``person_trials`` (one cue trial, its recording in the format of
:mod:`estimator.recording`).
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import sqlalchemy as sa

from agents.tools.play_log import PlayedEpisode, parse_played, played_csv

__all__ = ["DEFAULT_DATABASE", "PersonTrialRow", "Store"]

DEFAULT_DATABASE = "sqlite:///runs/web.sqlite"
"""The database a server opens without ``--database``: a SQLite file under ``runs/``."""

_META = sa.MetaData()
CAREGIVER = sa.Table(
    "caregiver_trials",
    _META,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("env_id", sa.String(200), nullable=False),
    sa.Column("seed", sa.Integer, nullable=False),
    # The episode's line of the played-episodes CSV, as agents.tools.play_log writes and reads it.
    sa.Column("csv_line", sa.Text, nullable=False),
)
SESSIONS = sa.Table(
    "person_sessions",
    _META,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("created_at_utc", sa.String(40), nullable=False),
    sa.Column("design_seed", sa.Integer, nullable=False),
    sa.Column("n_trials", sa.Integer, nullable=False),
)
PERSON = sa.Table(
    "person_trials",
    _META,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("session_id", sa.Integer, sa.ForeignKey("person_sessions.id"), nullable=False),
    sa.Column("trial_index", sa.Integer, nullable=False),
    sa.Column("finished_at_utc", sa.String(40), nullable=False),
    sa.Column("requested_xi", sa.Integer, nullable=False),
    sa.Column("live_judgment", sa.Integer, nullable=False),
    sa.Column("recording", sa.Text, nullable=False),
    # A trial is stored once: a second tab or a replayed request cannot add it twice.
    sa.UniqueConstraint("session_id", "trial_index"),
)


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="microseconds")


@dataclass(frozen=True)
class PersonTrialRow:
    """One stored person trial: where it sits in its session, and its recording's CSV text."""

    session_id: int
    trial_index: int
    requested_xi: int
    live_judgment: int
    recording: str


class Store:
    """The database of finished trials.

    Args:
        url: A SQLAlchemy URL; a SQLite file's folder is created.
    """

    def __init__(self, url: str = DEFAULT_DATABASE) -> None:  # noqa: D107  (the class docstring gives the arguments)
        parsed = sa.make_url(url)
        if parsed.get_backend_name() == "sqlite" and parsed.database not in (None, "", ":memory:"):
            Path(parsed.database).parent.mkdir(parents=True, exist_ok=True)
        self.engine = sa.create_engine(parsed)
        if parsed.get_backend_name() == "sqlite":
            sa.event.listen(self.engine, "connect", _sqlite_pragmas)
        _META.create_all(self.engine)

    def add_caregiver(self, episode: PlayedEpisode) -> int:
        """Store one finished caregiver episode (one transaction); returns its row id."""
        row = {"env_id": episode.env_id, "seed": episode.seed, "csv_line": episode.csv_line()}
        with self.engine.begin() as conn:
            return _inserted_id(conn.execute(CAREGIVER.insert().values(**row)))

    def caregiver_csv(self) -> str:
        """Every stored caregiver episode as a played-episodes CSV (what ``agents.evaluate --human`` scores)."""
        with self.engine.connect() as conn:
            lines = conn.execute(sa.select(CAREGIVER.c.csv_line).order_by(CAREGIVER.c.id)).scalars().all()
        return played_csv(lines)

    def caregiver_episodes(self) -> list[PlayedEpisode]:
        """Every stored caregiver episode, in the order played."""
        return parse_played(self.caregiver_csv(), "database")

    def next_seed(self, env_id: str) -> int:
        """One past the largest seed stored for ``env_id`` (0 for none): the next of the evaluation's episodes."""
        with self.engine.connect() as conn:
            top = conn.execute(sa.select(sa.func.max(CAREGIVER.c.seed)).where(CAREGIVER.c.env_id == env_id)).scalar()
        return 0 if top is None else int(top) + 1

    def new_session(self, design_seed: int, n_trials: int) -> int:
        """Open a person session (its trial design drawn from ``design_seed``); returns its id."""
        with self.engine.begin() as conn:
            values = {"created_at_utc": _now(), "design_seed": design_seed, "n_trials": n_trials}
            return _inserted_id(conn.execute(SESSIONS.insert().values(**values)))

    def session(self, session_id: int) -> dict[str, Any] | None:
        """A session's ``design_seed``, ``n_trials`` and ``done`` (trials stored), or None if there is none."""
        with self.engine.connect() as conn:
            row = conn.execute(sa.select(SESSIONS).where(SESSIONS.c.id == session_id)).mappings().first()
            if row is None:
                return None
            done = conn.execute(
                sa.select(sa.func.count()).select_from(PERSON).where(PERSON.c.session_id == session_id)
            ).scalar()
        return {"design_seed": row["design_seed"], "n_trials": row["n_trials"], "done": int(done or 0)}

    def add_person_trial(self, row: PersonTrialRow) -> None:
        """Store one finished person trial (one transaction); a trial already stored raises ``IntegrityError``."""
        with self.engine.begin() as conn:
            conn.execute(PERSON.insert().values(finished_at_utc=_now(), **row.__dict__))

    def person_trials(self, session_id: int | None = None) -> list[PersonTrialRow]:
        """The stored person trials (of one session, or all), in session and trial order."""
        query = sa.select(PERSON).order_by(PERSON.c.session_id, PERSON.c.trial_index)
        if session_id is not None:
            query = query.where(PERSON.c.session_id == session_id)
        with self.engine.connect() as conn:
            rows = conn.execute(query).mappings().all()
        return [
            PersonTrialRow(r["session_id"], r["trial_index"], r["requested_xi"], r["live_judgment"], r["recording"])
            for r in rows
        ]

    def close(self) -> None:
        """Release the connections."""
        self.engine.dispose()


def _sqlite_pragmas(dbapi_connection: Any, _record: Any) -> None:
    cursor = dbapi_connection.cursor()
    cursor.execute("PRAGMA journal_mode=WAL")
    cursor.execute("PRAGMA synchronous=FULL")
    cursor.execute("PRAGMA foreign_keys=ON")
    cursor.close()


def _inserted_id(result: Any) -> int:
    return int(result.inserted_primary_key[0])
