"""A minimal Foxglove WebSocket client, as Foxglove itself speaks the protocol to a live source:
the server's ``serverInfo`` and ``advertise`` (channels: topic, encoding, schema), the
client's ``subscribe``, and the server's binary ``messageData`` (op 1, the subscription's id,
the message's log time in ns, its bytes).

A subscription the server answers with ``Unknown channel ID: N`` for a channel it advertised,
and has not taken back, is sent again (at most :data:`RESUBSCRIBE` times): the SDK's server
(0.30) sends a channel's ``advertise`` before it adds the channel to the client's own map, so a
client that subscribes at once, while the channel is new, can be refused (once on a fresh
clone: a channel created while the client was connected, never subscribed)."""

from __future__ import annotations

import base64
import json
import re
import struct
import time
from collections import Counter
from dataclasses import dataclass

from websockets.sync.client import ClientConnection, connect

SUBPROTOCOL = "foxglove.sdk.v1"
"""The subprotocol of the Foxglove WebSocket protocol the Foxglove SDK's server speaks."""
MESSAGE_DATA = 1
_MESSAGE_DATA = struct.Struct("<BIQ")
RESUBSCRIBE = 10
"""How many times a subscription refused for an advertised channel is sent again (each
channel)."""
RESUBSCRIBE_WAIT_S = 0.02
"""How long the first subscription sent again waits, and each next one twice as long (at
most 1 s): the server refuses it for as long as its thread that advertised the channel is
descheduled."""
UNKNOWN_CHANNEL = re.compile(r"Unknown channel ID: (\d+)")
WAIT_S = 20.0
"""The longest a test waits for what it expects (it never measures time)."""


@dataclass(frozen=True)
class Advertised:
    """A channel as the server advertises it."""

    id: int
    topic: str
    encoding: str
    schema_name: str
    schema_encoding: str
    schema: bytes
    """The schema's data (a protobuf one arrives in base64: decoded here)."""


@dataclass(frozen=True)
class Received:
    """A message as the client receives it."""

    topic: str
    log_time_ns: int
    data: bytes


class FoxgloveClient:
    """Connected to ``url``; :meth:`subscribe` to channels, :meth:`receive` their messages."""

    def __init__(self, url: str, subprotocols=(SUBPROTOCOL,), **options):
        offered = list(subprotocols) or None
        self._open = connect(
            url, subprotocols=offered, proxy=None, max_size=None, max_queue=None, **options
        )
        self.ws: ClientConnection = self._open.__enter__()
        self.channels: dict[int, Advertised] = {}
        self.server_info: dict = json.loads(self.ws.recv(timeout=WAIT_S))
        assert self.server_info["op"] == "serverInfo", self.server_info
        self._subscriptions: dict[int, int] = {}
        """Subscription id → channel id."""
        self.resubscribed: Counter[int] = Counter()
        """Channel id → subscriptions to it sent again (see the module docstring)."""

    def _handle(self, frame: str | bytes) -> Received | None:
        if isinstance(frame, bytes):
            op, subscription, log_time = _MESSAGE_DATA.unpack_from(frame)
            assert op == MESSAGE_DATA, op
            channel = self.channels[self._subscriptions[subscription]]
            return Received(channel.topic, log_time, frame[_MESSAGE_DATA.size :])
        message = json.loads(frame)
        if message["op"] == "advertise":
            for c in message["channels"]:
                schema = c["schema"]
                data = base64.b64decode(schema) if c["schemaEncoding"] == "protobuf" else schema
                self.channels[c["id"]] = Advertised(
                    c["id"],
                    c["topic"],
                    c["encoding"],
                    c["schemaName"],
                    c["schemaEncoding"],
                    data if isinstance(data, bytes) else data.encode(),
                )
        elif message["op"] == "unadvertise":
            for channel in message["channelIds"]:
                self.channels.pop(channel, None)
        elif message["op"] == "status" and (unknown := UNKNOWN_CHANNEL.search(message["message"])):
            self._subscribe_again(int(unknown.group(1)))
        return None

    def _subscribe_again(self, channel: int) -> None:
        """The server refused a subscription to ``channel``: sent again if it advertised it."""
        mine = [s for s, c in self._subscriptions.items() if c == channel]
        assert mine and channel in self.channels, f"channel {channel} is not advertised"
        refused = self.resubscribed[channel]
        assert refused < RESUBSCRIBE, f"channel {channel} refused {RESUBSCRIBE + 1} times"
        self.resubscribed[channel] += 1
        time.sleep(min(RESUBSCRIBE_WAIT_S * 2**refused, 1.0))  # the server's thread, descheduled
        subscriptions = [{"id": mine[0], "channelId": channel}]
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))

    def advertised(self, topics: set[str]) -> dict[str, Advertised]:
        """Wait until every topic of ``topics`` is advertised; every advertised channel by
        topic."""
        deadline = time.monotonic() + WAIT_S
        while not topics <= {c.topic for c in self.channels.values()}:
            assert self._handle(self.ws.recv(timeout=deadline - time.monotonic())) is None
        return {c.topic: c for c in self.channels.values()}

    def subscribe(self, channels) -> None:
        """Subscribe to each of ``channels`` (:class:`Advertised`)."""
        subscriptions = []
        for channel in channels:
            subscription = len(self._subscriptions) + 1
            self._subscriptions[subscription] = channel.id
            subscriptions.append({"id": subscription, "channelId": channel.id})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))

    def receive(self, count: int) -> list[Received]:
        """The next ``count`` messages of the subscribed channels."""
        deadline = time.monotonic() + WAIT_S
        out: list[Received] = []
        while len(out) < count:
            received = self._handle(self.ws.recv(timeout=deadline - time.monotonic()))
            if received is not None:
                out.append(received)
        return out

    def close(self) -> None:
        self._open.__exit__(None, None, None)

    def __enter__(self) -> FoxgloveClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def wait_until(condition, what: str) -> None:
    """Wait (at most :data:`WAIT_S`) until ``condition()`` holds."""
    deadline = time.monotonic() + WAIT_S
    while not condition():
        assert time.monotonic() < deadline, f"still not {what} after {WAIT_S:g} s"
        time.sleep(0.01)
