"""Deciding, from an agent's own evidence, that an estimate has settled.

An estimate has settled when, for ``window`` updates running, it is within ``tolerance`` times
its size of the oldest of its last ``window`` values (where it was ``window`` updates before,
once there are that many), and no single update moved it by more than that. This looks at
drift, not at jitter: lost messages make estimates tremble by tiny amounts from one tick to the
next, which must not keep a converged estimate from counting as settled.
O(size of the estimate) per update.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence


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
        past = self._past
        if past:
            last, oldest = past[-1], past[0]
            size2 = step2 = drift2 = 0.0
            for v, a, b in zip(value, last, oldest):
                size2 += v * v
                step2 += (v - a) * (v - a)
                drift2 += (v - b) * (v - b)
            limit2 = self.tolerance * self.tolerance * max(size2, self.floor * self.floor)
            quiet = step2 <= limit2 and drift2 <= limit2
            self.streak = self.streak + 1 if quiet else 0
        past.append(tuple(value))
        if self.settled and self.first_settled is None:
            self.first_settled = tick
        return self.settled

    @property
    def settled(self) -> bool:
        return self.streak >= self.window
