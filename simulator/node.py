"""The plant as a process on Zenoh: ``heft sim SCENARIO``.

It stands where the real AGVs will: it publishes each robot's measurement on
``heft/<team>/robot/<id>/velocity``, applies each robot's latest command from
``heft/<team>/robot/<id>/force``, and publishes ground truth on ``heft/<team>/plant/truth`` for
evaluation and display only (no agent subscribes to it).

- ``lockstep``: tick ``k`` is published, and the plant steps only once every live agent's
  command for tick ``k`` has arrived: deterministic, as fast as the agents allow. A robot that
  has not answered within :data:`RESEND_AFTER_S` is sent the tick again.
- ``realtime``: the plant steps on the wall clock at the sensor rate, applying the newest
  command each robot has sent; late and missing commands are held (the previous one stays)
  and counted, and the latency from publishing a tick to receiving each command is measured.

Robots whose agent's liveliness token disappears get zero force from then on.
"""

from __future__ import annotations

import logging
import statistics
import threading
import time
from dataclasses import fields

from agent.protocol import Clock, Command, DecodeError, Keys, decode, encode, encode_json
from agent.zenoh_session import EventQueue, ZenohSettings, open_session, tick_publisher
from simulator.plant import Plant, Truth
from simulator.scenario import Scenario

log = logging.getLogger("heft.sim")
TRUTH_FIELDS = tuple(f.name for f in fields(Truth))
RESEND_AFTER_S = 0.2
"""Lockstep: a tick not answered within this time is sent again to the silent robots."""


def truth_message(truth: Truth) -> bytes:
    """Every tick, so no deep copy: the fields as they are (tuples become JSON arrays)."""
    return encode_json("truth", {name: getattr(truth, name) for name in TRUTH_FIELDS})


class PlantNode:
    """The plant's loop (see the module docstring)."""

    def __init__(
        self,
        scenario: Scenario,
        session,
        team: str,
        clock: str = "lockstep",
        stop: threading.Event | None = None,
        start_timeout_s: float = 30.0,
    ):
        self.scenario = scenario
        self.plant = Plant(scenario)
        self.keys = keys = Keys(team)
        self.clock = clock
        self.stop = stop or threading.Event()
        self.start_timeout_s = start_timeout_s
        self.events = EventQueue()
        self.alive: set[int] = set()
        self.lost: set[int] = set()
        self.commands: dict[int, Command] = {}
        self.decode_errors = 0
        self.late = 0
        self.missing = 0
        self.overruns = 0
        self.resent = 0
        self._sent: list[bytes] = []
        self.latencies: list[float] = []
        self._published_at = 0.0
        n = scenario.n
        self._velocity = [
            tick_publisher(session, keys.robot(i, "velocity")) for i in range(1, n + 1)
        ]
        self._clock = session.declare_publisher(keys.plant("clock"))
        self._truth = session.declare_publisher(keys.plant("truth"))
        self._status = session.declare_publisher(keys.plant("status"))
        self._subscribers = [
            session.declare_subscriber(
                keys.robot(0, "force"),
                lambda s: self.events.put(
                    ("force", str(s.key_expr), s.payload.to_bytes(), time.perf_counter())
                ),
            ),
            session.declare_subscriber(
                keys.control, lambda s: self.events.put(("control", s.payload.to_bytes()))
            ),
            session.liveliness().declare_subscriber(
                keys.robot(0, "alive"),
                lambda s: self.events.put(("alive", str(s.key_expr), str(s.kind))),
                history=True,
            ),
        ]

    # ------------------------------------------------------------------ events
    def _handle(self, event) -> None:
        kind = event[0]
        if kind == "force":
            _, key, payload, arrived = event
            try:
                command = decode(Command, payload)
                if command.robot != Keys.robot_of(key) or not 1 <= command.robot <= self.scenario.n:
                    raise DecodeError(f"command of robot {command.robot} on {key}")
            except DecodeError as err:
                self.decode_errors += 1
                if self.decode_errors <= 10:
                    log.warning("undecodable command #%d: %s", self.decode_errors, err)
                return
            if command.robot in self.lost:
                return
            previous = self.commands.get(command.robot)
            if previous is None or command.tick > previous.tick:
                self.commands[command.robot] = command
                if command.tick == self.plant.tick:
                    self.latencies.append(arrived - self._published_at)
        elif kind == "control":
            try:
                if decode("control", event[1]).get("command") == "stop":
                    self.stop.set()
            except DecodeError as err:
                log.warning("undecodable control message: %s", err)
        elif kind == "alive":
            try:
                robot = Keys.robot_of(event[1])
            except DecodeError:
                return
            if "DELETE" in event[2].upper():
                if self.stop.is_set():
                    log.info("robot %d: agent left (the run is over)", robot)
                    self.alive.discard(robot)
                    return
                if robot not in self.lost:
                    log.warning(
                        "robot %d: agent gone at t = %.2f s; it pushes no more",
                        robot,
                        self.plant.time_s,
                    )
                self.lost.add(robot)
                self.alive.discard(robot)
                self.commands.pop(robot, None)
                self.plant.command(robot, (0.0, 0.0))
                self.publish_status()
            elif robot not in self.lost:
                self.alive.add(robot)

    def _drain(self, timeout: float | None) -> None:
        self.events.drain(self._handle, timeout)

    # ------------------------------------------------------------------ ticks
    def _publish(self) -> None:
        k = self.plant.tick
        self._published_at = time.perf_counter()
        self._sent = [encode(m) for m in self.plant.measure()]
        for publisher, payload in zip(self._velocity, self._sent):
            publisher.put(payload)
        self._clock.put(encode(Clock(k, self.plant.time_s)))

    def _republish_to_the_silent(self) -> None:
        """Lockstep: send tick ``k`` again to the robots that have not answered it."""
        k = self.plant.tick
        for robot in range(1, self.scenario.n + 1):
            command = self.commands.get(robot)
            if robot not in self.lost and (command is None or command.tick < k):
                self._velocity[robot - 1].put(self._sent[robot - 1])
                self.resent += 1

    def _apply(self) -> None:
        k = self.plant.tick
        for robot in range(1, self.scenario.n + 1):
            command = self.commands.get(robot)
            if robot in self.lost or command is None:
                if robot not in self.lost:
                    self.missing += 1
                self.plant.command(robot, (0.0, 0.0))
                continue
            if command.tick < k:
                self.late += 1
            self.plant.command(robot, command.force)
        self._truth.put(truth_message(self.plant.truth()))
        self.plant.advance()

    def _everyone_answered(self) -> bool:
        k = self.plant.tick
        for robot in range(1, self.scenario.n + 1):
            if robot in self.lost:
                continue
            command = self.commands.get(robot)
            if command is None or command.tick < k:
                return False
        return True

    def wait_for_agents(self) -> bool:
        deadline = time.monotonic() + self.start_timeout_s
        n = self.scenario.n
        while len(self.alive) < n and not self.stop.is_set():
            if time.monotonic() > deadline:
                missing = sorted(set(range(1, n + 1)) - self.alive)
                log.error(
                    "agents of robots %s did not come up within %.0f s",
                    missing,
                    self.start_timeout_s,
                )
                return False
            self._drain(0.05)
        return not self.stop.is_set()

    def run(self) -> int:
        s = self.scenario
        log.info(
            "plant up: %r, %d robots, %s clock, team %s", s.name, s.n, self.clock, self.keys.team
        )
        if not self.wait_for_agents():
            self.publish_status()
            return 2
        log.info("all %d agents are up; starting", s.n)
        max_ticks = round(s.run.max_time_s / s.period_s)
        period = s.period_s
        start = time.monotonic()
        while not self.stop.is_set() and self.plant.tick <= max_ticks:
            self._publish()
            if self.clock == "lockstep":
                asked = time.monotonic()
                while not self.stop.is_set() and not self._everyone_answered():
                    self._drain(0.05)
                    if time.monotonic() - asked > RESEND_AFTER_S:
                        self._republish_to_the_silent()
                        asked = time.monotonic()
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
        log.info("plant stops at t = %.2f s (tick %d)", self.plant.time_s, self.plant.tick)
        self.publish_status()
        return 0

    def status(self) -> dict:
        lat = sorted(self.latencies)

        def pct(p: float) -> float | None:
            return lat[min(len(lat) - 1, round(p * (len(lat) - 1)))] * 1e3 if lat else None

        return {
            "tick": self.plant.tick,
            "time_s": self.plant.time_s,
            "clock": self.clock,
            "late_commands": self.late,
            "missing_commands": self.missing,
            "overruns": self.overruns,
            "resent": self.resent,
            "decode_errors": self.decode_errors,
            "lost": sorted(self.lost),
            "latency_ms_p50": pct(0.5),
            "latency_ms_p99": pct(0.99),
            "latency_ms_mean": statistics.fmean(lat) * 1e3 if lat else None,
            "latency_samples": len(lat),
        }

    def publish_status(self) -> None:
        self._status.put(encode_json("plant_status", self.status()))

    def close(self) -> None:
        for sub in self._subscribers:
            sub.undeclare()


def run_plant(
    scenario: Scenario,
    team: str,
    clock: str,
    zenoh: ZenohSettings,
    stop: threading.Event,
    start_timeout_s: float = 30.0,
) -> int:
    with open_session(zenoh) as session:
        node = PlantNode(scenario, session, team, clock, stop, start_timeout_s)
        try:
            return node.run()
        finally:
            node.close()
