"""The robot-I/O seam over Eclipse Zenoh (see :mod:`agent.platform.robot_io`).

Each port subscribes by name to exactly the keys of the robots it serves — never to a
wildcard — so an agent hears only its own robot's measurements and its neighbours'
liveliness, and a bridge only its robot's commands. Subscription callbacks run on Zenoh's
threads: they only queue the raw payload with its arrival time; :meth:`poll` decodes on the
caller's thread, counting what it rejects.
"""

from __future__ import annotations

import time
from collections.abc import Iterable

from agent.platform.process import RejectLog
from agent.platform.protocol import Command, Control, DecodeError, Keys, Measurement, decode, encode
from agent.platform.robot_io import (
    AgentReport,
    AgentsPort,
    Event,
    Liveliness,
    RobotPort,
    RobotReport,
)
from agent.platform.zenoh_session import tick_publisher, watch_liveliness


class _Wire:
    """Publishers by key (per-tick ones sent at once), subscribers, and decoding."""

    def __init__(self, session, keys: Keys, port):
        self.session = session
        self.keys = keys
        self.port = port
        self.publishers: dict[str, object] = {}
        self.subscribers: list = []

    def publish(self, message: object, per_tick: bool = False) -> None:
        key = self.keys.of(message)
        publisher = self.publishers.get(key)
        if publisher is None:
            if per_tick:
                publisher = tick_publisher(self.session, key)
            else:
                publisher = self.session.declare_publisher(key)
            self.publishers[key] = publisher
        publisher.put(encode(message))

    def subscribe(self, key: str, kind: type, robot: int | None) -> None:
        """Queue what arrives on ``key``: a ``kind`` message, for ``robot`` if not None."""
        put = self.port.events.put
        self.subscribers.append(
            self.session.declare_subscriber(
                key, lambda s: put((time.perf_counter(), kind, robot, s.payload.to_bytes()))
            )
        )

    def watch(self, key: str) -> None:
        put = self.port.events.put
        self.subscribers.append(
            watch_liveliness(
                self.session, key, lambda k, alive: put((time.perf_counter(), k, alive))
            )
        )

    def take(self, event, out: list[Event]) -> None:
        """Decode one queued event into ``out`` (or count it as rejected)."""
        if event is None:
            return
        if len(event) == 3:  # liveliness
            at, key, alive = event
            try:
                robot = Keys.robot_of(key)
            except DecodeError as err:
                self.port.rejects("liveliness", err)
                return
            who = "bridge" if key == self.keys.bridge_alive(robot) else "agent"
            out.append((at, Liveliness(robot, alive, who)))
            return
        at, kind, robot, payload = event
        name = kind.__name__.lower()
        try:
            message = decode(kind, payload)
        except DecodeError as err:
            self.port.rejects(name, err)
            return
        if robot is not None and message.robot != robot:
            self.port.rejects(name, f"robot {message.robot} on robot {robot}'s key", "wrong robot")
            return
        out.append((at, message))

    def close(self) -> None:
        for sub in self.subscribers:
            sub.undeclare()
        for publisher in self.publishers.values():
            publisher.undeclare()


class ZenohRobotPort(RobotPort):
    """An agent's side of its robot over Zenoh; :meth:`declare_alive` declares the agent's
    liveliness token."""

    def __init__(
        self,
        session,
        keys: Keys,
        robot: int,
        neighbours: Iterable[int],
        rejects: RejectLog,
    ):
        super().__init__(robot, neighbours, rejects)
        self._wire = _Wire(session, keys, self)
        self._wire.subscribe(keys.velocity(robot), Measurement, robot)
        self._wire.subscribe(keys.control(), Control, None)
        for j in sorted(self.neighbours):
            self._wire.watch(keys.alive(j))
        self._token = None

    def declare_alive(self) -> None:
        """Declare the agent's liveliness token: the plant starts the run once every agent's
        is there, so declare it once every subscription of the process is in place."""
        self._token = self._wire.session.liveliness().declare_token(
            self._wire.keys.alive(self.robot)
        )

    def _take(self, event, out: list[Event]) -> None:
        self._wire.take(event, out)

    def send(self, command: Command) -> None:
        self._wire.publish(command, per_tick=True)

    def report(self, message: AgentReport) -> None:
        self._wire.publish(message)

    def close(self) -> None:
        if self._token is not None:
            self._token.undeclare()
        self._wire.close()


class ZenohAgentsPort(AgentsPort):
    """A robot's side over Zenoh, for the agents of ``robots``.

    With ``bridges`` the robots sit behind AGV bridges (see :mod:`simulator.can_drivers`):
    their commands come over CAN, not from here, so the port does not subscribe to them, and
    it watches each robot's bridge's liveliness beside its agent's."""

    def __init__(
        self,
        session,
        keys: Keys,
        robots: Iterable[int],
        rejects: RejectLog,
        bridges: bool = False,
    ):
        super().__init__(robots, rejects)
        self._wire = _Wire(session, keys, self)
        for i in sorted(self.robots):
            if bridges:
                self._wire.watch(keys.bridge_alive(i))
            else:
                self._wire.subscribe(keys.force(i), Command, i)
            self._wire.watch(keys.alive(i))
        self._wire.subscribe(keys.control(), Control, None)

    def _take(self, event, out: list[Event]) -> None:
        self._wire.take(event, out)

    def send(self, measurement: Measurement) -> None:
        self._wire.publish(measurement, per_tick=True)

    def report(self, message: RobotReport) -> None:
        self._wire.publish(message)

    def close(self) -> None:
        self._wire.close()
