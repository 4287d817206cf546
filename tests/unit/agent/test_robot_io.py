"""The robot-I/O seam (agent/platform/robot_io.py): the agent and plant nodes run unchanged on its
in-memory back-end, in lockstep, and reproduce the in-process run exactly; the in-memory hub
delivers measurements and commands to the right robot only, and liveliness and stop to those
who must hear them."""

from __future__ import annotations

import logging
import threading
import time

import pytest

from agent.node import AgentNode, AgentNodeConfig
from agent.platform.faults import FaultSettings, FaultyTransport
from agent.platform.process import RejectLog
from agent.platform.protocol import (
    Command,
    Control,
    Estimates,
    LoadGeometry,
    Measurement,
    Phase,
    PlantStatus,
    Truth,
)
from agent.platform.robot_io import InMemoryRobots, Liveliness
from agent.platform.statistics import percentile
from agent.platform.transport import InMemoryTransport
from simulator.inprocess import run_inprocess
from simulator.node import PlantNode
from simulator.scenario import Scenario, load_scenario
from tests.helpers.paths import PAPER

LOG = logging.getLogger("test")


def _rejects() -> RejectLog:
    return RejectLog(LOG, "test")


def _items(port, timeout: float = 0.5) -> list:
    return [item for _, item in port.poll(timeout)]


def test_measurements_and_commands_reach_only_their_robot() -> None:
    hub = InMemoryRobots({1: (2,), 2: (1, 3), 3: (2,)}, _rejects())
    agents = {i: hub.agent_port(i) for i in (1, 2, 3)}
    robots = hub.robots_port()
    assert set(_items(robots)) == {Liveliness(i, True) for i in (1, 2, 3)}
    assert set(_items(agents[2])) == {Liveliness(1, True), Liveliness(3, True)}
    assert _items(agents[1]) == [Liveliness(2, True)]
    assert _items(agents[3]) == [Liveliness(2, True)]
    robots.send(Measurement(2, 7, 0.07, (1.0, 0.0), (0.0, 0.0)))
    assert _items(agents[2]) == [Measurement(2, 7, 0.07, (1.0, 0.0), (0.0, 0.0))]
    assert _items(agents[1], 0.05) == [] and _items(agents[3], 0.05) == []
    agents[3].send(Command(3, 7, (0.5, -0.5)))
    assert _items(robots) == [Command(3, 7, (0.5, -0.5))]


def test_a_leaving_agent_is_reported_to_its_neighbours_and_the_robots_only() -> None:
    hub = InMemoryRobots({1: (2,), 2: (1, 3), 3: (2,)}, _rejects())
    agents = {i: hub.agent_port(i) for i in (1, 2, 3)}
    robots = hub.robots_port()
    for port in (*agents.values(), robots):
        port.poll(0.0)
    agents[3].close()
    assert _items(agents[2]) == [Liveliness(3, False)]
    assert _items(robots) == [Liveliness(3, False)]
    assert _items(agents[1], 0.05) == []
    hub.stop()
    assert _items(agents[1]) == [Control("stop")]
    assert _items(robots) == [Control("stop")]


def test_wake_ends_a_waiting_poll_at_once() -> None:
    port = InMemoryRobots({1: (2,), 2: (1,)}, _rejects()).agent_port(1)
    threading.Timer(0.05, port.wake).start()
    started = time.perf_counter()
    assert port.poll(5.0) == []
    assert time.perf_counter() - started < 2.0


def test_the_plant_tells_displays_the_loads_geometry_with_its_statuses() -> None:
    """The load's outline and graph, which no other message carries, go out as the plant
    comes up and again with each status (a display that joins late gets them)."""
    scenario = load_scenario(PAPER)
    reports: list = []
    hub = InMemoryRobots(
        {i: scenario.neighbours(i) for i in (1, 2, 3, 4)}, _rejects(), reports.append
    )
    stop = threading.Event()
    stop.set()  # stopped before its agents came: it comes up, says so and leaves
    assert PlantNode(scenario, hub.robots_port(), "lockstep", stop).run() == 0
    assert [type(m) for m in reports] == [LoadGeometry, LoadGeometry, PlantStatus]
    assert reports[0] == reports[1] == scenario.load_geometry()


def _run_nodes(scenario: Scenario) -> tuple[dict[int, Estimates], Truth, list]:
    """Plant and agent nodes on threads over the in-memory seam, in lockstep, until every
    robot is done; returns every robot's estimates and the truth at the final instant."""
    n = scenario.n
    neighbours = {i: scenario.neighbours(i) for i in range(1, n + 1)}
    reports: list = []
    hub = InMemoryRobots(neighbours, _rejects(), reports.append)
    ports = {i: hub.agent_port(i) for i in neighbours}
    shares = InMemoryTransport(n, scenario.edges, wake=lambda j: ports[j].wake())
    nodes = [
        AgentNode(
            AgentNodeConfig(
                robot=i,
                n=n,
                neighbours=neighbours[i],
                period_s=scenario.period_s,
                seed=scenario.run.seed,
                tuning=scenario.agent,
            ),
            ports[i],
            FaultyTransport(shares, FaultSettings()),
        )
        for i in neighbours
    ]
    plant = PlantNode(scenario, hub.robots_port(), "lockstep")
    threads = [threading.Thread(target=x.run, daemon=True) for x in (*nodes, plant)]
    for thread in threads:
        thread.start()
    deadline = time.monotonic() + 60
    final = None
    while final is None and time.monotonic() < deadline:
        time.sleep(0.05)
        seen = list(reports)
        estimates = [m for m in seen if isinstance(m, Estimates)]
        done = {m.robot: m.phase_since for m in estimates if m.phase == Phase.DONE}
        if len(done) == n:
            instant = max(done.values())
            at = {m.robot: m for m in estimates if m.tick == instant}
            truth = [m for m in seen if isinstance(m, Truth) and m.tick == instant]
            if len(at) == n and truth:
                final = (at, truth[0], seen)
    hub.stop()
    for thread in threads:
        thread.join(timeout=10)
    assert final is not None, "the nodes did not finish within 60 s"
    assert not any(thread.is_alive() for thread in threads)
    return final


@pytest.mark.slow
def test_nodes_on_the_in_memory_seam_reproduce_the_inprocess_run(paper: Scenario) -> None:
    here = run_inprocess(paper)
    estimates, truth, reports = _run_nodes(paper)
    assert truth.tick == here.final.truth.tick
    assert truth == here.final.truth
    assert estimates == here.final.estimates  # exactly: the same arithmetic, in the same order
    assert not [m for m in reports if isinstance(m, Estimates) and m.phase == Phase.HALTED]


@pytest.fixture()
def paper() -> Scenario:
    return load_scenario(PAPER)


def test_the_plants_latency_percentiles_are_the_projects_one(paper: Scenario) -> None:
    """The plant's status gives its command latencies' p50 and p99 in ms, by
    :func:`~agent.platform.statistics.percentile` (linear between the closest ranks)."""
    hub = InMemoryRobots({1: (2,), 2: (1,)}, _rejects())
    plant = PlantNode(paper, hub.robots_port(), "realtime")
    assert plant.status().latency_ms_p50 is None  # none measured yet
    plant.latencies.extend([0.004, 0.001, 0.003, 0.002])
    status = plant.status()
    assert status.latency_ms_p50 == pytest.approx(2.5)
    assert status.latency_ms_p99 == pytest.approx(percentile([1.0, 2.0, 3.0, 4.0], 99)) == 3.97
