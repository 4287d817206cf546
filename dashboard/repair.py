"""Making a cut recording whole again (``heft record --repair FILE``, and the leftovers of killed
recorders at the next recorder's start).

A recorder killed with SIGKILL cannot write the MCAP summary and footer: the MCAP tools refuse
such a file (``heft dashboard --replay`` reads it up to the cut). :func:`repair` reads it front
to back (:class:`~dashboard.replay.Records`: every chunk whose CRC matches, up to the first that
is cut or damaged, so every message written before the recorder's last flush) and writes the
same records again through the ``mcap`` package's writer: the header, metadata, attachments,
schemas, channels and messages, each message with its own ``log_time``, ``publish_time`` and
``sequence``; then the summary and the footer. The new file replaces the old one only once it
is complete (a temporary file beside it, renamed over it).

A recorder holds a lock on its file while it writes (:mod:`dashboard.recording_file`), which
the kernel drops when the process dies, however it dies. So a cut file that no one holds is a
killed recorder's: :func:`repair_leftovers` repairs those of ``heft``'s own (the library in
their header) in a folder, which every recorder does in its own folder when it starts.
"""

from __future__ import annotations

import logging
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema

from dashboard.recording_file import LIBRARY, MAGIC, mcap_writer, take
from dashboard.replay import Recording, RecordingError, Records

LOG = logging.getLogger("heft.dashboard")


@dataclass(frozen=True)
class Repaired:
    """What :func:`repair` did to ``path``: ``messages`` kept, and where the file was ``cut``
    (None: it was complete, and was left as it was)."""

    path: Path
    messages: int
    cut: str | None


def counted(stream) -> int | None:
    """The number of messages of the complete MCAP file open as ``stream`` (its summary's; 0
    without one); None if it is cut (it does not end with its footer)."""
    stream.seek(0)
    try:
        summary = make_reader(stream).get_summary()
    except Exception:  # noqa: BLE001 - whatever a cut file's last bytes make the reader raise
        return None
    if summary is None or summary.statistics is None:
        return 0
    return summary.statistics.message_count


def repair(path: str | Path) -> Repaired:
    """Rewrite the MCAP file ``path``, cut short, into a complete one with every record it
    holds up to the cut; a complete file is left as it is. :class:`RecordingError` (one line)
    if it cannot be read, is not an MCAP file, or a recorder is writing it."""
    path = Path(path)
    Recording(path)  # readable, and an MCAP file
    with open(path, "rb") as source:
        if not take(source):
            raise RecordingError(f"{path}: a recorder is writing it (stop it first)")
        messages = counted(source)
        if messages is not None:
            return Repaired(path, messages, None)
        source.seek(0)
        return _rewrite(path, source)


def _rewrite(path: Path, source) -> Repaired:
    """``path`` (open as ``source``) replaced by its records rewritten whole."""
    temporary = None
    try:
        handle, temporary = tempfile.mkstemp(
            dir=path.parent, prefix=f".{path.name}.", suffix=".repair"
        )
        with os.fdopen(handle, "wb") as out:
            records = Records(source, validate_crcs=True)
            messages = _copy(records, out)
        os.chmod(temporary, path.stat().st_mode & 0o777)
        os.replace(temporary, path)
    except BaseException as err:
        if temporary is not None:
            Path(temporary).unlink(missing_ok=True)
        if isinstance(err, OSError):
            reason = err.strerror or str(err)
            raise RecordingError(f"{path}: cannot write it repaired ({reason})") from None
        raise
    return Repaired(path, messages, records.cut or "cut before its footer")


def _copy(records: Records, out) -> int:
    """Write ``records`` (a cut file's, front to back) to ``out`` as a complete MCAP file;
    the number of messages."""
    writer = mcap_writer(out)
    started = False
    schemas: dict[int, int] = {0: 0}
    channels: dict[int, int] = {}
    messages = 0
    for record in records:
        if not started:
            header = record if isinstance(record, Header) else Header("", "")
            writer.start(profile=header.profile, library=header.library)
            started = True
        if isinstance(record, Schema) and record.id not in schemas:
            schemas[record.id] = writer.register_schema(record.name, record.encoding, record.data)
        elif isinstance(record, Channel) and record.id not in channels:
            schema = schemas.get(record.schema_id)
            if schema is not None:
                channels[record.id] = writer.register_channel(
                    record.topic, record.message_encoding, schema, record.metadata
                )
        elif isinstance(record, Message) and record.channel_id in channels:
            writer.add_message(
                channels[record.channel_id],
                log_time=record.log_time,
                data=record.data,
                publish_time=record.publish_time,
                sequence=record.sequence,
            )
            messages += 1
        elif isinstance(record, Metadata):
            writer.add_metadata(record.name, record.metadata)
        elif isinstance(record, Attachment):
            writer.add_attachment(
                record.create_time, record.log_time, record.name, record.media_type, record.data
            )
    if not started:
        writer.start()
    writer.finish()
    return messages


def repair_leftovers(folder: Path, skip: Path | None = None) -> list[Repaired]:
    """Repair every ``*.mcap`` file in ``folder`` (but ``skip``) that a recorder of ``heft``
    wrote (its header says so), that is cut, and that no recorder is writing: what killed
    recorders left. Each is logged; one that cannot be repaired is logged and left."""
    repaired = []
    for path in sorted(folder.glob("*.mcap")):
        if skip is not None and path.resolve() == skip.resolve():
            continue
        try:
            if not _leftover(path):
                continue
            done = repair(path)
        except (OSError, RecordingError) as err:
            LOG.warning("%s: a cut recording that could not be repaired: %s", path, err)
            continue
        if done.cut is None:  # (completed in the meantime)
            continue
        LOG.warning(
            "%s: a killed recorder's file, %s: repaired, %d messages kept",
            path,
            done.cut,
            done.messages,
        )
        repaired.append(done)
    return repaired


def _leftover(path: Path) -> bool:
    """Whether ``path`` is a cut recording of ``heft``'s that no recorder holds."""
    with open(path, "rb") as stream:
        if stream.read(len(MAGIC)) != MAGIC or not take(stream):
            return False
        stream.seek(-len(MAGIC), os.SEEK_END)
        if stream.read(len(MAGIC)) == MAGIC and counted(stream) is not None:
            return False  # complete (the magic at its end is the footer's)
        stream.seek(0)
        header = next(iter(Records(stream)), None)
    return isinstance(header, Header) and header.library == LIBRARY
