"""One robot's AGV bridge as a process: ``heft bridge --config robot.toml``.

The I/O around a :class:`~bridge.bridge.Bridge`:

- the AGV's bus, a python-can bus (``socketcan`` on robots and in the hardware-in-the-loop
  tests, ``virtual`` in one process). A reader thread queues every frame with nothing else
  done on it; the main thread decodes. If the bus fails (the interface went down or
  disappeared, bus-off) the bridge logs it, closes the bus and reopens it every
  :data:`REOPEN_S` until it is back, counting each reopening;
- the robot's side of the robot-I/O seam over Zenoh
  (:class:`~agent.platform.zenoh_robot_io.ZenohAgentsPort` for this one robot): its agent's commands
  in, its measurements out, exactly as the plant's, so an agent cannot tell a bridged robot from a
  simulated one. The bridge declares its own liveliness token (``Keys.bridge_alive``) once the
  bus is open, and publishes its :class:`~agent.platform.protocol.BridgeStatus` every
  :data:`STATUS_EVERY_S` and whenever its watchdog (or, with the velocity profile, its stale
  sensor stop) trips or clears.

Its log is written by a thread of its own (:func:`log_aside`): a slow log (a pipe nobody
reads for a while, a file on a slow disk) never holds a stop frame. It runs until SIGINT,
SIGTERM or SIGHUP, and then commands zero force (standstill with the velocity profile) before
it leaves. The team's ``stop`` message ends a run, not the robot's link: the bridge commands
zero force (standstill) and keeps running.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import logging.handlers
import math
import os
import queue
import socket
import threading
import time
from typing import NamedTuple

import can

from agent.platform.process import RejectLog, StopSignals
from agent.platform.protocol import Command, Control, Keys
from agent.platform.robot_io import Event, Liveliness
from agent.platform.zenoh_robot_io import ZenohAgentsPort
from agent.platform.zenoh_session import open_session
from bridge.admittance import Admittance
from bridge.bridge import Bridge
from bridge.codec import AgvCodec
from bridge.config import BridgeConfig, CanSettings
from bridge.timing import ClockTicks, SyncTicks

log = logging.getLogger("heft.bridge")
STATUS_EVERY_S = 0.25
"""How often the bridge publishes its status when nothing changes (a watchdog that trips or
clears is published at once)."""
REOPEN_S = 0.5
MAX_WAIT_S = 0.2
"""The longest the loop waits for something to arrive (it then checks the bus and the stop)."""
READ_WAIT_S = 0.5
"""The longest the bus reader waits for a frame before it looks at its stop."""
BUS_TIME_S = 1.0
"""A frame's receive timestamp counts (:func:`bus_time`) if it is at most this old when read;
an older or a future one is not on this host's wall clock (an adapter's own), and the frame
counts from when it was read."""
RECEIVE_BUFFER = 4 << 20
"""Bytes of socket receive buffer asked for (a burst at the bus's full rate waits there)."""
GONE = (errno.ENODEV, errno.ENXIO, errno.ENETDOWN)


class BusUnavailable(Exception):
    """The bus cannot be opened; ``str()`` is one line naming it and why."""


def open_bus(settings: CanSettings) -> can.BusABC:
    """The python-can bus of ``settings``; :class:`BusUnavailable` if it cannot be opened."""
    options = {}
    if settings.interface not in ("socketcan", "virtual"):
        options["bitrate"] = settings.bitrate  # SocketCAN's is the interface's (ip link)
    try:
        bus = can.Bus(interface=settings.interface, channel=settings.channel, **options)
    except (can.CanError, OSError, ValueError, ImportError, NotImplementedError) as err:
        raise BusUnavailable(
            f"CAN bus {settings.interface}/{settings.channel}: cannot open it"
            f" ({type(err).__name__}: {err})"
        ) from None
    sock = getattr(bus, "socket", None)
    if isinstance(sock, socket.socket):
        for option in (getattr(socket, "SO_RCVBUFFORCE", None), socket.SO_RCVBUF):
            if option is None:
                continue
            try:
                sock.setsockopt(socket.SOL_SOCKET, option, RECEIVE_BUFFER)
                break
            except OSError:
                continue
    return bus


class _Received(NamedTuple):
    message: can.Message
    at: float
    """When it was on the bus (:func:`bus_time`; ``time.monotonic``, the clock of the bridge's
    watchdog)."""


def bus_time(message: can.Message) -> float:
    """When ``message`` was received, on ``time.monotonic``'s clock: SocketCAN stamps each frame
    in the kernel, on the wall clock, so its age when the reader gets it is ``time.time()``
    minus that stamp; a frame that waited for this process (its reader thread, busy elsewhere or
    not yet scheduled) counts from when it came. A stamp more than :data:`BUS_TIME_S` old or in
    the future is not taken: the frame counts from now."""
    now = time.monotonic()
    age = time.time() - message.timestamp
    return now - age if 0.0 <= age <= BUS_TIME_S else now


class _BusFailed(NamedTuple):
    error: Exception


class BridgePort(ZenohAgentsPort):
    """The robot's side over Zenoh for its one agent, whose event queue also carries what the
    bus reader reads (``_Received``, ``_BusFailed``)."""

    def _take(self, event, out: list[Event]) -> None:
        if isinstance(event, tuple) and len(event) == 2 and isinstance(event[1], _CAN_EVENTS):
            out.append(event)
            return
        super()._take(event, out)


_CAN_EVENTS = (_Received, _BusFailed)


class BridgeNode:
    """The bridge's loop (see the module docstring) on ``port``; the bus is opened by it."""

    def __init__(
        self,
        config: BridgeConfig,
        port: BridgePort,
        stop: threading.Event | None = None,
        open_bus=open_bus,
    ):
        self.config = config
        self.port = port
        self.stop = stop or threading.Event()
        self._open_bus = open_bus
        robot = config.robot
        ticks = SyncTicks() if config.can.time_source == "sync" else ClockTicks(robot.period_s)
        self.bridge = Bridge(
            robot=robot.robot,
            node=config.node,
            period_s=robot.period_s,
            watchdog_s=config.can.watchdog_ms / 1000.0,
            ticks=ticks,
            rejects=port.rejects,
            wall=time.time,
            codec=AgvCodec(config.can.profile),
            admittance=Admittance(config.can.admittance, robot.period_s)
            if config.can.profile == "velocity"
            else None,
        )
        self.bus: can.BusABC | None = None
        self._reader: threading.Thread | None = None
        self._reader_stop = threading.Event()
        self._next_reopen = 0.0
        self._last_failure = ""

    # ------------------------------------------------------------------ the bus
    def open(self) -> None:
        """Open the bus and start its reader (:class:`BusUnavailable` if it cannot)."""
        self.bus = self._open_bus(self.config.can)
        self._reader_stop = threading.Event()
        self._reader = threading.Thread(
            target=self._read, args=(self.bus, self._reader_stop), name="can-read", daemon=True
        )
        self._reader.start()

    def _read(self, bus: can.BusABC, stop: threading.Event) -> None:
        put = self.port.events.put
        while not stop.is_set():
            try:
                message = bus.recv(timeout=READ_WAIT_S)
            except (can.CanError, OSError, ValueError) as err:
                if not stop.is_set():
                    put((time.perf_counter(), _BusFailed(err)))
                return
            if message is not None:
                put((time.perf_counter(), _Received(message, bus_time(message))))

    def _close_bus(self) -> None:
        self._reader_stop.set()
        if self._reader is not None:
            self._reader.join(timeout=1.0)
            self._reader = None
        if self.bus is not None:
            try:
                self.bus.shutdown()
            except (can.CanError, OSError):
                pass
            self.bus = None

    def _bus_failed(self, error: Exception) -> None:
        self.bridge.counts["bus errors"] += 1
        log.error(
            "robot %d: CAN bus %s failed (%s); reopening it every %.1f s",
            self.config.robot.robot,
            self.config.can.channel,
            error,
            REOPEN_S,
        )
        self._close_bus()
        self._next_reopen = time.monotonic() + REOPEN_S

    def _try_reopen(self) -> None:
        if self.bus is not None or time.monotonic() < self._next_reopen:
            return
        try:
            self.open()
        except BusUnavailable as err:
            if str(err) != self._last_failure:
                log.warning("robot %d: %s; retrying", self.config.robot.robot, err)
                self._last_failure = str(err)
            self._next_reopen = time.monotonic() + REOPEN_S
            return
        self._last_failure = ""
        self.bridge.counts["reopens"] += 1
        log.info("robot %d: CAN bus %s is back", self.config.robot.robot, self.config.can.channel)

    def _send(self, frames: list[can.Message]) -> None:
        for frame in frames:
            if self.bus is None:
                self.bridge.counts["send failed"] += 1
                continue
            try:
                self.bus.send(frame, timeout=0.01)
                self.bridge.counts["frames out"] += 1
            except (can.CanError, OSError) as err:
                self.bridge.counts["send failed"] += 1
                failed = self.bridge.counts["send failed"]
                if failed <= 10 or failed % 1000 == 0:
                    log.warning("robot %d: send failed #%d: %s", self.bridge.robot, failed, err)
                code = getattr(err, "error_code", None) or getattr(err, "errno", None)
                if code in GONE:
                    self._bus_failed(err)

    # ------------------------------------------------------------------ the loop
    def _clock(self, at: float) -> float:
        """``at`` (``time.monotonic``) on the watchdog's clock
        (:attr:`~bridge.config.CanSettings.watchdog_clock`): itself, or on the bus's clock the
        start ``k T`` of the newest tick ``k`` the bus opened (0 before the first)."""
        if self.config.can.watchdog_clock == "wall":
            return at
        tick = self.bridge.ticks.latest(0.0)
        return 0.0 if tick is None else tick * self.bridge.period_s

    def _handle(self, item) -> None:
        bridge = self.bridge
        if isinstance(item, _Received):
            for measurement in bridge.receive(item.message, self._clock(item.at)):
                self.port.send(measurement)
        elif isinstance(item, _BusFailed):
            if self.bus is not None:
                self._bus_failed(item.error)
        elif isinstance(item, Command):
            self._send(bridge.command(item, self._clock(time.monotonic())))
        elif isinstance(item, Control):
            log.info("robot %d: the team was told to %s", bridge.robot, item.command)
        elif isinstance(item, Liveliness) and item.who == "agent":
            log.info("robot %d: agent %s", bridge.robot, "up" if item.alive else "gone")

    def _due(self, now: float) -> float:
        """When (``time.monotonic``) the watchdog has something to do, from ``now``: on the
        bus's clock, now or never, since that clock moves only when a frame comes."""
        at = self._clock(now)
        due = self.bridge.next_check(at)
        if self.config.can.watchdog_clock == "wall":
            return due
        return now if due <= at else math.inf

    def run(self) -> int:
        """Until stopped; 0."""
        config, bridge = self.config, self.bridge
        if self.bus is None:
            self.open()
        source = "the bus's Sync frames" if config.can.time_source == "sync" else "this clock"
        log.info(
            "bridge of robot %d up: node %d on %s/%s, %s profile, watchdog %d ms (%s clock),"
            " ticks from %s",
            bridge.robot,
            bridge.node,
            config.can.interface,
            config.can.channel,
            config.can.profile,
            config.can.watchdog_ms,
            config.can.watchdog_clock,
            source,
        )
        if bridge.admittance is not None:
            a = bridge.admittance.settings
            log.info(
                "robot %d: admittance M %g kg, D %g N s/m, integral %g s, deadzone %g N,"
                " max speed %g m/s, max accel %g m/s², tare over %d samples",
                bridge.robot,
                a.mass,
                a.damping,
                a.integral_time_s,
                a.deadzone_n,
                a.max_speed,
                a.max_accel,
                a.tare_samples,
            )
        next_status = time.monotonic()
        stops = (bridge.tripped, bridge.sensor_stale)
        try:
            while not self.stop.is_set():
                now = time.monotonic()
                wait = min(self._due(now), next_status, now + MAX_WAIT_S) - now
                for _, item in self.port.poll(max(wait, 0.0)):
                    self._handle(item)
                now = time.monotonic()
                self._send(bridge.watchdog(self._clock(now)))
                self._try_reopen()
                stopped = (bridge.tripped, bridge.sensor_stale)
                if now >= next_status or stopped != stops:
                    stops = stopped
                    self.port.report(bridge.status())
                    next_status = now + STATUS_EVERY_S
        finally:
            self._leave()
        return 0

    def _leave(self) -> None:
        """Zero force (standstill), the last status, the counters in the log; the bus
        closed."""
        bridge = self.bridge
        if self.bus is not None:
            self._send([bridge.halt(bridge.ticks.latest(time.time()) or 0)])
        self.port.report(bridge.status())
        self._close_bus()
        counts = dict(sorted(bridge.counts.items()))
        rejected = {f"{what}/{why}": n for (what, why), n in sorted(bridge.rejects.reasons.items())}
        log.info("bridge of robot %d stops: %s", bridge.robot, counts)
        if rejected:
            log.info("bridge of robot %d rejected: %s", bridge.robot, rejected)


def use_realtime_priority(priority: int) -> None:
    """Put this process's calling thread, and every thread it starts from now on, under
    ``SCHED_FIFO`` at ``priority`` (see :attr:`CanSettings.realtime_priority`); a warning,
    not a failure, if the system refuses."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as err:
        log.warning(
            "realtime_priority %d: the system refused SCHED_FIFO (%s); running without it",
            priority,
            getattr(err, "strerror", None) or err,
        )
        return
    log.info("real-time scheduling: SCHED_FIFO at priority %d", priority)


@contextlib.contextmanager
def log_aside():
    """While in the block, this process's log records are queued where they are made and
    written by a thread of their own, through the handlers the root logger had; all of them
    written by the end of the block."""
    root = logging.getLogger()
    handlers = root.handlers[:]
    records: queue.SimpleQueue = queue.SimpleQueue()
    writer = logging.handlers.QueueListener(records, *handlers, respect_handler_level=True)
    root.handlers = [logging.handlers.QueueHandler(records)]
    writer.start()
    try:
        yield
    finally:
        writer.stop()
        root.handlers = handlers


def run_bridge(config: BridgeConfig, stop: threading.Event | None = None) -> int:
    """Run the bridge of ``config`` until stopped (SIGINT, SIGTERM or SIGHUP), its log
    written aside (:func:`log_aside`); :class:`BusUnavailable` if its bus cannot be opened at
    the start."""
    stop = stop or StopSignals().take().event  # before any thread: all inherit the mask
    with log_aside():
        return _run_bridge(config, stop)


def _run_bridge(config: BridgeConfig, stop: threading.Event) -> int:
    if config.can.realtime_priority:  # before the loop's threads start: they inherit it
        use_realtime_priority(config.can.realtime_priority)
    robot = config.robot.robot
    rejects = RejectLog(log, f"bridge {robot}")
    with open_session(config.zenoh) as session:
        port = BridgePort(session, Keys(config.robot.team), [robot], rejects)
        node = BridgeNode(config, port, stop)
        token = None
        try:
            node.open()
            token = session.liveliness().declare_token(Keys(config.robot.team).bridge_alive(robot))
            return node.run()
        finally:
            if token is not None:
                token.undeclare()
            node._close_bus()
            port.close()
