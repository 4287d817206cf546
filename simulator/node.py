"""The plant as a process: ``heft sim SCENARIO``.

It stands where the real AGVs will, behind a robots' port (:mod:`agent.platform.robot_io`): it sends
each robot's measurement to its agent, applies each robot's latest command, and reports its
clock, ground truth (for evaluation and display only: no agent subscribes to it) and
counters.

Each tick is :mod:`simulator.lockstep`'s, the in-process run's, and so is the last one
(``run.max_time_s``); the clock says when the plant steps:

- ``lockstep``: tick ``k`` is published, and the plant steps only once every live agent's
  command for tick ``k`` has arrived: deterministic, as fast as the agents allow. A robot that
  has not answered within a timeout that follows the time a tick takes
  (:class:`~agent.platform.resend.ResendTimeout`) is sent the tick again.
- ``realtime``: the plant steps on the wall clock at the sensor rate, applying the newest
  command each robot has sent; late and missing commands are held (the previous one stays)
  and counted, and the latency from publishing a tick to receiving each command is measured.
  As an AGV's bridge does, a robot whose newest command is more than
  :data:`WATCHDOG_TICKS` ticks old gets zero force until it answers again (counted as
  missing): a robot cut off from the network stops pushing.

With velocity-commanded bases behind AGV bridges (``[agvs] profile = "velocity"`` over CAN)
the commands are the bridges' velocities, and zero is a standstill (the base brakes).

Robots whose agent's liveliness ends get zero force until it is back (the robot's agent
restarted, or its link up again): then the plant applies its commands again, as a real AGV
would.

It also tells displays the load's outline and the graph
(:class:`~agent.platform.protocol.LoadGeometry`) when it comes up and with each of its
statuses: a display or a recorder that joins late has it within :data:`STATUS_EVERY_S`.

The port is the robots' hardware as the plant stands in for it: Zenoh
(:class:`~agent.platform.zenoh_robot_io.ZenohAgentsPort`) when the agents talk to the plant
directly, or the AGVs' CAN buses (:class:`~simulator.can_drivers.CanDriversPort`, ``heft sim
--can``) when each robot's AGV bridge stands between them; then a robot is up once its agent and its
bridge are, and lost when either is gone.
"""

from __future__ import annotations

import logging
import statistics
import threading
import time
from collections import deque
from typing import TYPE_CHECKING

from agent.platform.geometry import Vec2
from agent.platform.process import RejectLog
from agent.platform.protocol import Clock, Command, Control, Keys, Measurement, PlantStatus
from agent.platform.resend import ResendTimeout
from agent.platform.robot_io import AgentsPort, Liveliness
from agent.platform.statistics import percentile
from agent.platform.zenoh_robot_io import ZenohAgentsPort
from agent.platform.zenoh_session import ZenohSettings, open_session
from simulator.lockstep import PlantTicks, RunEnd, VelocityCommand
from simulator.scenario import Scenario

if TYPE_CHECKING:
    from simulator.can_drivers import CanLink

log = logging.getLogger("heft.sim")
ZERO: Vec2 = (0.0, 0.0)
LATENCY_SAMPLES = 10_000
"""Command latencies kept for the percentiles: the newest 25 s of four robots at 100 Hz
(memory stays flat however long the plant runs)."""
WATCHDOG_TICKS = 20
"""Realtime: a robot's newest command older than this many ticks is no longer applied (200 ms
at the paper's 100 Hz, the AGV bridge's watchdog in a real-time run)."""
SLOW_TICK_S = 2.0
"""Lockstep: a tick that waits this long for a command is logged (once)."""
WAIT_S = 0.2
"""The longest the loop waits for something to arrive before it looks at its stop."""
STATUS_EVERY_S = 1.0
"""The plant's status (and the load's geometry) goes out this often (wall clock) while it
runs, besides at its end and each time a robot is lost: a plant killed before its end leaves
its counters behind."""


class PlantNode:
    """The plant's loop (see the module docstring), on any robots' port."""

    def __init__(
        self,
        scenario: Scenario,
        port: AgentsPort,
        clock: str = "lockstep",
        stop: threading.Event | None = None,
        start_timeout_s: float = 30.0,
        bridged: bool = False,
    ):
        self.scenario = scenario
        self.plant = PlantTicks(scenario, bridged=bridged)
        """The plant, tick by tick (the port carries the values: the buses quantise them;
        ``bridged``: the robots' AGV bridges run their admittance loops and command their
        bases' velocities, :class:`~simulator.lockstep.VelocityCommand`)."""
        self.geometry = scenario.load_geometry()
        self.port = port
        self.clock = clock
        self.stop = stop or threading.Event()
        self.start_timeout_s = start_timeout_s
        self.alive: set[int] = set()
        self.lost: set[int] = set()
        self.gone: dict[int, set[str]] = {}
        self.silent: set[int] = set()
        """Realtime: robots whose commands stopped (the watchdog gives them zero force)."""
        """What of each lost robot is gone (``agent``, ``bridge``) until it comes back."""
        self.commands: dict[int, Command | VelocityCommand] = {}
        self.late = 0
        self.missing = 0
        self.overruns = 0
        self.resent = 0
        self._sent: list[Measurement] = []
        self.latencies: deque[float] = deque(maxlen=LATENCY_SAMPLES)
        """The newest command latencies (s), for the percentiles of :meth:`status`."""
        self.latency_count = 0
        self._published_at = 0.0
        self.resend = ResendTimeout()

    # ------------------------------------------------------------------ events
    def _handle(self, arrived: float, item) -> None:
        if isinstance(item, (Command, VelocityCommand)):
            if item.tick > self.plant.tick:
                why = "tick from the future"
                self.port.rejects("command", f"tick {item.tick} at tick {self.plant.tick}", why)
                return
            if item.robot in self.lost:
                return
            previous = self.commands.get(item.robot)
            if previous is None or item.tick > previous.tick:
                self.commands[item.robot] = item
                if item.tick == self.plant.tick:
                    self.latencies.append(arrived - self._published_at)
                    self.latency_count += 1
        elif isinstance(item, Control):
            self.stop.set()
        elif isinstance(item, Liveliness):
            robot = item.robot
            if item.alive:
                gone = self.gone.get(robot, set())
                gone.discard(item.who)
                if robot in self.lost and not gone:
                    log.info(
                        "robot %d: back at t = %.2f s; it pushes again", robot, self.plant.time_s
                    )
                    self.lost.discard(robot)
                    del self.gone[robot]
                    self.publish_status()
                if robot not in self.lost:
                    self.alive.add(robot)
                return
            if self.stop.is_set():
                log.info("robot %d: %s left (the run is over)", robot, item.who)
                self.alive.discard(robot)
                return
            if robot not in self.lost:
                log.warning(
                    "robot %d: %s gone at t = %.2f s; it pushes no more",
                    robot,
                    item.who,
                    self.plant.time_s,
                )
            self.lost.add(robot)
            self.gone.setdefault(robot, set()).add(item.who)
            self.alive.discard(robot)
            self.commands.pop(robot, None)
            self.publish_status()

    def _drain(self, timeout: float | None) -> None:
        for arrived, item in self.port.poll(timeout):
            self._handle(arrived, item)

    # ------------------------------------------------------------------ ticks
    def _publish(self) -> None:
        k = self.plant.tick
        self._published_at = time.perf_counter()
        self._sent = self.plant.measure()
        for measurement in self._sent:
            self.port.send(measurement)
        self.port.report(Clock(k, self.plant.time_s))

    def _republish_to_the_silent(self) -> list[int]:
        """Lockstep: send tick ``k`` again to the robots that have not answered it; which."""
        k = self.plant.tick
        silent = []
        for robot in range(1, self.scenario.n + 1):
            command = self.commands.get(robot)
            if robot not in self.lost and (command is None or command.tick < k):
                self.port.send(self._sent[robot - 1])
                self.resent += 1
                silent.append(robot)
        return silent

    def _apply(self) -> None:
        commands = [self._command(robot) for robot in range(1, self.scenario.n + 1)]
        self.port.report(self.plant.apply(commands))

    def _command(self, robot: int) -> Vec2:
        """Robot ``robot``'s force for this tick (a bridged base's velocity): its newest
        command's, or zero when it is lost, has sent none or (on the wall clock) has been
        silent too long; late and missing commands counted."""
        k = self.plant.tick
        command = self.commands.get(robot)
        if robot in self.lost or command is None:
            if robot not in self.lost:
                self.missing += 1
            return ZERO
        if self.clock == "realtime" and k - command.tick > WATCHDOG_TICKS:
            if robot not in self.silent:
                self.silent.add(robot)
                log.warning(
                    "robot %d: no command for %d ticks at t = %.2f s; zero force until it"
                    " answers again",
                    robot,
                    k - command.tick,
                    self.plant.time_s,
                )
            self.missing += 1
            return ZERO
        if robot in self.silent:
            self.silent.discard(robot)
            log.info("robot %d: answering again at t = %.2f s", robot, self.plant.time_s)
        if command.tick < k:
            self.late += 1
        return command.force if isinstance(command, Command) else command.velocity

    def _everyone_answered(self) -> bool:
        k = self.plant.tick
        for robot in range(1, self.scenario.n + 1):
            if robot in self.lost:
                continue
            command = self.commands.get(robot)
            if command is None or command.tick < k:
                return False
        return True

    def _lockstep_wait(self) -> None:
        """Until every live robot answered this tick; the silent ones are sent it again after
        :attr:`resend`'s timeout (the time a tick takes, adapted)."""
        published = asked = time.monotonic()
        resent = told = False
        while not self.stop.is_set() and not self._everyone_answered():
            due = asked + self.resend.timeout_s
            self._drain(max(0.0, min(WAIT_S, due - time.monotonic())))
            if time.monotonic() >= due and not self._everyone_answered():
                silent = self._republish_to_the_silent()
                asked, resent = time.monotonic(), True
                if not told and asked - published > SLOW_TICK_S:
                    told = True
                    log.warning(
                        "tick %d: no command from robot(s) %s for %.1f s; sending it again",
                        self.plant.tick,
                        silent,
                        asked - published,
                    )
        if not resent and not self.stop.is_set():
            self.resend.observe(time.monotonic() - published)

    def wait_for_agents(self) -> bool:
        deadline = time.monotonic() + self.start_timeout_s
        n = self.scenario.n
        while len(self.alive) < n and not self.stop.is_set():
            if time.monotonic() > deadline:
                missing = sorted(set(range(1, n + 1)) - self.alive)
                log.error(
                    "robots %s were not up (agent, and bridge if any) within %.0f s",
                    missing,
                    self.start_timeout_s,
                )
                return False
            self._drain(WAIT_S)
        return not self.stop.is_set()

    def run(self) -> int:
        s = self.scenario
        pace = ""
        if self.clock == "realtime" and s.run.real_time_factor != 1.0:
            pace = f" at {s.run.real_time_factor:g} x real time"
        log.info("plant up: %r, %d robots, %s clock%s", s.name, s.n, self.clock, pace)
        self.port.report(self.geometry)
        if not self.wait_for_agents():
            self.publish_status()
            return 0 if self.stop.is_set() else 1  # stopped before the start, or agents missing
        log.info("all %d agents are up; starting", s.n)
        last_tick = RunEnd.of(s).last_tick
        period = s.period_s / s.run.real_time_factor  # wall-clock seconds per tick
        start = status_at = time.monotonic()
        while not self.stop.is_set() and self.plant.tick <= last_tick:
            self._publish()
            if self.clock == "lockstep":
                self._lockstep_wait()
            else:
                deadline = start + (self.plant.tick + 1) * period
                while True:
                    left = deadline - time.monotonic()
                    if left <= 0:
                        break
                    self._drain(left)
                if deadline - time.monotonic() < -period:
                    self.overruns += 1
            self._drain(0.0)
            self._apply()
            if time.monotonic() - status_at >= STATUS_EVERY_S:
                status_at = time.monotonic()
                self.publish_status()
        log.info("plant stops at t = %.2f s (tick %d)", self.plant.time_s, self.plant.tick)
        self.publish_status()
        return 0

    def status(self) -> PlantStatus:
        lat = list(self.latencies)

        def ms(q: float) -> float | None:
            return percentile(lat, q) * 1e3 if lat else None

        return PlantStatus(
            tick=self.plant.tick,
            time_s=self.plant.time_s,
            clock=self.clock,
            late_commands=self.late,
            missing_commands=self.missing,
            overruns=self.overruns,
            resent=self.resent,
            decode_errors=self.port.rejects.total,
            lost=tuple(sorted(self.lost)),
            latency_ms_p50=ms(50),
            latency_ms_p99=ms(99),
            latency_ms_mean=statistics.fmean(lat) * 1e3 if lat else None,
            latency_samples=self.latency_count,
        )

    def publish_status(self) -> None:
        self.port.report(self.geometry)
        self.port.report(self.status())


def run_plant(
    scenario: Scenario,
    team: str,
    clock: str,
    zenoh: ZenohSettings,
    stop: threading.Event,
    start_timeout_s: float = 30.0,
    can: CanLink | None = None,
) -> int:
    """Run the plant of ``scenario`` on Zenoh for team ``team`` until it is done or stopped;
    with ``can``, the robots are on CAN buses behind their AGV bridges (``heft sim --can``:
    :class:`~simulator.can_drivers.CanBusError` if a bus cannot be opened)."""
    rejects = RejectLog(log, "plant")
    robots = range(1, scenario.n + 1)
    if can is None:
        with open_session(zenoh) as session:
            port = ZenohAgentsPort(session, Keys(team), robots, rejects)
            try:
                return PlantNode(scenario, port, clock, stop, start_timeout_s).run()
            finally:
                port.close()
    from bridge.codec import AgvCodec
    from simulator.can_drivers import CanDriversPort, close_buses, open_buses

    buses = open_buses(can, robots)
    log.info(
        "robots on CAN: %s",
        ", ".join(f"{i} on {can.interface}/{can.channel_of(i)}" for i in robots),
    )
    try:
        with open_session(zenoh) as session:
            rest = ZenohAgentsPort(session, Keys(team), robots, rejects, bridges=True)
            port = CanDriversPort(rest, buses, clock, AgvCodec(scenario.agvs.profile))
            try:
                node = PlantNode(scenario, port, clock, stop, start_timeout_s, bridged=True)
                return node.run()
            finally:
                port.close()
    finally:
        close_buses(buses.values())
