"""The web app's HTTP side: a Starlette application of a page, its script and a small JSON API.

Every request that changes something is a ``POST`` of a JSON object; the answer is a JSON
object, or ``{"error": "..."}`` with status 400 (malformed or out of range), 403 (another
origin), 404 (no such trial) or 409 (the trial is played in another tab, or has ended).

=============================  ==============================================================
``POST /api/caregiver/start``  a new caregiver episode on the next of the evaluation's seeds
``POST /api/caregiver/step``   ``{trial_id, token, seq, push, verbal, lift}``: one 0.1 s step
``POST /api/person/start``     ``{session_id?}``: the session's next cue trial (a new session without one)
``POST /api/person/step``      ``{trial_id, token, seq, intention_m}``: one 0.1 s step
``POST /api/attach``           ``{trial_id}``: join a running trial -- always refused (one tab per trial)
``GET /api/person/results``    ``?session_id=N``: the paper's tables of the session's stored trials
=============================  ==============================================================

``token`` is handed to the tab that started the trial and ``seq`` counts its steps (1, 2, ...),
so a second tab, or a request sent twice, cannot advance a trial. A trial is stored in one
transaction when it ends; one left unfinished is dropped after :data:`IDLE_TRIAL_S`.
"""

from __future__ import annotations

import asyncio
import functools
import json
import secrets
import time
from dataclasses import dataclass, field
from importlib import resources
from typing import Any

from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.middleware import Middleware
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.requests import Request
from starlette.responses import HTMLResponse, JSONResponse, Response
from starlette.routing import Route

from agents.tools.serve.store import PersonTrialRow, Store
from agents.tools.serve.trials import BadInput, CaregiverTrial, PersonTrial, person_design
from coop_gym.experiment.protocol import ProtocolConfig, run_protocol
from estimator.estimate import estimate_recordings, summarize_recordings
from estimator.paper import XI_NAMES, format_tables
from estimator.recording import parse_recording

__all__ = ["IDLE_TRIAL_S", "ServerSettings", "make_app"]

IDLE_TRIAL_S = 5.0
"""A running trial no tab has stepped for this long is dropped, unstored, when a trial starts [s]: a
playing tab steps every 0.1 s, so such a trial's tab was closed, and its place is free again."""

_MAX_BODY_BYTES = 4096


@dataclass(frozen=True)
class ServerSettings:
    """What a server plays and where it keeps it.

    Attributes:
        env_id: The caregiver role's env id (``agents.evaluate``'s).
        personas: The caregiver role's persona set.
        person_trials: Cue trials in a person session (the paper: 25).
        origins: The origins a browser may send requests from (the server's own address).
        hosts: The ``Host`` names the server answers to.
    """

    env_id: str
    personas: str
    person_trials: int
    origins: tuple[str, ...]
    hosts: tuple[str, ...]


class Refused(Exception):
    """A request answered with an error status and message."""

    def __init__(self, status: int, message: str) -> None:
        """An error of HTTP ``status`` with ``message``."""
        super().__init__(message)
        self.status = status


@dataclass
class _Live:
    """A running trial, the tab that owns it, and the steps it has taken."""

    trial: CaregiverTrial | PersonTrial
    token: str = field(default_factory=lambda: secrets.token_urlsafe(16))
    seq: int = 0
    touched: float = field(default_factory=time.monotonic)
    lock: asyncio.Lock = field(default_factory=asyncio.Lock)


class _Server:
    """The app's state: the store, the running trials, the settings."""

    def __init__(self, store: Store, settings: ServerSettings) -> None:
        self.store, self.settings = store, settings
        self.live: dict[str, _Live] = {}

    async def body(self, request: Request) -> dict[str, Any]:
        """The request's JSON object, after the origin check; anything else is refused."""
        origin = request.headers.get("origin")
        if origin is not None and origin not in self.settings.origins:
            raise Refused(403, f"cross-origin request from {origin!r} refused (this server serves only itself)")
        raw = await request.body()
        if len(raw) > _MAX_BODY_BYTES:
            raise Refused(400, f"request body over {_MAX_BODY_BYTES} bytes")
        try:
            payload = json.loads(raw or b"{}")
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise Refused(400, f"malformed JSON: {exc}") from None
        if not isinstance(payload, dict):
            raise Refused(400, f"expected a JSON object, got {type(payload).__name__}")
        return payload

    def start(self, trial: CaregiverTrial | PersonTrial) -> tuple[str, _Live]:
        """Register a running trial (dropping the long idle ones); returns its id and record."""
        now = time.monotonic()
        for key in [k for k, v in self.live.items() if now - v.touched > IDLE_TRIAL_S]:
            dropped = self.live.pop(key).trial
            if isinstance(dropped, CaregiverTrial):
                dropped.close()
        trial_id = secrets.token_hex(6)
        self.live[trial_id] = _Live(trial)
        return trial_id, self.live[trial_id]

    def owned(self, payload: dict[str, Any], kind: type) -> _Live:
        """The running trial the request names, if the request comes from its tab and is its next step."""
        live = self.live.get(str(payload.get("trial_id")))
        if live is None or not isinstance(live.trial, kind):
            raise Refused(404, f"no running {kind.__name__} {payload.get('trial_id')!r} (ended, or never started)")
        if payload.get("token") != live.token:
            raise Refused(409, "this trial is being played in another tab (its token does not match)")
        seq = payload.get("seq")
        if isinstance(seq, bool) or not isinstance(seq, int) or seq != live.seq + 1:
            raise Refused(409, f"step {seq!r} out of order: the trial's next step is {live.seq + 1}")
        return live


def _refusals(handler: Any) -> Any:
    """Answer :class:`Refused` and :class:`BadInput` as JSON errors (400 for bad input)."""

    async def endpoint(request: Request) -> Response:
        try:
            return JSONResponse(await handler(request))
        except Refused as exc:
            return JSONResponse({"error": str(exc)}, status_code=exc.status)
        except BadInput as exc:
            return JSONResponse({"error": str(exc)}, status_code=400)

    return endpoint


async def _caregiver_start(server: _Server, request: Request) -> dict[str, Any]:
    await server.body(request)
    settings = server.settings
    seed = await run_in_threadpool(server.store.next_seed, settings.env_id)
    # A seed another tab is playing right now is skipped, so two players never share an episode.
    playing = {v.trial.seed for v in server.live.values() if isinstance(v.trial, CaregiverTrial)}
    while seed in playing:
        seed += 1
    trial = await run_in_threadpool(CaregiverTrial, settings.env_id, settings.personas, seed)
    trial_id, live = server.start(trial)
    return {"trial_id": trial_id, "token": live.token, "env_id": settings.env_id, "scene": trial.scene()}


async def _advance(server: _Server, request: Request, kind: type) -> tuple[Any, dict[str, Any]]:
    """Step the running trial the request names; an ended trial leaves the running set (the caller stores it)."""
    payload = await server.body(request)
    live = server.owned(payload, kind)
    async with live.lock:  # one step at a time, however many requests arrive
        scene = live.trial.step(payload)
        live.seq, live.touched = live.seq + 1, time.monotonic()
        if live.trial.done:
            server.live.pop(str(payload["trial_id"]), None)
    return live.trial, scene


async def _caregiver_step(server: _Server, request: Request) -> dict[str, Any]:
    trial, scene = await _advance(server, request, CaregiverTrial)
    if not trial.done:
        return {"scene": scene}
    await run_in_threadpool(server.store.add_caregiver, trial.played())
    trial.close()
    compared = await run_in_threadpool(trial.compared)
    return {"scene": scene, "stored": True, "compared": compared}


async def _person_start(server: _Server, request: Request) -> dict[str, Any]:
    payload = await server.body(request)
    store = server.store
    session_id = payload.get("session_id")
    session = None
    if session_id is not None:
        if isinstance(session_id, bool) or not isinstance(session_id, int):
            raise Refused(400, f"session_id must be an integer, got {session_id!r}")
        session = await run_in_threadpool(store.session, session_id)
        if session is None:
            raise Refused(404, f"no person session {session_id}")
    if session is None or session["done"] >= session["n_trials"]:
        design_seed = secrets.randbelow(2**31)
        session_id = await run_in_threadpool(store.new_session, design_seed, server.settings.person_trials)
        session = {"design_seed": design_seed, "n_trials": server.settings.person_trials, "done": 0}
    assert isinstance(session_id, int)
    index = session["done"]
    if any(isinstance(v.trial, PersonTrial) and (v.trial.session_id, v.trial.trial_index) == (session_id, index)
           for v in server.live.values()):  # fmt: skip
        raise Refused(409, f"trial {index} of session {session_id} is being played in another tab")
    config, specs = person_design(session["design_seed"], session["n_trials"])
    spec = specs[index]
    trial = PersonTrial(session_id, index, config, spec, seed=session["design_seed"] * 1000 + index)
    trial_id, live = server.start(trial)
    return {
        "trial_id": trial_id, "token": live.token, "session_id": session_id, "trial_index": index,
        "n_trials": session["n_trials"], "requested_xi": spec.requested_xi,
        "requested": XI_NAMES[spec.requested_xi + 1], "scene": trial.scene(),
    }  # fmt: skip


async def _person_step(server: _Server, request: Request) -> dict[str, Any]:
    trial, scene = await _advance(server, request, PersonTrial)
    if not trial.done:
        return {"scene": scene}
    row = PersonTrialRow(trial.session_id, trial.trial_index, trial.spec.requested_xi, trial.judgment or 0,
                         trial.recording())  # fmt: skip
    await run_in_threadpool(server.store.add_person_trial, row)
    out: dict[str, Any] = {"scene": scene, "stored": True}
    session = await run_in_threadpool(server.store.session, trial.session_id)
    if session is not None and session["done"] >= session["n_trials"]:
        out["results"] = await run_in_threadpool(person_results, server.store, trial.session_id)
    return out


def person_results(store: Store, session_id: int) -> dict[str, Any]:
    """The paper's tables and balanced accuracy of a session's stored trials, read back as recordings."""
    rows = store.person_trials(session_id)
    if not rows:
        raise Refused(404, f"no stored trials in person session {session_id}")
    recordings = [parse_recording(r.recording, name=f"web{session_id:04d}_t{r.trial_index:02d}") for r in rows]
    summary = summarize_recordings(recordings, estimate_recordings(recordings, "kalman"))
    title = f"you as the person: session {session_id}, {len(rows)} trials, the paper's filter  |  paper: 4 real people"
    simulated = simulated_subjects()
    summary["simulated_balanced_accuracy"] = simulated
    summary["text"] = format_tables(summary, title, ours="you") + (
        f"\nsimulated subjects ({SIMULATED}): balanced accuracy {100 * simulated:5.1f}%"
    )
    summary["session_id"] = session_id
    return summary


SIMULATED = "python -m coop_gym.experiment.protocol --seed 0"
"""The simulated subjects a person session is shown beside: the protocol's default run."""


@functools.cache
def simulated_subjects() -> float:
    """Balanced accuracy of the paper's filter on the simulated subjects of :data:`SIMULATED` (computed once)."""
    return float(run_protocol(ProtocolConfig(), seed=0)["balanced_accuracy"])


async def _results(server: _Server, request: Request) -> dict[str, Any]:
    try:
        session_id = int(request.query_params.get("session_id", ""))
    except ValueError:
        raise Refused(400, "session_id must be an integer") from None
    return await run_in_threadpool(person_results, server.store, session_id)


async def _attach(server: _Server, request: Request) -> dict[str, Any]:
    payload = await server.body(request)
    if str(payload.get("trial_id")) not in server.live:
        raise Refused(404, f"no running trial {payload.get('trial_id')!r}")
    raise Refused(409, "this trial is being played in another tab; start your own")


def _static(name: str, media_type: str) -> Response:
    text = resources.files("agents.tools.serve").joinpath("static", name).read_text(encoding="utf-8")
    return Response(text, media_type=media_type)


def make_app(store: Store, settings: ServerSettings) -> Starlette:
    """The application: the page, its script and the API, answering only ``settings.hosts``."""
    server = _Server(store, settings)

    def bound(handler: Any) -> Any:
        async def call(request: Request) -> dict[str, Any]:
            return await handler(server, request)  # type: ignore[no-any-return]

        return _refusals(call)

    routes = [
        Route("/", lambda _r: HTMLResponse(_static("index.html", "text/html").body)),
        Route("/app.js", lambda _r: _static("app.js", "text/javascript")),
        Route("/api/caregiver/start", bound(_caregiver_start), methods=["POST"]),
        Route("/api/caregiver/step", bound(_caregiver_step), methods=["POST"]),
        Route("/api/person/start", bound(_person_start), methods=["POST"]),
        Route("/api/person/step", bound(_person_step), methods=["POST"]),
        Route("/api/person/results", bound(_results), methods=["GET"]),
        Route("/api/attach", bound(_attach), methods=["POST"]),
    ]
    middleware = [Middleware(TrustedHostMiddleware, allowed_hosts=list(settings.hosts))]
    app = Starlette(routes=routes, middleware=middleware)
    app.state.server = server
    return app
