"""The agents' log lines as Foxglove's log messages (``foxglove.Log``, the SDK's own schema).

Each :class:`~agent.platform.protocol.LogLine` an agent publishes becomes one
``foxglove.messages.Log``: its text, its level (``critical`` is Foxglove's ``FATAL``), the
robot as the log's name (``robot 2``, which a log panel filters by, as the team's news of
:mod:`dashboard.scene` names it), stamped with the instant the caller gives (the same as the
line's record in a recording).
"""

from __future__ import annotations

from foxglove.messages import Log, LogLevel, Timestamp

from agent.platform.protocol import LogLine

LEVELS = {
    "info": LogLevel.Info,
    "warning": LogLevel.Warning,
    "error": LogLevel.Error,
    "critical": LogLevel.Fatal,
}
"""Each of :data:`~agent.platform.protocol.LOG_LEVELS` as Foxglove's level."""


def timestamp(ns: int) -> Timestamp:
    """``ns`` (ns since the epoch, or since a run's start) as a Foxglove timestamp."""
    sec, nsec = divmod(ns, 1_000_000_000)
    return Timestamp(sec, nsec)


def log_entry(line: LogLine, stamp: Timestamp) -> Log:
    """``line`` as a Foxglove log message stamped ``stamp`` (its record's instant)."""
    return Log(
        timestamp=stamp,
        level=LEVELS[line.level],
        message=line.text,
        name=f"robot {line.robot}",
    )
