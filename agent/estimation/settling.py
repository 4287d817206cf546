"""Deciding, from an agent's own evidence, that an estimate has settled.

An estimate has settled when, for ``window`` updates running, it is within ``tolerance`` times
its size of the oldest of its last ``window`` values (where it was ``window`` updates before,
once there are that many), and no single update moved it by more than that. This looks at
drift, not at jitter: lost messages make estimates tremble by tiny amounts from one tick to the
next, which must not keep a converged estimate from counting as settled.
O(size of the estimate) per update.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence


def _distance(a: Sequence[float], b: Sequence[float]) -> float:
    return math.sqrt(sum((x - y) * (x - y) for x, y in zip(a, b)))


class SettleDetector:
    """Tracks whether a (vector) estimate has stopped moving; remembers when it first did."""

    def __init__(self, window: int, tolerance: float, floor: float = 1e-3):
        self.window = max(1, int(window))
        self.tolerance = tolerance
        self.floor = floor
        self.streak = 0
        self.first_settled: int | None = None
        self._past: deque[tuple[float, ...]] = deque(maxlen=self.window + 1)

    def update(self, value: Sequence[float], tick: int) -> bool:
        """Feed the estimate at ``tick``; returns whether it is settled now."""
        current = tuple(value)
        past = self._past
        if past:
            size = max(math.sqrt(sum(v * v for v in current)), self.floor)
            limit = self.tolerance * size
            quiet = _distance(current, past[-1]) <= limit and _distance(current, past[0]) <= limit
            self.streak = self.streak + 1 if quiet else 0
        past.append(current)
        if self.settled and self.first_settled is None:
            self.first_settled = tick
        return self.settled

    @property
    def settled(self) -> bool:
        return self.streak >= self.window

    def reset(self) -> None:
        self.streak = 0
        self.first_settled = None
        self._past.clear()
