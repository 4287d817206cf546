"""A live Foxglove connection: a team's messages served over the Foxglove WebSocket protocol.

:class:`LiveFoxglove` runs the Foxglove SDK's WebSocket server (``foxglove.start_server``) on
127.0.0.1 at a free port, with a ``foxglove.Context`` of its own (nothing else of the process
logs to it), and logs on it what a recording would hold of each of the team's messages: every
:class:`~dashboard.topics.Outgoing` item of :meth:`Topics.of <dashboard.topics.Topics.of>`, on
a channel per topic created when the topic first appears, stamped with the item's own instant.
It is a sink of the live feed (:class:`~dashboard.feed.LiveFeed`) subscribed to every key of
the team, as a recorder is. The team is named when the server starts (``heft dashboard``) or
once it is known (:meth:`LiveFoxglove.follow`: ``heft demo``, whose team is named when its run
starts, serves before that). The SDK keeps at most ``message_backlog_size`` (1024) messages
waiting for each client and drops the oldest beyond: a slow client cannot grow the process.

The server answers on loopback only. Foxglove connects to it through the dashboard's own
``/foxglove`` route (:func:`dashboard.relay.relay`), behind the page's token.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING

from dashboard.server import LOOPBACK
from dashboard.topics import Outgoing, Topics

if TYPE_CHECKING:
    from dashboard.feed import Batch


class LiveFoxglove:
    """Team ``team``'s messages on the Foxglove SDK's WebSocket server (None: the team is
    named later, by :meth:`follow`); :meth:`close` it."""

    def __init__(self, team: str | None = None):
        import foxglove

        self._foxglove = foxglove
        self.topics = None if team is None else Topics(team)
        self.context = foxglove.Context()
        self.server = foxglove.start_server(
            name="heft" if team is None else f"heft {team}",
            host=LOOPBACK,
            port=0,
            context=self.context,
        )
        self.channels: dict[str, foxglove.Channel] = {}
        self.messages = 0
        """Messages logged (to whichever client subscribed)."""
        self._lock = threading.Lock()
        self._closed = False

    def follow(self, team: str) -> None:
        """Serve team ``team``'s messages from now on; a ``ValueError`` if another team's are
        served (their channels are named after it)."""
        with self._lock:
            if self.topics is None:
                self.topics = Topics(team)
            elif self.topics.team != team:
                raise ValueError(f"Foxglove is served team {self.topics.team!r}, not {team!r}")

    @property
    def url(self) -> str:
        """The SDK server's own address (loopback)."""
        return f"ws://{LOOPBACK}:{self.server.port}/"

    def _channel(self, out: Outgoing):
        channel = self.channels.get(out.topic)
        if channel is None:
            spec = out.schema
            schema = self._foxglove.Schema(name=spec.name, encoding=spec.encoding, data=spec.data)
            channel = self._foxglove.Channel(
                out.topic,
                schema=schema,
                message_encoding=out.message_encoding,
                context=self.context,
            )
            self.channels[out.topic] = channel
        return channel

    def write(self, key: str, message: object, received_ns: int) -> None:
        """Log what ``message`` (decoded, received on ``key`` at ``received_ns``, ns since the
        epoch) puts on the topics (nothing before the team is named)."""
        with self._lock:
            if self._closed or self.topics is None:
                return
            for out in self.topics.of(key, message, received_ns):
                self._channel(out).log(out.data, log_time=out.log_time_ns)
                self.messages += 1

    def ingest_batch(self, batch: Batch) -> None:
        """A live feed's sink."""
        for key, message, _, received_ns in batch:
            self.write(key, message, received_ns)

    def close(self) -> None:
        """Stop the server (its clients are disconnected) and close the channels."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self.server.stop()
            for channel in self.channels.values():
                channel.close()
