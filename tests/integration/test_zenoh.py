"""One process per robot over Zenoh: the same estimates as in one process, isolation between
non-neighbours, loss, lost agents, and clean shutdown. Everything runs on 127.0.0.1 with
multicast scouting off.
"""

from __future__ import annotations

import io
import json
import os
import signal
import threading
import time
from pathlib import Path

import pytest

from agent.node import AgentNodeConfig, zenoh_agent_node
from agent.platform.children import free_port
from agent.platform.faults import FaultSettings
from agent.platform.protocol import Keys, LogLine, Measurement, Share, decode, encode
from agent.platform.zenoh_session import ZenohSettings, open_session
from simulator.generate import generate_scenario
from simulator.inprocess import run_inprocess
from simulator.launcher import run_zenoh
from simulator.scenario import load_scenario
from tests.helpers.accuracy import assert_same_estimates, assert_within
from tests.helpers.paths import PAPER
from tests.helpers.processes import agent_pid, children_of, in_session, launch, wait_for

pytestmark = pytest.mark.slow  # Zenoh sessions and processes


@pytest.mark.parametrize("which", ["paper", "generated-8-robots"])
def test_lockstep_over_zenoh_reproduces_the_inprocess_run(which: str) -> None:
    scenario = load_scenario(PAPER) if which == "paper" else generate_scenario(7)
    assert scenario.n == (4 if which == "paper" else 8)
    here = run_inprocess(scenario)
    there = run_zenoh(scenario, log_stream=io.StringIO())
    assert there.converged
    assert_same_estimates(here, there)
    assert there.transport["plant"]["lost"] == ()
    assert children_of(os.getpid()) == []  # every child process is gone


def test_lockstep_over_zenoh_ends_at_the_inprocess_instant_every_time() -> None:
    """The final instant is decided by the team's state, not by which message arrives first:
    ten runs in a row, every one equal to the in-process run."""
    scenario = load_scenario(PAPER)
    here = run_inprocess(scenario)
    for _ in range(10):
        there = run_zenoh(scenario, log_stream=io.StringIO())
        assert there.converged
        assert_same_estimates(here, there)


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
    """Robot 1's neighbour is robot 2 only; robot 3 publishes on the same network. What it
    rejects it logs, and the team hears it as log lines on its log key."""
    keys = Keys("isolation")
    settings = ZenohSettings(mode="client", connect=(router,))
    config = AgentNodeConfig(
        robot=1, n=3, neighbours=(2,), team="isolation", clock="realtime", zenoh=settings
    )
    with (
        open_session(settings) as agent_session,
        open_session(settings) as others,
        zenoh_agent_node(config, agent_session) as node,
    ):
        lines: list[LogLine] = []
        log = others.declare_subscriber(
            keys.log(1), lambda s: lines.append(decode(LogLine, s.payload.to_bytes()))
        )
        thread = threading.Thread(target=node.run, daemon=True)
        thread.start()
        try:
            time.sleep(0.5)  # subscriptions reach the router
            share2 = others.declare_publisher(keys.share(2))
            share3 = others.declare_publisher(keys.share(3))
            velocity = others.declare_publisher(keys.velocity(1))
            for k in range(20):
                share2.put(encode(Share(sender=2, tick=k, velocity=(0.1, 0.0), degree=1)))
                share3.put(encode(Share(sender=3, tick=k, velocity=(9.0, 9.0), degree=1)))
            share2.put(b"not a share")  # undecodable: counted, not fatal
            share2.put(encode(Share(sender=3, tick=5, velocity=(0.0, 0.0), degree=1)))  # spoof
            velocity.put(b"\x48\x02")  # a truncated measurement
            velocity.put(encode(Measurement(2, 3, 0.03, (5.0, 5.0), (0.0, 0.0))))  # robot 2's
            for k in range(5):
                velocity.put(encode(Measurement(1, k, 0.01 * k, (0.0, 0.0), (0.0, 0.0))))
            deadline = time.monotonic() + 5
            while node.next_tick < 5 and time.monotonic() < deadline:
                time.sleep(0.05)
            time.sleep(0.3)
        finally:
            node.stop.set()
            thread.join(timeout=5)
            log.undeclare()
        assert node.next_tick == 5  # it kept stepping through the garbage
        # The undecodable share and the spoofed sender; none of robot 3's own 20 shares.
        assert node.port.rejects.counts["share"] == 2
        # The truncated measurement and robot 2's measurement on robot 1's key.
        assert node.port.rejects.counts["measurement"] == 2
        assert node.agent.rejected == 0
        rejected = [line for line in lines if "rejected" in line.text]
        assert [line.level for line in rejected] == ["warning"] * 4, lines
        assert {line.text.split(" #")[0] for line in rejected} == {
            "robot 1: rejected share",
            "robot 1: rejected measurement",
        }


def test_interrupt_stops_every_process(tmp_path: Path) -> None:
    launcher = launch("--clock", "realtime", out=tmp_path / "r.json")
    agent_pid(launcher.pid, 4)  # everything is up
    time.sleep(1.5)
    os.killpg(launcher.pid, signal.SIGINT)  # what Ctrl-C in a terminal does
    code, err = wait_for(launcher, timeout=30)
    assert code == 130, err
    assert "Traceback" not in err
    time.sleep(0.5)
    assert in_session(launcher.pid) == []


@pytest.mark.parametrize("fault", ["killed", "hung"])
def test_a_lost_agent_halts_the_team(tmp_path: Path, fault: str) -> None:
    """Robot 3 is killed (or hangs, noticed after its lease) in the middle of the run: the plant
    stops pushing for it, its neighbours notice and the team stops; what was recorded is kept."""
    out = tmp_path / "results.json"
    launcher = launch("--clock", "realtime", out=out)
    victim = agent_pid(launcher.pid, 3)
    time.sleep(3.0)  # Step 1 is under way
    os.kill(victim, signal.SIGKILL if fault == "killed" else signal.SIGSTOP)
    code, err = wait_for(launcher, timeout=60)
    assert code == 1, err
    assert "robot 3: agent gone" in err  # the plant
    assert "lost neighbour 3" in err  # robots 2 and 4
    assert "not converged: robot(s) [3] lost" in err
    assert "Traceback" not in err
    results = json.loads(out.read_text())
    assert results["converged"] is False and results["reason"] == "robot(s) [3] lost"
    time.sleep(0.5)
    assert in_session(launcher.pid) == []


def test_heft_watch_with_no_plant_says_so(capsys) -> None:
    """``heft watch`` shares ``heft run``'s way from its options to its run: with a router and
    no team on it, it gives up after ``--start-timeout`` with a verdict, exit status 1."""
    from agent.platform.heft import main

    listen = f"tcp/127.0.0.1:{free_port()}"
    with open_session(ZenohSettings(mode="peer", connect=(), listen=(listen,))):
        code = main(
            ["watch", str(PAPER), "--team", "nobody", "--connect", listen]
            + ["--start-timeout", "0.5", "--quiet"]
        )
    err = capsys.readouterr().err
    assert code == 1, err
    assert "Traceback" not in err
    assert "nothing heard of the plant within 0.5 s" in err.strip().splitlines()[-1]
