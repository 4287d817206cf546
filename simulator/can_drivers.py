"""The robots' drivers on CAN: the plant's side of the AGV protocol (``bridge/agv.dbc``, and
``bridge/agv-velocity.dbc`` for velocity-commanded bases).

In a CAN run (``heft sim SCENARIO --can``) the plant plays every AGV's driver. Each robot is
on a CAN bus (by default its own: robot ``i`` on ``vcan{i}``), where its AGV bridge
(``heft bridge``) meets it; the bridge turns the frames into the agent's Zenoh messages and
back. :class:`CanDriversPort` is the :class:`~agent.platform.robot_io.AgentsPort` of those drivers:

- :meth:`~CanDriversPort.send` of tick ``k``'s measurement puts ``Sync(k)`` on the robot's bus
  (once per tick per bus: it opens the tick; again with a re-sent tick), then the robot's
  ``Odometry`` (its velocity) and ``AppliedForce`` (its measured force) with
  ``Counter = k % 16``; with the velocity profile (the codec's, from ``[agvs] profile``) its
  ``MotionFeedback`` (its base's velocity) and ``ForceTorque`` (its sensor's raw force)
  instead. Values outside the DBC's ranges are clamped to them, and counted;
- every driver sends a ``Heartbeat`` every 100 ms (mode READY, then ACTIVE once the ticks run);
- a ``ForceCommand`` frame becomes a :class:`~agent.platform.protocol.Command` for the newest tick
  ``≤`` the last tick opened on that bus whose ``% 16`` is the frame's counter. A ZERO-mode
  frame is the bridge's watchdog (its agent fell silent): on the wall clock it is a zero
  command for the bus's latest tick; in lockstep it never counts as a tick's command (the
  run stays deterministic: the plant waits for the agent's own), it is only counted. With the
  velocity profile a ``MotionCommand`` frame is the tick's
  :class:`~simulator.lockstep.VelocityCommand` the same way, and its STOP mode the watchdog's
  (a zero velocity: the base brakes);
- a frame that does not decode (the other profile's among them), or is not one the drivers
  take, is counted in the port's
  :class:`~agent.platform.process.RejectLog`; the drivers' own frames coming back (buses that echo
  them) are ignored.

Everything that is not the robots' hardware — the agents' and bridges' liveliness, the
launcher's :class:`~agent.platform.protocol.Control`, the plant's reports — goes through another
port (``rest``: :class:`~agent.platform.zenoh_robot_io.ZenohAgentsPort` with ``bridges=True`` in a
process), whose event queue this port shares. A robot is up once both its agent and its bridge are,
and lost as soon as either is gone.

A reader thread per bus queues what arrives with its arrival time; frames are decoded on the
thread that polls. :class:`CanQuantiser` reproduces the link's quantisation in one process
(``run_inprocess(..., link="can")``), bit for bit.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import NamedTuple

import can

from agent.platform.config import ConfigError
from agent.platform.geometry import Vec2
from agent.platform.protocol import Command, Measurement
from agent.platform.robot_io import AgentsPort, Event, Liveliness, RobotReport
from bridge.codec import (
    COUNTER_MODULO,
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
    clamp_command_velocity,
    clamp_force,
)
from bridge.dbc import DRIVER_MODES, HEARTBEAT_PERIOD_MS, MAX_NODE, MAX_SPEED
from simulator.lockstep import VelocityCommand

log = logging.getLogger("heft.sim.can")

DEFAULT_INTERFACE = "socketcan"
DEFAULT_CHANNEL = "vcan{robot}"
"""Robot ``i``'s bus: ``vcan{robot}`` with ``{robot}`` replaced by ``i``."""
HEARTBEAT_PERIOD_S = HEARTBEAT_PERIOD_MS / 1000.0
READY = next(code for code, name in DRIVER_MODES.items() if name == "READY")
ACTIVE = next(code for code, name in DRIVER_MODES.items() if name == "ACTIVE")
READ_WAIT_S = 0.5
"""The longest a bus reader waits for a frame before it looks at whether the port closes."""
PARTIES = ("agent", "bridge")
"""Whose liveliness makes a robot up in a CAN run."""
FEEDBACK = {"force": (Odometry, AppliedForce), "velocity": (MotionFeedback, ForceTorque)}
"""Profile → the frames of a robot's sample: its velocity's, its measured force's."""


# ====================================================================== where the buses are
@dataclass(frozen=True)
class CanLink:
    """Where each robot's bus is: a python-can ``interface`` (``socketcan``; ``virtual`` in
    one process) and a ``channel`` template in which ``{robot}`` is the robot's id (a
    template without it puts every robot on one bus)."""

    interface: str = DEFAULT_INTERFACE
    channel: str = DEFAULT_CHANNEL

    def channel_of(self, robot: int) -> str:
        return self.channel.replace("{robot}", str(robot))

    def validate(self, where: str = "can") -> None:
        """:class:`ConfigError` naming the option (``where-interface``, ``where-channel``)
        unless both are usable."""
        if not self.interface.isidentifier():
            raise ConfigError(
                f"{where}-interface: expected a python-can interface name like socketcan or"
                f" virtual, got {self.interface!r}"
            )
        if not self.channel or not self.channel.isprintable() or " " in self.channel:
            raise ConfigError(
                f"{where}-channel: expected a channel name like vcan{{robot}}, got {self.channel!r}"
            )
        rest = self.channel.replace("{robot}", "")
        if "{" in rest or "}" in rest:
            raise ConfigError(
                f"{where}-channel: {self.channel!r}: the only placeholder is {{robot}}"
            )


class CanBusError(Exception):
    """A bus could not be opened; ``str()`` is one line naming the channel and why."""


def open_buses(link: CanLink, robots: Iterable[int]) -> dict[int, can.BusABC]:
    """Robot → its bus (robots on the same channel share one bus object). Close them with
    :func:`close_buses`. :class:`CanBusError` if one cannot be opened (none is left open)."""
    by_channel: dict[str, can.BusABC] = {}
    buses: dict[int, can.BusABC] = {}
    try:
        for robot in sorted(robots):
            channel = link.channel_of(robot)
            if channel not in by_channel:
                try:
                    by_channel[channel] = can.Bus(interface=link.interface, channel=channel)
                except (can.CanError, OSError, ValueError, ImportError) as err:
                    raise CanBusError(
                        f"CAN bus {link.interface}/{channel} (robot {robot}): cannot open it"
                        f" ({type(err).__name__}: {err})"
                    ) from None
            buses[robot] = by_channel[channel]
    except CanBusError:
        close_buses(by_channel.values())
        raise
    return buses


def close_buses(buses: Iterable[can.BusABC]) -> None:
    for bus in {id(b): b for b in buses}.values():
        try:
            bus.shutdown()
        except (can.CanError, OSError):
            pass


# ====================================================================== quantisation
def clamp_velocity(velocity: Vec2) -> tuple[Vec2, bool]:
    """``velocity`` with each axis clamped to the odometry's range (±16 m/s), and whether it
    had to be."""
    vx = min(max(velocity[0], -MAX_SPEED), MAX_SPEED)
    vy = min(max(velocity[1], -MAX_SPEED), MAX_SPEED)
    return (vx, vy), (vx, vy) != (velocity[0], velocity[1])


class CanQuantiser:
    """What crossing the CAN link does to the values, without a bus: the same clamps and the
    codec's own quantisation (:meth:`AgvCodec.quantize_velocity`,
    :meth:`~AgvCodec.quantize_force`, and for the velocity profile's commands
    :meth:`~AgvCodec.quantize_command_velocity`), so that a run in one process equals one over
    CAN; ``codec``'s profile is the robots'."""

    def __init__(self, period_s: float, codec: AgvCodec | None = None):
        self.period_s = period_s
        self.codec = codec or AgvCodec()

    def measurement(self, m: Measurement) -> Measurement:
        """``m`` as the agent gets it from its bridge (``time_s = tick × period``)."""
        velocity, _ = clamp_velocity(m.velocity)
        force, _ = clamp_force(m.force)
        return Measurement(
            robot=m.robot,
            tick=m.tick,
            time_s=m.tick * self.period_s,
            velocity=self.codec.quantize_velocity(velocity),
            force=self.codec.quantize_force(force),
        )

    def force(self, force: Vec2) -> Vec2:
        """A commanded force as the driver gets it from the bridge's ``ForceCommand``."""
        clamped, _ = clamp_force(force)
        return self.codec.quantize_force(clamped)

    def loop_force(self, force: Vec2) -> Vec2:
        """An agent's force as its AGV bridge gives it to the admittance loop (velocity
        profile): clamped to the protocol's ±500 N per axis, as the force profile's commands
        are (it crosses no bus: the agent's messages are not quantised)."""
        clamped, _ = clamp_force(force)
        return clamped

    def velocity(self, velocity: Vec2) -> Vec2:
        """A commanded velocity as the base's driver gets it from the bridge's
        ``MotionCommand`` (velocity profile)."""
        clamped, _ = clamp_command_velocity(velocity)
        return self.codec.quantize_command_velocity(clamped)


# ====================================================================== the port
class _Frame(NamedTuple):
    """A frame read from the bus of lane ``lane``, at ``at`` (``time.perf_counter()``), when
    the newest tick opened on it was ``synced``."""

    at: float
    lane: int
    message: can.Message
    synced: int


class _BusFailure(NamedTuple):
    at: float
    lane: int
    error: Exception


@dataclass(eq=False)
class _Lane:
    """One bus and the robots on it."""

    index: int
    bus: can.BusABC
    robots: frozenset[int]
    name: str
    lock: threading.Lock
    synced: int = -1
    """The last tick opened by a ``Sync`` on this bus (-1: none yet)."""
    sent: set[int] = dataclasses.field(default_factory=set)
    """The robots whose frames of tick ``synced`` went out (a second time is a re-send)."""


class CanDriversPort(AgentsPort):
    """The drivers of the robots in ``buses`` (robot → its bus) on CAN, beside ``rest`` for
    everything else (see the module docstring); ``clock`` is the plant's.

    The port starts a reader thread per bus and the heartbeat thread; :meth:`close` stops
    them and closes ``rest``, not the buses (the caller opened them). ``counts`` tells what
    happened on the buses: frames out and in, clamps, the watchdog's ZERO (STOP) frames, echoes,
    failed sends. The robots' profile is ``codec``'s."""

    def __init__(
        self,
        rest: AgentsPort,
        buses: Mapping[int, can.BusABC],
        clock: str,
        codec: AgvCodec | None = None,
        parties: Iterable[str] = PARTIES,
        heartbeat_period_s: float = HEARTBEAT_PERIOD_S,
    ):
        super().__init__(rest.robots, rest.rejects)
        if set(buses) != set(rest.robots):
            raise ValueError(f"buses for robots {sorted(buses)}, serving {sorted(rest.robots)}")
        for robot in buses:
            if not 1 <= robot <= MAX_NODE:
                raise ValueError(f"robot {robot}: CAN node ids are 1..{MAX_NODE}")
        self.events = rest.events  # one queue: what ``rest`` hears and what the buses carry
        self._rest = rest
        self.clock = clock
        self.codec = codec or AgvCodec()
        self._feedback = FEEDBACK[self.codec.profile]
        self.parties = frozenset(parties)
        self.counts: Counter[str] = Counter()
        self._counts_lock = threading.Lock()
        self._present: dict[int, set[str]] = {}
        self._lanes: list[_Lane] = []
        self._lane_of: dict[int, _Lane] = {}
        grouped: dict[int, list[int]] = {}
        for robot, bus in sorted(buses.items()):
            grouped.setdefault(id(bus), []).append(robot)
        for robots in grouped.values():
            bus = buses[robots[0]]
            name = str(getattr(bus, "channel_info", "") or f"bus of robots {robots}")
            lane = _Lane(len(self._lanes), bus, frozenset(robots), name, threading.Lock())
            self._lanes.append(lane)
            for robot in robots:
                self._lane_of[robot] = lane
        self._heartbeats = dict.fromkeys(buses, 0)
        self._mode = READY
        self._closing = threading.Event()
        self._threads = [
            threading.Thread(
                target=self._read, args=(lane,), name=f"can-read-{lane.index}", daemon=True
            )
            for lane in self._lanes
        ]
        self._threads.append(
            threading.Thread(
                target=self._beat, args=(heartbeat_period_s,), name="can-heartbeat", daemon=True
            )
        )
        for thread in self._threads:
            thread.start()

    # ------------------------------------------------------------------ out
    def send(self, measurement: Measurement) -> None:
        """Tick ``measurement.tick`` of its robot: ``Sync`` (if the tick is new on the bus),
        ``Odometry`` and ``AppliedForce`` (velocity profile: ``MotionFeedback`` and
        ``ForceTorque``)."""
        robot, tick = measurement.robot, measurement.tick
        lane = self._lane_of[robot]
        self._mode = ACTIVE
        velocity, clamped = clamp_velocity(measurement.velocity)
        if clamped:
            self._count("velocity clamped")
        force, clamped = clamp_force(measurement.force)
        if clamped:
            self._count("force clamped")
        counter = tick % COUNTER_MODULO
        frames: list = []
        # A tick's first frames open it; a re-send (lockstep: the command did not come back)
        # opens it again, in case the Sync was what got lost.
        again = tick == lane.synced and robot in lane.sent
        if tick > lane.synced or again:
            frames.append(Sync(tick))
        sampled, measured = self._feedback
        frames += [sampled(robot, counter, velocity), measured(robot, counter, force)]
        try:
            messages = [self.codec.encode(frame) for frame in frames]
        except ValueError as err:  # non-finite: a plant gone wrong
            self.rejects("measurement", f"robot {robot} tick {tick}: {err}", "unencodable")
            return
        if tick > lane.synced:
            lane.synced = tick
            lane.sent.clear()
        lane.sent.add(robot)
        for message in messages:
            self._put(lane, message)

    def _put(self, lane: _Lane, message: can.Message) -> None:
        try:
            with lane.lock:
                lane.bus.send(message, timeout=0.1)
            self._count("frames out")
        except (can.CanError, OSError) as err:
            failed = self._count("send failed")
            if failed <= 10 or failed % 1000 == 0:
                log.warning("%s: send failed #%d: %s", lane.name, failed, err)

    def _count(self, what: str) -> int:
        with self._counts_lock:  # the heartbeat thread counts too
            self.counts[what] += 1
            return self.counts[what]

    def _beat(self, period_s: float) -> None:
        """Every driver's heartbeat, every ``period_s``, until the port closes."""
        due = time.monotonic()
        while not self._closing.wait(max(0.0, due - time.monotonic())):
            due += period_s
            for robot, lane in self._lane_of.items():
                count = self._heartbeats[robot]
                self._heartbeats[robot] = count + 1
                beat = Heartbeat(robot, count % COUNTER_MODULO, self._mode)
                self._put(lane, self.codec.encode(beat))
                self._count("heartbeats")

    # ------------------------------------------------------------------ in
    def _read(self, lane: _Lane) -> None:
        put = self.events.put
        while not self._closing.is_set():
            try:
                message = lane.bus.recv(timeout=READ_WAIT_S)
            except (can.CanError, OSError, ValueError) as err:
                if self._closing.is_set():
                    return
                put(_BusFailure(time.perf_counter(), lane.index, err))
                self._closing.wait(0.1)
                continue
            if message is not None:
                put(_Frame(time.perf_counter(), lane.index, message, lane.synced))

    def _take(self, event, out: list[Event]) -> None:
        if isinstance(event, _Frame):
            self._frame(event, out)
            return
        if isinstance(event, _BusFailure):
            lane = self._lanes[event.lane]
            self.rejects("can bus", f"{lane.name}: {event.error}", "receive failed")
            return
        heard: list[Event] = []
        self._rest._take(event, heard)
        for at, item in heard:
            if isinstance(item, Liveliness):
                self._liveliness(at, item, out)
            else:
                out.append((at, item))

    def _frame(self, event: _Frame, out: list[Event]) -> None:
        self._count("frames in")
        lane = self._lanes[event.lane]
        try:
            frame = self.codec.decode(event.message)
        except FrameError as err:
            self.rejects("can frame", f"{lane.name}: {err}", err.reason)
            return
        if isinstance(frame, (ForceCommand, MotionCommand)):
            self._command(event, lane, frame, out)
        elif isinstance(frame, Sync) or frame.node in lane.robots:
            self._count("echoes")  # our own frame, on a bus that echoes them
        else:
            what = f"{lane.name}: {type(frame).__name__} of node {frame.node}"
            self.rejects("can frame", what, "not a robot on this bus")

    def _command(
        self, event: _Frame, lane: _Lane, frame: ForceCommand | MotionCommand, out: list[Event]
    ) -> None:
        if isinstance(frame, ForceCommand):
            what, active, value, command = "force command", frame.apply, frame.force, Command
        else:
            what, active, value = "motion command", frame.drive, frame.velocity
            command = VelocityCommand
        robot, at = frame.node, event.at
        if robot not in lane.robots:
            detail = f"{lane.name}: {type(frame).__name__} of node {robot}"
            self.rejects(what, detail, "not a robot on this bus")
            return
        latest = event.synced  # when it arrived: the tick it can answer at most
        tick = latest - (latest - frame.counter) % COUNTER_MODULO
        if tick < 0:
            detail = f"{lane.name}: node {robot} counter {frame.counter} at tick {latest}"
            self.rejects(what, detail, "before the first tick")
            return
        if not active:
            self._count("zero commands" if command is Command else "stop commands")
            if self.clock == "lockstep":
                return  # the watchdog's: never a tick's command, the plant waits for the agent's
            out.append((at, command(robot, latest, (0.0, 0.0))))
            return
        out.append((at, command(robot, tick, value)))

    def _liveliness(self, at: float, item: Liveliness, out: list[Event]) -> None:
        """A robot is up once every one of :attr:`parties` is, gone once one of them is."""
        if item.who not in self.parties:
            return
        present = self._present.setdefault(item.robot, set())
        was_up = present >= self.parties
        if item.alive:
            present.add(item.who)
            if not was_up and present >= self.parties:
                out.append((at, Liveliness(item.robot, True)))
        else:
            present.discard(item.who)
            out.append((at, item))

    # ------------------------------------------------------------------ the rest
    def report(self, message: RobotReport) -> None:
        self._rest.report(message)

    def close(self) -> None:
        self._closing.set()
        for thread in self._threads:
            thread.join(timeout=2.0)
        self._rest.close()
        if self.counts:
            log.info("CAN: %s", ", ".join(f"{k} {v}" for k, v in sorted(self.counts.items())))
