"""Fault injection on the links between agents: message loss and added delay.

These machines have no ``tc netem``, so faults are injected where messages are received, by
:class:`FaultyTransport` around any transport: a :class:`LinkFaults` per robot decides, with
its own seeded random numbers, whether each arriving message is dropped, and holds the others
for the added delay. What it drops it remembers, so a lockstep
run (which otherwise waits for every neighbour's message of the previous tick) knows not to wait
for a message that will never come.
"""

from __future__ import annotations

import heapq
import random
import time
from dataclasses import dataclass, field

from agent.platform.config import ConfigError
from agent.platform.protocol import Share


@dataclass(frozen=True)
class FaultSettings:
    """The ``[faults]`` table: applied to every message an agent receives from a neighbour."""

    drop: float = 0.0
    """Probability that a message is lost."""
    delay_s: float = 0.0
    """Added delay (s) before a message is delivered."""
    seed: int = 0

    def validate(self, where: str) -> None:
        if not 0.0 <= self.drop < 1.0:
            raise ConfigError(f"{where}.drop: expected a probability in [0, 1), got {self.drop}")
        if self.delay_s < 0:
            raise ConfigError(f"{where}.delay_s: expected a number >= 0, got {self.delay_s}")

    @property
    def active(self) -> bool:
        return self.drop > 0.0 or self.delay_s > 0.0


@dataclass
class LinkFaults:
    """Drops and delays the messages offered to it, per :class:`FaultSettings`."""

    settings: FaultSettings
    robot: int = 0
    dropped: set[tuple[int, int]] = field(default_factory=set)
    """``(sender, tick)`` of every message dropped so far (pruned by :meth:`forget`)."""

    def __post_init__(self) -> None:
        self._rng = random.Random(self.settings.seed * 7919 + self.robot)
        self._held: list[tuple[float, int, Share]] = []
        self._count = 0

    def offer(self, share: Share, now: float) -> None:
        """A message arrives at wall-clock time ``now``."""
        if self.settings.drop > 0.0 and self._rng.random() < self.settings.drop:
            self.dropped.add((share.sender, share.tick))
            return
        self._count += 1
        heapq.heappush(self._held, (now + self.settings.delay_s, self._count, share))

    def release(self, now: float) -> list[Share]:
        """The messages whose delay is over at ``now``, in arrival order."""
        out = []
        while self._held and self._held[0][0] <= now:
            out.append(heapq.heappop(self._held)[2])
        return out

    def next_release(self) -> float | None:
        return self._held[0][0] if self._held else None

    def forget(self, before_tick: int) -> None:
        self.dropped = {(s, t) for s, t in self.dropped if t >= before_tick}


class FaultyTransport:
    """Any :class:`~agent.platform.transport.Transport` — in memory or Zenoh — with loss and delay
    applied to what each robot receives: the one place where faults are injected."""

    def __init__(self, inner, settings: FaultSettings, clock=time.monotonic):
        self.inner = inner
        self.settings = settings
        self._clock = clock
        self._faults: dict[int, LinkFaults] = {}

    def _links(self, robot: int) -> LinkFaults:
        faults = self._faults.get(robot)
        if faults is None:
            faults = self._faults[robot] = LinkFaults(self.settings, robot)
        return faults

    def send(self, share: Share) -> None:
        self.inner.send(share)

    def receive(self, robot: int) -> list[Share]:
        faults = self._links(robot)
        now = self._clock()
        for share in self.inner.receive(robot):
            faults.offer(share, now)
        return faults.release(now)

    def dropped(self, robot: int, sender: int, tick: int) -> bool:
        """Whether ``sender``'s message of ``tick`` to ``robot`` was dropped (lockstep does
        not wait for it)."""
        return (sender, tick) in self._links(robot).dropped

    def next_release(self) -> float | None:
        """When the next delayed message falls due (``None`` if none is held)."""
        due = [t for f in self._faults.values() if (t := f.next_release()) is not None]
        return min(due, default=None)

    def forget(self, before_tick: int) -> None:
        for faults in self._faults.values():
            faults.forget(before_tick)
