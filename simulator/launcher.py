"""``heft run SCENARIO --transport zenoh``: router, plant and ``n`` agents as separate processes.

The launcher starts a Zenoh router (``heft router``), the plant (``heft sim``) and one
``heft agent`` per robot, each with its own ``robot.toml``, all on ``tcp/127.0.0.1`` with
multicast scouting off. It prefixes every child's log lines with its name, listens to the
agents' estimates and status and to the plant's truth (as any display would), and builds the
same :class:`~simulator.inprocess.RunOutcome` as the in-process run.

With ``can`` (``heft run --can``) the robots are AGVs on CAN: the plant plays their drivers
(``heft sim --can``, one bus per robot by default) and the launcher also starts one AGV bridge
per robot (``heft bridge``, its ``bridge-i.toml`` with a ``[can]`` table), which links the
robot's bus to its agent. A bridge is supervised as an agent is: one that dies is a lost robot.
The bridges' statuses go into the transport report (``bridges``).

Supervision. The launcher watches every process it started, not only what the team says:

- the team done → converged (``reason`` ``""``);
- the team halted, or an agent (or bridge) process gone → ``robot(s) [i, ...] lost``;
- the router or the plant process gone → ``router lost``, ``plant lost``;
- an agent (or bridge) gone before the run started, or the plant giving up waiting for them
  → ``agents did not come up``;
- the plant at the scenario's end → ``out of simulated time (run.max_time_s = … s)``;
- nothing heard from the plant for :data:`STALL_S` → ``stalled`` (the plant or router hangs);
- too long on the wall clock → ``wall-clock timeout``; asked to stop → ``interrupted``.

Each verdict is a short machine-readable ``reason`` and a sentence for people (``detail``).
Then it stops the plant, tells the agents to stop, and — whatever happened, success, failure,
a signal — stops every child it started (SIGTERM to all, then SIGKILL to what is left) and
closes its own session. Every child (:class:`~agent.platform.children.Child`) also asks the kernel
(Linux ``PR_SET_PDEATHSIG``) for a signal when the launcher dies, so even a ``kill -9`` of the
launcher leaves no orphan; and the folder of the processes' files that such a launcher leaves
is removed by the next run (:mod:`simulator.run_folder`).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import re
import sys
import threading
import time
from collections import defaultdict
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from agent.node import AgentNodeConfig
from agent.platform.children import Child, describe_exit, free_port, stop_all, wait_all
from agent.platform.config import to_toml
from agent.platform.evaluation import final_instant
from agent.platform.faults import FaultSettings
from agent.platform.process import RejectLog
from agent.platform.protocol import (
    BridgeStatus,
    Control,
    DecodeError,
    Estimates,
    Keys,
    Phase,
    PlantStatus,
    Status,
    Truth,
    decode,
    encode,
)
from agent.platform.zenoh_session import (
    SessionError,
    ZenohSettings,
    fifo_subscriber,
    open_session,
    take,
)
from bridge.config import CanSettings, can_table
from simulator.history import History
from simulator.inprocess import RunOutcome, Sample
from simulator.lockstep import INTERRUPTED, RunEnd, Verdict, halted, mass_verdict
from simulator.run_folder import run_folder
from simulator.scenario import Agvs, Scenario, scenario_to_toml

if TYPE_CHECKING:
    from simulator.can_drivers import CanLink

Progress = Callable[[float, str], None]
ROUTER_LOST = "router lost"
PLANT_LOST = "plant lost"
AGENTS_NOT_UP = "agents did not come up"
STALLED = "stalled"
WALL_TIMEOUT = "wall-clock timeout"
ROUTER_GRACE_S = 1.0
"""The router's time to exit on SIGTERM, last of all, before SIGKILL (``heft router`` waits for
its stop in a way that a signal landing on one of Zenoh's threads does not always wake)."""
HALT_GRACE_S = 0.5
FINAL_GRACE_S = 2.0
"""Messages from different processes cross: an instant after the final one may be complete
before the final one is. The run waits at least this long for the final instant itself, and
at least :data:`FINAL_GRACE_TICKS` ticks' worth of wall time at the run's pace (a slow machine
delays messages by more than 2 s)."""
FINAL_GRACE_TICKS = 50
FIFO_CAPACITY = 1 << 16
"""Messages each of the launcher's subscriptions holds before its reception waits."""
POLL_S = 0.002
"""How often :meth:`Collector.drain` looks at its subscriptions while they are empty."""
AGENT_GONE_S = 3.0
"""An agent process that exited mid-run: how long its neighbours have to halt the team before
the launcher names it lost itself (they notice a dead process at once, a hung one after the
2 s lease)."""
STALL_S = 15.0
"""Once the plant has started: no new truth for this long means it, or the router, hangs (in
lockstep a hung agent is dropped by the plant after its lease, so the truth goes on)."""
LAST_WORDS_S = 1.0
"""How long the launcher listens once the plant has exited (unless the run is over sooner):
its final status and the team's estimates of its last ticks may still be on their way."""
TICK_SLACK = 1000
"""How far ahead of the newest truth heard a message's tick may be: messages from different
processes cross on the way, and a loaded machine delays some (10 s at 100 Hz)."""
KEEP_TICKS = 500
"""Ticks of unmatched estimates and truth the collector keeps (a robot may lag behind)."""
BRIDGE_WATCHDOG_MS = 200
"""The bridges' command watchdog in a real-time CAN run: 20 sensor periods of the paper at
100 Hz, longer in proportion when the wall clock runs slower than real time
(``run.real_time_factor``)."""
LOCKSTEP_WATCHDOG_MS = BRIDGE_WATCHDOG_MS
"""The bridges' watchdog in a lockstep CAN run, on the bus's clock (``watchdog_clock = "bus"``):
20 ticks without a command. There the plant opens no tick before it has every robot's command
for the last one, so only a robot the plant gave up on goes 20 ticks without one; on the wall
clock a slow machine tripped it (in User-Mode Linux a velocity bridge heard no command for more
than 10 s once in a run of ``make hil``), and a trip changes the run: a force bridge's ZERO frames
load the plant, and a velocity bridge's stop forgets its admittance loop's state, which a run in
one process does not."""
PLANT_START_TIMEOUT_S = 300.0
"""How long the plant waits for every agent (and bridge) to come up. Ten processes that each
import numpy took 40 s to come up in User-Mode Linux; an agent that dies on the way is seen
by the launcher at once, so a long wait costs nothing when something fails."""
LOG = logging.getLogger("heft.launcher")


def robot_config(
    robot: int,
    scenario: Scenario,
    team: str,
    clock: str,
    zenoh: ZenohSettings,
    faults: FaultSettings | None = None,
) -> AgentNodeConfig:
    """The agent config of one robot of ``scenario`` whose session is ``zenoh``."""
    return AgentNodeConfig(
        robot=robot,
        n=scenario.n,
        neighbours=scenario.neighbours(robot),
        team=team,
        period_s=scenario.period_s,
        seed=scenario.run.seed,
        clock=clock,
        zenoh=zenoh,
        faults=faults or FaultSettings(),
        tuning=scenario.agent,
    )


def robot_toml(
    robot: int, scenario: Scenario, team: str, clock: str, router: str, faults: FaultSettings
) -> str:
    """The ``robot.toml`` of one robot of ``scenario``, a client of ``router``."""
    zenoh = ZenohSettings(mode="client", connect=(router,))
    config = robot_config(robot, scenario, team, clock, zenoh, faults)
    return to_toml(config, f"Agent of robot {robot} of scenario {scenario.name!r}, by heft run.")


def bridge_watchdog_ms(scenario: Scenario, clock: str) -> int:
    """The bridges' watchdog in a run of ``scenario`` on ``clock`` (see
    :data:`BRIDGE_WATCHDOG_MS` and :data:`LOCKSTEP_WATCHDOG_MS`)."""
    if clock == "lockstep":
        return LOCKSTEP_WATCHDOG_MS
    return min(10_000, math.ceil(BRIDGE_WATCHDOG_MS / min(1.0, scenario.run.real_time_factor)))


def can_settings(
    robot: int,
    can: CanLink,
    watchdog_ms: int = BRIDGE_WATCHDOG_MS,
    agvs: Agvs | None = None,
    clock: str = "realtime",
) -> CanSettings:
    """What robot ``robot``'s ``robot.toml`` says in its ``[can]`` table in a CAN run on
    ``clock`` (written by :func:`bridge.config.can_table`), which its AGV bridge (``heft
    bridge``) reads beside the agent's part: its robot's bus, as the plant opens it; node id =
    robot id; the tick from the plant's ``Sync`` frames, and in lockstep the watchdog on the
    bus's clock (:data:`LOCKSTEP_WATCHDOG_MS`); the scenario's AGV profile and admittance loop
    (``[agvs]``, ``[agvs.admittance]``; none: force drives)."""
    agvs = agvs or Agvs()
    return CanSettings(
        interface=can.interface,
        channel=can.channel_of(robot),
        node=robot,
        watchdog_ms=int(watchdog_ms),
        watchdog_clock="bus" if clock == "lockstep" else "wall",
        time_source="sync",
        profile=agvs.profile,
        admittance=agvs.admittance,
    )


class Collector:
    """What the launcher hears, as any display would: every robot's estimates and status, the
    plant's truth and counters.

    The final instant is decided by the team's state, not by message timing: it is the first
    instant at which every robot is done, ``max_i phase_since_i`` over the robots' ``done``
    estimates (and not before the scenario's ``end_s``) — the instant the in-process run ends
    at.

    Each subscription queues in Zenoh's own FIFO (:data:`FIFO_CAPACITY`), emptied by
    :meth:`drain`: reception never waits for this process's interpreter, so a launcher slowed
    down by its machine does not back up the router's link to it, where messages that may be
    dropped would be (a run whose final instant is missed ends on a later one)."""

    def __init__(
        self,
        session,
        keys: Keys,
        n: int,
        record_every: int,
        end_tick: int = 0,
        rejoin_s: float = HALT_GRACE_S,
    ):
        self.n = n
        self.end_tick = end_tick
        """The earliest final instant (the scenario's load changes and hold)."""
        self.rejoin_s = rejoin_s
        """How long a halted team is given to begin again before the run is over (robots that
        come back: a restarted agent, a link up again); by default only the moment it takes
        to hear who was lost."""
        self.rejoined = 0
        """The most rejoins heard from the team (:mod:`agent.algorithm.coordination`)."""
        self.rejoins: list[dict[str, int | None]] = []
        """Each new beginning: the tick the team halted at (``None``: its halt was not heard,
        e.g. the router was down) and the tick it began again."""
        self.halted_tick: int | None = None
        self.record_every = record_every
        """The history gets a complete instant at least this many ticks after the previous one
        it got (whichever ticks the agents report: every ``report_every``-th, the instant
        before it), and the final instant."""
        self._record_from = 0
        self.rejects = RejectLog(LOG, "launcher")
        self.estimates: dict[int, dict[int, Estimates]] = defaultdict(dict)  # instant → robot
        self.truths: dict[int, Truth] = {}
        self.history: History[Sample] = History()
        self.phase_ticks: dict[str, int] = {}
        self.newest: dict[int, Estimates] = {}
        """Each robot's newest estimates heard (since the team's latest rejoin)."""
        self.statuses: dict[int, Status] = {}
        """Each robot's latest status."""
        self.halted = False
        self.lost: set[int] = set()
        self.plant_status: PlantStatus | None = None
        self.bridges: dict[int, BridgeStatus] = {}
        """Each robot's bridge's latest status (a CAN run)."""
        self.latest: Sample | None = None
        """The newest complete sample before the team was done."""
        self.final: Sample | None = None
        """The sample at the final instant, once heard (until then, maybe a later one)."""
        self.final_at = 0.0
        self.latest_tick = 0
        self._finished = False
        self.first_truth_at: float | None = None
        self.advanced_at: float | None = None
        """When the first truth, or one of a newer tick than any before, arrived."""
        self.halted_at = 0.0
        self.finished_at: float | None = None
        self._subscribers = [
            self._subscribe(session, keys.truth(), Truth),
            self._subscribe(session, keys.all_estimates(), Estimates),
            self._subscribe(session, keys.all_statuses(), Status),
            self._subscribe(session, keys.plant_status(), PlantStatus),
            self._subscribe(session, keys.all_bridges(), BridgeStatus),
        ]

    def _subscribe(self, session, key: str, kind: type):
        return kind, fifo_subscriber(session, key, FIFO_CAPACITY)

    def drain(self, timeout: float) -> None:
        """Handle what has arrived, waiting up to ``timeout`` for something to: the truth
        first, then what the robots, the plant and the bridges said; each subscription up to
        what it held when it was reached."""
        deadline = time.monotonic() + timeout
        while True:
            handled = 0
            for kind, subscriber in self._subscribers:
                for sample in take(subscriber, FIFO_CAPACITY):
                    self._handle(kind, sample.payload.to_bytes())
                    handled += 1
            left = deadline - time.monotonic()
            if handled or left <= 0:
                return
            time.sleep(min(POLL_S, left))

    def listen(self, seconds: float, until: Callable[[], bool]) -> None:
        """Handle what arrives for up to ``seconds``, returning as soon as ``until()``."""
        deadline = time.monotonic() + seconds
        while not until():
            left = deadline - time.monotonic()
            if left <= 0:
                return
            self.drain(left)

    def _handle(self, kind: type, payload: bytes) -> None:
        if self._finished and kind not in (PlantStatus, BridgeStatus):
            return  # the verdict is in: what the team says while it shuts down changes nothing
        try:
            message = decode(kind, payload)
        except DecodeError as err:
            self.rejects(kind.__name__, err)
            return
        robot = getattr(message, "robot", 1)
        if not 1 <= robot <= self.n:
            self.rejects(kind.__name__, f"robot {robot} of a team of {self.n}", "not in the team")
            return
        # No robot's instant and no truth is ever far ahead of the newest truth (the plant
        # starts at tick 0).
        tick = getattr(message, "tick", 0)
        counters = isinstance(message, (PlantStatus, BridgeStatus))
        if not counters and tick > self.latest_tick + TICK_SLACK:
            why = "tick out of window"
            self.rejects(kind.__name__, f"tick {tick} at tick {self.latest_tick}", why)
            return
        if isinstance(message, Estimates):
            self._estimate(message)
        elif isinstance(message, Status):
            self._status(message)
        elif isinstance(message, Truth):
            now = time.perf_counter()
            if self.first_truth_at is None:
                self.first_truth_at = now
            if self.advanced_at is None or message.tick > self.latest_tick:
                self.advanced_at = now
            self.latest_tick = max(self.latest_tick, message.tick)
            self.truths[message.tick] = message
            self._complete(message.tick)
        elif isinstance(message, BridgeStatus):
            self.bridges[message.robot] = message
        else:
            self.plant_status = message
            if not self._finished:
                self.lost.update(message.lost)

    def _current(self, message: Estimates | Status) -> bool:
        """Whether ``message`` is of the team since its latest rejoin (after a newer one: the
        team began again, and what the collector knew of the old one's progress is dropped)."""
        if message.rejoins < self.rejoined:
            return False
        if message.rejoins > self.rejoined:
            if message.phase != Phase.HALTED:
                LOG.info("the team began again (rejoin %d)", message.rejoins)
                began = message.phase_since if isinstance(message, Estimates) else message.tick
                self.rejoins.append({"halted": self.halted_tick, "began": began})
                self.halted, self.halted_tick = False, None
                self.lost.clear()
                self.newest.clear()
                self.phase_ticks = {p: t for p, t in self.phase_ticks.items() if p == "halted"}
            self.rejoined = message.rejoins
        return True

    def _estimate(self, est: Estimates) -> None:
        if not self._current(est):
            return
        if est.phase == Phase.HALTED:
            self._halt(est.tick)
        self.newest[est.robot] = est  # (done, or not any more: a changed load is estimated again)
        self.estimates[est.tick][est.robot] = est
        self._complete(est.tick)

    def _status(self, status: Status) -> None:
        if not self._current(status):
            return
        self.statuses[status.robot] = status
        self.lost.update(status.lost_neighbours)
        tick = self.phase_ticks.get(status.phase.label)
        if tick is None or status.tick < tick:
            self.phase_ticks[status.phase.label] = status.tick
        if status.phase == Phase.HALTED:
            self._halt(status.tick)

    def _halt(self, tick: int) -> None:
        if not self.halted:
            self.halted = True
            self.halted_at = time.perf_counter()
            self.halted_tick = tick

    @property
    def done_instant(self) -> int | None:
        """The first instant at which every robot was done (the final instant:
        :func:`~agent.platform.evaluation.final_instant` of each robot's newest estimates)."""
        return final_instant([self.newest.get(i) for i in range(1, self.n + 1)], self.end_tick)

    def _complete(self, instant: int) -> None:
        robots = self.estimates.get(instant)
        truth = self.truths.get(instant)
        if robots is None or truth is None or len(robots) < self.n:
            return
        sample = Sample(time_s=truth.time_s, truth=truth, estimates=dict(robots))
        del self.estimates[instant]
        del self.truths[instant]
        done = self.done_instant
        if instant >= self._record_from or instant == done:
            self.history.append(sample)
            self._record_from = max(self._record_from, instant + self.record_every)
        if done is None or instant < done:
            if self.latest is None or instant > self.latest.truth.tick:
                self.latest = sample
        elif self.final is None or instant < self.final.truth.tick:
            if self.final is None:
                self.final_at = time.perf_counter()
            self.final = sample
        for old in [t for t in self.truths if t < instant - KEEP_TICKS]:
            del self.truths[old]
        for old in [t for t in self.estimates if t < instant - KEEP_TICKS]:
            del self.estimates[old]

    def conclude(self) -> None:
        """The run is over, whatever the team says next."""
        self.finished()
        self._finished = True

    def finished(self) -> bool:
        # After a halt, a moment more to hear who was lost (agents and plant report it).
        now = time.perf_counter()
        halt_over = self.halted and now - self.halted_at > self.rejoin_s
        final = self.final is not None and (
            self.final.truth.tick == self.done_instant or now - self.final_at > self._grace_s()
        )
        self._finished = self._finished or halt_over or final
        if self._finished and self.finished_at is None:
            self.finished_at = time.perf_counter()
        return self._finished

    def _grace_s(self) -> float:
        """How long to wait for the final instant (see :data:`FINAL_GRACE_S`)."""
        if self.first_truth_at is None or self.latest_tick <= 0:
            return FINAL_GRACE_S
        pace = (self.final_at - self.first_truth_at) / self.latest_tick  # wall s per tick
        return max(FINAL_GRACE_S, FINAL_GRACE_TICKS * pace)

    def rejections(self) -> dict:
        """Messages rejected: by the launcher (by kind), the plant, and each robot's agent
        (as its latest status reported them)."""
        plant = self.plant_status.decode_errors if self.plant_status else None
        return {
            "launcher": dict(self.rejects.counts),
            "plant": plant,
            "robots": {
                str(s.robot): {"decode_errors": s.decode_errors, "rejected": s.rejected}
                for s in sorted(self.statuses.values(), key=lambda s: s.robot)
            },
        }

    def close(self) -> None:
        for _, sub in self._subscribers:
            sub.undeclare()


def _child_env() -> dict[str, str]:
    env = dict(os.environ)
    root = str(Path(__file__).resolve().parents[1])
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    env["PYTHONUNBUFFERED"] = "1"
    return env


def _team_name(scenario: Scenario) -> str:
    """The run's team: the scenario's name (``paper``), as a deployed team's, so that its
    recordings open with the same Foxglove layout; each run has a router of its own, so two
    runs of one scenario never hear each other."""
    return re.sub(r"[^A-Za-z0-9_-]", "-", scenario.name)[:40]


class RunFailed(Exception):
    """A run that ended before any instant was recorded; ``reason`` and ``detail`` say why."""

    def __init__(self, reason: str, transport: dict, detail: str = ""):
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason
        self.detail = detail
        self.transport = transport


def run_zenoh(
    scenario: Scenario,
    *,
    clock: str = "lockstep",
    faults: FaultSettings | None = None,
    record_every: int = 5,
    progress: Progress | None = None,
    progress_every_s: float = 5.0,
    log_stream: TextIO | None = None,
    wall_timeout_s: float | None = None,
    stall_s: float | None = None,
    stop: threading.Event | None = None,
    can: CanLink | None = None,
    on_ready: Callable[[str, str], None] | None = None,
) -> RunOutcome:
    """Run ``scenario`` with one process per robot over Zenoh (see the module docstring);
    with ``can``, the robots on CAN behind one AGV bridge each.

    The run is ``stalled`` once the plant has published no new truth for ``stall_s``
    (default :data:`STALL_S`); a machine whose every tick is slow (User-Mode Linux on a
    loaded host) needs more.

    ``on_ready(router, team)`` is called once the run's router is up at endpoint ``router``,
    before the plant and the agents start: a recorder or a dashboard subscribes to team
    ``team`` there and misses nothing of the run.

    The run ends early, with the verdict ``interrupted``, once ``stop`` is set (``heft run``
    sets it on SIGINT, SIGTERM and SIGHUP) or on ``KeyboardInterrupt``; the processes are
    stopped and what was recorded is returned all the same. :class:`RunFailed` when nothing
    could be recorded."""
    faults = faults or FaultSettings()
    stop = stop or threading.Event()
    stream = log_stream or sys.stderr
    router = f"tcp/127.0.0.1:{free_port()}"
    team = _team_name(scenario)
    keys = Keys(team)
    env = _child_env()
    children: list[Child] = []

    def start(name: str, args: list[str]) -> Child:
        child = Child(name, [sys.executable, "-m", "agent", *args], stream, env)
        children.append(child)
        return child

    started = time.perf_counter()
    if wall_timeout_s is None:
        wall_timeout_s = 60.0 + 20.0 * scenario.run.max_time_s / min(
            1.0, scenario.run.real_time_factor
        )
    cpu: dict[str, float | None] = {}
    verdict = Verdict(INTERRUPTED, "asked to stop")
    collector: Collector | None = None
    with run_folder() as folder:
        scenario_file = folder / "scenario.toml"
        scenario_file.write_text(scenario_to_toml(scenario), encoding="utf-8")
        try:
            router_child = start("router", ["router", "--listen", router])
            with _launcher_session(router, router_child) as session:
                collector = Collector(session, keys, scenario.n, record_every, scenario.end_tick)
                if on_ready is not None:
                    on_ready(router, team)
                plant: Child | None = None
                agents: list[Child] = []
                bridges: list[Child] = []
                try:
                    try:
                        if not stop.is_set():
                            plant = start(
                                "plant",
                                ["sim", str(scenario_file), "--team", team, "--clock", clock]
                                + ["--connect", router]
                                + ["--start-timeout", f"{PLANT_START_TIMEOUT_S:g}"]
                                + _can_options(can),
                            )
                        for i in range(1, scenario.n + 1):
                            if stop.is_set():
                                break
                            config = folder / f"robot-{i}.toml"
                            text = robot_toml(i, scenario, team, clock, router, faults)
                            if can is not None:
                                watchdog_ms = bridge_watchdog_ms(scenario, clock)
                                settings = can_settings(i, can, watchdog_ms, scenario.agvs, clock)
                                text += can_table(settings)
                            config.write_text(text, encoding="utf-8")
                            if can is not None:
                                args = ["bridge", "--config", str(config)]
                                bridges.append(start(f"bridge {i}", args))
                            agents.append(start(f"robot {i}", ["agent", "--config", str(config)]))
                        all_up = len(agents) == scenario.n
                        if can is not None:
                            all_up = all_up and len(bridges) == scenario.n
                        if plant is not None and all_up:
                            watch = _Watch(
                                collector, router_child, plant, agents, scenario, bridges, stall_s
                            )
                            verdict = watch.run(
                                stop, progress, progress_every_s, started + wall_timeout_s
                            )
                    except KeyboardInterrupt:  # Ctrl-C when run_zenoh is called as a function
                        verdict = Verdict(INTERRUPTED, "asked to stop")
                    collector.conclude()  # agents leaving from now on are not lost robots
                    cpu.update({child.name: child.cpu_seconds() for child in children})
                    _shut_down(session, keys, collector, router_child, plant, agents + bridges)
                finally:
                    collector.close()
        finally:
            stop_all(children[:0:-1])  # whatever is left of the plant and the agents
            stop_all(children[:1], ROUTER_GRACE_S)
    return run_outcome(scenario, collector, verdict, started, cpu)


def run_outcome(
    scenario: Scenario,
    collector: Collector | None,
    verdict: Verdict,
    started: float,
    cpu: dict[str, float | None],
    heard: str = "recorded",
) -> RunOutcome:
    """The outcome of a run the collector followed since ``started``; :class:`RunFailed`
    (saying nothing was ``heard``) if no instant of every robot's estimates with the truth
    was."""
    transport = transport_report(collector, cpu)
    final = None if collector is None else collector.final or collector.latest
    if final is None:
        nothing = f"no instant of every robot's estimates with the truth was {heard}"
        raise RunFailed(verdict.reason or f"nothing {heard}", transport, verdict.detail or nothing)
    verdict = mass_verdict(verdict, final.estimates, final.time_s)
    return RunOutcome(
        scenario=scenario,
        converged=not verdict.reason,
        ticks=final.truth.tick,
        wall_s=time.perf_counter() - started,
        final=final,
        history=sorted(collector.history, key=lambda sample: sample.truth.tick),
        phase_ticks=dict(sorted(collector.phase_ticks.items(), key=lambda kv: kv[1])),
        transport=transport,
        reason=verdict.reason,
        detail=verdict.detail,
    )


def _launcher_session(router: str, router_child: Child):
    """The launcher's own session, through its router; :class:`RunFailed` if the router
    died before it could be reached (e.g. its port was taken in the meantime)."""
    try:
        return open_session(ZenohSettings(mode="client", connect=(router,)))
    except SessionError:
        code = router_child.process.poll()
        if code is None:
            raise
        ended = router_child.ended(code)
        detail = f"the Zenoh router process ended before it was reached ({ended})"
        raise RunFailed(ROUTER_LOST, {}, detail) from None


def _can_options(can: CanLink | None) -> list[str]:
    """``heft sim``'s options for the robots' buses (none without CAN)."""
    if can is None:
        return []
    return ["--can", "--can-interface", can.interface, "--can-channel", can.channel]


def _shut_down(
    session, keys: Keys, collector: Collector, router: Child, plant: Child | None, agents
) -> None:
    """Stop the plant, then the agents (and the bridges, with them); the router stays up
    until the caller stops it."""
    if plant is not None:  # the plant first, so that it never sees the agents leave as lost
        stop_all([plant])
    if router.process.poll() is None:  # without a router, nobody hears the stop message
        session.put(keys.control(), encode(Control("stop")))
        wait_all(agents, 1.0)  # they leave cleanly on the message; SIGTERM for the others
    stop_all(agents)
    collector.drain(0.2)


def transport_report(collector: Collector | None, cpu: dict[str, float | None]) -> dict:
    if collector is None:
        return {"cpu_s": cpu}
    report = {
        "plant": dataclasses.asdict(collector.plant_status) if collector.plant_status else None,
        "lost": sorted(collector.lost),
        "halted": collector.halted,
        "rejoins": collector.rejoins,
        "decode_errors": collector.rejects.total,
        "rejections": collector.rejections(),
        "cpu_s": cpu,
        "stepping_wall_s": (
            collector.finished_at - collector.first_truth_at
            if collector.finished_at and collector.first_truth_at
            else None
        ),
    }
    if collector.bridges:
        report["bridges"] = {
            str(robot): dataclasses.asdict(status)
            for robot, status in sorted(collector.bridges.items())
        }
    return report


class _Watch:
    """The launcher's watch over a run: what the team says (through the collector) and what
    its processes do (see the module docstring for the verdicts)."""

    def __init__(
        self,
        collector: Collector,
        router: Child,
        plant: Child,
        agents: list[Child],
        scenario: Scenario,
        bridges: Sequence[Child] = (),
        stall_s: float | None = None,
    ):
        self.collector = collector
        self.router = router
        self.plant = plant
        self.agents = agents
        self.bridges = list(bridges)
        """Robot ``i``'s AGV bridge at ``i - 1`` (a CAN run; none otherwise)."""
        self.scenario = scenario
        self.stall_s = STALL_S if stall_s is None else stall_s
        """How long without new truth from the plant makes the run ``stalled``."""
        self.gone: dict[int, tuple[float, int, str]] = {}
        """Robots whose agent (or bridge) process exited mid-run: when, its exit code, and
        which (``agent``, ``bridge``)."""

    def _t(self) -> str:
        return f"t = {self.collector.latest_tick * self.scenario.period_s:.2f} s simulated"

    def run(
        self,
        stop: threading.Event,
        progress: Progress | None,
        every_s: float,
        deadline: float,
    ) -> Verdict:
        """Watch until the run is over; the verdict."""
        collector = self.collector
        next_report = every_s
        while not collector.finished():
            collector.drain(0.05)
            t = collector.latest_tick * self.scenario.period_s
            if progress is not None and t >= next_report:
                progress(t, ", ".join(sorted(collector.phase_ticks, key=collector.phase_ticks.get)))
                next_report += every_s
            # Asked to stop is asked first: a Ctrl-C reaches the whole process group, and the
            # router or the plant that stopped on it is not a lost process.
            if stop.is_set():
                return Verdict(INTERRUPTED, "asked to stop")
            verdict = self._processes() or self._stalled()
            if verdict is not None:
                return verdict
            if time.perf_counter() > deadline:
                detail = f"the run took too long on the wall clock ({self._t()})"
                return Verdict(WALL_TIMEOUT, detail)
        return self._team()

    def _team(self) -> Verdict:
        """The verdict once the collector says the run is over."""
        collector = self.collector
        if collector.halted or self.gone:
            lost = sorted(set(collector.lost) | set(self.gone))
            ended: dict[tuple[str, str], list[int]] = defaultdict(list)
            for i, (_, code, which) in sorted(self.gone.items()):
                ended[which, describe_exit(code)].append(i)
            exits = "; ".join(
                f"the {which} process of robot(s) {robots} ended ({how})"
                for (which, how), robots in ended.items()
            )
            if collector.halted:
                why = "the team halted"
            elif any(which == "bridge" for _, _, which in self.gone.values()):
                why = "the team did not halt (agents do not watch the bridges)"
            else:
                why = "no neighbour was left to halt it"
            detail = (
                f"{exits + '; ' if exits else ''}{why} at {self._t()}"
                " (n is fixed: estimates without a robot would be wrong)"
            )
            return halted(lost, detail)
        return Verdict()

    def _processes(self) -> Verdict | None:
        """A verdict when the router, the plant or an agent process is gone."""
        collector = self.collector
        code = self.router.process.poll()
        if code is not None:
            how = describe_exit(code)
            return Verdict(ROUTER_LOST, f"the Zenoh router process ended ({how}) at {self._t()}")
        code = self.plant.process.poll()
        if code is not None:
            # What it said last (its status), and the team's last words: the estimates of
            # its last ticks may still be on their way.
            collector.listen(LAST_WORDS_S, collector.finished)
            if collector.finished():
                return self._team()
            return self._plant_exit(code)
        now = time.perf_counter()
        robots = [(i, child, "agent") for i, child in enumerate(self.agents, start=1)]
        robots += [(i, child, "bridge") for i, child in enumerate(self.bridges, start=1)]
        for i, child, which in robots:
            code = child.process.poll()
            if code is None or i in self.gone:
                continue
            if collector.first_truth_at is None:
                ended = child.ended(code)
                return Verdict(
                    AGENTS_NOT_UP,
                    f"robot {i}'s {which} process ended before the run started ({ended})",
                )
            self.gone[i] = (now, code, which)  # its neighbours should halt the team: wait
        if self.gone and now - min(t for t, _, _ in self.gone.values()) > AGENT_GONE_S:
            return self._team()
        return None

    def _plant_exit(self, code: int) -> Verdict:
        collector = self.collector
        how = describe_exit(code)
        if collector.first_truth_at is None:
            if code == 1:  # the plant's --start-timeout: see heft sim
                which = "agents and bridges" if self.bridges else "agents"
                return Verdict(AGENTS_NOT_UP, f"the plant gave up waiting for the {which}")
            ended = self.plant.ended(code)
            return Verdict(PLANT_LOST, f"the plant process ended before it started ({ended})")
        status = collector.plant_status
        tick = max(collector.latest_tick, status.tick if status else 0)
        end = RunEnd.of(self.scenario)
        if code == 0 and end.out_of_time(tick):
            return end.out_of_time_verdict()
        return Verdict(PLANT_LOST, f"the plant process ended ({how}) at {self._t()}")

    def _stalled(self) -> Verdict | None:
        advanced_at = self.collector.advanced_at
        if advanced_at is not None and time.perf_counter() - advanced_at > self.stall_s:
            return Verdict(
                STALLED,
                f"no new truth from the plant for {self.stall_s:g} s after {self._t()}: the plant,"
                " the router or an agent the plant waits for hangs",
            )
        return None
