"""One process per robot over Zenoh: the same estimates as in one process, isolation between
non-neighbours, loss, lost agents, and clean shutdown. Everything runs on 127.0.0.1 with
multicast scouting off.
"""

from __future__ import annotations

import io
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from agent.faults import FaultSettings
from agent.node import AgentNode, AgentNodeConfig
from agent.protocol import Keys, Measurement, Share, encode
from agent.zenoh_session import ZenohSettings, open_session
from heft.inprocess import RunOutcome, run_inprocess
from heft.launcher import free_port, run_zenoh
from simulator.generate import generate_scenario
from simulator.scenario import load_scenario
from tests.test_runs import PAPER, assert_within

ROOT = Path(__file__).resolve().parents[1]


def _processes(field: int, value: int) -> list[int]:
    """Processes whose ``/proc/<pid>/stat`` field (after the command: 1 = parent, 3 = session)
    is ``value``, other than ``value`` itself."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and int(entry.name) != value:
            try:
                stat = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(stat[field]) == value:
                found.append(int(entry.name))
    return found


def _children_of(pid: int) -> list[int]:
    return _processes(1, pid)


def _in_session(sid: int) -> list[int]:
    return _processes(3, sid)


def assert_same_estimates(a: RunOutcome, b: RunOutcome, rel: float = 1e-6) -> None:
    assert a.ticks == b.ticks
    for i, x in a.final.estimates.items():
        y = b.final.estimates[i]
        assert y.mass == pytest.approx(x.mass, rel=rel)
        assert y.moment == pytest.approx(x.moment, rel=rel)
        scale = max(1.0, math.hypot(*x.contact_to_com))
        assert math.dist(x.contact_to_com, y.contact_to_com) <= rel * scale
        for j, z in x.relative_positions.items():
            assert math.dist(z, y.relative_positions[j]) <= rel * max(1.0, math.hypot(*z))


@pytest.mark.parametrize("which", ["paper", "generated-8-robots"])
def test_lockstep_over_zenoh_reproduces_the_inprocess_run(which: str) -> None:
    scenario = load_scenario(PAPER) if which == "paper" else generate_scenario(7)
    assert scenario.n == (4 if which == "paper" else 8)
    here = run_inprocess(scenario)
    there = run_zenoh(scenario, log_stream=io.StringIO())
    assert there.converged
    assert_same_estimates(here, there)
    assert there.transport["plant"]["lost"] == []
    assert _children_of(os.getpid()) == []  # every child process is gone


def test_realtime_over_zenoh_converges_within_bounds() -> None:
    outcome = run_zenoh(load_scenario(PAPER), clock="realtime", log_stream=io.StringIO())
    assert_within(outcome, rel=0.005, metres=0.005)
    plant = outcome.transport["plant"]
    assert plant["clock"] == "realtime" and plant["latency_samples"] > 100
    # On the wall clock: a run of ~9 s simulated takes about as long.
    assert outcome.transport["stepping_wall_s"] >= 0.9 * outcome.sim_time_s


def test_realtime_with_messages_two_ticks_late_converges() -> None:
    """20 ms on every link between agents: each estimates two ticks further back, and must
    still turn its neighbours' states by the right angle."""
    faults = FaultSettings(delay_s=0.02)
    outcome = run_zenoh(
        load_scenario(PAPER), clock="realtime", faults=faults, log_stream=io.StringIO()
    )
    assert_within(outcome, rel=0.005, metres=0.005)


def test_lockstep_with_ten_percent_of_messages_lost_converges() -> None:
    faults = FaultSettings(drop=0.1, seed=3)
    outcome = run_zenoh(load_scenario(PAPER), faults=faults, log_stream=io.StringIO())
    assert_within(outcome, rel=0.005, metres=0.005)


@pytest.fixture()
def router():
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    with open_session(ZenohSettings(mode="router", connect=(), listen=(endpoint,))):
        yield endpoint


def test_an_agent_hears_nothing_from_robots_that_are_not_its_neighbours(router: str) -> None:
    """Robot 1's neighbour is robot 2 only; robot 3 publishes on the same network."""
    keys = Keys("isolation")
    settings = ZenohSettings(mode="client", connect=(router,))
    config = AgentNodeConfig(
        robot=1, n=3, neighbours=(2,), team="isolation", clock="realtime", zenoh=settings
    )
    with open_session(settings) as agent_session, open_session(settings) as others:
        node = AgentNode(config, agent_session)
        thread = threading.Thread(target=node.run, daemon=True)
        thread.start()
        try:
            time.sleep(0.5)  # subscriptions reach the router
            share2 = others.declare_publisher(keys.robot(2, "share"))
            share3 = others.declare_publisher(keys.robot(3, "share"))
            velocity = others.declare_publisher(keys.robot(1, "velocity"))
            for k in range(20):
                share2.put(encode(Share(sender=2, tick=k, velocity=(0.1, 0.0), degree=1)))
                share3.put(encode(Share(sender=3, tick=k, velocity=(9.0, 9.0), degree=1)))
            share2.put(b"not a share")  # undecodable: counted, not fatal
            share2.put(encode(Share(sender=3, tick=5, velocity=(0.0, 0.0), degree=1)))  # spoof
            velocity.put(b"\x48\x01")  # a truncated measurement
            for k in range(5):
                velocity.put(encode(Measurement(1, k, 0.01 * k, (0.0, 0.0), (0.0, 0.0))))
            deadline = time.monotonic() + 5
            while node.next_tick < 5 and time.monotonic() < deadline:
                time.sleep(0.05)
            time.sleep(0.3)
        finally:
            node.stop.set()
            thread.join(timeout=5)
            node.close()
        assert node.next_tick == 5  # it kept stepping through the garbage
        assert node.transport.samples == 22  # robot 2's 20 shares + 2 bad ones; none of 3's
        assert node.transport.decode_errors == 1
        assert node.transport.foreign == 1  # the spoofed sender is dropped too
        assert node.decode_errors == 1  # the truncated measurement
        assert node.agent.rejected == 0


def _launch(*args: str, out: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "heft",
            "run",
            str(PAPER),
            "--transport",
            "zenoh",
            "--out",
            str(out),
            *args,
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )


def _agent_pid(sid: int, robot: int, timeout: float = 20.0) -> int:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for pid in _in_session(sid):
            try:
                cmd = Path(f"/proc/{pid}/cmdline").read_bytes().decode()
            except OSError:
                continue
            if f"robot-{robot}.toml" in cmd:
                return pid
        time.sleep(0.1)
    raise AssertionError(f"no agent process for robot {robot}")


def _wait(process: subprocess.Popen, timeout: float = 60.0) -> tuple[int, str]:
    _, err = process.communicate(timeout=timeout)
    return process.returncode, err


def test_interrupt_stops_every_process(tmp_path: Path) -> None:
    launcher = _launch("--clock", "realtime", out=tmp_path / "r.json")
    _agent_pid(launcher.pid, 4)  # everything is up
    time.sleep(1.5)
    os.killpg(launcher.pid, signal.SIGINT)  # what Ctrl-C in a terminal does
    code, err = _wait(launcher, timeout=30)
    assert code == 130, err
    assert "Traceback" not in err
    time.sleep(0.5)
    assert _in_session(launcher.pid) == []


@pytest.mark.parametrize("fault", ["killed", "hung"])
def test_a_lost_agent_halts_the_team(tmp_path: Path, fault: str) -> None:
    """Robot 3 is killed (or hangs, noticed after its lease) in the middle of the run: the plant
    stops pushing for it, its neighbours notice and the team stops; what was recorded is kept."""
    out = tmp_path / "results.json"
    launcher = _launch("--clock", "realtime", out=out)
    victim = _agent_pid(launcher.pid, 3)
    time.sleep(3.0)  # Step 1 is under way
    os.kill(victim, signal.SIGKILL if fault == "killed" else signal.SIGSTOP)
    code, err = _wait(launcher, timeout=60)
    assert code == 1, err
    assert "robot 3: agent gone" in err  # the plant
    assert "lost neighbour 3" in err  # robots 2 and 4
    assert "robot(s) [3] were lost" in err
    assert "Traceback" not in err
    results = json.loads(out.read_text())
    assert results["converged"] is False
    time.sleep(0.5)
    assert _in_session(launcher.pid) == []
