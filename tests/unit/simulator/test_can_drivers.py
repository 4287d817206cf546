"""The robots' drivers on CAN (simulator/can_drivers.py), on python-can's ``virtual`` buses
(they cross threads within one process, no kernel CAN needed): the frames of each tick, the
heartbeats, force commands back with their ticks, the bridge watchdog's ZERO frames, bad
frames counted, and the in-process run quantised as CAN quantises."""

from __future__ import annotations

import dataclasses
import itertools
import logging
import math
import queue
import threading
import time

import can
import pytest

from agent.node import AgentNode, AgentNodeConfig
from agent.platform.faults import FaultSettings, FaultyTransport
from agent.platform.process import EventQueue, RejectLog
from agent.platform.protocol import Command, Estimates, Measurement, Phase, Truth
from agent.platform.robot_io import AgentsPort, InMemoryRobots, Liveliness
from agent.platform.transport import InMemoryTransport
from bridge.admittance import Admittance
from bridge.codec import (
    AgvCodec,
    AppliedForce,
    ForceCommand,
    ForceTorque,
    Heartbeat,
    MotionCommand,
    MotionFeedback,
    Odometry,
    Sync,
    clamp_command_velocity,
    clamp_force,
)
from bridge.dbc import MAX_SPEED
from simulator.can_drivers import (
    ACTIVE,
    FEEDBACK,
    READY,
    CanDriversPort,
    CanLink,
    CanQuantiser,
)
from simulator.inprocess import run_inprocess
from simulator.lockstep import RunEnd, VelocityCommand
from simulator.node import PlantNode
from simulator.scenario import load_scenario
from tests.helpers.accuracy import worst_errors
from tests.helpers.paths import PAPER

LOG = logging.getLogger("test")
CODEC = AgvCodec()
_channels = itertools.count()


def _channel() -> str:
    return f"heft-test-{time.monotonic_ns()}-{next(_channels)}"


class StubRest(AgentsPort):
    """The plant's non-CAN side, in memory: liveliness and control put in by the test,
    reports kept."""

    def __init__(self, robots) -> None:
        super().__init__(robots, RejectLog(LOG, "plant"))
        self.reports: list = []
        self.closed = False

    def send(self, measurement: Measurement) -> None:
        raise AssertionError("a CAN plant sends no measurement over the other side")

    def report(self, message) -> None:
        self.reports.append(message)

    def close(self) -> None:
        self.closed = True

    def up(self, robot: int, *who: str, alive: bool = True) -> None:
        for w in who:
            self.events.put((time.perf_counter(), Liveliness(robot, alive, w)))


class Buses:
    """Each robot's bus twice: the plant's end and the bridge's (the test's) end."""

    def __init__(self, robots, shared: bool = False) -> None:
        names = {i: _channel() for i in robots}
        if shared:
            names = dict.fromkeys(robots, names[min(robots)])
        opened: dict[str, can.BusABC] = {}
        self.plant = {}
        for i, name in names.items():
            if name not in opened:
                opened[name] = can.Bus(interface="virtual", channel=name)
            self.plant[i] = opened[name]
        self.peer = {i: can.Bus(interface="virtual", channel=names[i]) for i in robots}

    def frames(self, robot: int, timeout: float = 0.2, kinds=None, within: float = 2.0) -> list:
        """Every frame on robot's bus until ``timeout`` of silence or for ``within`` s at
        most (``kinds``: only those)."""
        out = []
        deadline = time.monotonic() + within
        while time.monotonic() < deadline:
            message = self.peer[robot].recv(timeout)
            if message is None:
                break
            frame = CODEC.decode(message)
            if kinds is None or isinstance(frame, kinds):
                out.append(frame)
        return out

    def command(self, robot: int, counter: int, force=(0.0, 0.0), apply: bool = True) -> None:
        self.peer[robot].send(CODEC.encode(ForceCommand(robot, counter, force, apply)))

    def close(self) -> None:
        for bus in {id(b): b for b in (*self.plant.values(), *self.peer.values())}.values():
            bus.shutdown()


@pytest.fixture()
def rig():
    """A CAN port for robots 1 and 2 (lockstep), its stub other side and the buses."""
    buses = Buses((1, 2))
    rest = StubRest((1, 2))
    port = CanDriversPort(rest, buses.plant, "lockstep", heartbeat_period_s=3600.0)
    yield port, rest, buses
    port.close()
    buses.close()


def _items(port: AgentsPort, timeout: float = 0.3) -> list:
    out = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        out += [item for _, item in port.poll(0.05)]
    return out


DATA = (Odometry, AppliedForce, Sync)


# ------------------------------------------------------------------------------ out
def test_each_tick_is_a_sync_then_odometry_and_applied_force_on_the_robots_bus(rig) -> None:
    port, _, buses = rig
    for tick in (0, 1, 17):
        port.send(Measurement(1, tick, tick * 0.01, (0.25, -1.5), (2.0, -3.0)))
        port.send(Measurement(2, tick, tick * 0.01, (0.5, 0.0), (0.0, 1.0)))
        c = tick % 16
        assert buses.frames(1, kinds=DATA) == [
            Sync(tick),
            Odometry(1, c, (0.25, -1.5)),
            AppliedForce(1, c, (2.0, -3.0)),
        ]
        assert buses.frames(2, kinds=DATA) == [
            Sync(tick),
            Odometry(2, c, (0.5, 0.0)),
            AppliedForce(2, c, (0.0, 1.0)),
        ]
    # The tick sent again (lockstep asks a silent robot again): its Sync too, in case that
    # was what got lost; the other robot's bus is left alone.
    port.send(Measurement(1, 17, 0.17, (0.25, -1.5), (2.0, -3.0)))
    assert [type(f) for f in buses.frames(1, kinds=DATA)] == [Sync, Odometry, AppliedForce]
    assert buses.frames(2, kinds=DATA) == []
    assert port.counts["frames out"] - port.counts["heartbeats"] == 3 * 6 + 3


def test_one_sync_per_tick_on_a_bus_the_robots_share() -> None:
    buses = Buses((1, 2, 3), shared=True)
    port = CanDriversPort(StubRest((1, 2, 3)), buses.plant, "lockstep", heartbeat_period_s=3600)
    try:
        for robot in (1, 2, 3):
            port.send(Measurement(robot, 5, 0.05, (0.0, 0.0), (0.0, 0.0)))
        frames = buses.frames(1, kinds=DATA)
        assert frames[0] == Sync(5) and frames.count(Sync(5)) == 1
        assert [f.node for f in frames[1:]] == [1, 1, 2, 2, 3, 3]
    finally:
        port.close()
        buses.close()


def test_values_go_out_quantised_and_clamped_to_the_dbc_ranges(rig) -> None:
    port, _, buses = rig
    velocity, force = (0.1234567891, 17.0), (612.5, -0.123456789)
    port.send(Measurement(1, 3, 0.03, velocity, force))
    _, odometry, applied = buses.frames(1, kinds=DATA)
    assert odometry.velocity == CODEC.quantize_velocity((0.1234567891, MAX_SPEED))
    assert applied.force == CODEC.quantize_force((500.0, -0.123456789))
    assert port.counts["velocity clamped"] == 1 and port.counts["force clamped"] == 1
    quantised = CanQuantiser(0.01).measurement(Measurement(1, 3, 0.0, velocity, force))
    assert (quantised.velocity, quantised.force) == (odometry.velocity, applied.force)
    assert quantised.time_s == 3 * 0.01


def test_every_driver_sends_a_heartbeat_every_period() -> None:
    buses = Buses((1, 2))
    port = CanDriversPort(StubRest((1, 2)), buses.plant, "realtime", heartbeat_period_s=0.02)
    try:
        before = buses.frames(1, kinds=Heartbeat, within=0.15)
        port.send(Measurement(1, 0, 0.0, (0.0, 0.0), (0.0, 0.0)))
        after = buses.frames(1, kinds=Heartbeat, within=0.15)
    finally:
        port.close()
        buses.close()
    assert len(before) >= 4 and {b.node for b in before} == {1}
    beats = before + after
    assert [b.counter for b in beats] == [k % 16 for k in range(len(beats))]
    assert before[0].mode == READY and after[-1].mode == ACTIVE  # ACTIVE once ticks run


# ------------------------------------------------------------------------------ in
def test_a_force_command_is_a_command_for_the_newest_tick_with_its_counter(rig) -> None:
    port, _, buses = rig
    port.send(Measurement(1, 33, 0.33, (0.0, 0.0), (0.0, 0.0)))  # opens tick 33 (33 % 16 = 1)
    buses.command(1, 1, (1.5, -2.5))
    buses.command(1, 0, (1.0, 0.0))  # 32
    buses.command(1, 2, (2.0, 0.0))  # 18: 34 is not open yet
    assert _items(port) == [
        Command(1, 33, (1.5, -2.5)),
        Command(1, 32, (1.0, 0.0)),
        Command(1, 18, (2.0, 0.0)),
    ]


def test_the_watchdogs_zero_frame_is_no_tick_command_in_lockstep(rig) -> None:
    port, _, buses = rig
    port.send(Measurement(2, 7, 0.07, (0.0, 0.0), (0.0, 0.0)))
    buses.command(2, 7, (3.0, 3.0), apply=False)
    assert _items(port) == []
    assert port.counts["zero commands"] == 1
    buses.command(2, 7, (3.0, 3.0))  # the agent's own, later: that is the tick's command
    assert _items(port) == [Command(2, 7, (3.0, 3.0))]


def test_the_watchdogs_zero_frame_is_a_zero_command_on_the_wall_clock() -> None:
    buses = Buses((1,))
    port = CanDriversPort(StubRest((1,)), buses.plant, "realtime", heartbeat_period_s=3600)
    try:
        port.send(Measurement(1, 40, 0.4, (0.0, 0.0), (0.0, 0.0)))
        buses.command(1, 5, apply=False)  # whatever its counter: the latest tick
        assert _items(port) == [Command(1, 40, (0.0, 0.0))]
        assert port.counts["zero commands"] == 1
    finally:
        port.close()
        buses.close()


def _raw(arbitration_id: int, data: bytes, **kw) -> can.Message:
    return can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=False, **kw)


def test_bad_frames_are_counted_never_raised(rig) -> None:
    port, rest, buses = rig
    good = CODEC.encode(ForceCommand(1, 0, (1.0, 1.0)))
    corrupted = bytearray(good.data)
    corrupted[2] ^= 0x10
    buses.command(1, 0, (1.0, 1.0))  # before any Sync: no tick to give it
    time.sleep(0.2)
    port.send(Measurement(1, 0, 0.0, (0.0, 0.0), (0.0, 0.0)))
    peer = buses.peer[1]
    peer.send(_raw(good.arbitration_id, bytes(corrupted)))  # checksum
    peer.send(_raw(0x123, bytes(8)))  # unknown id
    peer.send(_raw(good.arbitration_id, bytes(good.data[:6])))  # wrong length
    peer.send(can.Message(arbitration_id=0x201, data=bytes(8), is_extended_id=True))
    peer.send(_raw(0x201, b"", is_remote_frame=True, dlc=8))
    peer.send(CODEC.encode(ForceCommand(2, 0, (1.0, 1.0))))  # robot 2's, on robot 1's bus
    peer.send(CODEC.encode(Odometry(9, 0, (0.0, 0.0))))  # another driver on the bus
    peer.send(CODEC.encode(Odometry(1, 0, (0.0, 0.0))))  # our own frame, echoed: ignored
    peer.send(CODEC.encode(Sync(0)))
    buses.command(1, 0, (1.0, 1.0))  # and the port still works
    assert _items(port) == [Command(1, 0, (1.0, 1.0))]
    reasons: dict[str, int] = {}
    for (_, why), n in rest.rejects.reasons.items():
        reasons[why] = reasons.get(why, 0) + n
    assert reasons == {
        "before the first tick": 1,
        "checksum": 1,
        "unknown id": 1,
        "wrong length": 1,
        "extended id": 1,
        "remote frame": 1,
        "not a robot on this bus": 2,
    }
    assert port.rejects.total == 8 and port.counts["echoes"] == 2


def test_a_robot_is_up_once_its_agent_and_its_bridge_are_and_lost_when_either_goes(rig) -> None:
    port, rest, _ = rig
    rest.up(1, "agent")
    assert _items(port, 0.1) == []
    rest.up(1, "bridge")
    rest.up(2, "bridge", "agent")
    assert _items(port) == [Liveliness(1, True), Liveliness(2, True)]
    rest.up(1, "bridge", alive=False)
    rest.up(2, "agent", alive=False)
    assert _items(port) == [Liveliness(1, False, "bridge"), Liveliness(2, False, "agent")]


def test_reports_go_to_the_other_side_and_closing_closes_it(rig) -> None:
    port, rest, _ = rig
    port.report(
        Truth(
            0,
            0.0,
            (0.0, 0.0),
            0.0,
            (0.0, 0.0),
            0.0,
            ((0.0, 0.0),),
            ((0.0, 0.0),),
            ((0.0, 0.0),),
            1.0,
            1.0,
        )
    )
    assert len(rest.reports) == 1
    port.close()
    assert rest.closed


def test_channel_templates() -> None:
    assert CanLink().channel_of(3) == "vcan3"
    assert CanLink("virtual", "bus").channel_of(3) == "bus"
    assert CanLink("socketcan", "can{robot}-agv").channel_of(12) == "can12-agv"
    for bad in (CanLink("socket can"), CanLink(channel="vcan{i}"), CanLink(channel="")):
        with pytest.raises(ValueError):
            bad.validate()


# ------------------------------------------------------------------------------ in one process
def _speeds(outcome) -> float:
    return max(abs(v) for s in outcome.history for c in s.truth.contact_velocities for v in c)


def test_the_inprocess_can_run_converges_on_the_papers_scenario() -> None:
    """Quantised as on the bus (1 µm/s, 0.1 mN), the paper's scenario still converges within
    the noise-free bounds, and its contacts stay inside the odometry's range."""
    outcome = run_inprocess(load_scenario(PAPER), link="can")
    worst = worst_errors(outcome)
    print(
        f"\nin process, CAN-quantised paper: converged {outcome.converged}"
        f" after {outcome.sim_time_s:.2f} s simulated; worst errors: mass"
        f" {worst['mass']:.2e}, J {worst['moment']:.2e}, contact-to-COM"
        f" {worst['contact_to_com'] * 1e3:.3f} mm, z_ij {worst['relative'] * 1e3:.3f} mm;"
        f" fastest contact {_speeds(outcome):.2f} m/s"
    )
    assert outcome.converged and outcome.sim_time_s < 20.0
    assert worst["mass"] < 1e-3 and worst["moment"] < 1e-3
    assert worst["contact_to_com"] < 1e-3 and worst["relative"] < 1e-3
    assert _speeds(outcome) < MAX_SPEED


def test_the_can_link_only_quantises(monkeypatch) -> None:
    """What the agents get is what the codec decodes, and what the plant applies is what
    the driver decodes from the bridge's frame."""
    from simulator import inprocess
    from simulator.plant import Plant

    seen: list[Measurement] = []
    applied: list = []
    step = inprocess.Agent.step

    def spy_step(self, measurement, shares):
        seen.append(measurement)
        return step(self, measurement, shares)

    command = Plant.command

    def spy_command(self, robot, force):
        applied.append(force)
        return command(self, robot, force)

    monkeypatch.setattr(inprocess.Agent, "step", spy_step)
    monkeypatch.setattr(Plant, "command", spy_command)
    scenario = load_scenario(PAPER)
    scenario = dataclasses.replace(scenario, run=dataclasses.replace(scenario.run, max_time_s=1))
    run_inprocess(scenario, link="can")
    assert len(seen) > 400
    for m in seen:
        assert m.velocity == CODEC.quantize_velocity(m.velocity)
        assert m.force == CODEC.quantize_force(m.force)
        assert m.time_s == m.tick * scenario.period_s
    assert any(f != (0.0, 0.0) for f in applied)
    for f in applied:
        assert f == CODEC.quantize_force(clamp_force(f)[0])


def test_an_unknown_link_is_refused() -> None:
    with pytest.raises(ValueError, match="link"):
        run_inprocess(load_scenario(PAPER), link="carrier pigeon")


# ------------------------------------------------------------------------------ nodes
class StandInBridges:
    """A minimal stand-in for the AGV bridges: robot i's frames of a tick → its agent's
    measurement (``time_s = tick × period``), its agent's command → a ForceCommand frame; with
    admittance ``loops`` (velocity profile), the raw force tared by robot i's loop, and its
    velocity for the agent's force → a MotionCommand frame."""

    def __init__(
        self,
        buses: Buses,
        hub_port: AgentsPort,
        period_s: float,
        codec: AgvCodec = CODEC,
        loops: dict[int, Admittance] | None = None,
    ) -> None:
        self.buses = buses
        self.hub_port = hub_port
        self.period_s = period_s
        self.codec = codec
        self.loops = loops
        self.stop = threading.Event()
        self.threads = [
            threading.Thread(target=self._frames, args=(i,), daemon=True) for i in buses.peer
        ]
        self.threads.append(threading.Thread(target=self._commands, daemon=True))
        for thread in self.threads:
            thread.start()

    def _frames(self, robot: int) -> None:
        tick, velocity = -1, None
        sampled, measured = FEEDBACK[self.codec.profile]
        while not self.stop.is_set():
            message = self.buses.peer[robot].recv(0.05)
            if message is None:
                continue
            frame = self.codec.decode(message)
            if isinstance(frame, Sync):
                tick, velocity = frame.tick, None
            elif isinstance(frame, sampled) and frame.counter == tick % 16:
                velocity = frame.velocity
            elif isinstance(frame, measured) and velocity is not None:
                force = (
                    frame.force if self.loops is None else self.loops[robot].measure(frame.force)
                )
                m = Measurement(robot, tick, tick * self.period_s, velocity, force)
                self.hub_port.send(m)

    def _commands(self) -> None:
        while not self.stop.is_set():
            for _, item in self.hub_port.poll(0.05):
                if not isinstance(item, Command):
                    continue
                if self.loops is None:
                    force, _ = clamp_force(item.force)
                    self.buses.command(item.robot, item.tick % 16, force)
                    continue
                force, _ = clamp_force(item.force)
                velocity, _ = clamp_command_velocity(self.loops[item.robot].step(force))
                frame = MotionCommand(item.robot, item.tick % 16, velocity)
                self.buses.peer[item.robot].send(self.codec.encode(frame))

    def close(self) -> None:
        self.stop.set()
        for thread in self.threads:
            thread.join(timeout=5)


def _on_can(scenario, until, codec: AgvCodec = CODEC):
    """PlantNode on the CAN port of ``codec``'s profile, stand-in bridges (with admittance
    loops for velocity bases) and the agent nodes, all on threads, until ``until(estimates,
    truths, done)`` returns something (or 120 s): that, and the port."""
    n = scenario.n
    neighbours = {i: scenario.neighbours(i) for i in range(1, n + 1)}
    reports: queue.SimpleQueue = queue.SimpleQueue()
    hub = InMemoryRobots(neighbours, RejectLog(LOG, "test"), reports.put)
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
    buses = Buses(tuple(neighbours))
    bridged = scenario.agvs.velocity
    loops = None
    if bridged:
        loops = {i: Admittance(scenario.agvs.admittance, scenario.period_s) for i in neighbours}
    bridges = StandInBridges(buses, hub.robots_port(), scenario.period_s, codec, loops)
    rest = StubRest(tuple(neighbours))
    rest.report = reports.put
    for i in neighbours:
        rest.up(i, "agent", "bridge")
    port = CanDriversPort(rest, buses.plant, "lockstep", codec)
    plant = PlantNode(scenario, port, "lockstep", bridged=bridged)
    threads = [threading.Thread(target=x.run, daemon=True) for x in (*nodes, plant)]
    for thread in threads:
        thread.start()
    estimates: dict[int, dict[int, Estimates]] = {}
    truths: dict[int, Truth] = {}
    done: dict[int, int] = {}
    final = None
    deadline = time.monotonic() + 120
    try:
        while final is None and time.monotonic() < deadline:
            try:
                m = reports.get(timeout=0.5)
            except queue.Empty:
                continue
            if isinstance(m, Estimates):
                estimates.setdefault(m.tick, {})[m.robot] = m
                if m.phase == Phase.DONE:
                    done[m.robot] = m.phase_since
            elif isinstance(m, Truth):
                truths[m.tick] = m
            final = until(estimates, truths, done)
    finally:
        plant.stop.set()
        hub.stop()
        for thread in threads:
            thread.join(timeout=10)
        bridges.close()
        port.close()
        buses.close()
    assert final is not None, "the nodes did not finish within 120 s"
    return final, port


@pytest.mark.slow
def test_plant_node_on_can_in_lockstep_reproduces_the_inprocess_can_run() -> None:
    """PlantNode on the CAN port, stand-in bridges and the agent nodes, all on threads:
    exactly the in-process run quantised as CAN quantises."""
    scenario = load_scenario(PAPER)
    here = run_inprocess(scenario, link="can")

    def until(estimates, truths, done):
        if len(done) == scenario.n:
            instant = max(done.values())
            if len(estimates.get(instant, {})) == scenario.n and instant in truths:
                return estimates[instant], truths[instant]
        return None

    final, port = _on_can(scenario, until)
    assert final[1] == here.final.truth
    assert final[0] == here.final.estimates  # exactly: the same arithmetic, the same values
    assert port.rejects.total == 0 and port.counts["zero commands"] == 0
    assert math.isclose(final[1].time_s, here.final.time_s)


@pytest.mark.slow
def test_velocity_bases_on_can_in_lockstep_reproduce_the_inprocess_can_run() -> None:
    """The same with velocity-commanded bases behind their bridges' admittance loops, for the
    scenario's first 2 s (the plant's every tick, truth and estimates)."""
    scenario = load_scenario(PAPER.with_name("paper-velocity.toml"))
    scenario = dataclasses.replace(scenario, run=dataclasses.replace(scenario.run, max_time_s=2.0))
    here = run_inprocess(scenario, link="can", record_every=1)
    last = RunEnd.of(scenario).last_tick

    def until(estimates, truths, done):
        ready = last in truths and len(estimates.get(last - 1, {})) == scenario.n
        return (estimates, truths) if ready else None

    (estimates, truths), port = _on_can(scenario, until, AgvCodec("velocity"))
    compared = [s for s in here.history if s.truth.tick < last]
    assert len(compared) == last
    for sample in compared:
        assert truths[sample.truth.tick] == sample.truth
    published = [s for s in compared if len(estimates.get(s.truth.tick, {})) == scenario.n]
    assert len(published) >= 40  # (the agents publish every fifth tick)
    for sample in published:
        assert estimates[sample.truth.tick] == sample.estimates
    assert port.rejects.total == 0 and port.counts["stop commands"] == 0
    assert max(math.hypot(*t.com_velocity) for t in truths.values()) > 0.003  # it moved


def test_an_event_queue_is_shared_with_the_other_side(rig) -> None:
    port, rest, _ = rig
    assert port.events is rest.events and isinstance(port.events, EventQueue)


# ------------------------------------------------------------------------------ the commands
@pytest.mark.parametrize(
    "args, words",
    [
        (["sim", str(PAPER), "--can-interface", "virtual"], "--can-interface needs --can"),
        (["sim", str(PAPER), "--can", "--can-channel", "vcan{i}"], "--can-channel"),
        (["sim", str(PAPER), "--can", "--can-interface", "socket can"], "--can-interface"),
        (["run", str(PAPER), "--can-channel", "can{robot}"], "--can-channel needs --can"),
        (["run", str(PAPER), "--can", "--can-channel", "a b"], "--can-channel"),
    ],
)
def test_bad_can_options_are_one_line_and_status_2(args, words, capsys) -> None:
    from agent.platform.heft import main

    code = main(args)
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert err.strip().splitlines() == [err.strip()] and err.startswith("heft: error: ")
    assert words in err


def test_heft_run_can_in_one_process_is_the_quantised_reference(tmp_path, capsys) -> None:
    import json

    from agent.platform.heft import main

    path = PAPER
    out = tmp_path / "results.json"
    code = main(["run", str(path), "--can", "--transport", "inprocess", "-q", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    results = json.loads(out.read_text())
    reference = run_inprocess(load_scenario(PAPER), link="can")
    assert results["sim_time_s"] == reference.sim_time_s
    assert results["robots"]["1"]["mass"] == reference.final.estimates[1].mass


# ------------------------------------------------------------------------------ velocity profile
VELOCITY = AgvCodec("velocity")


@pytest.fixture()
def velocity_rig():
    """A CAN port of the velocity profile for robots 1 and 2 (lockstep) and the buses."""
    buses = Buses((1, 2))
    port = CanDriversPort(
        StubRest((1, 2)), buses.plant, "lockstep", VELOCITY, heartbeat_period_s=3600.0
    )
    yield port, buses
    port.close()
    buses.close()


def _velocity_frames(buses: Buses, robot: int) -> list:
    out = []
    while (message := buses.peer[robot].recv(0.2)) is not None:
        frame = VELOCITY.decode(message)
        if not isinstance(frame, Heartbeat):
            out.append(frame)
    return out


def test_velocity_bases_send_their_velocity_and_raw_force_each_tick(velocity_rig) -> None:
    port, buses = velocity_rig
    port.send(Measurement(1, 19, 0.19, (0.25, -1.5), (612.5, -0.123456789)))
    assert _velocity_frames(buses, 1) == [
        Sync(19),
        MotionFeedback(1, 3, (0.25, -1.5)),
        ForceTorque(1, 3, VELOCITY.quantize_force((500.0, -0.123456789))),
    ]
    assert port.counts["force clamped"] == 1


def test_a_motion_command_is_the_ticks_velocity_and_stop_is_the_watchdogs(velocity_rig) -> None:
    port, buses = velocity_rig
    port.send(Measurement(2, 33, 0.33, (0.0, 0.0), (0.0, 0.0)))
    send = buses.peer[2].send
    send(VELOCITY.encode(MotionCommand(2, 1, (0.5, -0.25))))
    send(VELOCITY.encode(MotionCommand(2, 0, (0.125, 0.0))))  # 32
    send(VELOCITY.encode(MotionCommand(2, 1, (0.5, 0.5), drive=False)))
    assert _items(port) == [
        VelocityCommand(2, 33, (0.5, -0.25)),
        VelocityCommand(2, 32, (0.125, 0.0)),
    ]
    assert port.counts["stop commands"] == 1 and port.counts["zero commands"] == 0
    # The force profile's command is not a velocity base's: refused and counted.
    send(CODEC.encode(ForceCommand(2, 1, (1.0, 0.0))))
    assert _items(port) == []
    assert port.rejects.reasons == {("can frame", "wrong profile"): 1}


def test_a_stop_frame_is_a_standstill_on_the_wall_clock() -> None:
    buses = Buses((1,))
    port = CanDriversPort(
        StubRest((1,)), buses.plant, "realtime", VELOCITY, heartbeat_period_s=3600
    )
    try:
        port.send(Measurement(1, 40, 0.4, (0.0, 0.0), (0.0, 0.0)))
        buses.peer[1].send(VELOCITY.encode(MotionCommand(1, 5, (1.0, 1.0), drive=False)))
        assert _items(port) == [VelocityCommand(1, 40, (0.0, 0.0))]
        assert port.counts["stop commands"] == 1
    finally:
        port.close()
        buses.close()
