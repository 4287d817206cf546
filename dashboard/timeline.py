"""Each message's own instant, on one clock for the whole team: the ``log_time`` of a recording
and of a live Foxglove connection (:class:`Timeline`).

The team's clock is the plant's: sample ``k`` is taken at ``t_k``, simulated seconds since tick
0, ``t_k = k T`` with ``T`` the sensor period (``LoadGeometry.period_s``); in lockstep faster
than the wall clock, in real time paced by it. A message's instant on it:

- its ``time_s`` when it has one (:class:`~agent.platform.protocol.Clock`, ``Truth``,
  ``PlantStatus``, ``Measurement``);
- else the time of its ``tick`` (``Command``, ``Share``, ``Estimates``, ``Status``,
  ``BridgeStatus``): ``t_k = t_c + (k - c) T``, from the latest tick ``c`` whose time ``t_c`` was
  heard (a Clock's, Truth's, PlantStatus's or Measurement's ``time_s``), so that a tick's
  messages get its Clock's very instant; ``T`` is the plant's period, or, without a plant, the
  robots' (a measurement's ``time_s / tick``: a bridge stamps sample ``k`` with ``k T``);
- none for a message without one (``Control``, ``LoadGeometry``, a tick of -1 before the first
  sample, a tick while no time or period is known): it takes the newest instant given so far.

A message's ``log_time`` (ns) is ``origin + instant``. The origin is fixed once, by the first
message with an instant or of the plant's:

- 0 if that message is the plant's (``Clock``, ``Truth``, ``PlantStatus``, ``LoadGeometry``):
  the plant's clock as it is. ``heft run`` and ``heft demo`` subscribe before their plant
  starts, and the plant speaks first, so in a lockstep run's recording ``log_time`` equals
  ``time_s`` to the nanosecond for every message that has one;
- otherwise tick 0 on the wall clock, once: ``arrival - instant`` of the first message with an
  instant. That is a team without a plant (real robots: a bridge numbers its samples from its
  bus's ticks), or a recorder that joined a simulated team late and heard a robot before the
  plant.

The messages heard before the origin is fixed have no instant (an agent's log lines and a
bridge's statuses of tick -1 while it waits for the first sample): their caller holds them
(:class:`~dashboard.topics.Topics`, for at most :data:`~dashboard.topics.HOLD_S`) and they take
the first instant once it is fixed. If nothing fixes it in that time, :meth:`Timeline.on_wall`
gives up waiting: they are stamped with their arrival, and so are those that follow until a
message with an instant anchors tick 0 on the wall clock.

Either way one recording has one clock: never the plant's for some messages and the wall's
for others. ``publish_time`` stays the wall clock when each message was recorded.
"""

from __future__ import annotations

from agent.platform.protocol import Clock, LoadGeometry, PlantStatus, Truth
from dashboard.ticks import TickWindow

FUTURE_NS = 60 * 10**9
"""How far ahead of the newest ``log_time`` given a message's instant may be (ns): one further
ahead takes the newest."""

PLANT_KINDS = (Clock, Truth, PlantStatus, LoadGeometry)
"""What only a plant publishes: the first message of a recording being one of these puts it on
the plant's clock."""


class Timeline:
    """The ``log_time`` of each of one team's messages, in the order received
    (:meth:`log_time_ns`); see the module docstring."""

    def __init__(self) -> None:
        self.origin_ns: int | None = None
        """``log_time`` of the clock's 0 (0 on the plant's clock; None until fixed)."""
        self.period_s: float | None = None
        """``T``: the plant's period, else the robots' (None until known)."""
        self.plant_period = False
        """Whether :attr:`period_s` is the plant's (LoadGeometry), which a robot's does not
        replace."""
        self.anchor: tuple[int, float] | None = None
        """The latest tick whose time was heard, and that time ``(c, t_c)`` (s); before any,
        tick 0 is at 0."""
        self.newest_ns: int | None = None
        """The newest ``log_time`` given (what a message without an instant takes)."""
        self.window = TickWindow()
        """The ticks believed (:meth:`in_window`)."""
        self._on_wall = False

    def log_time_ns(self, message: object, received_ns: int) -> int | None:
        """``message``'s ``log_time`` (ns): ``origin + instant``; received at
        ``received_ns`` (ns since the epoch). None for a message without an instant while the
        origin is not fixed: the caller holds it until it is (the next message that fixes it,
        or :meth:`on_wall`), then asks again. A message outside the window
        (:meth:`in_window`) has no instant and teaches nothing."""
        if self.window.admits(message):
            self._learn(message)
            instant = self._instant_s(message)
            self.window.hear(message)
        else:
            instant = None
        if self.origin_ns is None:
            if isinstance(message, PLANT_KINDS) and not self._on_wall:
                self.origin_ns = 0
            elif instant is not None:
                self.origin_ns = received_ns - round(instant * 1e9)
            elif self._on_wall:
                return self._given(received_ns)
            else:
                return None
        if instant is None:
            return self._given(self.origin_ns if self.newest_ns is None else self.newest_ns)
        stamp = max(0, self.origin_ns + round(instant * 1e9))
        if self.newest_ns is not None and stamp > self.newest_ns + FUTURE_NS:
            return self.newest_ns  # an instant far ahead of the team's: not believed
        return self._given(stamp)

    def in_window(self, message: object) -> bool:
        """Whether ``message``'s tick (if it has one) is within the window of the ticks heard
        (:class:`~dashboard.ticks.TickWindow`, as the dashboard's page takes them): a message
        from far ahead (forged, or a robot gone wrong) is recorded, but stamped with the newest
        instant, and teaches the clock nothing and Foxglove's scene nothing."""
        return self.window.admits(message)

    def on_wall(self) -> None:
        """No plant spoke first: from now on, a message without an instant before the origin
        is fixed is stamped with its arrival, and the origin is tick 0 on the wall clock."""
        self._on_wall = True

    def _given(self, stamp: int) -> int:
        if self.newest_ns is None or stamp > self.newest_ns:
            self.newest_ns = stamp
        return stamp

    def _learn(self, message: object) -> None:
        """The period and the latest tick with a time, from what ``message`` says."""
        if isinstance(message, LoadGeometry):
            self.period_s, self.plant_period = message.period_s, True
            return
        tick, time_s = getattr(message, "tick", None), getattr(message, "time_s", None)
        if tick is None or time_s is None or tick < 0:
            return
        self.anchor = (tick, time_s)
        if tick > 0 and not self.plant_period:
            self.period_s = time_s / tick

    def _instant_s(self, message: object) -> float | None:
        """``message``'s instant on the team's clock (s), or None if it has none."""
        time_s = getattr(message, "time_s", None)
        if time_s is not None:
            return time_s
        tick = getattr(message, "tick", None)
        if tick is None or tick < 0:
            return None
        c, t_c = self.anchor or (0, 0.0)  # before any: tick 0 is at 0, as on the plant's clock
        if tick == c:
            return t_c
        if self.period_s is None:
            return None
        return t_c + (tick - c) * self.period_s
