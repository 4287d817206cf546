"""Recording a team's traffic to MCAP (``heft record``, and ``heft run``/``heft demo``).

One MCAP channel per Zenoh key (the topic is the key, e.g. ``heft/paper/robot/2/force``), each
message a JSON object with the fields of its protocol message (record format 2: an optional
field absent while None) under a JSON schema named ``heft.<Class>`` (:mod:`dashboard.channels`),
so that Foxglove and PlotJuggler show named fields; beside them, what Foxglove draws of the
team in its own schemas (:class:`~dashboard.topics.Topics`). Every robot's measurements and
commands are recorded, not only the estimates: a centralized estimator can be run on a
recording afterwards, and the plant's load geometry is recorded as the rest is. A metadata
record names the team (``heft.team``).

Each message is stamped twice: ``log_time`` is its own instant on the team's clock (the
plant's simulated time, :mod:`dashboard.timeline`), ``publish_time`` the wall clock when the
recorder wrote it (what arrived before the team's clock was known waits for it).

A recording stays readable if its process is killed: messages are written in chunks closed
at least every :data:`FLUSH_EVERY_S` (and whenever a chunk reaches
:data:`~dashboard.recording_file.CHUNK_BYTES`), and handed to the kernel at once, so a ``kill
-9`` loses at most the last fraction of a second; :meth:`Recorder.close` (on SIGINT, SIGTERM,
SIGHUP, or the end of a run) writes the summary and index that make the file seekable.
:mod:`dashboard.replay` reads either kind. While it writes, a recorder holds an exclusive lock
on its file (:mod:`dashboard.recording_file`), which the kernel drops when the process dies: a
recorder that starts repairs the cut files that killed recorders left in its folder
(:func:`dashboard.repair.repair_leftovers`), and ``heft record --repair FILE`` any other.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

from dashboard.channels import MESSAGE_KINDS, RECORD_FORMAT
from dashboard.recording_file import LIBRARY, TEAM_METADATA, mcap_writer, open_held
from dashboard.repair import repair_leftovers
from dashboard.topics import Outgoing, Topics

FLUSH_EVERY_S = 0.5
"""The longest a recorded message waits in memory before it is in the file."""


class Recorder:
    """Writes one team's messages to an MCAP file; thread-safe. Use as a context manager, or
    :meth:`close` it."""

    def __init__(
        self,
        path: str | Path,
        team: str,
        flush_every_s: float = FLUSH_EVERY_S,
    ):
        self.path = Path(path)
        self.team = team
        self.flush_every_s = flush_every_s
        self.messages = 0
        self._lock = threading.Lock()
        repair_leftovers(self.path.parent, skip=self.path)
        self._stream = open_held(self.path)
        self._writer = mcap_writer(self._stream)
        self._writer.start(profile="", library=LIBRARY)
        self.topics = Topics(team)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._flushed_at = time.monotonic()
        self._closed = False
        self._writer.add_metadata(TEAM_METADATA, {"team": team, "format": RECORD_FORMAT})
        self._stream.flush()

    def _channel(self, out: Outgoing) -> int:
        channel = self._channels.get(out.topic)
        if channel is None:
            schema = self._schemas.get(out.schema.name)
            if schema is None:
                spec = out.schema
                schema = self._writer.register_schema(spec.name, spec.encoding, spec.data)
                self._schemas[spec.name] = schema
            channel = self._writer.register_channel(out.topic, out.message_encoding, schema)
            self._channels[out.topic] = channel
        return channel

    def write(self, key: str, message: object, received_ns: int | None = None) -> None:
        """Record ``message`` (a decoded protocol message) as received on ``key`` at
        ``received_ns`` (ns since the epoch; now by default), with what Foxglove draws of it
        (:class:`~dashboard.topics.Topics`)."""
        if type(message) not in MESSAGE_KINDS:
            raise TypeError(f"not a protocol message: {type(message).__name__}")
        received = time.time_ns() if received_ns is None else received_ns
        with self._lock:
            if self._closed:
                return
            self._add(self.topics.of(key, message, received), received)
            if time.monotonic() - self._flushed_at >= self.flush_every_s:
                self._flush()

    def _add(self, items: list[Outgoing], received_ns: int) -> None:
        for out in items:
            self._writer.add_message(
                self._channel(out),
                log_time=out.log_time_ns,
                data=out.data,
                publish_time=received_ns,
            )
            self.messages += 1

    def flush(self) -> None:
        """Close the current chunk and hand the file's bytes to the kernel."""
        with self._lock:
            if not self._closed:
                self._flush()

    def _flush(self) -> None:
        # The writer closes a chunk by size only; closing it by time as well (Writer.flush: the
        # chunk in progress, then the stream) is what keeps a killed recorder's file readable up
        # to the last flush.
        self._writer.flush()
        self._flushed_at = time.monotonic()

    def close(self) -> None:
        """Write the summary and index, and close the file (idempotent)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            try:
                self._add(self.topics.flush(), time.time_ns())  # held for the team's clock
                self._writer.finish()
            finally:
                self._stream.close()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
