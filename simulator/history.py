"""A run's recorded samples, in bounded memory whatever the run's length.

:class:`History` keeps at most ``capacity`` samples spread over the whole run: when it is
full it drops every other sample and from then on records only every other one offered
(the stride doubles). A long run is thus kept at a coarser time resolution, never cut short,
and memory stays flat (the plots of a 10-minute run need no more points than those of a
10-second one).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Generic, TypeVar

T = TypeVar("T")
CAPACITY = 2000


class History(Generic[T]):
    """At most ``capacity`` of the samples offered, evenly strided (see the module docstring)."""

    def __init__(self, capacity: int = CAPACITY):
        if capacity < 2:
            raise ValueError("capacity must be at least 2")
        self.capacity = capacity
        self.stride = 1
        self._offered = 0
        self._samples: list[T] = []

    def append(self, sample: T) -> None:
        if self._offered % self.stride == 0:
            self._samples.append(sample)
            if len(self._samples) >= self.capacity:
                del self._samples[1::2]
                self.stride *= 2
        self._offered += 1

    def __iter__(self) -> Iterator[T]:
        return iter(self._samples)

    def __len__(self) -> int:
        return len(self._samples)

    def __getitem__(self, index):
        return self._samples[index]
