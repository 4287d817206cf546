"""Stand-ins for parts of a Zenoh session, for tests that run in one process."""

from __future__ import annotations

import collections


class FakeFifo:
    """A subscription of a fake Zenoh session declared with a handler (as the launcher's
    collector declares its own with ``zenoh.handlers.FifoChannel``): call it with a sample
    to queue it, :meth:`try_recv` to take one (None when empty)."""

    def __init__(self, undeclare=lambda: None) -> None:
        self.samples: collections.deque = collections.deque()
        self.undeclare = undeclare

    def __call__(self, sample) -> None:
        self.samples.append(sample)

    def try_recv(self):
        return self.samples.popleft() if self.samples else None
