"""One robot's AGV bridge with stand-ins around it, as processes on this machine.

:class:`BridgeRig` starts a Zenoh router (``heft router``) on ``tcp/127.0.0.1``, one
``heft bridge`` for robot 1 on a CAN channel (its ``robot.toml`` with a ``[can]`` table, in
a folder the caller gives) and the echo agent (:mod:`bridge.devtools.echo_agent`), and follows the
bridge's :class:`~agent.platform.protocol.BridgeStatus` through a Zenoh session of its own. The AGV
driver is the caller's to play on the bus. Every child asks the kernel to kill it if this
process dies (Linux ``PR_SET_PDEATHSIG``), so a killed caller leaves no orphan.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

from agent.node import AgentNodeConfig
from agent.platform.children import Child, cpu_seconds, free_port
from agent.platform.config import to_toml
from agent.platform.protocol import BridgeStatus, DecodeError, Keys, decode
from agent.platform.zenoh_session import ZenohSettings, open_session
from bridge.admittance import AdmittanceSettings
from bridge.config import CanSettings, can_table
from bridge.devtools.echo_agent import READY
from bridge.node import STATUS_EVERY_S

LOG_TAIL = 2000
"""Characters of a child's log quoted when it fails."""
STOP_GRACE_S = 30.0
"""How long a child has to exit on SIGTERM before SIGKILL. In User-Mode Linux, right after a
burst of 2000 random frames, a bridge once took over 10 s to get through its backlog and exit
(the tests check that it exits by itself, with status 0)."""


class RigError(Exception):
    """The rig could not be brought up; ``str()`` says which process and why (with the end
    of its log)."""


class RigChild(Child):
    """A :class:`~agent.platform.children.Child` whose output goes to the file ``log``."""

    def __init__(self, name: str, args: list[str], log: Path, env: dict[str, str]):
        self.log = log
        self._file = log.open("w", encoding="utf-8")
        super().__init__(name, args, self._file, env, signal.SIGTERM)

    @property
    def pid(self) -> int:
        return self.process.pid

    def tail(self) -> str:
        """The end of its log, indented, for an error message."""
        try:
            text = self.log.read_text(errors="replace")[-LOG_TAIL:]
        except OSError:
            return ""
        return "\n".join(f"  {line}" for line in text.splitlines() if line.strip())

    def check(self) -> None:
        """:class:`RigError` if it has exited."""
        code = self.process.poll()
        if code is not None:
            raise RigError(f"the {self.name} process {self.ended(code)}:\n{self.tail()}")

    def stop(self, grace_s: float = STOP_GRACE_S) -> None:
        super().stop(grace_s)
        self._file.close()


def bridge_toml(
    router: str,
    team: str,
    channel: str,
    period_s: float,
    watchdog_ms: int,
    robot: int = 1,
    realtime_priority: int = 0,
    profile: str = "force",
    admittance: AdmittanceSettings | None = None,
) -> str:
    """Robot ``robot``'s ``robot.toml`` (a client of ``router``) with its ``[can]`` table:
    node id = robot id, ticks from the bus's ``Sync`` frames, the AGV protocol's ``profile``
    (and with ``velocity`` the admittance loop's settings)."""
    config = AgentNodeConfig(
        robot=robot,
        n=2,
        neighbours=(2 if robot == 1 else 1,),
        team=team,
        period_s=period_s,
        clock="realtime",
        zenoh=ZenohSettings(mode="client", connect=(router,)),
    )
    can = CanSettings(
        interface="socketcan",
        channel=channel,
        node=robot,
        watchdog_ms=int(watchdog_ms),
        time_source="sync",
        realtime_priority=int(realtime_priority),
        profile=profile,
        admittance=admittance or AdmittanceSettings(),
    )
    return to_toml(config, f"Robot {robot}'s bridge, for a benchmark.") + can_table(can)


class BridgeRig:
    """A router, robot 1's ``heft bridge`` on ``channel`` and the echo agent (see the module
    docstring); files and logs in ``folder``. :meth:`start` brings them up, :meth:`close`
    stops them. With ``profile = "velocity"`` the bridge runs the admittance loop of
    ``admittance`` and the agent pushes with ``push_n`` newtons
    (:func:`~bridge.devtools.echo_agent.push`)."""

    ROBOT = 1

    def __init__(
        self,
        channel: str,
        folder: Path,
        period_s: float,
        team: str = "bench",
        watchdog_ms: int = 100,
        realtime_priority: int = 0,
        profile: str = "force",
        admittance: AdmittanceSettings | None = None,
        push_n: float | None = None,
    ) -> None:
        self.channel = channel
        self.folder = folder
        self.period_s = period_s
        self.team = team
        self.watchdog_ms = watchdog_ms
        self.realtime_priority = realtime_priority
        self.profile = profile
        self.admittance = admittance
        self.push_n = push_n
        self.router = f"tcp/127.0.0.1:{free_port()}"
        self.children: dict[str, Child] = {}
        self.session = None
        self._statuses: list[tuple[float, BridgeStatus]] = []
        self._lock = threading.Lock()

    # ------------------------------------------------------------------ processes
    def _start(self, name: str, args: list[str]) -> RigChild:
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        log = self.folder / f"{name.replace(' ', '-')}.log"
        child = RigChild(name, [sys.executable, *args], log, env)
        self.children[name] = child
        return child

    def start(self, timeout_s: float = 180.0) -> None:
        """Start every process and wait until the bridge reports and the agent answers;
        :class:`RigError` if one ends or ``timeout_s`` passes first (generous: in User-Mode
        Linux one ``heft bridge`` took over 60 s just to start and read its config, once)."""
        deadline = time.monotonic() + timeout_s
        self._start("router", ["-m", "agent", "router", "--listen", self.router])
        config = self.folder / "robot-1.toml"
        text = bridge_toml(
            self.router,
            self.team,
            self.channel,
            self.period_s,
            self.watchdog_ms,
            realtime_priority=self.realtime_priority,
            profile=self.profile,
            admittance=self.admittance,
        )
        config.write_text(text, encoding="utf-8")
        self._start("bridge", ["-m", "agent", "bridge", "--config", str(config)])
        settings = ZenohSettings(
            mode="client", connect=(self.router,), connect_timeout_ms=int(timeout_s * 1000)
        )
        self.session = open_session(settings)
        self.session.declare_subscriber(Keys(self.team).bridge(self.ROBOT), self._on_status)
        self.start_agent(deadline - time.monotonic())
        self.wait_status(lambda s: True, deadline - time.monotonic(), "the bridge reports")

    def start_agent(self, timeout_s: float = 120.0) -> None:
        """Start the echo agent (again) and wait until it answers."""
        args = ["-m", "bridge.devtools.echo_agent", "--connect", self.router, "--team", self.team]
        if self.push_n is not None:
            args += ["--push", repr(self.push_n)]
        agent = self._start("echo agent", args)
        if not agent.wait_for_line(READY, timeout_s):
            self.check()
            raise RigError(f"the echo agent did not come up in time:\n{agent.tail()}")

    def check(self) -> None:
        """:class:`RigError` if a process of the rig has ended."""
        for child in self.children.values():
            child.check()

    def pid(self, name: str) -> int:
        return self.children[name].pid

    def cpu_seconds(self) -> dict[str, float | None]:
        """CPU seconds used so far by each process of the rig, by name."""
        return {name: cpu_seconds(child.pid) for name, child in self.children.items()}

    def close(self) -> None:
        """Stop the agent, the bridge, then the router; close the session."""
        if self.session is not None:
            self.session.close()
            self.session = None
        for name in ("echo agent", "bridge", "router"):
            if name in self.children:
                self.children[name].stop()

    # ------------------------------------------------------------------ the bridge's status
    def _on_status(self, sample) -> None:
        try:
            status = decode(BridgeStatus, sample.payload.to_bytes())
        except DecodeError:
            return
        with self._lock:
            self._statuses.append((time.monotonic(), status))
            del self._statuses[:-50]

    def latest(self) -> tuple[float, BridgeStatus] | None:
        """The newest status heard and when (``time.monotonic()``), or None."""
        with self._lock:
            return self._statuses[-1] if self._statuses else None

    def wait_status(
        self, condition: Callable[[BridgeStatus], bool], timeout_s: float, what: str
    ) -> BridgeStatus:
        """The first status (the newest heard) meeting ``condition``; :class:`RigError` naming
        ``what`` after ``timeout_s``, or if a process ends."""
        deadline = time.monotonic() + timeout_s
        while True:
            latest = self.latest()
            if latest is not None and condition(latest[1]):
                return latest[1]
            self.check()
            if time.monotonic() >= deadline:
                raise RigError(
                    f"not within {timeout_s:.0f} s: {what}; the bridge's last status:"
                    f" {latest[1] if latest else None}\n{self.children['bridge'].tail()}"
                )
            time.sleep(0.02)

    def settled_status(self, frames_in: int, quiet_s: float = 3 * STATUS_EVERY_S, timeout_s=3.0):
        """A status heard after this call that counts ``frames_in`` frames read, or else the
        one in which the count stopped changing for ``quiet_s`` (at most ``timeout_s``)."""
        since = time.monotonic()
        deadline = since + timeout_s
        last_count, changed_at = -1, since
        while True:
            latest = self.latest()
            now = time.monotonic()
            if latest is not None and latest[0] > since:
                heard_at, status = latest
                if status.frames_in >= frames_in:
                    return status
                if status.frames_in != last_count:
                    last_count, changed_at = status.frames_in, heard_at
                elif now - changed_at >= quiet_s or now >= deadline:
                    return status
            self.check()
            if now >= deadline + 1.0:
                raise RigError(f"the bridge reported nothing for {timeout_s + 1:.0f} s")
            time.sleep(0.02)
