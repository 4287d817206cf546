"""The dashboard's two services as parts of a process: :class:`Display` (the page, served on a
thread, fed live or by a replay, and, if asked, the team live to Foxglove) and
:class:`TeamRecording` (a recorder with its own live subscription). ``heft dashboard`` and
``heft record`` each run one; ``heft demo`` holds both beside its run
(:mod:`dashboard.companion`)."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING

from agent.platform.zenoh_session import ZenohSettings

if TYPE_CHECKING:
    from dashboard.feed import Sink

LOG = logging.getLogger("heft.dashboard")
DEFAULT_PORT = 8765
"""The dashboard's port unless told otherwise."""


class Display:
    """The dashboard as a part of a process: a hub, the app served on a thread, and the
    live feed once :meth:`watch` is called. ``heft dashboard`` is one; ``heft demo`` can
    hold one beside its run. With :attr:`foxglove` (a
    :class:`~dashboard.foxglove_live.LiveFoxglove`), the feed takes every key of the team and
    Foxglove connects to :attr:`foxglove_url`. A display opened before its team is known
    (``heft demo``'s) is given it by :meth:`watch`, or by the recording that feeds it
    (:class:`TeamRecording`)."""

    def __init__(self, hub, server, url: str, foxglove=None, foxglove_url: str | None = None):
        self.hub = hub
        self.server = server
        self.url = url
        self.foxglove = foxglove
        self.foxglove_url = foxglove_url
        self.feed = None

    @classmethod
    def open(
        cls,
        team: str | None,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        token: str | None = None,
        recording: Path | None = None,
        foxglove: bool = False,
    ) -> Display:
        """Serve the page on ``host:port`` (:class:`~dashboard.server.ServeError` if taken);
        with ``foxglove``, team ``team`` (or the one watched later) live to Foxglove on
        ``/foxglove`` too."""
        from dashboard.app import AppSettings, create_app, missing_vendor
        from dashboard.hub import Hub
        from dashboard.server import Server

        missing = missing_vendor()
        if missing:
            LOG.warning(
                "dashboard: the page's charts will not draw: not installed: %s", "; ".join(missing)
            )
        live = None
        if foxglove:
            from dashboard.foxglove_live import LiveFoxglove

            live = LiveFoxglove(team or None)
        settings = AppSettings(token=token, foxglove=None if live is None else live.url)
        hub = Hub(team or "", recording=recording)
        try:
            server = Server(create_app(hub, settings), host, port).start()
        except BaseException:
            if live is not None:
                live.close()
            raise
        query = "" if token is None else f"?token={token}"
        ws_url = None if live is None else f"ws{server.url.removeprefix('http')}foxglove{query}"
        return cls(hub, server, server.url + query, live, ws_url)

    def watch(self, settings: ZenohSettings, team: str | None = None) -> None:
        """Follow team ``team`` (the hub's, by default) live through Zenoh."""
        from agent.platform.protocol import Keys
        from dashboard.feed import LiveFeed, everything

        keys = Keys(team or self.hub.team)
        subscriptions = None if self.foxglove is None else everything(keys)
        self.feed = LiveFeed(
            settings, keys, self.follow(keys.team), subscriptions, liveliness=self.hub.liveliness
        ).start()

    def follow(self, team: str) -> list[Sink]:
        """Show team ``team`` (on the page, and to Foxglove if served): the sinks of a feed of
        its messages (a feed for Foxglove takes every key of the team)."""
        self.hub.team = self.hub.state.team = team
        sinks = [self.hub.ingest_batch]
        if self.foxglove is not None:
            self.foxglove.follow(team)
            sinks.append(self.foxglove.ingest_batch)
        return sinks

    def close(self) -> None:
        if self.feed is not None:
            self.feed.close()
            self.feed = None
        self.hub.stop_replay()
        if self.foxglove is not None:
            self.foxglove.close()
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
        messages feed its page, and Foxglove if it serves it, too (one subscription, each
        message decoded once)."""
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
            sinks += display.follow(keys.team)
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
