"""The transport seam over Eclipse Zenoh (see :mod:`agent.transport`).

A robot publishes its :class:`~agent.protocol.Share` on ``heft/<team>/robot/<id>/share`` and
subscribes to that key of each graph neighbour, by name — never to a wildcard — so it receives
nothing from robots that are not its neighbours, even on a network every robot shares.
Subscription callbacks run on Zenoh's threads; they only queue the raw payload and wake the
agent's thread, which decodes (counting and logging what it cannot decode), applies the
injected link faults and hands the messages to the agent.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Callable, Iterable

from agent.faults import FaultSettings, LinkFaults
from agent.protocol import DecodeError, Keys, Share, decode, encode
from agent.zenoh_session import tick_publisher

log = logging.getLogger(__name__)


class ZenohTransport:
    """Shares of one robot, over an open Zenoh session."""

    def __init__(
        self,
        session,
        keys: Keys,
        robot: int,
        neighbours: Iterable[int],
        faults: FaultSettings | None = None,
        wake: Callable[[], None] = lambda: None,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.robot = robot
        self.neighbours = frozenset(neighbours)
        self.faults = LinkFaults(faults or FaultSettings(), robot)
        self.decode_errors = 0
        self.samples = 0
        """Samples received, before decoding (only ever from the neighbours' keys)."""
        self.foreign = 0
        """Messages that decoded but did not come from a neighbour (never delivered)."""
        self._clock = clock
        self._wake = wake
        self._incoming: deque[tuple[float, bytes]] = deque()
        self._publisher = tick_publisher(session, keys.robot(robot, "share"))
        self._subscribers = [
            session.declare_subscriber(keys.robot(j, "share"), self._on_sample)
            for j in sorted(self.neighbours)
        ]

    def _on_sample(self, sample) -> None:
        self.samples += 1
        self._incoming.append((self._clock(), sample.payload.to_bytes()))
        self._wake()

    def send(self, share: Share) -> None:
        self._publisher.put(encode(share))

    def receive(self, robot: int | None = None) -> list[Share]:
        """Every share delivered since the last call (after the injected faults)."""
        while self._incoming:
            arrived, payload = self._incoming.popleft()
            try:
                share = decode(Share, payload)
            except DecodeError as err:
                self.decode_errors += 1
                if self.decode_errors <= 10 or self.decode_errors % 1000 == 0:
                    log.warning(
                        "robot %d: undecodable share #%d: %s", self.robot, self.decode_errors, err
                    )
                continue
            if share.sender not in self.neighbours:
                self.foreign += 1
                continue
            self.faults.offer(share, arrived)
        return self.faults.release(self._clock())

    def next_release(self) -> float | None:
        """When the next delayed message falls due (``None`` if none is held)."""
        return self.faults.next_release()

    def close(self) -> None:
        for sub in self._subscribers:
            sub.undeclare()
        self._publisher.undeclare()
