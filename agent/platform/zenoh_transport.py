"""The transport seam over Eclipse Zenoh (see :mod:`agent.platform.transport`).

A robot publishes its :class:`~agent.platform.protocol.Share` on ``heft/<team>/robot/<id>/share``
and subscribes to that key of each graph neighbour, by name — never to a wildcard — so it receives
nothing from robots that are not its neighbours, even on a network every robot shares.
Subscription callbacks run on Zenoh's threads; they only queue the raw payload and wake the
agent's thread, which decodes, counting what it rejects. Link faults are injected around any
transport by :class:`~agent.platform.faults.FaultyTransport`.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable

from agent.platform.process import RejectLog
from agent.platform.protocol import DecodeError, Keys, Share, decode, encode
from agent.platform.zenoh_session import tick_publisher


class ZenohTransport:
    """Shares of one robot, over an open Zenoh session."""

    def __init__(
        self,
        session,
        keys: Keys,
        robot: int,
        neighbours: Iterable[int],
        rejects: RejectLog,
        wake: Callable[[], None] = lambda: None,
    ):
        self.robot = robot
        self.neighbours = frozenset(neighbours)
        self.rejects = rejects
        self._wake = wake
        self._incoming: deque[bytes] = deque()
        self._publisher = tick_publisher(session, keys.share(robot))
        self._subscribers = [
            session.declare_subscriber(keys.share(j), self._on_sample)
            for j in sorted(self.neighbours)
        ]

    def _on_sample(self, sample) -> None:
        self._incoming.append(sample.payload.to_bytes())
        self._wake()

    def send(self, share: Share) -> None:
        self._publisher.put(encode(share))

    def receive(self, robot: int) -> list[Share]:
        """Every share from a neighbour that arrived since the last call."""
        out = []
        while self._incoming:
            try:
                share = decode(Share, self._incoming.popleft())
            except DecodeError as err:
                self.rejects("share", err)
                continue
            if share.sender not in self.neighbours:
                self.rejects("share", f"from robot {share.sender}", "not a neighbour")
                continue
            out.append(share)
        return out

    def close(self) -> None:
        for sub in self._subscribers:
            sub.undeclare()
        self._publisher.undeclare()
