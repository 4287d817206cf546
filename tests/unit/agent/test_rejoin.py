"""A halted team begins again once every robot is back: the barrier's rejoins, and agents
that drop what they knew and estimate the load anew from Step 1 (agent/algorithm/coordination.py,
agent/algorithm/agent.py)."""

from __future__ import annotations

import dataclasses

import pytest

from agent.algorithm.coordination import PhaseBarrier
from agent.platform.protocol import Barrier, Phase, Share, decode, encode
from agent.platform.transport import InMemoryTransport
from dashboard.state import TeamState
from simulator.inprocess import make_agents
from simulator.plant import Plant
from simulator.scenario import load_scenario
from tests.helpers.fakes import FakeFifo
from tests.helpers.paths import PAPER


def _share(i: int, tick: int, b: PhaseBarrier) -> Share:
    return Share(
        i,
        tick,
        (0.0, 0.0),
        1,
        barrier=Barrier(
            phase=b.phase,
            ready=b.ready,
            switch_at=b.switch_at,
            load_changes=b.load_changes,
            rejoins=b.rejoins,
        ),
    )


def _line(n: int, ticks: int, back: dict[int, int], halted_from: int = 0):
    """``n`` barriers on a line, all halted from ``halted_from``; robot ``i`` has every
    neighbour back from tick ``back[i]``. Returns the barriers and the tick each began again
    (one more rejoin)."""
    barriers = {i: PhaseBarrier(i, n, 2) for i in range(1, n + 1)}
    heard: dict[int, list[Share]] = {i: [] for i in barriers}
    began: dict[int, int] = {}
    for tick in range(ticks):
        sent = []
        for i, b in barriers.items():
            if tick == halted_from:
                b.halt()
            ready = b.phase == Phase.HALTED and tick >= back[i]
            if b.step(tick, ready, [s.barrier for s in heard[i]]) and b.rejoins == 1:
                began.setdefault(i, tick)
            sent.append(_share(i, tick, b))
        heard = {i: [s for s in sent if abs(s.sender - i) == 1] for i in barriers}
    return barriers, began


def test_a_halted_team_begins_again_together_once_every_robot_is_back() -> None:
    back = {1: 5, 2: 9, 3: 30, 4: 7}
    barriers, began = _line(4, 60, back)
    assert set(began) == {1, 2, 3, 4} and len(set(began.values())) == 1
    assert min(began.values()) > max(back.values())  # not before the last robot is back
    assert all(
        (b.phase, b.load_changes, b.rejoins) == (Phase.EXCITE, 0, 1) for b in barriers.values()
    )


def test_a_halted_team_waits_for_its_last_robot() -> None:
    barriers, began = _line(4, 60, {1: 0, 2: 0, 3: 0, 4: 10_000})
    assert began == {}
    assert all(b.phase == Phase.HALTED and b.rejoins == 0 for b in barriers.values())


def test_more_rejoins_are_caught_up_with_and_fewer_are_ignored() -> None:
    b = PhaseBarrier(1, 2, 0)
    b.phase = Phase.HALTED
    b.step(10, False, [Barrier(phase=Phase.EXCITE, rejoins=2)])
    assert (b.phase, b.rejoins) == (Phase.EXCITE, 2)  # it missed the agreed tick
    b.step(11, True, [Barrier(phase=Phase.DONE, rejoins=1)])
    assert (b.phase, b.rejoins) == (Phase.EXCITE, 2)
    assert b.ready == 0b01  # its own readiness only: bits of fewer rejoins are not merged


def test_a_new_process_catches_up_with_a_halted_team() -> None:
    fresh = PhaseBarrier(3, 4, 2)  # a robot's agent restarted: no rejoin, excite
    fresh.step(0, False, [Barrier(phase=Phase.HALTED, rejoins=3)])
    assert (fresh.phase, fresh.rejoins) == (Phase.HALTED, 3)


def test_the_rejoins_cross_the_wire_and_are_domain_checked() -> None:
    share = Share(1, 5, (0.0, 0.0), 1, barrier=Barrier(rejoins=7))
    assert decode(Share, encode(share)).barrier.rejoins == 7
    with pytest.raises(ValueError, match="share.barrier.rejoins"):
        decode(Share, encode(dataclasses.replace(share, barrier=Barrier(rejoins=60_000))))


# ------------------------------------------------------------------------------ agents
@pytest.mark.slow
def test_agents_halted_mid_run_begin_again_and_estimate_the_load_as_well() -> None:
    """The paper's team, noise-free, in one process: robot 3 is lost at 4 s (its neighbours
    halt the team), every robot is back at 6 s; the team begins again at one tick, from
    Step 1, and its estimates at the end are as good as a run's without a halt."""
    scenario = load_scenario(PAPER)
    plant = Plant(scenario)
    agents = make_agents(scenario)
    transport = InMemoryTransport(scenario.n, scenario.edges)
    lost_at, back_at = 400, 600
    began: dict[int, int] = {}
    halted = set()
    truths = []
    for k in range(round(scenario.run.max_time_s / scenario.period_s)):
        truths = [*truths[-1:], plant.truth()]  # of ticks k - 1 and k
        measurements = plant.measure()
        if k == lost_at:
            for a in agents:
                if a.robot in (2, 4):  # robot 3's neighbours
                    a.halt()
        if k == back_at:
            for a in agents:
                a.team_back = True
        shares = []
        for agent, measurement in zip(agents, measurements):
            command, share = agent.step(measurement, transport.receive(agent.robot))
            assert command.tick == k and share.tick == k  # the run's ticks, whatever the origin
            if agent.phase == Phase.HALTED:
                halted.add(agent.robot)
                assert command.force == (0.0, 0.0)
            if agent.rejoins == 1:
                began.setdefault(agent.robot, k)
            plant.command(agent.robot, command.force)
            shares.append(share)
        for share in shares:
            transport.send(share)
        if all(a.phase == Phase.DONE and a.rejoins == 1 for a in agents):
            break
        plant.advance()
    assert halted == {1, 2, 3, 4}
    assert len(set(began.values())) == 1 and min(began.values()) > back_at
    assert all(a.origin == began[1] for a in agents)
    assert all(a.phase == Phase.DONE for a in agents), [a.phase for a in agents]
    truth = truths[0]  # the estimates are those of instant k - 1
    for a in agents:
        est = a.estimates()
        assert est.tick == truth.tick
        assert est.rejoins == 1 and est.phase_since > began[1]
        assert min(est.started.values()) >= began[1]
        assert abs(est.mass - truth.mass) / truth.mass < 1e-3
        assert abs(est.moment - truth.moment) / truth.moment < 1e-3
        c = truth.contact_to_com[a.robot - 1]
        assert abs(est.contact_to_com[0] - c[0]) < 2e-3 and abs(est.contact_to_com[1] - c[1]) < 2e-3
    # The dashboard's table says the team began again.
    state = TeamState("rejoin", scenario.load_geometry())
    state.ingest(truth, truth.time_s)
    for a in agents:
        state.ingest(a.estimates(), truth.time_s)
    rows = state.page_scene(truth.time_s)["table"]["robots"]
    assert len(rows) == 4 and {row["rejoins"] for row in rows.values()} == {1}


def _stepped(robot: int, ticks: int):
    """Robot ``robot`` of the paper's team after ``ticks`` ticks alone (no neighbour heard)."""
    from agent.platform.protocol import Measurement

    agent = make_agents(load_scenario(PAPER))[robot - 1]
    for k in range(ticks):
        agent.step(Measurement(robot, k, k * 0.01, (0.0, 0.0), (0.0, 0.0)), [])
    return agent, Measurement


def test_an_agent_that_missed_the_agreed_tick_begins_again_where_it_is() -> None:
    agent, Measurement = _stepped(2, 50)
    agent.halt()
    agent.step(Measurement(2, 50, 0.5, (0.0, 0.0), (0.0, 0.0)), [])
    assert agent.phase == Phase.HALTED
    late = Share(1, 52, (0.0, 0.0), 1, barrier=Barrier(phase=Phase.EXCITE, rejoins=1))
    command, share = agent.step(Measurement(2, 53, 0.53, (0.0, 0.0), (0.0, 0.0)), [late])
    assert (agent.phase, agent.rejoins, agent.origin) == (Phase.EXCITE, 1, 53)
    assert (share.tick, share.barrier.rejoins, command.tick) == (53, 1, 53)
    assert command.force != (0.0, 0.0)  # its own kick, from its own tick 0


def test_an_agent_caught_up_past_step_1_halts_after_that_rejoin() -> None:
    agent, Measurement = _stepped(2, 50)
    late = Share(1, 50, (0.0, 0.0), 1, barrier=Barrier(phase=Phase.INERTIA, rejoins=1))
    command, share = agent.step(Measurement(2, 51, 0.51, (0.0, 0.0), (0.0, 0.0)), [late])
    assert (agent.phase, agent.rejoins) == (Phase.HALTED, 1)
    assert command.force == (0.0, 0.0) and share.barrier.phase == Phase.HALTED


class _Session:
    """Enough of a Zenoh session for the launcher's collector: its subscriptions by key."""

    def __init__(self) -> None:
        self.fifos: dict[str, FakeFifo] = {}

    def declare_subscriber(self, key, handler):
        self.fifos[key] = FakeFifo()
        return self.fifos[key]


def test_the_collector_follows_the_rejoins_of_a_team_that_begins_again() -> None:
    from agent.platform.protocol import Estimates, Keys, Status
    from simulator.launcher import Collector

    keys = Keys("t")
    session = _Session()
    collector = Collector(session, keys, 2, 5, rejoin_s=30.0)

    def say(message) -> None:
        status = isinstance(message, Status)
        fifo = session.fifos[keys.all_statuses() if status else keys.all_estimates()]
        fifo(type("Sample", (), {"payload": _Bytes(encode(message))})())
        collector.drain(0.0)

    say(Status(1, 400, Phase.HALTED, lost_neighbours=(2,)))
    assert collector.halted and collector.lost == {2}
    say(Estimates(1, 650, Phase.EXCITE, phase_since=651, rejoins=1))
    assert not collector.halted and collector.lost == set() and collector.rejoined == 1
    say(Status(2, 660, Phase.HALTED))  # from before the rejoin: late, ignored
    assert not collector.halted
    say(Estimates(2, 900, Phase.EXCITE, phase_since=901, rejoins=2))  # its halt unheard
    assert collector.rejoins == [{"halted": 400, "began": 651}, {"halted": None, "began": 901}]


class _Bytes:
    def __init__(self, data: bytes) -> None:
        self._data = data

    def to_bytes(self) -> bytes:
        return self._data
