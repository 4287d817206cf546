"""One robot's agent as a standalone process on Zenoh: ``heft agent --config robot.toml``.

The process is the I/O around an :class:`~agent.agent.Agent`: it receives its robot's
measurements (from the plant or the robot's CAN bridge), its neighbours' shares, and the
liveliness of its neighbours; it publishes force commands, its share, and now and then its
estimates and status. It declares a liveliness token so the plant and the neighbours notice
when it is gone.

Clocks:

- ``lockstep``: tick ``k`` is stepped once its measurement *and* every live neighbour's share
  of tick ``k − 1`` have arrived (a share the fault injector dropped is not waited for). The
  plant waits for every command, so a run is deterministic: the same as in one process. A
  message the network loses (e.g. one sent before the subscription reached the router) is sent
  again: an idle agent repeats its latest share, and answers a repeated measurement with its
  command again.
- ``realtime``: tick ``k`` is stepped as soon as its measurement arrives, with whatever shares
  are there; a late share is used at a later tick (counted as late).

A neighbour whose liveliness token disappears (killed, or hung past its lease) is lost: the
agent halts the team (see :mod:`agent.agent`) and keeps answering with zero force until it is
told to stop.
"""

from __future__ import annotations

import logging
import signal
import threading
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

from agent.agent import DONE, HALTED, PHASES, Agent
from agent.config import AgentConfig, AgentTuning, ConfigError, from_table
from agent.faults import FaultSettings
from agent.protocol import CLOCKS, DecodeError, Keys, Measurement, Status, decode, encode
from agent.zenoh_session import EventQueue, ZenohSettings, open_session, tick_publisher
from agent.zenoh_transport import ZenohTransport

log = logging.getLogger("heft.agent")
RESEND_AFTER_S = 0.2
"""An agent idle this long sends its latest share again (lockstep tolerates lost messages)."""


@dataclass(frozen=True)
class AgentNodeConfig:
    """A robot's ``robot.toml``: who it is, where its team's Zenoh network is, its limits."""

    robot: int
    n: int
    neighbours: tuple[int, ...]
    team: str = "heft"
    period_s: float = 0.01
    """Sensor period (s): the plant's or the robot's odometry rate."""
    seed: int = 1
    clock: str = "lockstep"
    report_every: int = 5
    """Publish estimates every this many ticks (and every tick once done)."""
    zenoh: ZenohSettings = ZenohSettings()
    faults: FaultSettings = FaultSettings()
    tuning: AgentTuning = AgentTuning()

    def validate(self, where: str) -> None:
        if self.n < 2:
            raise ConfigError(f"{where}.n: expected at least 2 robots, got {self.n}")
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
        if not self.period_s > 0 or self.report_every < 1:
            raise ConfigError(f"{where}: period_s must be > 0 and report_every >= 1")
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
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as err:
        raise ConfigError(f"{path}: cannot read ({err.strerror or err})") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise ConfigError(f"{path}: not valid TOML: {err}") from None
    try:
        return from_table(AgentNodeConfig, data, "agent")
    except ConfigError as err:
        raise ConfigError(f"{path}: {err}") from None


class AgentNode:
    """The agent process's loop (see the module docstring)."""

    def __init__(self, config: AgentNodeConfig, session, stop: threading.Event | None = None):
        self.config = config
        self.keys = Keys(config.team)
        self.agent = Agent(config.agent_config())
        self.stop = stop or threading.Event()
        self.events = EventQueue()
        self.measurements: dict[int, Measurement] = {}
        self.shares = []
        self.have: set[tuple[int, int]] = set()
        self.lost: set[int] = set()
        self.decode_errors = 0
        self.late = 0
        self.next_tick = 0
        self.last_phase = -1
        self.last_command: bytes | None = None
        self.last_share = None
        self.last_sent = time.monotonic()
        robot, keys = config.robot, self.keys
        wake = lambda: self.events.put(None)  # noqa: E731
        self.transport = ZenohTransport(
            session, keys, robot, config.neighbours, config.faults, wake=wake
        )
        self._force = tick_publisher(session, keys.robot(robot, "force"))
        self._estimate = session.declare_publisher(keys.robot(robot, "estimate"))
        self._status = session.declare_publisher(keys.robot(robot, "status"))
        self._subscribers = [
            session.declare_subscriber(
                keys.robot(robot, "velocity"),
                lambda s: self.events.put(("velocity", s.payload.to_bytes())),
            ),
            session.declare_subscriber(
                keys.control, lambda s: self.events.put(("control", s.payload.to_bytes()))
            ),
        ]
        liveliness = session.liveliness()
        self._token = liveliness.declare_token(keys.robot(robot, "alive"))
        self._alive_subscribers = [
            liveliness.declare_subscriber(
                keys.robot(j, "alive"),
                lambda s, j=j: self.events.put(("alive", j, str(s.kind))),
                history=True,
            )
            for j in config.neighbours
        ]

    # ------------------------------------------------------------------ events
    def _handle(self, event) -> None:
        if event is None:
            return  # a share arrived; collected when stepping
        kind = event[0]
        if kind == "velocity":
            try:
                m = decode(Measurement, event[1])
            except DecodeError as err:
                self._decode_error("measurement", err)
                return
            if m.robot != self.config.robot:
                self._decode_error("measurement", f"for robot {m.robot}")
                return
            if m.tick >= self.next_tick:
                self.measurements[m.tick] = m
            elif m.tick == self.next_tick - 1 and self.last_command is not None:
                self._force.put(self.last_command)  # the plant missed it: it asks again
        elif kind == "control":
            try:
                body = decode("control", event[1])
            except DecodeError as err:
                self._decode_error("control", err)
                return
            if body.get("command") == "stop":
                log.info("robot %d: told to stop", self.config.robot)
                self.stop.set()
        elif kind == "alive":  # a neighbour's token appeared (nothing to do) or disappeared
            j, what = event[1], event[2]
            if "DELETE" in what.upper():
                if self.agent.phase == DONE or self.stop.is_set():
                    log.info(
                        "robot %d: neighbour %d left after the team finished", self.config.robot, j
                    )
                    return
                if j not in self.lost:
                    log.warning(
                        "robot %d: lost neighbour %d; halting the team", self.config.robot, j
                    )
                self.lost.add(j)
                self.agent.halt()

    def _decode_error(self, what: str, err) -> None:
        self.decode_errors += 1
        if self.decode_errors <= 10 or self.decode_errors % 1000 == 0:
            log.warning(
                "robot %d: undecodable %s #%d: %s", self.config.robot, what, self.decode_errors, err
            )

    # ------------------------------------------------------------------ stepping
    def _collect_shares(self) -> None:
        for share in self.transport.receive():
            self.shares.append(share)
            self.have.add((share.sender, share.tick))
            if share.tick < self.next_tick - 1:
                self.late += 1

    def _can_step(self, k: int) -> bool:
        if k not in self.measurements:
            return False
        if self.config.clock == "realtime" or k == 0:
            return True
        dropped = self.transport.faults.dropped
        for j in self.config.neighbours:
            if j in self.lost:
                continue
            if (j, k - 1) not in self.have and (j, k - 1) not in dropped:
                return False
        return True

    def _step(self, k: int) -> None:
        agent = self.agent
        measurement = self.measurements.pop(k)
        command, share = agent.step(measurement, self.shares)
        self.shares = []
        self.last_command = encode(command)
        self._force.put(self.last_command)
        self.transport.send(share)
        self.last_share = share
        self.last_sent = time.monotonic()
        if k % self.config.report_every == 0 or agent.phase >= DONE:
            self._estimate.put(encode(agent.estimates()))
        if agent.phase != self.last_phase or k % 100 == 0:
            if agent.phase != self.last_phase:
                log.info("robot %d: tick %d: phase %s", self.config.robot, k, PHASES[agent.phase])
            self.last_phase = agent.phase
            self._status.put(encode(self.status(k)))
        self.next_tick = k + 1
        if k % 50 == 0:  # forget what is too old to matter
            forget = k - 50
            self.have = {(j, t) for j, t in self.have if t >= forget}
            self.transport.faults.forget(forget)
            for old in [t for t in self.measurements if t < k]:
                del self.measurements[old]

    def status(self, tick: int) -> Status:
        return Status(
            robot=self.config.robot,
            tick=tick,
            phase=PHASES[self.agent.phase],
            rejected=self.agent.rejected + self.transport.foreign,
            decode_errors=self.decode_errors + self.transport.decode_errors,
            late=self.late,
            lost_neighbours=tuple(sorted(self.lost)),
        )

    def run(self) -> int:
        """Run until told to stop; returns the process exit status."""
        log.info(
            "robot %d: up (team %s, neighbours %s, %s clock)",
            self.config.robot,
            self.config.team,
            list(self.config.neighbours),
            self.config.clock,
        )
        while not self.stop.is_set():
            due = self.transport.next_release()
            timeout = 0.05 if due is None else max(0.0, min(0.05, due - time.monotonic()))
            self.events.drain(self._handle, timeout)
            self._collect_shares()
            if self.config.clock == "realtime" and self.measurements:
                self.next_tick = max(self.next_tick, min(self.measurements))
            while self._can_step(self.next_tick):
                self._step(self.next_tick)
                self._collect_shares()
            if self.last_share is not None and time.monotonic() - self.last_sent > RESEND_AFTER_S:
                # Idle: a neighbour may be waiting for a share the network lost. Say it again.
                self.transport.send(self.last_share)
                self.last_sent = time.monotonic()
        self._status.put(encode(self.status(self.next_tick - 1)))
        return 3 if self.agent.phase == HALTED else 0

    def close(self) -> None:
        self._token.undeclare()
        for sub in self._subscribers + self._alive_subscribers:
            sub.undeclare()
        self.transport.close()


def run_agent(config: AgentNodeConfig) -> int:
    """Open the session, run the node until stopped (control message, SIGINT or SIGTERM)."""
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    with open_session(config.zenoh) as session:
        node = AgentNode(config, session, stop)
        try:
            return node.run()
        finally:
            node.close()
