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
  ``watchdog_s`` without one, until commands return: a command for a tick the bus opened at
  or after the trip (an older one, sent before the agent fell silent and late from the
  network, is no sign that it is back: refused as ``stale after a stop``); each trip is
  logged and counted, and :meth:`Bridge.status` says so.

With the velocity profile (``[can] profile = "velocity"``, :mod:`bridge.dbc`) the AGV is a base
that takes velocity commands and a force/torque sensor at its contact, and the bridge closes
the admittance loop between them (:class:`~bridge.admittance.Admittance`). Tick ``k``:

1. the base's ``MotionFeedback`` (``v_k``) and the sensor's ``ForceTorque`` (raw ``r_k``) become
   the agent's measurement with the tared force ``f_k = measure(r_k)`` (the first
   ``tare_samples`` samples are averaged into the sensor's bias). A ``ForceTorque`` with a
   status bit set (overrange, fault) is not used: counted, and the tick has no measurement;
2. the agent's command ``u_k`` for tick ``k`` (the same tick checks) gives the base's velocity
   ``step(u_k)`` for ``[t_k, t_{k+1})``, sent as ``MotionCommand`` (``Counter = k mod 16``,
   each axis clamped to the DBC's ±8 m/s, counted). The loop steps once per tick: a command
   repeated for the tick just stepped sends the same frame again; one for an older tick, or
   for a tick whose sample is not in, is refused and counted;
3. two stops, each the loop's state forgotten and ``MotionCommand`` in mode STOP, paced as the
   ZERO frames above: the agent silent for ``watchdog_s`` (the watchdog), and the sensor stale
   (no usable ``ForceTorque`` read for ``watchdog_s`` since the last, once one has come, while
   the bus has opened a tick without one), each logged once per trip with its reason and
   counted. The base drives again once both are back. A contact force beyond the loop's
   ``max_contact_force`` is a third: the loop commands standstill (a ``MotionCommand`` of zero
   velocity for that tick, so that a lockstep bus master still gets its tick's command),
   counted as ``overload stops`` and logged once per episode.

:meth:`Bridge.status` gives the profile, the loop's force-tracking error and the stale sensor.

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
from bridge.admittance import Admittance, AdmittanceSettings
from bridge.codec import (
    COUNTER_MODULO,
    REASONS,
    AgvCodec,
    AppliedForce,
    ForceCommand,
    ForceTorque,
    FrameError,
    Heartbeat,
    MotionCommand,
    MotionFeedback,
    Odometry,
    Sync,
    Vec2,
    clamp_command_velocity,
    clamp_force,
)
from bridge.dbc import SENSOR_STATUS_BITS
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
    to the methods (``at``) are ``time.monotonic()``-like seconds. The codec's profile is the
    bridge's; with the velocity profile ``admittance`` is its loop (default: the default
    gains at ``period_s``).
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
        admittance: Admittance | None = None,
    ):
        self.robot = robot
        self.node = node
        self.period_s = period_s
        self.watchdog_s = watchdog_s
        self.ticks = ticks
        self.rejects = rejects
        self.wall = wall
        self.codec = codec or AgvCodec()
        self.velocity_profile = self.codec.profile == "velocity"
        self.admittance = admittance
        """The admittance loop (velocity profile only)."""
        if self.velocity_profile and admittance is None:
            self.admittance = Admittance(AdmittanceSettings(), period_s)
        self.counts: Counter[str] = Counter()
        """What happened, by kind: ``frames in``, ``frames out``, ``measurements``,
        ``commands``, ``missed ticks``, ``repeats``, ``counter jumps``, ``lost frames``,
        ``clamped``, ``other nodes``, ``zero frames``, ``watchdog trips``, ``bus errors``,
        ``reopens``, ``send failed``; with the velocity profile also ``stop frames``,
        ``sensor faults`` (samples with a status bit set), ``sensor stale trips`` and
        ``overload stops`` (the admittance loop's protective stops);
        rejections are in ``rejects``."""
        self.tripped = False
        """Whether the watchdog commands zero force (standstill) now."""
        self.sensor_stale = False
        """Whether the base stands still because the force/torque sensor is stale."""
        self.driver_mode = UNKNOWN_MODE
        self.driver_faults = 0
        self._sample: _Sample | None = None
        self._last_measured: int | None = None
        self._last_counter: dict[type, int] = {}
        self._last_sync: int | None = None
        self._last_command_at: float | None = None
        self._tripped_tick = 0
        """The bus's newest tick when the watchdog last tripped."""
        self._last_zero_at = -math.inf
        self._zero_tick: int | None = None
        """The tick of the last ZERO (STOP) frame."""
        self._measured: tuple[int, Vec2] | None = None
        self._overloaded = False
        """Whether the last step was a protective stop (logged once per episode)."""
        """The newest tick given to the admittance loop, and its tared force."""
        self._stepped: tuple[int, can.Message] | None = None
        """The tick the loop last stepped for, and the frame it gave."""
        self._sensor_tick: int | None = None
        """The tick of the newest usable ``ForceTorque``."""
        self._sensor_heard_at = -math.inf
        """When it was received (on the bus)."""
        self._sensor_owed_since: float | None = None
        """When the bus was first seen with a tick newer than the sensor's last sample."""
        self._sensor_status = 0
        """The status bits of the newest unusable ``ForceTorque`` since the last usable one."""

    # ------------------------------------------------------------------ the bus → the agent
    def receive(self, message: can.Message, at: float) -> list[Measurement]:
        """A frame from the bus, received at ``at`` (the clock of :meth:`watchdog`); the
        measurements it completes (zero or one)."""
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
        if isinstance(frame, ForceCommand | MotionCommand):  # ours come from here only
            what = f"{type(frame).__name__} for node {self.node} on the bus"
            self.rejects("can frame", what, "foreign")
            return []
        self._sequence(frame)
        if isinstance(frame, Heartbeat):
            self.driver_mode, self.driver_faults = frame.mode, frame.faults
            return []
        return self._sampled(frame, at)

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

    def _sequence(self, frame: Odometry | AppliedForce | MotionFeedback | ForceTorque | Heartbeat):
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

    def _sampled(
        self, frame: Odometry | AppliedForce | MotionFeedback | ForceTorque, at: float
    ) -> list[Measurement]:
        tick = self.ticks.tick_of(frame.counter, self.wall())
        if tick is None:
            what = f"{type(frame).__name__} counter {frame.counter}"
            self.rejects("can frame", f"{what}: no open tick has it", "stale")
            return []
        if isinstance(frame, ForceTorque) and not self._sensed(frame, tick, at):
            return []
        sample = self._sample
        if sample is None or sample.tick != tick:
            sample = self._sample = _Sample(tick)
        if isinstance(frame, Odometry | MotionFeedback):
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
        force = self._tared(tick, sample.force) if self.velocity_profile else sample.force
        return [Measurement(self.robot, tick, tick * self.period_s, sample.velocity, force)]

    def _sensed(self, frame: ForceTorque, tick: int, at: float) -> bool:
        """Whether the sensor's sample, received at ``at``, is usable (no status bit set); the
        sensor is heard only then."""
        if frame.status:
            self.counts["sensor faults"] += 1
            self._sensor_status = frame.status
            return False
        self._sensor_status = 0
        if self._sensor_tick is None or tick >= self._sensor_tick:
            self._sensor_tick, self._sensor_heard_at = tick, at
            self._sensor_owed_since = None
        if self.sensor_stale:
            self.sensor_stale = False
            log.warning("robot %d: the force/torque sensor is back at tick %d", self.robot, tick)
        return True

    def _tared(self, tick: int, raw: Vec2) -> Vec2:
        """The sensor's raw force of ``tick`` as the loop measures it (once per tick: a tick
        the bus repeats, or an older one, does not count twice in the tare)."""
        measured = self._measured
        if measured is not None and tick == measured[0]:
            return measured[1]
        if measured is not None and tick < measured[0]:
            bias = self.admittance.bias
            return (raw[0] - bias[0], raw[1] - bias[1])
        force = self.admittance.measure(raw)
        self._measured = (tick, force)
        return force

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
        if self.tripped and command.tick < self._tripped_tick:
            what = f"tick {command.tick}: the watchdog tripped at tick {self._tripped_tick}"
            self.rejects("command", what, "stale after a stop")
            return []
        if self.velocity_profile:
            return self._drive(command, at)
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
        self._heard(command, at)
        return [frame]

    def _heard(self, command: Command, at: float) -> None:
        """A valid command came: the agent is not silent."""
        self._last_command_at = at
        if self.tripped:
            self.tripped = False
            log.warning(
                "robot %d: commands are back at tick %d: watchdog cleared", self.robot, command.tick
            )

    def _drive(self, command: Command, at: float) -> list[can.Message]:
        """The velocity profile's command: the admittance loop's step for its tick."""
        tick = command.tick
        if not all(map(math.isfinite, command.force)):  # the protocol's checks keep these out
            self.rejects("command", f"force {command.force!r}", "unencodable")
            return []
        self._heard(command, at)
        if self.sensor_stale:  # the watchdog keeps the base at standstill
            return []
        stepped = self._stepped
        if stepped is not None and tick == stepped[0]:  # the bus repeated the tick
            self.counts["commands"] += 1
            return [stepped[1]]
        if stepped is not None and tick < stepped[0]:
            self.rejects("command", f"tick {tick} after tick {stepped[0]}", "out of order")
            return []
        measured = self._measured
        if measured is None or measured[0] < tick:
            self.rejects("command", f"tick {tick}: its sample is not in", "no sample")
            return []
        force, clamped = clamp_force(command.force)
        velocity, too_fast = clamp_command_velocity(self.admittance.step(force))
        if clamped or too_fast:
            self.counts["clamped"] += 1
        self._protect(tick)
        frame = self.codec.encode(
            MotionCommand(self.node, tick % COUNTER_MODULO, velocity, drive=True)
        )
        self._stepped = (tick, frame)
        self.counts["commands"] += 1
        return [frame]

    def _protect(self, tick: int) -> None:
        """Count and log the admittance loop's protective stops (a contact force beyond
        ``max_contact_force``: the loop commands standstill), once per episode in the log."""
        if not self.admittance.overloaded:
            self._overloaded = False
            return
        self.counts["overload stops"] += 1
        if not self._overloaded:
            log.warning(
                "robot %d: contact force %.1f N beyond max_contact_force %.0f N at tick %d:"
                " commanding standstill",
                self.robot,
                math.hypot(*self._measured[1]),
                self.admittance.settings.max_contact_force,
                tick,
            )
        self._overloaded = True

    def watchdog(self, at: float) -> list[can.Message]:
        """Zero force (mode ZERO), or standstill (STOP) with the velocity profile, if the agent
        fell silent for ``watchdog_s`` or the force/torque sensor is stale: a frame when it
        trips, then one for each tick the bus opens (at most one a period) and, with no new
        tick, one every ``watchdog_s``: a frame a period on a bus that ticks in real time,
        and no flood where ticks come slower (a lockstep simulation, a stopped bus master)."""
        agent_silent = (
            self._last_command_at is not None and at - self._last_command_at > self.watchdog_s
        )
        latest = self.ticks.latest(self.wall())
        tripped = self.velocity_profile and self._sensor_trips(at, latest)
        if not agent_silent and not self.sensor_stale:
            return []
        latest = latest or 0
        if agent_silent and not self.tripped:
            self.tripped = tripped = True
            self._tripped_tick = latest
            self.counts["watchdog trips"] += 1
            silent_ms = (at - self._last_command_at) * 1e3
            log.warning(
                "robot %d: no command for %.0f ms (watchdog %.0f ms): commanding %s",
                self.robot,
                silent_ms,
                self.watchdog_s * 1e3,
                "standstill" if self.velocity_profile else "zero force",
            )
        if not tripped:
            if at - self._last_zero_at < self.period_s:
                return []
            if latest == self._zero_tick and at - self._last_zero_at < self.watchdog_s:
                return []
        self._last_zero_at, self._zero_tick = at, latest
        self.counts["stop frames" if self.velocity_profile else "zero frames"] += 1
        return [self.halt(latest)]

    def _sensor_trips(self, at: float, latest: int | None) -> bool:
        """Whether the force/torque sensor goes stale now: no usable sample received for
        ``watchdog_s`` since its last one (once one has come), while the bus has opened a
        tick without one (:meth:`_sensor_deadline`)."""
        if self._sensor_tick is None or latest is None or latest <= self._sensor_tick:
            return False
        if self._sensor_owed_since is None:
            self._sensor_owed_since = at
        if self.sensor_stale or at <= self._sensor_deadline(self._sensor_owed_since):
            return False
        self.sensor_stale = True
        self.counts["sensor stale trips"] += 1
        bits = [name for bit, name in SENSOR_STATUS_BITS.items() if self._sensor_status >> bit & 1]
        why = f"it reports {' and '.join(bits)}" if bits else "no ForceTorque frame"
        log.warning(
            "robot %d: force/torque sensor stale since tick %d (%s) for %.0f ms (watchdog %.0f"
            " ms): commanding standstill",
            self.robot,
            self._sensor_tick,
            why,
            (at - self._sensor_heard_at) * 1e3,
            self.watchdog_s * 1e3,
        )
        return True

    def _sensor_deadline(self, owed_since: float) -> float:
        """When the sensor owed a sample since ``owed_since`` is stale: ``watchdog_s`` after
        its last usable sample was received, and at least half of ``watchdog_s`` after the bus
        opened the first tick without one. On a bus that ticks in real time the second comes a
        period after the sample, so the stop comes a watchdog after the last sample, however
        late the ticks between. The second holds when the bus stood still longer than that (a
        lockstep bus master waiting for a slow plant): its next tick's sample, a frame behind
        the tick, gets time to come."""
        return max(self._sensor_heard_at + self.watchdog_s, owed_since + self.watchdog_s / 2)

    def halt(self, tick: int) -> can.Message:
        """The frame that stops the AGV, for ``tick``: ``ForceCommand`` in mode ZERO, or with
        the velocity profile ``MotionCommand`` in mode STOP (the loop's state forgotten)."""
        counter = tick % COUNTER_MODULO
        if not self.velocity_profile:
            return self.codec.encode(ForceCommand(self.node, counter, (0.0, 0.0), apply=False))
        self.admittance.stop()
        self._stepped = None
        return self.codec.encode(MotionCommand(self.node, counter, (0.0, 0.0), drive=False))

    def next_check(self, at: float) -> float:
        """When :meth:`watchdog` has something to do next (a time like ``at``)."""
        due = []
        owed_since = self._sensor_owed_since
        if owed_since is not None and not self.sensor_stale:
            due.append(max(at, self._sensor_deadline(owed_since) + 1e-4))
        if self.tripped or self.sensor_stale:  # a new tick is a frame, and the loop checks
            due.append(max(at, self._last_zero_at + self.watchdog_s))  # after every frame
        elif self._last_command_at is None:
            due.append(at + self.period_s)
        else:
            due.append(max(at, self._last_command_at + self.watchdog_s + 1e-4))
        return min(due)

    # ------------------------------------------------------------------ health
    def status(self) -> BridgeStatus:
        """The counters as the protocol message the bridge publishes."""
        c = self.counts
        decode_errors = sum(self.rejects.reasons["can frame", why] for why in REASONS)
        latest = self.ticks.latest(self.wall())
        tracking = self.admittance.tracking() if self.velocity_profile else None
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
            profile=self.codec.profile,
            force_error_rms=tracking.rms if tracking else 0.0,
            force_error_p95=tracking.p95 if tracking else 0.0,
            sensor_stale=self.sensor_stale,
            sensor_stale_trips=c["sensor stale trips"],
            overload_stops=c["overload stops"],
            wrong_profile=self.rejects.reasons["can frame", "wrong profile"],
        )
