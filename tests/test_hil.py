"""Hardware-in-the-loop: the whole chain on real kernel CAN (vcan), plant ↔ CAN ↔ bridge ↔
Zenoh ↔ agents. These need vcan1... (``make hil`` runs them in ``heft vcan``, in User-Mode
Linux where this kernel has no SocketCAN); without vcan they skip, saying how to get it, or fail
where CI requires it (``HEFT_REQUIRE_VCAN=1``)."""

from __future__ import annotations

import collections
import io
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from agent.protocol import BridgeStatus, Keys, decode
from agent.zenoh_session import ZenohSettings, open_session
from bridge.codec import (
    AgvCodec,
    AppliedForce,
    FrameError,
    Heartbeat,
    Odometry,
    Sync,
)
from simulator.can_drivers import CanLink
from simulator.inprocess import run_inprocess
from simulator.launcher import free_port, run_zenoh
from simulator.scenario import load_scenario
from tests.conftest import PAPER, ROOT, assert_same_estimates, worst_errors

pytestmark = [pytest.mark.hil, pytest.mark.usefixtures("vcan")]

CODEC = AgvCodec()
RIG_CHANNEL = "vcan8"
RIG_TEAM = "hil"
PERIOD = 0.01
WATCHDOG_MS = 100


def _bus(channel: str):
    import can

    return can.Bus(interface="socketcan", channel=channel)


class Candump:
    """Every frame on ``channel`` in candump's log format (``candump -L``), as python-can's
    ``CanutilsLogWriter`` writes it, until :meth:`close`."""

    def __init__(self, channel: str, path: Path) -> None:
        import can

        self.bus = _bus(channel)
        self.writer = can.CanutilsLogWriter(str(path), channel=channel)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.stop.is_set():
            message = self.bus.recv(0.1)
            if message is not None:
                self.writer.on_message_received(message)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(5)
        self.writer.stop()
        self.bus.shutdown()


# ------------------------------------------------------------------------------ whole runs
def test_lockstep_over_can_reproduces_the_inprocess_can_run(tmp_path: Path) -> None:
    """``heft run paper.toml --can``: the estimates of the in-process run quantised as the
    bus quantises, to 1e-9, the final instant included; robot 1's bus traffic, logged in
    candump's format, decodes with cantools."""
    scenario = load_scenario(PAPER)
    here = run_inprocess(scenario, link="can")
    log = tmp_path / "vcan1.log"
    dump = Candump("vcan1", log)
    started = time.perf_counter()
    output = io.StringIO()
    try:
        there = run_zenoh(scenario, can=CanLink(), log_stream=output)
    finally:
        dump.close()
    wall = time.perf_counter() - started
    assert there.converged, f"{there.verdict}; the run's log ends:\n{output.getvalue()[-8000:]}"
    worst = worst_errors(there)
    bridges = there.transport["bridges"]
    print(
        f"\nlockstep over vcan: converged {there.converged} at {there.sim_time_s:.2f} s"
        f" simulated, {wall:.0f} s wall; worst m {worst['mass']:.2e}, J {worst['moment']:.2e},"
        f" ctc {worst['contact_to_com'] * 1e3:.3f} mm; bridge 1: {bridges['1']}"
    )
    assert there.converged
    assert_same_estimates(here, there)
    for status in bridges.values():
        assert status["decode_errors"] == 0 and status["missed_ticks"] == 0
        assert status["counter_jumps"] == 0 and status["frames_in"] > 3 * there.ticks

    # The candump log: every line decodes with cantools, one Odometry_1 per tick.
    done = subprocess.run(
        [sys.executable, "-m", "cantools", "decode", "--single-line", str(ROOT / "bridge/agv.dbc")],
        stdin=log.open("rb"),
        capture_output=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    lines = done.stdout.decode().splitlines()
    assert len(lines) == len(log.read_text().splitlines()) > 3 * there.ticks
    assert not [line for line in lines if "Unknown frame id" in line]
    kinds = collections.Counter(line.split("::")[0].split()[-1] for line in lines if "::" in line)
    assert kinds["Odometry_1"] >= there.ticks and kinds["Sync"] >= there.ticks
    assert kinds["ForceCommand_1"] >= there.ticks and kinds["Heartbeat_1"] > 0


# ------------------------------------------------------------------------------ one bridge
AGENT = """
import sys, threading
from agent.protocol import Command, Keys, Measurement, decode, encode
from agent.zenoh_session import ZenohSettings, open_session
keys = Keys(sys.argv[2])
with open_session(ZenohSettings(mode="client", connect=(sys.argv[1],))) as session:
    publisher = session.declare_publisher(keys.force(1))
    def answer(sample):
        m = decode(Measurement, sample.payload.to_bytes())
        publisher.put(encode(Command(1, m.tick, (1.5, -2.5))))
    session.declare_subscriber(keys.velocity(1), answer)
    print("agent up", flush=True)
    threading.Event().wait()
"""


class Rig:
    """A router, one ``heft bridge`` on :data:`RIG_CHANNEL` (watchdog 100 ms), a stand-in
    agent process answering every measurement, and a stand-in AGV driver here: a tick every
    10 ms (Sync, Odometry, AppliedForce) and a heartbeat every 100 ms."""

    def __init__(self, folder: Path) -> None:
        self.router = f"tcp/127.0.0.1:{free_port()}"
        self.procs: dict[str, subprocess.Popen] = {}
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        self.env = env
        self._start("router", ["router", "--listen", self.router])
        config = folder / "robot-1.toml"
        config.write_text(
            f'robot = 1\nn = 2\nneighbours = [2]\nteam = "{RIG_TEAM}"\nclock = "realtime"\n'
            f'[zenoh]\nmode = "client"\nconnect = ["{self.router}"]\n'
            f'[can]\nchannel = "{RIG_CHANNEL}"\nwatchdog_ms = {WATCHDOG_MS}\n',
            encoding="utf-8",
        )
        self.bridge_log = folder / "bridge.log"
        self._start("bridge", ["bridge", "--config", str(config)], self.bridge_log.open("wb"))
        self.session = open_session(ZenohSettings(mode="client", connect=(self.router,)))
        self.statuses: list[BridgeStatus] = []
        self.session.declare_subscriber(
            Keys(RIG_TEAM).bridge(1),
            lambda s: self.statuses.append(decode(BridgeStatus, s.payload.to_bytes())),
        )
        self.start_agent()
        self.tick = 0
        self.frames: list = []  # (kernel timestamp, frame) of the bridge's frames
        self.stop = threading.Event()
        self.bus = _bus(RIG_CHANNEL)
        self.lock = threading.Lock()
        self.threads = [
            threading.Thread(target=self._drive, daemon=True),
            threading.Thread(target=self._listen, daemon=True),
        ]
        for thread in self.threads:
            thread.start()
        self.wait(lambda s: s.frames_out > 20, 60, "the bridge answers ticks")

    def _start(self, name: str, args: list[str], out=subprocess.DEVNULL) -> None:
        self.procs[name] = subprocess.Popen(
            [sys.executable, "-m", "agent", *args], cwd=ROOT, env=self.env, stdout=out, stderr=out
        )

    def start_agent(self) -> None:
        self.procs["agent"] = subprocess.Popen(
            [sys.executable, "-c", AGENT, self.router, RIG_TEAM],
            cwd=ROOT,
            env=self.env,
            stdout=subprocess.PIPE,
        )
        assert self.procs["agent"].stdout.readline().strip() == b"agent up"

    def send(self, message) -> None:
        with self.lock:
            while True:
                try:
                    self.bus.send(message, timeout=1.0)
                    return
                except Exception:  # the interface is being re-created: try again
                    if self.stop.is_set():
                        return
                    time.sleep(0.05)
                    self._reopen()

    def _reopen(self) -> None:
        try:
            self.bus.shutdown()
        except Exception:
            pass
        try:
            self.bus = _bus(RIG_CHANNEL)
        except Exception:
            time.sleep(0.1)

    def _drive(self) -> None:
        due = time.monotonic()
        beats = 0
        while not self.stop.is_set():
            k = self.tick
            for frame in (
                Sync(k),
                Odometry(1, k % 16, (0.1, 0.2)),
                AppliedForce(1, k % 16, (3, 4)),
            ):
                self.send(CODEC.encode(frame))
            if k % 10 == 0:
                self.send(CODEC.encode(Heartbeat(1, beats % 16, 2)))
                beats += 1
            self.tick = k + 1
            due += PERIOD
            time.sleep(max(0.0, due - time.monotonic()))

    def _listen(self) -> None:
        bus = None
        while not self.stop.is_set():
            try:
                bus = bus or _bus(RIG_CHANNEL)
                message = bus.recv(0.1)
            except Exception:
                bus = None
                time.sleep(0.1)
                continue
            if message is None or message.arbitration_id != 0x201:
                continue
            try:  # the bridge's frames (random ones on its id do not decode)
                self.frames.append((message.timestamp, CODEC.decode(message)))
            except FrameError:
                pass

    def latest(self) -> BridgeStatus:
        return self.statuses[-1]

    def wait(self, condition, timeout: float, what: str) -> BridgeStatus:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.statuses and condition(self.statuses[-1]):
                return self.statuses[-1]
            time.sleep(0.05)
        last = self.statuses[-1] if self.statuses else None
        log = self.bridge_log.read_text(errors="replace")[-3000:]
        raise AssertionError(f"not within {timeout} s: {what}; last status {last}\n{log}")

    def close(self) -> None:
        self.stop.set()
        for thread in self.threads:
            thread.join(5)
        for name in ("agent", "bridge", "router"):
            proc = self.procs[name]
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
                try:
                    proc.wait(10)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
        self.session.close()
        self.bus.shutdown()


@pytest.fixture(scope="module")
def rig(tmp_path_factory, vcan) -> Rig:
    rig = Rig(tmp_path_factory.mktemp("rig"))
    yield rig
    rig.close()
    assert rig.procs["bridge"].returncode == 0, rig.bridge_log.read_text()[-3000:]


def test_the_bridge_survives_its_interface_being_deleted_and_recreated(rig: Rig) -> None:
    before = rig.latest()
    subprocess.run(["ip", "link", "delete", RIG_CHANNEL], check=True)
    time.sleep(1.0)
    subprocess.run(["ip", "link", "add", "dev", RIG_CHANNEL, "type", "vcan"], check=True)
    subprocess.run(["ip", "link", "set", RIG_CHANNEL, "up"], check=True)
    after = rig.wait(lambda s: s.reopens == before.reopens + 1, 30, "the bus reopened")
    resumed = rig.wait(lambda s: s.frames_out > after.frames_out + 50, 30, "commands flow again")
    print(f"\nvcan re-created: {resumed}")
    assert rig.procs["bridge"].poll() is None


def test_the_watchdog_commands_zero_force_when_the_agent_is_killed(rig: Rig) -> None:
    """kill -9 the agent: zero-force frames follow its last command within the watchdog
    plus one frame period, by the frames' kernel timestamps; commands return with it."""
    rig.wait(lambda s: not s.watchdog, 30, "the watchdog is clear")
    rig.frames.clear()
    time.sleep(0.5)
    rig.procs["agent"].kill()
    rig.procs["agent"].wait()
    tripped = rig.wait(lambda s: s.watchdog, 10, "the watchdog trips")
    time.sleep(0.3)
    frames = list(rig.frames)
    last_force = max(t for t, f in frames if f.apply)
    first_zero = min(t for t, f in frames if not f.apply and t > last_force)
    delay_ms = (first_zero - last_force) * 1e3
    zeros = [t for t, f in frames if not f.apply and t > last_force]
    print(
        f"\nwatchdog: first zero-force frame {delay_ms:.1f} ms after the last command"
        f" (watchdog {WATCHDOG_MS} ms, period {PERIOD * 1e3:.0f} ms); {len(zeros)} zero frames"
        f" in the next {(max(zeros) - first_zero) * 1e3:.0f} ms"
    )
    assert WATCHDOG_MS <= delay_ms <= WATCHDOG_MS + PERIOD * 1e3
    assert tripped.watchdog_trips >= 1
    rig.start_agent()
    rig.wait(lambda s: not s.watchdog, 10, "commands are back")


def test_a_bridge_config_is_refused_in_one_line_before_the_bus(tmp_path: Path) -> None:
    path = tmp_path / "robot.toml"
    path.write_text('robot = 1\nn = 2\nneighbours = [2]\n[can]\nchannel = ""\n', "utf-8")
    done = subprocess.run(
        [sys.executable, "-m", "agent", "bridge", "--config", str(path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert "can.channel" in done.stderr
