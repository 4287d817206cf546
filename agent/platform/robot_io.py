"""The robot-I/O seam: where an agent meets its robot, and a robot meets its agent.

An agent process never talks to hardware or to a network library itself, and neither does the
plant that stands in for the robots. Each holds a *port*, an interface with interchangeable
back-ends — as python-can puts every bus behind ``BusABC``, with a virtual one for tests:

- :class:`RobotPort`, the agent's side of its robot: measurements and the team's control
  messages in, force commands out, plus the liveliness of the agent's graph neighbours;
- :class:`AgentsPort`, a robot's side (the simulated plant's, for all ``n`` robots, or one AGV
  bridge's, for its robot): commands in, measurements out, plus the liveliness of the agents.

Both ``report`` telemetry for displays (estimates, status, log lines, truth, the plant's
counters) and ``poll`` for what arrived: each event is ``(arrival time, item)`` with ``item`` a
decoded, checked protocol message or a :class:`Liveliness` change. What cannot be decoded, or
arrives for a robot the port does not serve, is counted in the port's
:class:`~agent.platform.process.RejectLog` and never returned.

Back-ends: :class:`InMemoryRobots` (one process: tests and in-process nodes) here, and
:mod:`agent.platform.zenoh_robot_io` (one process per robot over Zenoh). A CAN back-end for the AGV
bridge plugs in as another :class:`AgentsPort`'s peer.
"""

from __future__ import annotations

import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from agent.platform.process import EventQueue, RejectLog
from agent.platform.protocol import (
    BridgeStatus,
    Clock,
    Command,
    Control,
    Estimates,
    LoadGeometry,
    LogLine,
    Measurement,
    PlantStatus,
    Status,
    Truth,
)

AgentReport = Estimates | Status | LogLine
RobotReport = Clock | Truth | LoadGeometry | PlantStatus | BridgeStatus


@dataclass(frozen=True, slots=True)
class Liveliness:
    """Robot ``robot``'s agent (or, ``who = "bridge"``, its AGV bridge) appeared (``alive``)
    or is gone (killed, or hung past its lease)."""

    robot: int
    alive: bool
    who: str = "agent"


Event = tuple[float, object]
"""``(time.perf_counter() when it arrived, Measurement | Command | Control | Liveliness)``."""


class _Port(ABC):
    """What both sides share: an event queue, a reject log, reports, closing."""

    def __init__(self, rejects: RejectLog):
        self.rejects = rejects
        self.events = EventQueue()

    def wake(self) -> None:
        """Make a waiting :meth:`poll` return (something it does not carry arrived)."""
        self.events.put(None)

    def poll(self, timeout: float | None) -> list[Event]:
        """Wait up to ``timeout`` s for something to arrive; return all that did."""
        out: list[Event] = []
        self.events.drain(lambda e: self._take(e, out), timeout)
        return out

    def _take(self, event, out: list[Event]) -> None:
        if event is not None:
            out.append(event)

    @abstractmethod
    def close(self) -> None:
        """Withdraw from the network (an agent's liveliness ends with it)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class RobotPort(_Port):
    """An agent's side of its robot ``robot``."""

    def __init__(self, robot: int, neighbours: Iterable[int], rejects: RejectLog):
        super().__init__(rejects)
        self.robot = robot
        self.neighbours = frozenset(neighbours)

    @abstractmethod
    def send(self, command: Command) -> None:
        """The force the robot applies from ``command.tick`` on."""

    @abstractmethod
    def report(self, message: AgentReport) -> None:
        """Telemetry for displays and the launcher."""


class AgentsPort(_Port):
    """A robot's side, for the agents of ``robots`` (all of a team for the plant)."""

    def __init__(self, robots: Iterable[int], rejects: RejectLog):
        super().__init__(rejects)
        self.robots = frozenset(robots)

    @abstractmethod
    def send(self, measurement: Measurement) -> None:
        """Robot ``measurement.robot``'s sample, to its agent."""

    @abstractmethod
    def report(self, message: RobotReport) -> None:
        """Telemetry for displays and the launcher."""


# ====================================================================== in memory
class InMemoryRobots:
    """The seam in one process: one :class:`AgentsPort` for the robots of a team of ``n``
    and a :class:`RobotPort` per agent, delivering at once (thread-safe).

    Every port's telemetry goes to ``report`` (called on the reporting thread); :meth:`stop`
    is the launcher's :class:`~agent.platform.protocol.Control`."""

    def __init__(
        self,
        neighbours: dict[int, tuple[int, ...]],
        rejects: RejectLog,
        report: Callable[[object], None] = lambda message: None,
    ):
        self.neighbours = neighbours
        self.rejects = rejects
        self.report = report
        self._lock = threading.Lock()
        self._agents: dict[int, _InMemoryRobotPort] = {}
        self._robots: _InMemoryAgentsPort | None = None

    def robots_port(self) -> AgentsPort:
        with self._lock:
            self._robots = _InMemoryAgentsPort(self, self.neighbours)
            alive = list(self._agents)
        for i in alive:
            self._robots.events.put((time.perf_counter(), Liveliness(i, True)))
        return self._robots

    def agent_port(self, robot: int) -> RobotPort:
        port = _InMemoryRobotPort(self, robot, self.neighbours[robot])
        with self._lock:
            self._agents[robot] = port
            present = [j for j in self.neighbours[robot] if j in self._agents]
        for j in present:  # as a liveliness subscriber hears the tokens already there
            port.events.put((time.perf_counter(), Liveliness(j, True)))
        self._liveliness(robot, True)
        return port

    def stop(self) -> None:
        for port in self._ports():
            port.events.put((time.perf_counter(), Control("stop")))

    def _ports(self) -> list[_Port]:
        with self._lock:
            return [*self._agents.values(), *([self._robots] if self._robots else [])]

    def _liveliness(self, robot: int, alive: bool) -> None:
        now = time.perf_counter()
        with self._lock:
            targets = [p for j, p in self._agents.items() if j in self.neighbours[robot]]
            if self._robots is not None:
                targets.append(self._robots)
        for port in targets:
            port.events.put((now, Liveliness(robot, alive)))

    def _to_agent(self, item: Measurement) -> None:
        port = self._agents.get(item.robot)
        if port is not None:
            port.events.put((time.perf_counter(), item))

    def _to_robots(self, item: Command) -> None:
        if self._robots is not None:
            self._robots.events.put((time.perf_counter(), item))

    def _leave(self, robot: int) -> None:
        with self._lock:
            self._agents.pop(robot, None)
        self._liveliness(robot, False)


class _InMemoryRobotPort(RobotPort):
    def __init__(self, hub: InMemoryRobots, robot: int, neighbours: Iterable[int]):
        super().__init__(robot, neighbours, hub.rejects)
        self._hub = hub

    def send(self, command: Command) -> None:
        self._hub._to_robots(command)

    def report(self, message: AgentReport) -> None:
        self._hub.report(message)

    def close(self) -> None:
        self._hub._leave(self.robot)


class _InMemoryAgentsPort(AgentsPort):
    def __init__(self, hub: InMemoryRobots, neighbours: dict[int, tuple[int, ...]]):
        super().__init__(neighbours, hub.rejects)
        self._hub = hub

    def send(self, measurement: Measurement) -> None:
        self._hub._to_agent(measurement)

    def report(self, message: RobotReport) -> None:
        self._hub.report(message)

    def close(self) -> None:
        pass
