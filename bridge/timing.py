"""Which tick a driver's sample belongs to.

The paper's estimators assume that every robot samples at the same instants ``t_k = k T``
(``T`` the sensor period, ``period_s``). A robot's agent numbers its samples by ``k``, and the
team's shares are matched by it, so each bridge must give each of its driver's samples the same
``k`` every other bridge gives the same instant. Per-tick frames carry only ``k mod 16`` (their
``Counter``); a tick source supplies the rest:

- :class:`SyncTicks` (``time_source = "sync"``, CANopen's SYNC as the model): a bus master —
  the plant in tests, a sync master on robots whose drivers sample on SYNC — sends ``Sync(k)``
  at ``t_k``; every driver samples then and sends its frames with ``Counter = k mod 16``. A
  sample belongs to the newest tick the bus opened, if its counter matches; anything else is
  stale or lost, and the tick goes without a measurement.
- :class:`ClockTicks` (``time_source = "clock"``): no sync frame. Each robot computer's clock is
  synchronised (chrony or PTP, well under a period) and tick ``k`` is the period
  ``[E + k T, E + (k+1) T)`` of the Unix time, counted from the team's epoch ``E``
  (:data:`EPOCH`, 2026-01-01 UTC); a driver sampling at ``t`` numbers its sample
  ``floor((t - E) / T) mod 16``. A sample received at ``t'`` belongs to the newest tick
  ``k <= floor((t' - E) / T)`` whose counter matches: the transmission delay may be up to 15
  periods.

Either way a tick is never invented: a tick without both of its frames is a missing
measurement, counted by :class:`bridge.bridge.Bridge`.
"""

from __future__ import annotations

import math

from bridge.codec import COUNTER_MODULO


class SyncTicks:
    """Ticks opened by the bus's ``Sync`` frames."""

    def __init__(self) -> None:
        self.current: int | None = None
        """The newest tick a ``Sync`` opened (None before the first)."""

    def opened(self, tick: int) -> None:
        """A ``Sync(tick)`` frame arrived."""
        self.current = tick

    def tick_of(self, counter: int, now: float) -> int | None:
        """The tick a sample with ``counter`` belongs to: the open tick if it matches."""
        del now
        if self.current is None or self.current % COUNTER_MODULO != counter:
            return None
        return self.current

    def latest(self, now: float) -> int | None:
        """The newest tick there is (commands may not be for a later one)."""
        del now
        return self.current


EPOCH = 1_767_225_600.0
"""2026-01-01 00:00:00 UTC as Unix time: tick 0 of :class:`ClockTicks` (so that ticks and
times stay within the protocol's domains for decades)."""


class ClockTicks:
    """Ticks of this host's (synchronised) Unix clock ``now``: tick ``k`` is
    ``[EPOCH + k T, EPOCH + (k+1) T)``."""

    def __init__(self, period_s: float, epoch: float = EPOCH) -> None:
        if not period_s > 0:
            raise ValueError(f"period_s must be positive, got {period_s!r}")
        self.period_s = period_s
        self.epoch = epoch

    def opened(self, tick: int) -> None:
        """``Sync`` frames are not this source's: ignored."""

    def latest(self, now: float) -> int:
        return max(0, math.floor((now - self.epoch) / self.period_s))

    def tick_of(self, counter: int, now: float) -> int | None:
        """The newest tick ``<= floor((now - E) / T)`` whose counter is ``counter``."""
        latest = self.latest(now)
        tick = latest - (latest - counter) % COUNTER_MODULO
        return tick if tick >= 0 else None


TickSource = SyncTicks | ClockTicks
