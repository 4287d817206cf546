"""The dashboard's web app (FastAPI): the page, its JSON API and its WebSocket.

========================== ==============================================================
``GET /``                   the page (``dashboard/static/``)
``GET /vendor/uplot.js``    the charting library (and ``uplot.css``), installed from the npm
                            registry into ``dashboard/node_modules`` by ``make`` (no CDN:
                            robots run offline)
``GET /api/snapshot``       the latest state: per robot phase, m̂, Ĵ, ``τ̂_c``, ``μ̂``,
                            ``contact_to_com``, ``relative_positions`` and their
                            uncertainties; each link's health; the truth if known
``GET /api/summary``        the final table of estimates against truth (404 before)
``GET /api/series``         every chart's kept points
``POST /api/replay``        steer a replay: ``{"action": "play"|"pause"|"step"|"restart",
                            "speed": X}``
``WS /ws``                  a ``hello`` (the estimated scalars, charts and scene), then
                            ``frame``\\ s at ``frame_hz``: the charts' new points (with
                            their 95 % half-widths) and the scene
``WS /foxglove``            with ``AppSettings.foxglove``: the Foxglove WebSocket protocol,
                            relayed to the Foxglove SDK's server on loopback
                            (:mod:`dashboard.foxglove_live`, :mod:`dashboard.relay`)
========================== ==============================================================

Frames are built once per period for every page, only when something changed (or every
second, for ages and alarms), and each page has a short queue of them: a page that cannot
keep up loses frames and is sent a fresh ``hello``, so the server's memory does not grow with a
slow browser.

Safe by default: the server listens on 127.0.0.1. When it listens elsewhere a token is
required on every request, HTTP and WebSocket alike: the ``Authorization: Bearer TOKEN``
header, the ``X-Heft-Token`` header, or the ``token`` query parameter (the page, opened with
``?token=...``, gets a same-site cookie that carries it for its own requests). A request
without it gets 401 with the reason.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import hmac
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import orjson
from fastapi import FastAPI, HTTPException, Request, WebSocket, WebSocketDisconnect
from fastapi.responses import FileResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, Field

from dashboard.hub import REPLAY_STEP_S, Hub
from dashboard.relay import relay
from dashboard.replay import RecordingError

STATIC = Path(__file__).with_name("static")
TOKEN_COOKIE = "heft_token"
TOKEN_HEADER = "x-heft-token"
CLIENT_QUEUE = 8
"""Frames waiting for one page; beyond, it is resynchronised with a fresh hello."""
IDLE_FRAME_S = 1.0
"""A frame at least this often even when nothing arrived (link ages, alarms)."""
LOG = logging.getLogger("heft.dashboard")


@dataclass(frozen=True)
class AppSettings:
    """How the app serves: frames per second, the token (None: no token needed) and the
    loopback address of a Foxglove WebSocket server to relay on ``/foxglove`` (None: no such
    route)."""

    frame_hz: float = 20.0
    token: str | None = None
    foxglove: str | None = None


class ReplayCommand(BaseModel):
    """``POST /api/replay``."""

    action: Literal["play", "pause", "step", "restart"]
    speed: float | None = Field(default=None, ge=0, le=1000)
    """Recorded seconds per wall-clock second (0: as fast as possible)."""
    seconds: float = Field(default=REPLAY_STEP_S, gt=0, le=3600)
    """With ``step``: how much of the recording to let through."""


def to_json(value) -> str:
    """``value`` as compact JSON text for the pages (orjson: a frame is encoded 20 times a
    second; a number that is not finite becomes ``null``)."""
    return orjson.dumps(value, option=orjson.OPT_NON_STR_KEYS).decode()


UPLOT = Path(__file__).with_name("node_modules") / "uplot" / "dist"
"""Where ``npm ci --prefix dashboard`` (run by ``make``) puts uPlot's bundle."""
NPM_HINT = "run make, or npm ci --prefix dashboard"


@functools.cache
def vendor_files() -> dict[str, tuple[Path, str, str]]:
    """The charting library's files the page loads from ``/vendor/``: each one's path, media
    type, and how to install it."""
    return {
        "uplot.js": (UPLOT / "uPlot.iife.min.js", "text/javascript", NPM_HINT),
        "uplot.css": (UPLOT / "uPlot.min.css", "text/css", NPM_HINT),
    }


def missing_vendor() -> list[str]:
    """Those of :func:`vendor_files` that are not installed, each with how to install it."""
    return [f"{path} ({hint})" for path, _, hint in vendor_files().values() if not path.is_file()]


class Broadcaster:
    """Builds a frame per period and queues it for every connected page."""

    def __init__(self, hub: Hub, settings: AppSettings):
        self.hub = hub
        self.settings = settings
        self.clients: set[asyncio.Queue] = set()
        self.failures = 0
        self._seen: tuple[int, int] | None = None
        self._sent_at = 0.0

    async def run(self) -> None:
        period = 1.0 / self.settings.frame_hz
        while True:
            started = time.monotonic()
            if self.clients:
                version = self.hub.version()
                if version != self._seen or started - self._sent_at >= IDLE_FRAME_S:
                    self._seen = version
                    self._sent_at = started
                    try:
                        self.publish(to_json(self.hub.frame()))
                    except Exception:  # noqa: BLE001 - the pages must outlive one bad frame
                        self.failures += 1
                        if self.failures <= 10:
                            LOG.exception("dashboard: a frame could not be built")
            await asyncio.sleep(max(0.0, period - (time.monotonic() - started)))

    def publish(self, text: str) -> None:
        for queue in list(self.clients):
            if queue.full():  # a page that cannot keep up: start it over
                while not queue.empty():
                    queue.get_nowait()
                queue.put_nowait(None)
            else:
                queue.put_nowait(text)


def _token_of(headers, query, cookies) -> str | None:
    auth = headers.get("authorization", "")
    if auth.lower().startswith("bearer "):
        return auth[7:].strip()
    return headers.get(TOKEN_HEADER) or query.get("token") or cookies.get(TOKEN_COOKIE)


def _token_ok(expected: str | None, given: str | None) -> bool:
    if expected is None:
        return True
    return given is not None and hmac.compare_digest(given.encode(), expected.encode())


def create_app(hub: Hub, settings: AppSettings | None = None) -> FastAPI:
    """The dashboard's app over ``hub``."""
    settings = settings or AppSettings()
    broadcaster = Broadcaster(hub, settings)

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI):
        task = asyncio.create_task(broadcaster.run())
        try:
            yield
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    app = FastAPI(
        title="heft dashboard",
        lifespan=lifespan,
        docs_url=None,
        redoc_url=None,
        openapi_url=None,
    )
    app.state.hub = hub
    app.state.broadcaster = broadcaster

    @app.middleware("http")
    async def require_token(request: Request, call_next):
        given = _token_of(request.headers, request.query_params, request.cookies)
        if not _token_ok(settings.token, given):
            reason = "a token is required (Authorization: Bearer, X-Heft-Token or ?token=)"
            if given is not None:
                reason = "wrong token"
            return JSONResponse({"detail": reason}, status_code=401)
        response = await call_next(request)
        if settings.token is not None and request.query_params.get("token"):
            response.set_cookie(
                TOKEN_COOKIE, settings.token, httponly=True, samesite="strict", path="/"
            )
        return response

    @app.get("/", include_in_schema=False)
    async def index() -> FileResponse:
        return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-cache"})

    @app.get("/vendor/{name}", include_in_schema=False)
    async def vendor(name: str) -> FileResponse:
        if name not in vendor_files():
            raise HTTPException(404, f"no such file: /vendor/{name}")
        path, media_type, hint = vendor_files()[name]
        if not path.is_file():
            raise HTTPException(503, f"{path} is not installed: {hint}")
        return FileResponse(
            path, media_type=media_type, headers={"Cache-Control": "public, max-age=86400"}
        )

    app.mount("/static", StaticFiles(directory=STATIC), name="static")

    @app.get("/api/snapshot")
    async def snapshot() -> dict:
        return hub.snapshot()

    @app.get("/api/summary")
    async def summary() -> dict:
        table = hub.summary()
        if table is None:
            raise HTTPException(404, "no final table yet: the team is not done")
        return table

    @app.get("/api/series")
    async def series() -> dict:
        return hub.hello()["series"]

    @app.post("/api/replay")
    async def replay(command: ReplayCommand) -> dict:
        if command.action == "restart":
            if hub.recording is None:
                raise HTTPException(409, "no recording to replay")
            speed = 1.0 if command.speed is None else command.speed
            try:
                hub.replay(hub.recording, speed=speed)
            except (RecordingError, ValueError) as err:
                raise HTTPException(409, str(err)) from None
            return hub.source()
        replayer = hub.replayer
        if replayer is None:
            raise HTTPException(409, "not replaying: restart a replay first")
        try:
            if command.action == "play":
                replayer.play(command.speed)
            elif command.action == "pause":
                replayer.pause()
            else:
                replayer.step(command.seconds)
        except ValueError as err:
            raise HTTPException(400, str(err)) from None
        return hub.source()

    async def refused(websocket: WebSocket) -> bool:
        """Close ``websocket`` (before accepting it) unless it carries the token."""
        given = _token_of(websocket.headers, websocket.query_params, websocket.cookies)
        if _token_ok(settings.token, given):
            return False
        await websocket.close(code=1008, reason="a valid token is required")
        return True

    @app.websocket("/ws")
    async def stream(websocket: WebSocket) -> None:
        if await refused(websocket):
            return
        await websocket.accept()
        queue: asyncio.Queue = asyncio.Queue(maxsize=CLIENT_QUEUE)
        broadcaster.clients.add(queue)
        try:
            await websocket.send_text(to_json(hub.hello()))
            while True:
                text = await queue.get()
                if text is None:  # it fell behind: start it over
                    text = to_json(hub.hello())
                await websocket.send_text(text)
        except (WebSocketDisconnect, RuntimeError, OSError):  # the page went away
            pass
        finally:
            broadcaster.clients.discard(queue)

    if settings.foxglove is not None:

        @app.websocket("/foxglove")
        async def foxglove(websocket: WebSocket) -> None:
            if not await refused(websocket):
                await relay(websocket, settings.foxglove)

    @app.exception_handler(404)
    async def not_found(request: Request, exc) -> Response:
        detail = getattr(exc, "detail", None) or f"no such page: {request.url.path}"
        return JSONResponse({"detail": detail}, status_code=404)

    return app
