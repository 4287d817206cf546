"""The transport seam: how agents' messages reach their graph neighbours, and only them.

An agent never talks to a network itself. Whatever carries its
:class:`~agent.platform.protocol.Share` messages — this in-memory queue for in-process runs and
tests, Zenoh between processes and machines — implements :class:`Transport`: ``send`` delivers a
message from its sender to the sender's graph neighbours and nowhere else; ``receive`` hands a robot
what has been delivered to it since its last call. Delivery order and timing may vary; the agent
uses a message only from the tick after its stamp, so results do not depend on them.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable
from typing import Protocol

from agent.platform.protocol import Share


class Transport(Protocol):
    def send(self, share: Share) -> None:
        """Deliver ``share`` to every graph neighbour of ``share.sender``."""

    def receive(self, robot: int) -> list[Share]:
        """The messages delivered to ``robot`` since the last call, oldest first."""


def neighbour_map(n: int, edges: Iterable[tuple[int, int]]) -> dict[int, tuple[int, ...]]:
    """Robot id → sorted neighbour ids for an undirected graph on robots ``1..n``."""
    adjacent: dict[int, set[int]] = {i: set() for i in range(1, n + 1)}
    for i, j in edges:
        adjacent[i].add(j)
        adjacent[j].add(i)
    return {i: tuple(sorted(js)) for i, js in adjacent.items()}


class InMemoryTransport:
    """Delivers each message at once into its recipients' inboxes (one process; safe for
    agents on several threads). ``wake(robot)``, if given, is called for each delivery."""

    def __init__(self, n: int, edges: Iterable[tuple[int, int]], wake=None):
        self.neighbours = neighbour_map(n, edges)
        self._inbox: dict[int, list[Share]] = {i: [] for i in self.neighbours}
        self._lock = threading.Lock()
        self._wake = wake

    def send(self, share: Share) -> None:
        with self._lock:
            for j in self.neighbours[share.sender]:
                self._inbox[j].append(share)
        if self._wake is not None:
            for j in self.neighbours[share.sender]:
                self._wake(j)

    def receive(self, robot: int) -> list[Share]:
        with self._lock:
            inbox = self._inbox[robot]
            self._inbox[robot] = []
        return inbox
