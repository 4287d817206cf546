"""The live source: a team's messages from Zenoh, decoded on a thread of their own.

Each subscription queues its samples in Zenoh's own FIFO (:data:`FIFO_CAPACITY`), outside
Python: no Zenoh thread ever waits for this process's interpreter, and a flood fills the FIFOs,
then backs up the link to the router, never this process's memory. A worker thread empties
them every :data:`POLL_S`, decodes each payload through the protocol
(:func:`dashboard.channels.decode_on`: every field checked, a robot's message only on its own
key), counts and drops what fails, and hands the rest to the sinks (the dashboard's hub, a
recorder) in one batch. A message's arrival is when the worker took it (within
:data:`POLL_S`). The agents' liveliness tokens, rare, come through a callback.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence

from agent.platform.config import MAX_ROBOTS
from agent.platform.process import RejectLog
from agent.platform.protocol import DecodeError, Keys
from agent.platform.zenoh_session import (
    ZenohSettings,
    fifo_subscriber,
    open_session,
    take,
    watch_liveliness,
)
from dashboard.channels import decode_on, team_wildcard

POLL_S = 0.02
FIFO_CAPACITY = 1 << 14
"""Samples each subscription holds for the worker before Zenoh's reception waits."""
LOG = logging.getLogger("heft.dashboard")

Batch = list[tuple[str, object, float, int]]
"""``(key, message, arrival on the monotonic clock (s), arrival (ns since the epoch))``."""
Sink = Callable[[Batch], None]
LivelinessSink = Callable[[int, bool, float], None]


def display_keys(keys: Keys) -> list[str]:
    """What a display subscribes to: the estimates, statuses, bridges and commands of every
    robot, each robot's shares (the links' health), the plant's truth, load geometry and
    status, the control key. Not the measurements or the clock, the bulk of a team's
    traffic."""
    return [
        keys.all_estimates(),
        keys.all_statuses(),
        keys.all_bridges(),
        keys.all_forces(),
        keys.truth(),
        keys.geometry(),
        keys.plant_status(),
        keys.control(),
        *(keys.share(i) for i in range(1, MAX_ROBOTS + 1)),
    ]


def everything(keys: Keys) -> list[str]:
    """What a recorder subscribes to: every key of the team."""
    return [team_wildcard(keys)]


class LiveFeed:
    """Subscribes to ``subscriptions`` of ``keys``' team and feeds ``sinks``; :meth:`start`,
    then :meth:`close`. ``liveliness`` (if given) hears the agents' tokens come and go."""

    def __init__(
        self,
        settings: ZenohSettings,
        keys: Keys,
        sinks: Sequence[Sink],
        subscriptions: Sequence[str] | None = None,
        liveliness: LivelinessSink | None = None,
        session=None,
    ):
        self.settings = settings
        self.keys = keys
        self.sinks = list(sinks)
        self.subscriptions = list(subscriptions or display_keys(keys))
        self.on_liveliness = liveliness
        self.rejects = RejectLog(LOG, "dashboard")
        self.failures = 0
        self._fifos: list = []
        self._tokens: deque = deque()
        """Liveliness changes from Zenoh's callback: ``(key, alive, arrival)``."""
        self._session = session
        self._own_session = session is None
        self._subscribers: list = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="dashboard-feed", daemon=True)

    def start(self) -> LiveFeed:
        """Open the session (:class:`~agent.platform.zenoh_session.SessionError` if Zenoh cannot)
        and
        subscribe; the worker starts at once."""
        if self._session is None:
            self._session = open_session(self.settings)
        for key in self.subscriptions:
            self._fifos.append(fifo_subscriber(self._session, key, FIFO_CAPACITY))
        self._subscribers.extend(self._fifos)
        if self.on_liveliness is not None:
            tokens = self._tokens
            self._subscribers.append(
                watch_liveliness(
                    self._session,
                    self.keys.all_alive(),
                    lambda key, alive: tokens.append((key, alive, time.monotonic())),
                )
            )
        self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.wait(POLL_S):
            self._drain_safely()
        self._drain_safely()

    def _drain_safely(self) -> None:
        """:meth:`drain`, never ending the worker: a failure is logged and counted."""
        try:
            self.drain()
        except Exception:  # noqa: BLE001 - a display must outlive one bad batch
            self.failures += 1
            if self.failures <= 10:
                LOG.exception("dashboard: a batch of messages could not be handled")

    def drain(self) -> None:
        """Decode what has arrived and hand it to the sinks (the worker does it every
        :data:`POLL_S`)."""
        tokens = self._tokens
        for _ in range(len(tokens)):
            self._liveliness(*tokens.popleft())
        batch: Batch = []
        arrived, stamp = time.monotonic(), time.time_ns()
        keys, rejects = self.keys, self.rejects
        for fifo in self._fifos:
            for sample in take(fifo, FIFO_CAPACITY):  # what it held when reached, at most
                key = str(sample.key_expr)
                try:
                    message = decode_on(keys, key, sample.payload.to_bytes())
                except DecodeError as err:
                    rejects(key.rsplit("/", 1)[-1], err)
                    continue
                batch.append((key, message, arrived, stamp))
        if batch:
            for sink in self.sinks:
                sink(batch)

    def _liveliness(self, key: str, alive: bool, arrived: float) -> None:
        try:
            robot = Keys.robot_of(key)
            ours = key == self.keys.alive(robot)
        except (DecodeError, ValueError) as err:
            self.rejects("liveliness", err)
            return
        if ours and self.on_liveliness is not None:
            self.on_liveliness(robot, alive, arrived)

    def close(self) -> None:
        """Stop the worker, undeclare and close the session (if this feed opened it)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
        for subscriber in self._subscribers:
            try:
                subscriber.undeclare()
            except Exception:  # noqa: BLE001 - the session may be gone already
                pass
        self._subscribers.clear()
        if self._own_session and self._session is not None:
            self._session.close()
            self._session = None
