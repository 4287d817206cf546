"""What a recording or a live Foxglove connection carries for each of a team's messages.

A recorder (:mod:`dashboard.recorder`) and a live Foxglove server both turn every decoded
message of a team into the same :class:`Outgoing` items, through one :class:`Topics`:

- the message itself, on its Zenoh key as topic, as a JSON record under its JSON schema
  (:mod:`dashboard.channels`);
- what Foxglove draws of it, in Foxglove's own schemas (the scene, the frames, the log lines);

each stamped with its own instant (``log_time_ns``, :mod:`dashboard.timeline`), not with the
moment it arrived.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass

from dashboard.channels import json_schema, record_bytes
from dashboard.scene import Scene
from dashboard.timeline import Timeline


@dataclass(frozen=True, slots=True)
class SchemaSpec:
    """A channel's schema: its name, encoding (``jsonschema`` or ``protobuf``) and data."""

    name: str
    encoding: str
    data: bytes


@dataclass(frozen=True, slots=True)
class Outgoing:
    """One message on one topic: its schema, message encoding (``json`` or ``protobuf``),
    bytes, and instant (ns)."""

    topic: str
    schema: SchemaSpec
    message_encoding: str
    data: bytes
    log_time_ns: int


LOG = logging.getLogger("heft.dashboard")
HOLD_S = 2.0
"""The longest a message without an instant waits for the team's clock to be known (wall-clock
seconds, counted from the first one held); :data:`HOLD_LIMIT` messages at most."""
HOLD_LIMIT = 1000


class Topics:
    """One team's messages as :class:`Outgoing` items (:meth:`of`), in the order received."""

    def __init__(self, team: str):
        self.team = team
        self.scene = Scene(team)
        self.timeline = Timeline()
        self.failures = 0
        """Messages whose drawing failed (recorded all the same)."""
        self._held: list[tuple[str, object, int]] = []
        """What arrived before the team's clock was known: ``(key, message, arrival)``."""
        self._schemas: dict[type, SchemaSpec] = {}

    def schema(self, kind: type) -> SchemaSpec:
        """The JSON schema of protocol message class ``kind``."""
        spec = self._schemas.get(kind)
        if spec is None:
            data = json.dumps(json_schema(kind)).encode()
            spec = self._schemas[kind] = SchemaSpec(f"heft.{kind.__name__}", "jsonschema", data)
        return spec

    def drawing_schema(self, kind: type) -> SchemaSpec:
        """The schema of Foxglove SDK message class ``kind`` (``foxglove.SceneUpdate``…)."""
        spec = self._schemas.get(kind)
        if spec is None:
            schema = kind.get_schema()
            spec = SchemaSpec(schema.name, schema.encoding, bytes(schema.data))
            self._schemas[kind] = spec
        return spec

    def of(self, key: str, message: object, received_ns: int) -> list[Outgoing]:
        """What ``message``, received on ``key`` at ``received_ns`` (ns since the epoch),
        puts on the topics: its record, then what Foxglove draws of it
        (:class:`~dashboard.scene.Scene`), all at the message's own instant
        (:class:`~dashboard.timeline.Timeline`). A message that has no instant before the
        team's clock is known is held (none is returned for it) and comes out with the
        message that makes it known, at its instant, or after :data:`HOLD_S` at its arrival."""
        log_time_ns = self.timeline.log_time_ns(message, received_ns)
        if log_time_ns is None:
            self._held.append((key, message, received_ns))
            first = self._held[0][2]
            if len(self._held) < HOLD_LIMIT and received_ns - first < HOLD_S * 1e9:
                return []
            self.timeline.on_wall()
            return self.flush()
        return [*self.flush(), *self._items(key, message, log_time_ns)]

    def flush(self) -> list[Outgoing]:
        """What is held, stamped: at the team's first instant if it is known, else at each
        message's arrival (a recorder closing with nothing else heard)."""
        if not self._held:
            return []
        held, self._held = self._held, []
        if self.timeline.origin_ns is None:
            self.timeline.on_wall()
        out: list[Outgoing] = []
        for key, message, received_ns in held:
            out += self._items(key, message, self.timeline.log_time_ns(message, received_ns))
        return out

    def _items(self, key: str, message: object, log_time_ns: int) -> list[Outgoing]:
        data = record_bytes(message)
        record = Outgoing(key, self.schema(type(message)), "json", data, log_time_ns)
        if not self.timeline.in_window(message):
            return [record]  # recorded as it came; Foxglove's panels draw nothing of it
        try:
            drawn = self._drawn(message, log_time_ns)
        except Exception:  # noqa: BLE001 - what is drawn of one message never costs its record
            self.failures += 1
            if self.failures <= 10:
                LOG.exception("%s: what Foxglove draws of a %s failed", key, type(message).__name__)
            return [record]
        return [record, *drawn]

    def _drawn(self, message: object, log_time_ns: int) -> list[Outgoing]:
        return [
            Outgoing(topic, self.drawing_schema(type(m)), "protobuf", m.encode(), log_time_ns)
            for topic, m in self.scene.of(message, log_time_ns)
        ]
