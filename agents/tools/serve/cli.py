"""The command line of the web app: serve it, or export what it stored.

    python -m agents.tools.serve                                  # http://127.0.0.1:8000/, runs/web.sqlite
    python -m agents.tools.serve --database sqlite:///study.sqlite --port 8080
    python -m agents.tools.serve --database sqlite:///study.sqlite --export study/

``--export DIR`` writes ``DIR/caregiver.csv`` (the played-episodes CSV: ``python -m
agents.evaluate --human DIR/caregiver.csv``) and ``DIR/person/*.csv`` (one recording per person
trial: ``python -m estimator.estimate DIR/person``) and exits.
"""

from __future__ import annotations

import socket
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import tyro

from agents.tools.play import DEFAULT_ENV_ID
from agents.tools.play_log import personas_arg
from agents.tools.serve.app import ServerSettings, make_app
from agents.tools.serve.store import DEFAULT_DATABASE, Store
from coop_gym.cli import BadArgs, PositiveInt, fail, output_path_problem, parse
from coop_gym.io import write_text
from coop_gym.model.personas import resolve_personas

__all__ = ["PROG", "Args", "export", "main"]

PROG = "python -m agents.tools.serve"
DESCRIPTION = "People in the loop: a local web app to play the caregiver or be the person; every trial stored."


@dataclass
class Args:
    """The command line's arguments; each field's docstring is its ``--help``."""

    host: str = "127.0.0.1"
    """address to listen on (loopback: only this machine can reach the app)"""
    port: Annotated[int, tyro.conf.arg(metavar="PORT")] = 8000
    """port to listen on (0: any free one; the address is printed)"""
    database: str = DEFAULT_DATABASE
    """SQLAlchemy database URL (sqlite:///FILE, postgresql://...)"""
    env: str = DEFAULT_ENV_ID
    """the caregiver role's env id (as agents.evaluate --env)"""
    personas: str = "test"
    """the caregiver role's persona set (as agents.evaluate --personas)"""
    person_trials: PositiveInt = 25
    """cue trials in a person session (the paper: 25)"""
    export: Annotated[str | None, tyro.conf.arg(metavar="DIR")] = None
    """write the stored trials to DIR (caregiver.csv, person/*.csv) and exit"""

    def __post_init__(self) -> None:
        """The first value no run can use is a usage error naming it."""
        if not 0 <= self.port < 65536:
            raise BadArgs(f"--port must be in 0..65535, got {self.port}")
        try:
            resolve_personas(personas_arg(self.personas))
        except ValueError as exc:
            raise BadArgs(f"--personas: {exc}") from None
        problem = output_path_problem(self.export, folder=True) if self.export is not None else None
        if problem:
            raise BadArgs(f"--export: {problem}")


def export(store: Store, folder: str | Path) -> tuple[Path, list[Path]]:
    """Write the stored trials: the caregiver episodes as one played-episodes CSV, each person trial as a recording."""
    folder = Path(folder)
    (folder / "person").mkdir(parents=True, exist_ok=True)
    played = write_text(folder / "caregiver.csv", store.caregiver_csv())
    recordings = [
        write_text(folder / "person" / f"web{row.session_id:04d}_t{row.trial_index:02d}.csv", row.recording)
        for row in store.person_trials()
    ]
    return played, recordings


def _open_store(url: str) -> Store:
    """The database at ``url``; a usage error naming it where it cannot be opened (a bad URL, a missing driver)."""
    import sqlalchemy as sa

    try:
        return Store(url)
    except (sa.exc.SQLAlchemyError, ValueError, OSError, ImportError) as exc:
        fail(PROG, f"--database {url}: cannot open it ({type(exc).__name__}: {str(exc).splitlines()[0]})")


def main(argv: Sequence[str] | None = None) -> int:
    """Serve until interrupted (or export and exit); usage errors exit with status 2."""
    args = parse(Args, argv, PROG, DESCRIPTION)
    store = _open_store(args.database)
    if args.export is not None:
        played, recordings = export(store, args.export)
        print(f"wrote {played} ({len(store.caregiver_episodes())} caregiver episodes) and {len(recordings)} recordings")
        return 0
    import uvicorn

    # Bound here, so port 0 gives a free port and the printed address is the real one.
    sock = socket.socket(socket.AF_INET6 if ":" in args.host else socket.AF_INET)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((args.host, args.port))
    except OSError as exc:  # the port is taken, or the host is no address of this machine
        sock.close()
        fail(PROG, f"--host {args.host} --port {args.port}: cannot listen there ({exc.strerror or exc})")
    sock.listen(128)  # connections wait in the backlog until uvicorn accepts them
    port = sock.getsockname()[1]
    names = {args.host, "127.0.0.1", "localhost"} if args.host in ("127.0.0.1", "localhost") else {args.host}
    settings = ServerSettings(
        env_id=args.env,
        personas=args.personas,
        person_trials=args.person_trials,
        origins=tuple(f"http://{name}:{port}" for name in sorted(names)),
        hosts=tuple(sorted(names)),
    )
    app = make_app(store, settings)
    print(f"coop_gym web app: http://{args.host}:{port}/  (database {args.database}; Ctrl-C stops)", flush=True)
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning"))
    server.run(sockets=[sock])
    store.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
