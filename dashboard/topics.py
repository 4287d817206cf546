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
from dataclasses import dataclass

from dashboard.channels import json_schema, record_bytes
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


class Topics:
    """One team's messages as :class:`Outgoing` items (:meth:`of`), in the order received."""

    def __init__(self, team: str):
        self.team = team
        self.timeline = Timeline()
        self._schemas: dict[type, SchemaSpec] = {}

    def schema(self, kind: type) -> SchemaSpec:
        """The JSON schema of protocol message class ``kind``."""
        spec = self._schemas.get(kind)
        if spec is None:
            data = json.dumps(json_schema(kind)).encode()
            spec = self._schemas[kind] = SchemaSpec(f"heft.{kind.__name__}", "jsonschema", data)
        return spec

    def of(self, key: str, message: object, received_ns: int) -> list[Outgoing]:
        """What ``message``, received on ``key`` at ``received_ns`` (ns since the epoch),
        puts on the topics."""
        log_time_ns = self.timeline.log_time_ns(message, received_ns)
        data = record_bytes(message)
        return [Outgoing(key, self.schema(type(message)), "json", data, log_time_ns)]
