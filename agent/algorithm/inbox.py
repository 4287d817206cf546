"""What a robot has heard: its own and its neighbours' velocities, their latest messages, and
which instants can be estimated.

Timing. Robot ``i`` has its own sample of tick ``k`` but its neighbours' samples only up to
``k − 1`` (they arrive with their messages). So its estimates at tick ``k`` refer to the
*estimation instant* ``e``, the newest instant with every neighbour's velocity: ``k − 1`` when
messages arrive within a tick, earlier when they are late (instants skipped are caught up in
order). The force for ``[t_k, t_{k+1})`` is predicted from them. A step uses only messages
stamped before ``k``, so a run whose messages arrive in time is reproducible whatever the
transport's timing.
"""

from __future__ import annotations

from collections.abc import Iterable

from agent.platform.geometry import Vec2
from agent.platform.protocol import Measurement, Share

HISTORY_TICKS = 64
"""Ticks of history kept: a message this much older than the current tick is of no use."""


class Inbox:
    """One robot's intake of its own samples and its neighbours' messages."""

    def __init__(self, neighbours: Iterable[int]):
        self.neighbours = tuple(neighbours)
        self.tick = -1
        """The tick of the newest own sample."""
        self.own_velocity: dict[int, Vec2] = {}
        """``ṗ_Ci`` by tick."""
        self.neighbour_velocity: dict[int, dict[int, Vec2]] = {j: {} for j in self.neighbours}
        """``ṗ_Cj`` by neighbour ``j``, then by tick."""
        self.latest: dict[int, Share] = {}
        """Each neighbour's newest message (stamped before the current tick)."""
        self.rejected = 0
        """Messages never used: not from a neighbour, or unusable (see :func:`usable`)."""
        self._pending: list[Share] = []
        """Messages stamped at or after the current tick: used from the tick after theirs."""

    def receive(self, measurement: Measurement, shares: Iterable[Share]) -> int:
        """Take in the own sample of tick ``k`` and the messages delivered since the last call;
        returns the newest instant every neighbour has reported: the estimation instant this
        tick reaches (``k − 1`` unless messages are late; ``-1`` before any)."""
        k = measurement.tick
        self.tick = k
        self.own_velocity[k] = measurement.velocity
        incoming, self._pending = self._pending, []
        incoming.extend(shares)
        for s in incoming:
            history = self.neighbour_velocity.get(s.sender)
            if history is None or not usable(s, k):
                self.rejected += 1  # not from a neighbour, or unusable: never used
                continue
            if s.tick >= k:
                self._pending.append(s)  # early: used from tick s.tick + 1 on
                continue
            history[s.tick] = s.velocity
            latest = self.latest.get(s.sender)
            if latest is None or s.tick > latest.tick:
                self.latest[s.sender] = s
        newest = k - 1 if len(self.latest) == len(self.neighbours) else -1
        for s in self.latest.values():
            if s.tick < newest:
                newest = s.tick
        return newest

    def forget(self, before: int) -> None:
        """Drop the velocities of tick ``before`` (kept :data:`HISTORY_TICKS`)."""
        self.own_velocity.pop(before, None)
        for history in self.neighbour_velocity.values():
            history.pop(before, None)


def usable(share: Share, tick: int) -> bool:
    """A share whose numbers an agent can use at ``tick``: finite, and not stamped so far
    ahead that it could only come from a clock gone wrong."""
    if share.tick >= tick + HISTORY_TICKS:
        return False
    vx, vy = share.velocity
    total = vx - vx + vy - vy
    # x - x == 0 exactly for every finite float, and is NaN for NaN and ±inf.
    for value in share.consensus:
        if type(value) is tuple:
            total += value[0] - value[0] + value[1] - value[1]
        else:
            total += value - value
    return total == 0.0
