"""The dashboard's two services as parts of a process: :class:`Display` (the page, served on a
thread, fed live or by a replay) and :class:`TeamRecording` (a recorder with its own live
subscription). ``heft dashboard`` and ``heft record`` each run one; ``heft demo`` holds both
beside its run (:mod:`dashboard.companion`)."""

from __future__ import annotations

import logging
from pathlib import Path

from agent.platform.zenoh_session import ZenohSettings

LOG = logging.getLogger("heft.dashboard")
DEFAULT_PORT = 8765
"""The dashboard's port unless told otherwise."""


class Display:
    """The dashboard as a part of a process: a hub, the app served on a thread, and the
    live feed once :meth:`watch` is called. ``heft dashboard`` is one; ``heft demo`` can
    hold one beside its run."""

    def __init__(self, hub, server, url: str):
        self.hub = hub
        self.server = server
        self.url = url
        self.feed = None

    @classmethod
    def open(
        cls,
        team: str | None,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        token: str | None = None,
        recording: Path | None = None,
    ) -> Display:
        """Serve the page on ``host:port`` (:class:`~dashboard.server.ServeError` if taken)."""
        from dashboard.app import AppSettings, create_app, missing_vendor
        from dashboard.hub import Hub
        from dashboard.server import Server

        missing = missing_vendor()
        if missing:
            LOG.warning(
                "dashboard: the page's charts will not draw: not installed: %s", "; ".join(missing)
            )
        hub = Hub(team or "", recording=recording)
        server = Server(create_app(hub, AppSettings(token=token)), host, port).start()
        url = server.url if token is None else f"{server.url}?token={token}"
        return cls(hub, server, url)

    def watch(self, settings: ZenohSettings, team: str | None = None) -> None:
        """Follow team ``team`` (the hub's, by default) live through Zenoh."""
        from agent.platform.protocol import Keys
        from dashboard.feed import LiveFeed

        keys = Keys(team or self.hub.team)
        self.hub.team = keys.team
        self.hub.state.team = keys.team
        self.feed = LiveFeed(
            settings, keys, [self.hub.ingest_batch], liveliness=self.hub.liveliness
        ).start()

    def close(self) -> None:
        if self.feed is not None:
            self.feed.close()
            self.feed = None
        self.hub.stop_replay()
        self.server.stop()


class TeamRecording:
    """A recorder fed by its own live subscription to every key of a team."""

    def __init__(self, recorder, feed, session):
        self.recorder = recorder
        self.feed = feed
        self.session = session

    @classmethod
    def open(
        cls,
        path: Path,
        team: str,
        settings: ZenohSettings,
        display: Display | None = None,
    ) -> TeamRecording:
        """Start recording; :class:`~agent.platform.zenoh_session.SessionError` if Zenoh cannot (the
        file is created only once the session is open). With ``display``, the same decoded
        messages feed its page too (one subscription, each message decoded once)."""
        from agent.platform.protocol import Keys
        from agent.platform.zenoh_session import open_session
        from dashboard.feed import LiveFeed, everything
        from dashboard.recorder import Recorder

        keys = Keys(team)
        session = open_session(settings)
        try:
            recorder = Recorder(path, team)
        except BaseException:
            session.close()
            raise

        def write(batch) -> None:
            for key, message, _, stamp in batch:
                recorder.write(key, message, stamp)

        sinks, liveliness = [write], None
        if display is not None:
            display.hub.team = display.hub.state.team = keys.team
            sinks.append(display.hub.ingest_batch)
            liveliness = display.hub.liveliness
        feed = LiveFeed(settings, keys, sinks, everything(keys), liveliness, session=session)
        try:
            feed.start()
        except BaseException:
            feed.close()
            recorder.close()
            session.close()
            raise
        return cls(recorder, feed, session)

    def close(self) -> None:
        """Stop listening, then write the file's summary (idempotent)."""
        try:
            self.feed.close()
        finally:
            try:
                self.recorder.close()
            finally:
                if self.session is not None:
                    self.session.close()
                    self.session = None
