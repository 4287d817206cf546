"""``heft run SCENARIO --transport zenoh``: router, plant and ``n`` agents as separate processes.

The launcher starts a Zenoh router (``heft router``), the plant (``heft sim``) and one
``heft agent`` per robot, each with its own ``robot.toml``, all on ``tcp/127.0.0.1`` with
multicast scouting off. It prefixes every child's log lines with its name, listens to the
agents' estimates and status and to the plant's truth (as any display would), and builds the
same :class:`~heft.inprocess.RunOutcome` as the in-process run. When the team is done (or halted,
or out of time) it stops the plant, then tells the agents to stop; whatever happens — success,
failure, Ctrl-C — it stops every child it started (SIGTERM, then SIGKILL) and closes its own
session.
"""

from __future__ import annotations

import dataclasses
import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

from agent.faults import FaultSettings
from agent.protocol import DecodeError, Estimates, Keys, Status, decode, encode_json
from agent.zenoh_session import EventQueue, ZenohSettings, open_session
from heft.inprocess import RunOutcome, Sample
from simulator.plant import Truth
from simulator.scenario import Scenario, scenario_to_toml

Progress = Callable[[float, str], None]
STOP_GRACE_S = 5.0
HALT_GRACE_S = 0.5


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def truth_from_dict(data: dict) -> Truth:
    """The :class:`Truth` published by the plant as JSON."""
    pairs = ("contacts", "contact_velocities", "contact_to_com")
    fields = {k: tuple(map(tuple, v)) if k in pairs else v for k, v in data.items()}
    for key in ("com_position", "com_velocity"):
        fields[key] = tuple(fields[key])
    return Truth(**fields)


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {value!r} as TOML")


def robot_toml(
    robot: int, scenario: Scenario, team: str, clock: str, router: str, faults: FaultSettings
) -> str:
    """The ``robot.toml`` of one robot of ``scenario``."""
    lines = [
        f"# Agent of robot {robot} of scenario {scenario.name!r}, written by heft run.",
        f"robot = {robot}",
        f"n = {scenario.n}",
        f"neighbours = {_toml_value(scenario.neighbours(robot))}",
        f"team = {_toml_value(team)}",
        f"period_s = {scenario.period_s!r}",
        f"seed = {scenario.run.seed}",
        f"clock = {_toml_value(clock)}",
        "",
        "[zenoh]",
        'mode = "client"',
        f"connect = [{_toml_value(router)}]",
        "",
        "[faults]",
    ]
    lines += [f"{k} = {_toml_value(v)}" for k, v in dataclasses.asdict(faults).items()]
    lines += ["", "[tuning]"]
    lines += [f"{k} = {_toml_value(v)}" for k, v in dataclasses.asdict(scenario.agent).items()]
    return "\n".join(lines) + "\n"


class Child:
    """A child process whose output lines are copied to ``stream`` behind ``[name]``."""

    def __init__(self, name: str, args: list[str], stream: TextIO, env: dict[str, str]):
        self.name = name
        self.process = subprocess.Popen(
            args,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            text=True,
            bufsize=1,
            env=env,
        )
        self._thread = threading.Thread(target=self._copy, args=(stream,), daemon=True)
        self._thread.start()

    def _copy(self, stream: TextIO) -> None:
        for line in self.process.stdout:
            stream.write(f"[{self.name}] {line}")
            stream.flush()

    def cpu_seconds(self) -> float | None:
        """User + system CPU time the process has used so far (Linux ``/proc``)."""
        try:
            fields = Path(f"/proc/{self.process.pid}/stat").read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            return None
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def stop(self, grace_s: float = STOP_GRACE_S) -> None:
        """Wait up to ``grace_s`` for it to exit, then SIGTERM, then SIGKILL."""
        for sig in (None, signal.SIGTERM, signal.SIGKILL):
            if sig is not None and self.process.poll() is None:
                if sig == signal.SIGTERM:
                    self.process.send_signal(signal.SIGCONT)  # a stopped process can't exit
                self.process.send_signal(sig)
            try:
                self.process.wait(timeout=grace_s)
                break
            except subprocess.TimeoutExpired:
                continue
        self._thread.join(timeout=1.0)


class Collector:
    """What the launcher hears: every robot's estimates, the truth, the team's status."""

    def __init__(self, session, keys: Keys, n: int, record_every: int):
        self.n = n
        self.record_every = record_every
        self.events = EventQueue()
        self.estimates: dict[int, dict[int, Estimates]] = defaultdict(dict)  # instant → robot
        self.truths: dict[int, Truth] = {}
        self.history: list[Sample] = []
        self.phase_ticks: dict[str, int] = {}
        self.done_at: dict[int, int] = {}
        self.halted = False
        self.lost: set[int] = set()
        self.plant_status: dict | None = None
        self.final: Sample | None = None
        self.decode_errors = 0
        self.latest_tick = 0
        self._finished = False
        self.first_truth_at: float | None = None
        self.halted_at = 0.0
        self.finished_at: float | None = None
        put = self.events.put
        self._subscribers = [
            session.declare_subscriber(
                keys.robot(0, "estimate"), lambda s: put(("estimate", s.payload.to_bytes()))
            ),
            session.declare_subscriber(
                keys.robot(0, "status"), lambda s: put(("status", s.payload.to_bytes()))
            ),
            session.declare_subscriber(
                keys.plant("truth"), lambda s: put(("truth", s.payload.to_bytes()))
            ),
            session.declare_subscriber(
                keys.plant("status"), lambda s: put(("plant", s.payload.to_bytes()))
            ),
        ]

    def drain(self, timeout: float) -> None:
        self.events.drain(lambda event: self._handle(*event), timeout)

    def _handle(self, kind: str, payload: bytes) -> None:
        if self._finished and kind != "plant":
            return  # the verdict is in: what the team says while it shuts down changes nothing
        try:
            if kind == "estimate":
                self._estimate(decode(Estimates, payload))
            elif kind == "status":
                self._status(decode(Status, payload))
            elif kind == "truth":
                truth = truth_from_dict(decode("truth", payload))
                if self.first_truth_at is None:
                    self.first_truth_at = time.perf_counter()
                self.latest_tick = truth.tick
                self.truths[truth.tick] = truth
                self._complete(truth.tick)
            else:
                self.plant_status = decode("plant_status", payload)
                if not self._finished:
                    self.lost.update(self.plant_status.get("lost", []))
        except (DecodeError, TypeError, KeyError, ValueError) as err:
            self.decode_errors += 1
            if self.decode_errors <= 5:
                print(f"heft: undecodable {kind} message: {err}", file=sys.stderr)

    def _estimate(self, est: Estimates) -> None:
        if est.phase == "halted":
            self._halt()
        if est.phase == "done" and est.robot not in self.done_at:
            self.done_at[est.robot] = est.tick + 1
        self.estimates[est.tick][est.robot] = est
        self._complete(est.tick)

    def _status(self, status: Status) -> None:
        self.lost.update(status.lost_neighbours)
        tick = self.phase_ticks.get(status.phase)
        if tick is None or status.tick < tick:
            self.phase_ticks[status.phase] = status.tick
        if status.phase == "halted":
            self._halt()

    def _halt(self) -> None:
        if not self.halted:
            self.halted = True
            self.halted_at = time.perf_counter()

    @property
    def done_instant(self) -> int | None:
        """The first tick at which every robot was done (the final instant)."""
        if len(self.done_at) < self.n:
            return None
        return max(self.done_at.values())

    def _complete(self, instant: int) -> None:
        robots = self.estimates.get(instant)
        truth = self.truths.get(instant)
        if robots is None or truth is None or len(robots) < self.n:
            return
        sample = Sample(time_s=truth.time_s, truth=truth, estimates=dict(robots))
        done = self.done_instant
        if instant % self.record_every == self.record_every - 1 or instant == done:
            self.history.append(sample)
        if done is None or instant <= done:
            self.final = sample  # so far: the newest instant before the team was done
        elif self.final is None or self.final.truth.tick < done:
            # The first complete instant once the whole team was done (as in-process; a robot
            # catching up on late messages may not publish every instant).
            self.final = sample
        del self.estimates[instant]
        for old in [t for t in self.truths if t <= instant]:
            del self.truths[old]

    def conclude(self) -> None:
        """The run is over, whatever the team says next."""
        self.finished()
        self._finished = True

    def finished(self) -> bool:
        done = self.done_instant
        # After a halt, a moment more to hear who was lost (agents and plant report it).
        halt_over = self.halted and time.perf_counter() - self.halted_at > HALT_GRACE_S
        self._finished = (
            self._finished
            or halt_over
            or (done is not None and self.final is not None and self.final.truth.tick >= done)
        )
        if self._finished and self.finished_at is None:
            self.finished_at = time.perf_counter()
        return self._finished

    def close(self) -> None:
        for sub in self._subscribers:
            sub.undeclare()


def _child_env() -> dict[str, str]:
    env = dict(os.environ)
    root = str(Path(__file__).resolve().parents[1])
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    env["PYTHONUNBUFFERED"] = "1"
    return env


def _team_name(scenario: Scenario) -> str:
    return re.sub(r"[^A-Za-z0-9_-]", "-", scenario.name)[:40] + f"-{os.getpid()}"


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
) -> RunOutcome:
    """Run ``scenario`` with one process per robot over Zenoh (see the module docstring)."""
    faults = faults or FaultSettings()
    stream = log_stream or sys.stderr
    port = free_port()
    router = f"tcp/127.0.0.1:{port}"
    team = _team_name(scenario)
    keys = Keys(team)
    env = _child_env()
    python = [sys.executable, "-m", "heft"]
    children: list[Child] = []
    started = time.perf_counter()
    if wall_timeout_s is None:
        wall_timeout_s = 60.0 + 20.0 * scenario.run.max_time_s
    cpu: dict[str, float | None] = {}
    with tempfile.TemporaryDirectory(prefix="heft-run-") as tmp:
        folder = Path(tmp)
        scenario_file = folder / "scenario.toml"
        scenario_file.write_text(scenario_to_toml(scenario), encoding="utf-8")
        try:
            children.append(Child("router", python + ["router", "--listen", router], stream, env))
            settings = ZenohSettings(mode="client", connect=(router,))
            with open_session(settings) as session:
                collector = Collector(session, keys, scenario.n, record_every)
                try:
                    children.append(
                        Child(
                            "plant",
                            python
                            + [
                                "sim",
                                str(scenario_file),
                                "--team",
                                team,
                                "--clock",
                                clock,
                                "--connect",
                                router,
                            ],
                            stream,
                            env,
                        )
                    )
                    for i in range(1, scenario.n + 1):
                        config = folder / f"robot-{i}.toml"
                        config.write_text(
                            robot_toml(i, scenario, team, clock, router, faults), encoding="utf-8"
                        )
                        children.append(
                            Child(
                                f"robot {i}",
                                python + ["agent", "--config", str(config)],
                                stream,
                                env,
                            )
                        )
                    _wait(
                        collector,
                        children,
                        scenario,
                        progress,
                        progress_every_s,
                        started + wall_timeout_s,
                    )
                    collector.conclude()  # agents leaving from now on are not lost robots
                    cpu.update({child.name: child.cpu_seconds() for child in children})
                    # The plant first, so that it never sees the agents leave as robots lost.
                    plant = children[1]
                    if plant.process.poll() is None:
                        plant.process.send_signal(signal.SIGTERM)
                    plant.stop()
                    session.put(keys.control, encode_json("control", {"command": "stop"}))
                    for child in children[2:]:
                        child.stop()
                    collector.drain(0.2)
                finally:
                    collector.close()
        finally:
            for child in reversed(children):
                if child.process.poll() is None:
                    child.process.send_signal(signal.SIGCONT)
                    child.process.send_signal(signal.SIGTERM)
            for child in reversed(children):
                child.stop(grace_s=STOP_GRACE_S)
    if collector.final is None:
        raise RuntimeError("the run produced no complete sample of estimates and truth")
    converged = (
        not collector.halted
        and collector.done_instant is not None
        and collector.final.truth.tick >= collector.done_instant
    )
    return RunOutcome(
        scenario=scenario,
        converged=converged,
        ticks=collector.final.truth.tick,
        wall_s=time.perf_counter() - started,
        final=collector.final,
        history=collector.history,
        phase_ticks=dict(sorted(collector.phase_ticks.items(), key=lambda kv: kv[1])),
        transport={
            "plant": collector.plant_status,
            "lost": sorted(collector.lost),
            "halted": collector.halted,
            "decode_errors": collector.decode_errors,
            "cpu_s": cpu,
            "stepping_wall_s": (
                collector.finished_at - collector.first_truth_at
                if collector.finished_at and collector.first_truth_at
                else None
            ),
        },
    )


def _wait(
    collector: Collector,
    children: list[Child],
    scenario: Scenario,
    progress: Progress | None,
    every_s: float,
    deadline: float,
) -> None:
    """Until the team is done or halted, the plant has stopped, or time is up."""
    next_report = every_s
    plant = children[1]
    while not collector.finished():
        collector.drain(0.05)
        t = collector.latest_tick * scenario.period_s
        if progress is not None and t >= next_report:
            progress(t, ", ".join(sorted(collector.phase_ticks, key=collector.phase_ticks.get)))
            next_report += every_s
        if plant.process.poll() is not None:
            collector.drain(0.5)
            return
        if time.perf_counter() > deadline:
            print("heft: the run took too long on the wall clock; stopping it", file=sys.stderr)
            return
        for child in children:
            if child.process.poll() is not None and child.name.startswith("robot"):
                # A dead agent: its neighbours halt the team; give them time to say so.
                collector.drain(0.5)
