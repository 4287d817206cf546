"""One robot's agent as a standalone process: ``heft agent --config robot.toml``.

The process is the I/O around an :class:`~agent.algorithm.agent.Agent`: through its robot port
(:mod:`agent.platform.robot_io`) it receives its robot's measurements (from the plant or the robot's
CAN bridge), the team's control messages and the liveliness of its neighbours, and sends force
commands and, now and then, its estimates and status; through its transport
(:mod:`agent.platform.transport`, with :mod:`agent.platform.faults` around it) it exchanges shares
with its graph neighbours. On Zenoh the port declares a liveliness token, so the plant and the
neighbours notice when the agent is gone.

Clocks:

- ``lockstep``: tick ``k`` is stepped once its measurement *and* every live neighbour's share
  of tick ``k − 1`` have arrived (a share the fault injector dropped is not waited for). The
  plant waits for every command, so a run is deterministic: the same as in one process. A
  message the network loses (e.g. one sent before the subscription reached the router) is sent
  again: an idle agent repeats its latest two shares (a neighbour may be a tick behind), and
  answers a repeated measurement with its command again. The clock starts at tick 0.
- ``realtime``: tick ``k`` is stepped as soon as its measurement arrives, with whatever shares
  are there; a late share is used at a later tick (counted as late). The clock starts at the
  first of two consecutive samples.

Either way a measurement stamped more than :data:`TICK_WINDOW` ticks ahead is rejected, never
adopted as the clock.

A neighbour whose liveliness token disappears (killed, or hung past its lease) is lost: the
agent halts the team (see :mod:`agent.algorithm.phase_machine`) and answers with zero force. When
every neighbour's token is back (the link is up again, or the robot's agent was restarted), the
robot is ready to begin again, and once every robot is, the team starts over from Step 1, one
more *rejoin* (:mod:`agent.algorithm.coordination`): a robot that was away missed its own
measurements, a restarted one lost all it knew, and the load moved unobserved meanwhile, so
nothing estimated before the halt is kept.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from agent.algorithm.agent import Agent
from agent.algorithm.tuning import AgentConfig, AgentTuning
from agent.platform.config import (
    MAX_ROBOTS,
    MAX_SEED,
    ConfigError,
    bounded,
    check_bounds,
    from_table,
    read_toml,
)
from agent.platform.faults import FaultSettings, FaultyTransport
from agent.platform.log_lines import LogLines
from agent.platform.process import RejectLog, StopSignals
from agent.platform.protocol import (
    CLOCKS,
    Command,
    Control,
    Keys,
    Measurement,
    Phase,
    Share,
    Status,
)
from agent.platform.resend import ResendTimeout
from agent.platform.robot_io import Liveliness, RobotPort
from agent.platform.zenoh_robot_io import ZenohRobotPort
from agent.platform.zenoh_session import ZenohSettings, open_session
from agent.platform.zenoh_transport import ZenohTransport

log = logging.getLogger("heft.agent")
TICK_WINDOW = 500
"""A measurement stamped more than this many ticks ahead of the agent's clock is rejected. In
lockstep the clock starts at 0 (the plant's first tick); in real time at the first of two
consecutive samples (a robot's ticks count from its own synchronised clock)."""
SLOW_TICK_S = 2.0
"""Lockstep: a tick that waits this long for its neighbours' shares is logged (once)."""
IDLE_WAIT_S = 0.2
"""The longest the loop waits for something to arrive before it looks at its stop."""


@dataclass(frozen=True)
class AgentNodeConfig:
    """A robot's ``robot.toml``: who it is, where its team's Zenoh network is, its limits.

    Every value has a range, checked by :meth:`validate` before the agent starts (the
    tables' own: :class:`~agent.platform.zenoh_session.ZenohSettings`,
    :class:`~agent.algorithm.tuning.AgentTuning`).
    """

    robot: int
    """This robot's id, in 1..n."""
    n: int
    """Robots in the team: 2 to :data:`~agent.platform.config.MAX_ROBOTS` (32)."""
    neighbours: tuple[int, ...]
    """Its graph neighbours: other robots of 1..n, at least one, each once."""
    team: str = "heft"
    """The first level of every key: non-empty, without / * $ ? #."""
    period_s: float = bounded(0.01, 0.001, 0.1, "s")
    """Sensor period (s): the plant's or the robot's odometry rate, 10 Hz to 1 kHz."""
    seed: int = bounded(1, 0, MAX_SEED)
    """Seed of the random push that starts Step 1 (mixed with the robot id)."""
    clock: str = "lockstep"
    """``lockstep`` or ``realtime``."""
    report_every: int = bounded(5, 1, 1000, "ticks")
    """Publish estimates every this many ticks (and every tick once done)."""
    zenoh: ZenohSettings = ZenohSettings()
    faults: FaultSettings = FaultSettings()
    """Injected message loss and delay (tests): ``drop`` in [0, 1), ``delay_s`` in
    [0, 10] s."""
    tuning: AgentTuning = AgentTuning()

    MAX_DELAY_S = 10.0
    """The largest injected delay (s) (``heft run --delay-ms``: at most 10000)."""

    def validate(self, where: str) -> None:
        """:class:`ConfigError` naming the key and its range unless every value is in range."""
        if not 2 <= self.n <= MAX_ROBOTS:
            raise ConfigError(f"{where}.n: expected 2 to {MAX_ROBOTS} robots, got {self.n}")
        if not 1 <= self.robot <= self.n:
            raise ConfigError(f"{where}.robot: expected 1..{self.n}, got {self.robot}")
        if not self.neighbours:
            raise ConfigError(f"{where}.neighbours: a robot needs at least one neighbour")
        for j in self.neighbours:
            if not 1 <= j <= self.n or j == self.robot:
                raise ConfigError(f"{where}.neighbours: {j} is not another robot of 1..{self.n}")
        if len(set(self.neighbours)) != len(self.neighbours):
            raise ConfigError(f"{where}.neighbours: repeated robot")
        if self.clock not in CLOCKS:
            raise ConfigError(f"{where}.clock: expected lockstep or realtime, got {self.clock!r}")
        check_bounds(self, where)
        if not self.faults.delay_s <= self.MAX_DELAY_S:
            raise ConfigError(
                f"{where}.faults.delay_s: expected a number in [0, {self.MAX_DELAY_S:g}] s,"
                f" got {self.faults.delay_s!r}"
            )
        self.tuning.check_period(f"{where}.tuning", self.period_s, f"period_s = {self.period_s:g}")
        try:
            Keys(self.team)
        except ValueError as err:
            raise ConfigError(f"{where}.team: {err}") from None

    def agent_config(self) -> AgentConfig:
        return AgentConfig(
            robot=self.robot,
            n=self.n,
            neighbours=self.neighbours,
            period_s=self.period_s,
            seed=self.seed,
            tuning=self.tuning,
        )


def load_agent_config(path: str | Path) -> AgentNodeConfig:
    """Read ``robot.toml``; :class:`ConfigError` (one line naming the key) if it is bad."""
    data = read_toml(path)
    data.pop("can", None)  # the robot's AGV bridge's table (bridge/config.py checks it)
    try:
        return from_table(AgentNodeConfig, data, "agent")
    except ConfigError as err:
        raise ConfigError(f"{path}: {err}") from None


class AgentNode:
    """The agent process's loop (see the module docstring), on any port and transport."""

    def __init__(
        self,
        config: AgentNodeConfig,
        port: RobotPort,
        transport: FaultyTransport,
        stop: threading.Event | None = None,
    ):
        self.config = config
        self.robot = config.robot
        self.agent = Agent(config.agent_config())
        self.port = port
        self.transport = transport
        self.stop = stop or threading.Event()
        self.measurements: dict[int, Measurement] = {}
        self.shares = []
        self.have: set[tuple[int, int]] = set()
        self.lost: set[int] = set()
        self.present: set[int] = set()
        """The neighbours whose liveliness token is there."""
        self.late = 0
        self.next_tick = 0
        self.last_phase: Phase | None = None
        self.alarmed = False
        """Whether this robot's probes have found the load changed (logged once until the team
        restarts for it: one more load change)."""
        self.last_command: Command | None = None
        self.recent_shares: deque[Share] = deque(maxlen=2)
        self.last_sent = time.monotonic()
        self.resend = ResendTimeout()
        """After how long idle the latest shares go again: the time a tick takes, adapted."""
        self.resent = False
        """Whether the shares went again since the last step (that interval is no sample)."""
        self.told = -1
        """The last tick whose long wait was logged."""

    # ------------------------------------------------------------------ events
    def _handle(self, item) -> None:
        if isinstance(item, Measurement):
            waiting = self.config.clock == "realtime" and self.last_command is None
            if not waiting and item.tick > self.next_tick + TICK_WINDOW:
                # Not adopted as the new clock: only a clock gone wrong (or a forger) says so.
                why = "tick out of window"
                self.port.rejects("measurement", f"tick {item.tick} at tick {self.next_tick}", why)
            elif item.tick >= self.next_tick:
                self.measurements[item.tick] = item
                if waiting and len(self.measurements) > TICK_WINDOW:
                    latest = max(self.measurements)
                    del self.measurements[latest]
                    self.port.rejects(
                        "measurement", f"tick {latest} before the start", "unconfirmed"
                    )
            elif item.tick == self.next_tick - 1 and self.last_command is not None:
                self.port.send(self.last_command)  # the plant missed it: it asks again
        elif isinstance(item, Control):
            log.info("robot %d: told to %s", self.robot, item.command)
            self.stop.set()
        elif isinstance(item, Liveliness) and item.alive:
            j = item.robot
            self.present.add(j)
            if j in self.lost:
                self.lost.discard(j)
                log.info("robot %d: neighbour %d is back", self.robot, j)
            self.agent.team_back = self.present >= set(self.config.neighbours)
        elif isinstance(item, Liveliness):
            j = item.robot
            self.present.discard(j)
            self.agent.team_back = False
            if self.agent.phase == Phase.DONE or self.stop.is_set():
                log.info("robot %d: neighbour %d left after the team finished", self.robot, j)
                return
            if j not in self.lost:
                log.warning("robot %d: lost neighbour %d; halting the team", self.robot, j)
            self.lost.add(j)
            self.agent.halt()

    # ------------------------------------------------------------------ stepping
    def _collect_shares(self) -> None:
        for share in self.transport.receive(self.robot):
            self.shares.append(share)
            self.have.add((share.sender, share.tick))
            if share.tick < self.next_tick - 1:
                self.late += 1

    def _can_step(self, k: int) -> bool:
        if k not in self.measurements:
            return False
        if self.config.clock == "realtime" or k == 0:
            return True
        for j in self.config.neighbours:
            if j in self.lost:
                continue
            if (j, k - 1) not in self.have and not self.transport.dropped(self.robot, j, k - 1):
                return False
        return True

    def _tell_a_long_wait(self) -> None:
        """Lockstep: log once a tick whose measurement waits :data:`SLOW_TICK_S` for shares."""
        k = self.next_tick
        if self.config.clock != "lockstep" or k not in self.measurements or k == self.told:
            return
        if time.monotonic() - self.last_sent < SLOW_TICK_S:
            return
        self.told = k
        missing = [
            j for j in self.config.neighbours if j not in self.lost and (j, k - 1) not in self.have
        ]
        log.warning(
            "robot %d: tick %d waits %.1f s for the shares of tick %d from robot(s) %s",
            self.robot,
            k,
            time.monotonic() - self.last_sent,
            k - 1,
            missing,
        )

    def _step(self, k: int) -> None:
        agent = self.agent
        measurement = self.measurements.pop(k)
        command, share = agent.step(measurement, self.shares)
        self.shares = []
        self.port.send(command)
        self.transport.send(share)
        self.recent_shares.append(share)
        now = time.monotonic()
        if self.last_command is not None and not self.resent:
            self.resend.observe(now - self.last_sent)
        self.last_sent, self.resent = now, False
        self.last_command = command
        if k % self.config.report_every == 0 or agent.phase >= Phase.DONE:
            self.port.report(agent.estimates())
        if agent.pipeline.changed and not self.alarmed:
            log.warning(
                "robot %d: tick %d: the load has changed (a probe scored %.1f standard"
                " deviations, above %g); asking the team to estimate it again",
                self.robot,
                k,
                agent.pipeline.change_score,
                agent.config.tuning.robust.change_threshold,
            )
        self.alarmed = agent.pipeline.changed
        if agent.phase != self.last_phase or k % 100 == 0:
            if agent.phase != self.last_phase:
                changes = agent.load_changes
                again = ""
                if changes and agent.phase == Phase.INERTIA:
                    again = f" (load change {changes}: the load changed)"
                elif agent.rejoins and agent.phase == Phase.EXCITE:
                    again = f" (rejoin {agent.rejoins}: every robot is back, from Step 1)"
                log.info("robot %d: tick %d: phase %s%s", self.robot, k, agent.phase.label, again)
            self.last_phase = agent.phase
            self.port.report(self.status(k))
        self.next_tick = k + 1
        if k % 50 == 0:  # forget what is too old to matter
            forget = k - 50
            self.have = {(j, t) for j, t in self.have if t >= forget}
            self.transport.forget(forget)
            for old in [t for t in self.measurements if t < k]:
                del self.measurements[old]

    def status(self, tick: int) -> Status:
        return Status(
            robot=self.robot,
            tick=tick,
            phase=self.agent.phase,
            rejected=self.agent.rejected,
            decode_errors=self.port.rejects.total,
            late=self.late,
            lost_neighbours=tuple(sorted(self.lost)),
            rejoins=self.agent.rejoins,
        )

    def pump(self, timeout: float) -> None:
        """Wait up to ``timeout`` for events, then step every tick that can be stepped."""
        due = self.transport.next_release()
        if self.recent_shares:
            resend = self.last_sent + self.resend.timeout_s
            due = resend if due is None else min(due, resend)
        if due is not None:
            timeout = max(0.0, min(timeout, due - time.monotonic()))
        for _, item in self.port.poll(timeout):
            self._handle(item)
        self._collect_shares()
        if self.config.clock == "realtime" and self.measurements:
            if self.last_command is None:
                # The robot's clock is taken from two consecutive samples, not from one message.
                first = [k for k in self.measurements if k + 1 in self.measurements]
                if not first:
                    return
                self.next_tick = min(first)
                for k in [k for k in self.measurements if k > self.next_tick + TICK_WINDOW]:
                    del self.measurements[k]
                    self.port.rejects("measurement", f"tick {k} at the start", "tick out of window")
            else:
                self.next_tick = max(self.next_tick, min(self.measurements))
        while self._can_step(self.next_tick):
            self._step(self.next_tick)
            self._collect_shares()
        self._tell_a_long_wait()
        if self.recent_shares and time.monotonic() - self.last_sent > self.resend.timeout_s:
            # Idle: a neighbour may be waiting for a share the network lost. Say it again. In
            # lockstep a neighbour is at most one tick behind: it may need the one before too.
            for share in self.recent_shares:
                self.transport.send(share)
            self.last_sent, self.resent = time.monotonic(), True

    def run(self) -> int:
        """Run until told to stop; returns the process exit status. What the loop logs at
        INFO and above goes to the team too, as :class:`~agent.platform.protocol.LogLine`\\ s
        (:mod:`agent.platform.log_lines`: a few a second at most)."""
        lines = LogLines(self.robot, lambda: self.next_tick - 1)
        root = logging.getLogger()
        root.addHandler(lines)
        try:
            log.info(
                "robot %d: up (team %s, neighbours %s, %s clock)",
                self.robot,
                self.config.team,
                list(self.config.neighbours),
                self.config.clock,
            )
            while not self.stop.is_set():
                self.pump(IDLE_WAIT_S)
                self._publish(lines)
            self.port.report(self.status(self.next_tick - 1))
        finally:
            root.removeHandler(lines)
        self._publish(lines)
        return 3 if self.agent.phase == Phase.HALTED else 0

    def _publish(self, lines: LogLines) -> None:
        for line in lines.take():
            self.port.report(line)


@contextmanager
def zenoh_agent_node(config: AgentNodeConfig, session, stop: threading.Event | None = None):
    """The agent node of ``config`` on an open Zenoh session (its port and transport are
    closed on leaving the ``with`` block)."""
    keys = Keys(config.team)
    rejects = RejectLog(log, f"robot {config.robot}")
    port = ZenohRobotPort(session, keys, config.robot, config.neighbours, rejects)
    shares = ZenohTransport(session, keys, config.robot, config.neighbours, rejects, port.wake)
    # Alive only once every subscription is in place: the plant starts the run on it, and a
    # share sent before its subscription reached the router is lost.
    port.declare_alive()
    try:
        yield AgentNode(config, port, FaultyTransport(shares, config.faults), stop)
    finally:
        shares.close()
        port.close()


def run_agent(config: AgentNodeConfig, stop: threading.Event | None = None) -> int:
    """Run the agent of ``config`` on Zenoh until stopped (a control message, or SIGINT,
    SIGTERM or SIGHUP)."""
    stop = stop or StopSignals().handle().event
    with open_session(config.zenoh) as session, zenoh_agent_node(config, session, stop) as node:
        return node.run()
