"""Deciding, from an agent's own evidence, that an estimate has settled.

An estimate has settled when the sum of its step-to-step changes over the last ``window``
updates is below ``tolerance`` times its size: each update's change must stay below
``tolerance · max(|value|, floor) / window`` for ``window`` updates running. O(1) per update.
"""

from __future__ import annotations

import math
from collections.abc import Sequence


class SettleDetector:
    """Tracks whether a (vector) estimate has stopped moving; remembers when it first did."""

    def __init__(self, window: int, tolerance: float, floor: float = 1e-3):
        self.window = max(1, int(window))
        self.tolerance = tolerance
        self.floor = floor
        self.streak = 0
        self.first_settled: int | None = None
        self._last: tuple[float, ...] | None = None

    def update(self, value: Sequence[float], tick: int) -> bool:
        """Feed the estimate at ``tick``; returns whether it is settled now."""
        last = self._last
        if last is not None:
            size2 = change2 = 0.0
            for a, b in zip(value, last):
                size2 += a * a
                change2 += (a - b) * (a - b)
            limit = self.tolerance * max(math.sqrt(size2), self.floor) / self.window
            if change2 <= limit * limit:
                self.streak += 1
            else:
                self.streak = 0
        self._last = tuple(value)
        if self.settled and self.first_settled is None:
            self.first_settled = tick
        return self.settled

    @property
    def settled(self) -> bool:
        return self.streak >= self.window

    def reset(self) -> None:
        self.streak = 0
        self.first_settled = None
        self._last = None
