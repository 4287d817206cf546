"""An agent's own log lines, for the team's displays (:class:`~agent.platform.protocol.LogLine`).

:class:`LogLines` is a :class:`logging.Handler` that an agent's loop puts on the root logger
while it runs (:meth:`agent.node.AgentNode.run`). It keeps the records of INFO and above that
the loop's own thread logs — its phases, lost neighbours, rejected messages — not those of
another thread (Zenoh's log, another agent in the same process), as :class:`LogLine`\\ s
stamped with the agent's latest tick; the loop takes them (:meth:`LogLines.take`) and
publishes them beside its status.

A log storm (thousands of rejected messages a second) must not flood the team: a token bucket
lets :data:`BURST` lines through at once and :data:`PER_S` a second over time. What it drops
it counts, and the next :meth:`~LogLines.take` that has a token left says how many in one
line of its own (at ``warning``).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable

from agent.platform.protocol import LogLine, log_text

PER_S = 5.0
"""Lines a second an agent publishes over time."""
BURST = 20
"""Lines an agent publishes at once (a phase change, a neighbour lost and its halt)."""


def level_of(levelno: int) -> str:
    """A ``logging`` level number as a :data:`~agent.platform.protocol.LOG_LEVELS` name
    (INFO and above)."""
    if levelno >= logging.CRITICAL:
        return "critical"
    if levelno >= logging.ERROR:
        return "error"
    if levelno >= logging.WARNING:
        return "warning"
    return "info"


class LogLines(logging.Handler):
    """Robot ``robot``'s log records of INFO and above, logged by the thread that made this
    handler, as log lines stamped with ``tick()``; at most ``burst`` at once and ``per_s`` a
    second (``clock`` in seconds, monotonic)."""

    def __init__(
        self,
        robot: int,
        tick: Callable[[], int],
        per_s: float = PER_S,
        burst: int = BURST,
        clock: Callable[[], float] = time.monotonic,
    ):
        super().__init__(logging.INFO)
        self.robot = robot
        self.tick = tick
        self.per_s = per_s
        self.burst = burst
        self.clock = clock
        self.thread = threading.get_ident()
        self.dropped = 0
        """Records not published since the last notice: the bucket was empty."""
        self._lines: deque[LogLine] = deque(maxlen=burst)
        self._tokens = float(burst)
        self._filled_at = clock()

    def _token(self) -> bool:
        """Take a token from the bucket, if there is one."""
        now = self.clock()
        self._tokens = min(self.burst, self._tokens + (now - self._filled_at) * self.per_s)
        self._filled_at = now
        if self._tokens < 1.0:
            return False
        self._tokens -= 1.0
        return True

    def emit(self, record: logging.LogRecord) -> None:
        if record.thread != self.thread:
            return
        try:
            if not self._token():
                self.dropped += 1
                return
            if len(self._lines) == self._lines.maxlen:  # not taken for long: the oldest goes
                self.dropped += 1
            text = log_text(record.getMessage())
            self._lines.append(LogLine(self.robot, self.tick(), level_of(record.levelno), text))
        except Exception:  # noqa: BLE001 - logging must never raise in the caller
            self.handleError(record)

    def take(self) -> list[LogLine]:
        """The lines kept since the last call, oldest first, and a notice of the records
        dropped meanwhile if the bucket has a token for it."""
        lines = list(self._lines)
        self._lines.clear()
        if self.dropped and self._token():
            text = (
                f"robot {self.robot}: {self.dropped} log lines not published (more than"
                f" {self.per_s:g} a second)"
            )
            lines.append(LogLine(self.robot, self.tick(), "warning", text))
            self.dropped = 0
        return lines
