"""Reading MCAP recordings back (:class:`Recording`) and playing them into the dashboard
(:class:`Replayer`: at 1×, faster, as fast as possible, or stepped).

A recording is read front to back as a stream, a chunk at a time, so that memory does not grow
with its length, and a file cut short (its recorder killed) is read up to the cut. Every
message goes through the protocol's checks again (:func:`dashboard.channels.from_record`):
what fails is counted and dropped, as on the network. What Foxglove draws of them (the channels
of ``foxglove.*`` schemas: :mod:`dashboard.scene`) is derived from them and skipped.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from collections.abc import Callable, Collection, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from agent.platform.protocol import DecodeError, Keys
from dashboard.channels import RECORD_FORMATS, from_record, kind_of
from dashboard.recording_file import MAGIC, TEAM_METADATA

RECORD_LIMIT = 64 * 2**20
"""The largest MCAP record read (bytes): a corrupt length cannot make the reader allocate
more."""


class RecordingError(ValueError):
    """A file that is not a team's recording (``str()`` is one line naming it)."""


@dataclass(frozen=True)
class Recorded:
    """One recorded message: when it was received (``time_ns``, the MCAP ``publish_time``: ns
    since the epoch), on which key, and its own instant (``log_time_ns``: on the team's clock,
    :mod:`dashboard.timeline`; a recording made before that clock has the arrival there too)."""

    time_ns: int
    key: str
    message: object
    log_time_ns: int


class Records:
    """An MCAP stream's records, front to back (iterate it once), up to its end or to where it
    was cut: :attr:`cut` says where and why reading stopped before the end (None if it did
    not). With ``validate_crcs``, a chunk whose data does not match its CRC is such a cut."""

    def __init__(self, stream: BinaryIO, validate_crcs: bool = False):
        self.stream = stream
        self.validate_crcs = validate_crcs
        self.cut: str | None = None

    def __iter__(self) -> Iterator[object]:
        stream = self.stream
        reader = StreamReader(
            stream, record_size_limit=RECORD_LIMIT, validate_crcs=self.validate_crcs
        )
        records = reader.records
        while True:
            try:
                record = next(records)
            except StopIteration:
                return
            except Exception as err:  # noqa: BLE001 - truncated: struct, mcap, zstd errors
                self.cut = f"cut at byte {stream.tell()} ({type(err).__name__})"
                return
            yield record


class Recording:
    """A recording, read once, front to back (iterate :meth:`messages`).

    :attr:`team` and :attr:`record_format` (:data:`~dashboard.channels.RECORD_FORMATS`: ``1``
    when the metadata names none) are known once the first message has been read (the metadata
    comes first); :attr:`cut` says why reading stopped before the file's end (None if
    it did not), :attr:`rejected` counts the messages dropped, by what and why."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.team: str | None = None
        self.record_format = "1"
        self.cut: str | None = None
        self.read_count = 0
        self.rejected: Counter[tuple[str, str]] = Counter()
        try:
            with open(self.path, "rb") as stream:
                head = stream.read(8)
        except OSError as err:
            raise RecordingError(f"{self.path}: cannot read ({err.strerror or err})") from None
        if head != MAGIC:
            raise RecordingError(f"{self.path}: not an MCAP file")

    def header(self) -> str:
        """The recording's team, read from its first records."""
        for record in self._records():
            if isinstance(record, Metadata):
                self._metadata(record)
            elif isinstance(record, Message):
                break
        if self.team is None:
            raise RecordingError(f"{self.path}: no {TEAM_METADATA} metadata (not a team's)")
        return self.team

    def _records(self) -> Iterator[object]:
        """The file's records, up to its end or to where it was cut (:attr:`cut`)."""
        with open(self.path, "rb") as stream:
            records = Records(stream)
            yield from records
            self.cut = records.cut

    def messages(self, kinds: Collection[type] | None = None) -> Iterator[Recorded]:
        """Every valid message (of ``kinds`` only, if given: the others are not even
        decoded), in the order recorded."""
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, type | None]] = {}
        drawn: set[int] = set()  # what Foxglove draws of the messages (dashboard/scene.py)
        keys: Keys | None = None
        for record in self._records():
            if isinstance(record, Metadata):
                keys = self._metadata(record) or keys
            elif isinstance(record, Schema):
                schemas[record.id] = record.name
            elif isinstance(record, Channel) and schemas.get(record.schema_id, "").startswith(
                "foxglove."
            ):
                drawn.add(record.id)
            elif isinstance(record, Channel):
                kind = None if keys is None else kind_of(keys, record.topic)
                if kind is not None and schemas.get(record.schema_id) != f"heft.{kind.__name__}":
                    kind = None
                channels[record.id] = (record.topic, kind)
            elif isinstance(record, Message):
                if record.channel_id in drawn:
                    continue
                if kinds is not None:
                    kind = channels.get(record.channel_id, (None, None))[1]
                    if kind is not None and kind not in kinds:
                        continue
                recorded = self._message(record, channels)
                if recorded is not None:
                    yield recorded

    def _metadata(self, record: Metadata) -> Keys | None:
        if record.name == TEAM_METADATA:
            try:
                keys = Keys(str(record.metadata.get("team", "")))
            except ValueError as err:
                raise RecordingError(f"{self.path}: {TEAM_METADATA}: {err}") from None
            record_format = str(record.metadata.get("format", "1"))
            if record_format not in RECORD_FORMATS:
                raise RecordingError(
                    f"{self.path}: record format {record_format!r}, this program reads"
                    f" {', '.join(RECORD_FORMATS)}"
                )
            self.team, self.record_format = keys.team, record_format
            return keys
        return None

    def _message(self, record: Message, channels: dict) -> Recorded | None:
        topic, kind = channels.get(record.channel_id, (None, None))
        if kind is None:
            self.rejected["message", "not a channel of the team"] += 1
            return None
        try:
            message = from_record(kind, record.data, self.record_format)
        except DecodeError:
            self.rejected[kind.__name__, "invalid"] += 1
            return None
        self.read_count += 1
        return Recorded(record.publish_time, topic, message, record.log_time)


Sink = Callable[[Recorded, float], None]
"""Where a replay delivers each message, with the recording's clock (s) at that message."""


class Replayer:
    """Plays a :class:`Recording` into ``sink`` on a thread of its own.

    It is paced by when each message arrived (:attr:`Recorded.time_ns`, the ``publish_time``),
    not by the message's own instant (``log_time``): the page replays what it showed live, a
    lockstep run at the pace it ran and a stalled team stalled (the team's clock stops while
    the wall clock, by which links age and alarms go off, goes on), and recordings whose
    ``log_time`` was the arrival as well replay the same.

    ``speed`` is how many recorded seconds pass per wall-clock second (``0``: as fast as
    possible). :meth:`pause`, :meth:`play` and :meth:`step` (while paused: let ``seconds`` of
    the recording through) steer it; :meth:`now` is the recording's clock, which the
    dashboard's link ages and alarms use."""

    def __init__(
        self,
        recording: Recording,
        sink: Sink,
        speed: float = 1.0,
        paused: bool = False,
        kinds: Collection[type] | None = None,
    ):
        if not (speed == 0 or 0.01 <= speed <= 1000):
            raise ValueError(f"speed {speed} is outside [0.01, 1000] (or 0: as fast as possible)")
        self.recording = recording
        self.sink = sink
        self.kinds = kinds
        self.speed = speed
        self.paused = paused
        self.finished = threading.Event()
        self.position_s = 0.0
        """The recording's clock: seconds since its first message."""
        self._start_ns: int | None = None
        self._wall = time.monotonic()
        self._wall_position = 0.0
        self._step_until: float | None = None
        self._stop = threading.Event()
        self._wake = threading.Condition()
        self._thread = threading.Thread(target=self._run, name="replay", daemon=True)

    def start(self) -> Replayer:
        self._thread.start()
        return self

    def now(self) -> float:
        """The recording's clock now (s): it runs at ``speed`` while playing."""
        with self._wake:
            if self.paused or self.speed == 0 or self.finished.is_set():
                return self.position_s
            return self._wall_position + (time.monotonic() - self._wall) * self.speed

    def play(self, speed: float | None = None) -> None:
        with self._wake:
            if speed is not None:
                if not (speed == 0 or 0.01 <= speed <= 1000):
                    raise ValueError(f"speed {speed} is outside [0.01, 1000] (or 0)")
                self.speed = speed
            self.paused = False
            self._step_until = None
            self._rebase()
            self._wake.notify_all()

    def pause(self) -> None:
        with self._wake:
            self.paused = True
            self._wake.notify_all()

    def step(self, seconds: float) -> None:
        """Let ``seconds`` more of the recording through, then pause."""
        with self._wake:
            self.paused = True
            base = self.position_s if self._step_until is None else self._step_until
            self._step_until = base + max(0.0, seconds)
            self._wake.notify_all()

    def stop(self) -> None:
        self._stop.set()
        with self._wake:
            self._wake.notify_all()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=5.0)

    def _rebase(self) -> None:
        self._wall = time.monotonic()
        self._wall_position = self.position_s

    def _wait_for(self, position: float) -> bool:
        """Wait until the message at ``position`` may be delivered; False to stop."""
        with self._wake:
            while not self._stop.is_set():
                if self.paused:
                    if self._step_until is not None and position <= self._step_until:
                        return True
                    self._wake.wait(0.1)
                    continue
                if self.speed == 0:
                    return True
                due = self._wall + (position - self._wall_position) / self.speed
                delay = due - time.monotonic()
                if delay <= 0:
                    return True
                self._wake.wait(min(delay, 0.1))
            return False

    def _run(self) -> None:
        try:
            for recorded in self.recording.messages(self.kinds):
                if self._start_ns is None:
                    self._start_ns = recorded.time_ns
                position = max(0.0, (recorded.time_ns - self._start_ns) / 1e9)
                if not self._wait_for(position):
                    return
                with self._wake:
                    self.position_s = max(self.position_s, position)
                self.sink(recorded, self.position_s)
        finally:
            with self._wake:
                if self._step_until is not None:
                    self.position_s = max(self.position_s, self._step_until)
            self.finished.set()
