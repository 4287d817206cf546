"""No message can crash, stall or hijack a run: well-encoded messages with adversarial field
values, on every key of a team, are rejected and counted by the agents, the plant and the
launcher's collector, and a run with thousands of them interleaved gives the clean run's
estimates.

The agents, the plant and the collector run here with their real Zenoh ports and transports,
on an in-process bus that stands in for a Zenoh session (the same callbacks, keys and
liveliness tokens), so every byte goes through the code that decodes it on robots. A run over
real Zenoh with a forger on its router is in
tests/integration/test_forged_messages_over_zenoh.py."""

from __future__ import annotations

import logging
import random
import struct
import threading
import time
from collections import defaultdict

import pytest
import zenoh
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.node import AgentNode, AgentNodeConfig, zenoh_agent_node
from agent.platform.process import RejectLog
from agent.platform.protocol import (
    DOMAINS,
    Barrier,
    Command,
    Control,
    DecodeError,
    Measurement,
    Phase,
    Share,
    encode,
)
from agent.platform.team import ConsensusState
from agent.platform.zenoh_robot_io import ZenohAgentsPort
from simulator.inprocess import run_inprocess
from simulator.launcher import Collector
from simulator.node import PlantNode
from simulator.scenario import Scenario, load_scenario
from tests.helpers.fakes import FakeFifo
from tests.helpers.forged import KEYS, TEAM, forged_messages
from tests.helpers.paths import PAPER

_LOG = logging.getLogger("test.hardening")


# ----------------------------------------------------------------------------- the bus
class _Payload:
    def __init__(self, data: bytes):
        self._data = data

    def to_bytes(self) -> bytes:
        return self._data


class _Sample:
    def __init__(self, key: str, data: bytes = b"", kind=zenoh.SampleKind.PUT):
        self.key_expr = key
        self.payload = _Payload(data)
        self.kind = kind


def _matches(pattern: str, key: str) -> bool:
    a, b = pattern.split("/"), key.split("/")
    return len(a) == len(b) and all(p in ("*", k) for p, k in zip(a, b))


class Bus:
    """Publish/subscribe and liveliness in one process, with Zenoh's session interface."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.subscribers: list[tuple[str, object]] = []
        self.watchers: list[tuple[str, object]] = []
        self.tokens: set[str] = set()

    def session(self) -> _Session:
        return _Session(self)

    def put(self, key: str, data: bytes) -> None:
        with self.lock:
            targets = [cb for pattern, cb in self.subscribers if _matches(pattern, key)]
        for cb in targets:
            cb(_Sample(key, data))

    def token(self, key: str, alive: bool) -> None:
        with self.lock:
            (self.tokens.add if alive else self.tokens.discard)(key)
            targets = [cb for pattern, cb in self.watchers if _matches(pattern, key)]
        kind = zenoh.SampleKind.PUT if alive else zenoh.SampleKind.DELETE
        for cb in targets:
            cb(_Sample(key, kind=kind))


class _Declared:
    def __init__(self, undeclare=lambda: None, put=None):
        self._undeclare = undeclare
        self.put = put

    def undeclare(self) -> None:
        self._undeclare()


class _Session:
    """What the project asks of a ``zenoh.Session``, on the bus."""

    def __init__(self, bus: Bus):
        self.bus = bus

    def declare_subscriber(self, key, handler):
        """``handler``: a callback, or a Zenoh handler (then samples queue in a FIFO)."""
        fifo = None if callable(handler) else FakeFifo()
        entry = (key, handler if fifo is None else fifo)
        with self.bus.lock:
            self.bus.subscribers.append(entry)
        undeclare = lambda: self.bus.subscribers.remove(entry)  # noqa: E731
        if fifo is None:
            return _Declared(undeclare)
        fifo.undeclare = undeclare
        return fifo

    def declare_publisher(self, key, **_):
        return _Declared(put=lambda data: self.bus.put(key, data))

    def put(self, key, data) -> None:
        self.bus.put(key, data)

    def liveliness(self) -> _Liveliness:
        return _Liveliness(self.bus)


class _Liveliness:
    def __init__(self, bus: Bus):
        self.bus = bus

    def declare_token(self, key):
        self.bus.token(key, True)
        return _Declared(lambda: self.bus.token(key, False))

    def declare_subscriber(self, key, callback, history=False):
        entry = (key, callback)
        with self.bus.lock:
            self.bus.watchers.append(entry)
            present = [k for k in self.bus.tokens if _matches(key, k)] if history else []
        for k in present:
            callback(_Sample(k))
        return _Declared(lambda: self.bus.watchers.remove(entry))


def _rejections(nodes, plant, collector) -> int:
    total = plant.port.rejects.total + collector.rejects.total
    seen = set()
    for node in nodes:
        if id(node.port.rejects) not in seen:
            seen.add(id(node.port.rejects))
            total += node.port.rejects.total
        total += node.agent.rejected
    return total


# ----------------------------------------------------------------------------- the team
class Team:
    """A scenario's plant, agents and collector on one bus, each agent on its own thread."""

    def __init__(self, scenario: Scenario):
        self.scenario = scenario
        self.bus = Bus()
        n = scenario.n
        self.collector = Collector(self.bus.session(), KEYS, n, record_every=5)
        self._contexts = []
        self.nodes: list[AgentNode] = []
        for i in range(1, n + 1):
            config = AgentNodeConfig(
                robot=i,
                n=n,
                neighbours=scenario.neighbours(i),
                team=TEAM,
                period_s=scenario.period_s,
                seed=scenario.run.seed,
                tuning=scenario.agent,
            )
            context = zenoh_agent_node(config, self.bus.session())
            self._contexts.append(context)
            self.nodes.append(context.__enter__())
        port = ZenohAgentsPort(self.bus.session(), KEYS, range(1, n + 1), RejectLog(_LOG, "plant"))
        self.plant = PlantNode(scenario, port, "lockstep")
        self.threads = [threading.Thread(target=x.run, daemon=True) for x in self.nodes]
        self.threads.append(threading.Thread(target=self.plant.run, daemon=True))

    def start(self) -> None:
        for thread in self.threads:
            thread.start()

    def finish(self, timeout_s: float = 60.0) -> None:
        deadline = time.monotonic() + timeout_s
        while not self.collector.finished() and time.monotonic() < deadline:
            self.collector.drain(0.05)
        self.collector.conclude()
        self.plant.stop.set()
        self.bus.put(KEYS.control(), encode(Control()))
        for thread in self.threads:
            thread.join(timeout=10)
        for context in self._contexts:
            context.__exit__(None, None, None)
        assert not any(t.is_alive() for t in self.threads)

    def rejections(self) -> int:
        self.collector.drain(0.0)
        return _rejections(self.nodes, self.plant, self.collector)


@pytest.fixture(scope="module")
def clean():
    return run_inprocess(load_scenario(PAPER))


@pytest.mark.slow
def test_the_team_on_the_bus_gives_the_inprocess_estimates(clean) -> None:
    team = Team(load_scenario(PAPER))
    team.start()
    team.finish()
    assert team.collector.final is not None
    assert team.collector.final.estimates == clean.final.estimates
    assert team.rejections() == 0


@pytest.mark.slow
def test_ten_thousand_forged_messages_change_nothing(clean) -> None:
    """Forged messages on every key, while the team runs: every one is rejected and counted,
    nothing crashes or stalls, and the estimates are the clean run's, number for number."""
    team = Team(load_scenario(PAPER))
    rng = random.Random(7)
    sent = 0
    forger_done = threading.Event()

    def forge() -> None:
        nonlocal sent
        while sent < 10_000:
            tick = team.plant.plant.tick
            for key, payload in forged_messages(rng, team.scenario.n, tick):
                team.bus.put(key, payload)
                sent += 1
            time.sleep(0.001)
        forger_done.set()

    team.start()
    forger = threading.Thread(target=forge, daemon=True)
    forger.start()
    forger_done.wait(120)
    team.finish()
    assert sent >= 10_000
    assert team.collector.final is not None, "the team did not finish"
    assert team.collector.final.estimates == clean.final.estimates
    # Every forged message is rejected by everyone who hears it: at least once each.
    assert team.rejections() >= sent
    by_reason = defaultdict(int)
    for node in team.nodes:
        for (what, why), count in node.port.rejects.reasons.items():
            by_reason[what, why] += count
    assert by_reason["measurement", "tick out of window"] > 0
    assert by_reason["share", "undecodable"] > 0
    assert team.plant.port.rejects.reasons["command", "tick from the future"] > 0


# ----------------------------------------------------------------------------- one by one
finite = st.floats(allow_nan=False, allow_infinity=False)
ids = st.integers(0, 2**16 - 1)
ticks = st.integers(-(2**63), 2**63 - 1)
pairs = st.tuples(finite, finite)
adversarial = st.one_of(
    st.builds(Measurement, robot=ids, tick=ticks, time_s=finite, velocity=pairs, force=pairs),
    st.builds(Command, robot=ids, tick=ticks, force=pairs),
    st.builds(
        Share,
        sender=ids,
        tick=ticks,
        velocity=pairs,
        degree=st.integers(0, 255),
        barrier=st.builds(
            Barrier,
            phase=st.sampled_from(Phase),
            ready=st.integers(0, 2**64 - 1),
            switch_at=ticks,
        ),
        consensus=st.builds(ConsensusState, centroid_offset=pairs, mean_square_offset=finite),
        flows=st.lists(st.tuples(ids, *[finite] * 9), max_size=4).map(tuple),
        instant=ticks,
    ),
)


def _out_of_domain(message) -> bool:
    """Encodable, and out of its domain (what decode must refuse)."""
    try:
        encode(message)
    except struct.error:
        return False
    try:
        DOMAINS[type(message)](message)
    except DecodeError:
        return True
    return False


@settings(max_examples=300, deadline=None, database=None)
@given(st.lists(adversarial.filter(_out_of_domain), min_size=1, max_size=5))
def test_every_adversarial_message_is_counted_and_nothing_raises(messages) -> None:
    bus = Bus()
    scenario = load_scenario(PAPER)
    config = AgentNodeConfig(robot=2, n=4, neighbours=(1, 3), team=TEAM, clock="realtime")
    with zenoh_agent_node(config, bus.session()) as node:
        plant_port = ZenohAgentsPort(bus.session(), KEYS, range(1, 5), RejectLog(_LOG, "plant"))
        plant = PlantNode(scenario, plant_port, "realtime")
        collector = Collector(bus.session(), KEYS, 4, record_every=5)
        sent = 0
        for message in messages:
            payload = encode(message)
            for key in (KEYS.velocity(2), KEYS.share(1), KEYS.force(2), KEYS.estimate(1)):
                bus.put(key, payload)
                sent += 1
        node.pump(0.0)
        plant._drain(0.0)
        collector.drain(0.0)
        # On a key of another kind the payload is undecodable; on its own, out of its domain.
        assert _rejections([node], plant, collector) == sent
        assert node.next_tick == 0 and plant.commands == {}


# ----------------------------------------------------------------------------- the clocks
def _agent(bus: Bus, clock: str):
    config = AgentNodeConfig(robot=1, n=2, neighbours=(2,), team=TEAM, clock=clock)
    return zenoh_agent_node(config, bus.session())


def _measure(bus: Bus, tick: int, robot: int = 1) -> None:
    m = Measurement(robot, tick, tick * 0.01, (0.0, 0.0), (0.0, 0.0))
    bus.put(KEYS.velocity(robot), encode(m))


def test_a_measurement_far_ahead_is_not_adopted_as_the_clock() -> None:
    """The probe: one measurement stamped far ahead once made a robot jump there and never
    step again. It is rejected; the agent keeps its clock and keeps stepping."""
    bus = Bus()
    with _agent(bus, "realtime") as node:
        for k in range(3):
            _measure(bus, k)
            node.pump(0.0)
        assert node.next_tick == 3
        _measure(bus, 3 + 10_000)
        _measure(bus, 3)
        node.pump(0.0)
        assert node.next_tick == 4
        assert node.port.rejects.reasons["measurement", "tick out of window"] == 1


def test_in_real_time_the_clock_starts_at_two_consecutive_samples() -> None:
    bus = Bus()
    with _agent(bus, "realtime") as node:
        _measure(bus, 7_000_000)  # a lone sample (a forger's, or a clock gone wrong)
        _measure(bus, 120)
        node.pump(0.0)
        assert node.next_tick == 0 and node.last_command is None  # not started on one sample
        _measure(bus, 121)
        node.pump(0.0)
        assert node.next_tick == 122  # started at 120, stepped 120 and 121
        assert 7_000_000 not in node.measurements
        assert node.port.rejects.reasons["measurement", "tick out of window"] == 1


def test_in_lockstep_the_clock_starts_at_the_plants_first_tick() -> None:
    bus = Bus()
    with _agent(bus, "lockstep") as node:
        _measure(bus, 10**9)
        _measure(bus, 0)
        node.pump(0.0)
        assert node.next_tick == 1
        assert node.port.rejects.reasons["measurement", "tick out of window"] == 1


def test_the_plant_takes_no_command_from_the_future() -> None:
    """The probe: one command stamped far ahead was kept as "the newest" for the rest of the
    run (J estimated 1479 against 12.38). It is rejected; the next real command applies."""
    bus = Bus()
    scenario = load_scenario(PAPER)
    port = ZenohAgentsPort(bus.session(), KEYS, range(1, 5), RejectLog(_LOG, "plant"))
    plant = PlantNode(scenario, port, "realtime")
    bus.put(KEYS.force(3), encode(Command(3, 40, (10.0, 0.0))))
    bus.put(KEYS.force(3), encode(Command(3, 0, (1.0, 0.0))))
    plant._drain(0.0)
    assert plant.commands[3] == Command(3, 0, (1.0, 0.0))
    assert port.rejects.reasons["command", "tick from the future"] == 1
