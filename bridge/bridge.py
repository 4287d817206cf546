"""The AGV bridge's logic: CAN frames ↔ the agent's measurements and commands (no I/O here).

One robot's bridge stands where the plant stands in a simulation: its agent cannot tell the
two apart. :class:`Bridge` is a state machine fed by :mod:`bridge.node`, which owns the bus and
the Zenoh session:

- :meth:`Bridge.receive` takes each frame read from the bus. :class:`~bridge.codec.AgvCodec`
  rejects what is not a valid protocol frame (counted by reason: unknown id, wrong length,
  checksum, out of range, error frame, ...). Frames of other nodes (a shared bus) are counted
  and ignored. The driver's ``Odometry`` (``ṗ_Ci``) and ``AppliedForce`` (``f_i``) of one tick —
  the tick their counter ties them to (:mod:`bridge.timing`) — become the agent's
  :class:`~agent.platform.protocol.Measurement` with ``time_s = k T``, once both have arrived. A
  tick that never gets both is a missing measurement: counted, never invented.
- :meth:`Bridge.command` takes the agent's :class:`~agent.platform.protocol.Command` (already
checked
  against the protocol's domains) and gives its ``ForceCommand`` frame: the force clamped to
  the DBC's ±500 N per axis (clamps counted), ``Counter = k mod 16``. A command for a tick the
  bus has not opened, or more than 15 ticks old (its counter would name another tick), is
  refused and counted.
- :meth:`Bridge.watchdog`, called after every frame and at :meth:`Bridge.next_check`: once
  armed by a first command, if no valid command came for ``watchdog_s`` the bridge commands
  zero force (``ForceCommand`` in mode ZERO) on every tick the bus opens, and every
  ``watchdog_s`` without one, until commands return; each trip is logged and counted, and
  :meth:`Bridge.status` says so.

Sequence: every frame's 4-bit ``Counter`` goes up by one per frame of its kind. A counter that
repeats the previous one is a repeated (stale) frame; one that skips is a jump, and the frames
skipped are lost frames (both counted). A repeated frame for the tick the bus has open is still
used: in lockstep the bus master sends a tick again when a command did not come back.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

import can

from agent.platform.process import RejectLog
from agent.platform.protocol import BridgeStatus, Command, Measurement
from bridge.codec import (
    COUNTER_MODULO,
    REASONS,
    AgvCodec,
    AppliedForce,
    ForceCommand,
    FrameError,
    Heartbeat,
    Odometry,
    Sync,
    Vec2,
    clamp_force,
)
from bridge.timing import TickSource

log = logging.getLogger("heft.bridge")
CAN_ERR_BUSOFF = 0x40
"""The bus-off bit of a SocketCAN error frame's id (``linux/can/error.h``)."""
UNKNOWN_MODE = -1
"""The driver's mode before its first heartbeat."""


@dataclass
class _Sample:
    """What has arrived of one tick's measurement."""

    tick: int
    velocity: Vec2 | None = None
    force: Vec2 | None = None


class Bridge:
    """Robot ``robot``'s bridge to AGV ``node`` (see the module docstring).

    ``ticks`` numbers the samples (:mod:`bridge.timing`), ``wall`` is the (synchronised) Unix
    clock it reads, ``rejects`` counts and logs every frame or command refused. Times given
    to the methods (``at``) are ``time.monotonic()``-like seconds.
    """

    def __init__(
        self,
        robot: int,
        node: int,
        period_s: float,
        watchdog_s: float,
        ticks: TickSource,
        rejects: RejectLog,
        wall: Callable[[], float],
        codec: AgvCodec | None = None,
    ):
        self.robot = robot
        self.node = node
        self.period_s = period_s
        self.watchdog_s = watchdog_s
        self.ticks = ticks
        self.rejects = rejects
        self.wall = wall
        self.codec = codec or AgvCodec()
        self.counts: Counter[str] = Counter()
        """What happened, by kind: ``frames in``, ``frames out``, ``measurements``,
        ``commands``, ``missed ticks``, ``repeats``, ``counter jumps``, ``lost frames``,
        ``clamped``, ``other nodes``, ``zero frames``, ``watchdog trips``, ``bus errors``,
        ``reopens``, ``send failed``; rejections are in ``rejects``."""
        self.tripped = False
        """Whether the watchdog commands zero force now."""
        self.driver_mode = UNKNOWN_MODE
        self.driver_faults = 0
        self._sample: _Sample | None = None
        self._last_measured: int | None = None
        self._last_counter: dict[type, int] = {}
        self._last_sync: int | None = None
        self._last_command_at: float | None = None
        self._last_zero_at = -math.inf
        self._zero_tick: int | None = None
        """The tick of the last ZERO frame."""

    # ------------------------------------------------------------------ the bus → the agent
    def receive(self, message: can.Message) -> list[Measurement]:
        """A frame from the bus; the measurements it completes (zero or one)."""
        self.counts["frames in"] += 1
        try:
            frame = self.codec.decode(message)
        except FrameError as err:
            why = err.reason
            if message.is_error_frame:
                self.counts["bus errors"] += 1
                if message.arbitration_id & CAN_ERR_BUSOFF:
                    why = "bus off"
            self.rejects("can frame", err, why)
            return []
        if isinstance(frame, Sync):
            self._sync(frame)
            return []
        if frame.node != self.node:
            self.counts["other nodes"] += 1
            return []
        if isinstance(frame, ForceCommand):  # ours come from here only: someone else sends
            self.rejects("can frame", f"ForceCommand for node {self.node} on the bus", "foreign")
            return []
        self._sequence(frame)
        if isinstance(frame, Heartbeat):
            self.driver_mode, self.driver_faults = frame.mode, frame.faults
            return []
        return self._sampled(frame)

    def _sync(self, frame: Sync) -> None:
        last = self._last_sync
        if last is not None and frame.tick == last:
            self.counts["repeats"] += 1
        elif last is not None and frame.tick != last + 1:
            self.counts["counter jumps"] += 1
            if frame.tick > last:
                self.counts["lost frames"] += frame.tick - last - 1
        self._last_sync = frame.tick
        self.ticks.opened(frame.tick)

    def _sequence(self, frame: Odometry | AppliedForce | Heartbeat) -> None:
        kind = type(frame)
        last = self._last_counter.get(kind)
        self._last_counter[kind] = frame.counter
        if last is None:
            return
        if frame.counter == last:
            self.counts["repeats"] += 1
        elif frame.counter != (last + 1) % COUNTER_MODULO:
            self.counts["counter jumps"] += 1
            self.counts["lost frames"] += (frame.counter - last - 1) % COUNTER_MODULO

    def _sampled(self, frame: Odometry | AppliedForce) -> list[Measurement]:
        tick = self.ticks.tick_of(frame.counter, self.wall())
        if tick is None:
            what = f"{type(frame).__name__} counter {frame.counter}"
            self.rejects("can frame", f"{what}: no open tick has it", "stale")
            return []
        sample = self._sample
        if sample is None or sample.tick != tick:
            sample = self._sample = _Sample(tick)
        if isinstance(frame, Odometry):
            sample.velocity = frame.velocity
        else:
            sample.force = frame.force
        if sample.velocity is None or sample.force is None:
            return []
        self._sample = None
        last = self._last_measured
        if last is not None and tick > last + 1:
            self.counts["missed ticks"] += tick - last - 1
        if last is None or tick > last:
            self._last_measured = tick
        self.counts["measurements"] += 1
        return [Measurement(self.robot, tick, tick * self.period_s, sample.velocity, sample.force)]

    # ------------------------------------------------------------------ the agent → the bus
    def command(self, command: Command, at: float) -> list[can.Message]:
        """The agent's command; the frame that carries it to the driver (or none)."""
        latest = self.ticks.latest(self.wall())
        if command.robot != self.robot:
            self.rejects("command", f"robot {command.robot}'s command", "wrong robot")
            return []
        if latest is None or command.tick > latest:
            self.rejects("command", f"tick {command.tick} at tick {latest}", "ahead of the bus")
            return []
        if command.tick < latest - (COUNTER_MODULO - 1):
            self.rejects("command", f"tick {command.tick} at tick {latest}", "too old")
            return []
        force, clamped = clamp_force(command.force)
        if clamped:
            self.counts["clamped"] += 1
        try:
            frame = self.codec.encode(
                ForceCommand(self.node, command.tick % COUNTER_MODULO, force, apply=True)
            )
        except ValueError as err:  # non-finite: the protocol's checks keep these out
            self.rejects("command", err, "unencodable")
            return []
        self.counts["commands"] += 1
        self._last_command_at = at
        if self.tripped:
            self.tripped = False
            log.warning(
                "robot %d: commands are back at tick %d: watchdog cleared", self.robot, command.tick
            )
        return [frame]

    def watchdog(self, at: float) -> list[can.Message]:
        """Zero force (mode ZERO) if the agent fell silent for ``watchdog_s``: a frame when it
        trips, then one for each tick the bus opens (at most one a period) and, with no new
        tick, one every ``watchdog_s``: a frame a period on a bus that ticks in real time,
        and no flood where ticks come slower (a lockstep simulation, a stopped bus master)."""
        if self._last_command_at is None or at - self._last_command_at <= self.watchdog_s:
            return []
        latest = self.ticks.latest(self.wall()) or 0
        if not self.tripped:
            self.tripped = True
            self.counts["watchdog trips"] += 1
            silent_ms = (at - self._last_command_at) * 1e3
            log.warning(
                "robot %d: no command for %.0f ms (watchdog %.0f ms): commanding zero force",
                self.robot,
                silent_ms,
                self.watchdog_s * 1e3,
            )
        elif at - self._last_zero_at < self.period_s:
            return []
        elif latest == self._zero_tick and at - self._last_zero_at < self.watchdog_s:
            return []
        self._last_zero_at, self._zero_tick = at, latest
        self.counts["zero frames"] += 1
        frame = ForceCommand(self.node, latest % COUNTER_MODULO, (0.0, 0.0), apply=False)
        return [self.codec.encode(frame)]

    def next_check(self, at: float) -> float:
        """When :meth:`watchdog` has something to do next (a time like ``at``)."""
        if self._last_command_at is None:
            return at + self.period_s
        if self.tripped:  # a new tick is a frame, and the loop checks after every frame
            return max(at, self._last_zero_at + self.watchdog_s)
        return max(at, self._last_command_at + self.watchdog_s + 1e-4)

    # ------------------------------------------------------------------ health
    def status(self) -> BridgeStatus:
        """The counters as the protocol message the bridge publishes."""
        c = self.counts
        decode_errors = sum(self.rejects.reasons["can frame", why] for why in REASONS)
        latest = self.ticks.latest(self.wall())
        return BridgeStatus(
            robot=self.robot,
            tick=-1 if latest is None else latest,
            watchdog=self.tripped,
            watchdog_trips=c["watchdog trips"],
            frames_in=c["frames in"],
            frames_out=c["frames out"],
            missed_ticks=c["missed ticks"],
            decode_errors=decode_errors,
            repeats=c["repeats"],
            counter_jumps=c["counter jumps"],
            lost_frames=c["lost frames"],
            clamped=c["clamped"],
            rejected_commands=self.rejects.counts["command"],
            bus_errors=c["bus errors"],
            reopens=c["reopens"],
            driver_mode=self.driver_mode,
            driver_faults=self.driver_faults,
        )
