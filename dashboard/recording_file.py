"""What makes an MCAP file a ``heft`` recording, for what writes it (:mod:`dashboard.recorder`),
reads it (:mod:`dashboard.replay`) and repairs it (:mod:`dashboard.repair`): the library its
header names, the metadata record that names the team, its chunks, and the lock a recorder
holds on it while it writes.

The lock is an exclusive ``flock`` on the open file: the kernel drops it when the process
closes the file or dies, however it dies. A cut recording that no one holds is a killed
recorder's.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path
from typing import BinaryIO

from mcap.writer import CompressionType, Writer

MAGIC = b"\x89MCAP0\r\n"
"""The first (and, in a complete file, the last) 8 bytes of an MCAP file."""
LIBRARY = "heft"
"""The library a recording's header names."""
TEAM_METADATA = "heft.team"
"""The metadata record that names the recording's team (``{"team": T}``), before any message."""
CHUNK_BYTES = 256 * 1024
"""A chunk is closed when it reaches this size (uncompressed)."""


def mcap_writer(stream: BinaryIO) -> Writer:
    """An MCAP writer to ``stream`` as a recording's: chunks of :data:`CHUNK_BYTES`, zstd."""
    return Writer(stream, chunk_size=CHUNK_BYTES, compression=CompressionType.ZSTD)


def open_held(path: Path) -> BinaryIO:
    """``path`` opened for writing, emptied, with the lock a recorder holds while it writes;
    :class:`BlockingIOError` (naming it) if another recorder holds it."""
    stream = os.fdopen(os.open(path, os.O_WRONLY | os.O_CREAT, 0o666), "wb")  # (not emptied)
    if not take(stream):
        stream.close()
        raise BlockingIOError(f"{path}: another recorder is writing it")
    stream.truncate(0)
    return stream


def take(stream: BinaryIO) -> bool:
    """Take the lock of the open file ``stream``, unless a recorder holds it (then False). No
    recorder can start writing the file while it is held."""
    try:
        fcntl.flock(stream, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True
