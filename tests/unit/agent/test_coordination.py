"""The phase barrier (``agent.algorithm.coordination``) and the in-memory transport
(``agent.platform.transport``).

The barrier is simulated as the agents run it: each tick every agent first receives what its
neighbours sent after their step of the previous tick (through :class:`InMemoryTransport`), then
steps, then sends its :class:`Share`. Readiness is scripted per agent and per phase.
"""

from __future__ import annotations

import random
from collections.abc import Callable

import pytest

from agent.algorithm.coordination import PhaseBarrier
from agent.platform.protocol import Barrier, Phase, Share
from agent.platform.transport import InMemoryTransport, neighbour_map

MARGIN = 3


def graph(kind: str, n: int) -> list[tuple[int, int]]:
    """Undirected graphs on robots ``1..n``."""
    if kind == "path":
        return [(i, i + 1) for i in range(1, n)]
    if kind == "ring":
        return [(i, i % n + 1) for i in range(1, n + 1)]
    if kind == "star":
        return [(1, i) for i in range(2, n + 1)]
    if kind == "star_last_hub":
        return [(n, i) for i in range(1, n)]
    raise ValueError(kind)


class Team:
    """``n`` barriers talking through an :class:`InMemoryTransport` with a one-tick delay.

    ``ready_after[phase][i]`` is how many ticks after entering ``phase`` robot ``i`` becomes
    ready to leave it (``None``: never; phases not listed: never). ``drop(tick, sender,
    receiver)`` says whether a message delivered at ``tick`` is lost."""

    def __init__(
        self,
        n: int,
        edges: list[tuple[int, int]],
        ready_after: dict[int, dict[int, int | None]],
        margin: int = MARGIN,
        drop: Callable[[int, int, int], bool] | None = None,
        levels: dict[int, tuple[int, int]] | None = None,
    ):
        self.n = n
        self.levels = levels or {}
        """The levels each robot asks for once ready to leave Step 1."""
        self.transport = InMemoryTransport(n, edges)
        self.barriers = {i: PhaseBarrier(i, n, margin) for i in range(1, n + 1)}
        self.ready_after = ready_after
        self.drop = drop or (lambda tick, sender, receiver: False)
        self.entered = {i: {0: 0} for i in self.barriers}  # robot → phase → tick entered
        self.ready_tick: dict[int, dict[int, int]] = {}  # phase → robot → first ready tick
        self.tick = 0

    def own_ready(self, i: int) -> bool:
        b = self.barriers[i]
        delay = self.ready_after.get(b.phase, {}).get(i)
        if delay is None:
            return False
        ready = self.tick >= self.entered[i][b.phase] + delay
        if ready:
            self.ready_tick.setdefault(b.phase, {}).setdefault(i, self.tick)
        return ready

    def run(self, ticks: int) -> None:
        for _ in range(ticks):
            tick = self.tick
            inbox = {}
            for i in self.barriers:
                shares = self.transport.receive(i)
                for s in shares:
                    assert s.tick == tick - 1  # one-tick delay
                inbox[i] = [s for s in shares if not self.drop(tick, s.sender, i)]
            for i, b in self.barriers.items():
                before = b.phase
                asked = self.levels.get(i, (0, 0))
                changed = b.step(tick, self.own_ready(i), [s.barrier for s in inbox[i]], asked)
                assert changed == (b.phase != before)
                assert b.phase >= before
                if changed:
                    for phase in range(before + 1, b.phase + 1):
                        self.entered[i][phase] = tick
            for i, b in self.barriers.items():
                degree = len(self.transport.neighbours[i])
                self.transport.send(
                    Share(
                        sender=i,
                        tick=tick,
                        velocity=(0.0, 0.0),
                        degree=degree,
                        barrier=Barrier(
                            phase=b.phase, ready=b.ready, switch_at=b.switch_at, levels=b.levels
                        ),
                    )
                )
            self.tick += 1

    def switch_ticks(self, phase: int) -> dict[int, int | None]:
        return {i: self.entered[i].get(phase) for i in self.barriers}


KINDS = ["path", "ring", "star", "star_last_hub"]


@pytest.mark.parametrize("n", [2, 4, 7])
@pytest.mark.parametrize("kind", KINDS)
def test_barrier_switches_everyone_at_the_same_tick(kind, n):
    rng = random.Random(1000 * n + KINDS.index(kind))
    for _ in range(5):
        ready = {i: rng.randint(0, 40) for i in range(1, n + 1)}
        team = Team(n, graph(kind, n), {0: ready})
        team.run(40 + 4 * n + MARGIN + 20)
        ticks = team.switch_ticks(1)
        assert len(set(ticks.values())) == 1, ticks
        switch = ticks[1]
        last_ready = max(ready.values())
        assert switch is not None
        # Nobody can know all are ready before the last one is; proposals fall due n + margin
        # ticks after they are made; the news and the proposal each need < n ticks to spread.
        assert last_ready + n + MARGIN <= switch <= last_ready + 2 * n + MARGIN
        assert all(b.phase == 1 for b in team.barriers.values())
        assert all(b.ready == 0 and b.switch_at == -1 for b in team.barriers.values())


@pytest.mark.parametrize("kind", KINDS)
def test_every_robot_leaves_step_1_with_the_largest_levels_asked_for(kind):
    """Levels that robots ask for as they become ready (in any order, the largest asked last
    on a path's far end) are the same on every robot at the agreed tick, and kept after it."""
    n = 7
    rng = random.Random(11 + KINDS.index(kind))
    for _ in range(5):
        ready = {i: rng.randint(0, 40) for i in range(1, n + 1)}
        levels = {i: (rng.randint(0, 12), rng.randint(0, 12)) for i in ready}
        last = max(ready, key=lambda i: ready[i])
        levels[last] = (13, 2)  # the last robot ready asks for the most Step 4 torque
        team = Team(n, graph(kind, n), {0: ready}, levels=levels)
        team.run(40 + 2 * n + MARGIN + 1)
        assert len(set(team.switch_ticks(1).values())) == 1
        largest = (13, max(level[1] for level in levels.values()))
        assert {b.levels for b in team.barriers.values()} == {largest}
        team.run(3 * n)
        assert {b.levels for b in team.barriers.values()} == {largest}


def test_levels_begin_again_after_a_halt():
    b = PhaseBarrier(1, 2, 0)
    b.step(0, True, [], (5, 3))
    b.step(1, False, [Barrier(ready=0b10, levels=(7, 1))])
    assert b.levels == (7, 3)
    # asked only once, as the robot becomes ready: a later ask is not taken
    b.step(2, True, [], (9, 9))
    assert b.levels == (7, 3)
    b.halt()
    b.step(4, True, [Barrier(phase=Phase.HALTED, ready=0b10, levels=(7, 3))])
    b.step(5, False, [], (1, 1))
    b.step(6, False, [], (1, 1))
    assert b.phase is Phase.EXCITE and b.rejoins == 1 and b.levels == (0, 0)
    # a neighbour's levels of an earlier beginning are not taken
    b.step(7, False, [Barrier(levels=(7, 3))])
    assert b.levels == (0, 0)


@pytest.mark.parametrize("kind", ["path", "ring", "star"])
def test_barrier_consecutive_phases(kind):
    n = 6
    rng = random.Random(7)
    ready = {phase: {i: rng.randint(0, 25) for i in range(1, n + 1)} for phase in range(3)}
    team = Team(n, graph(kind, n), ready)
    team.run(3 * (25 + 2 * n + MARGIN) + 20)
    previous = 0
    for phase in (1, 2, 3):
        ticks = team.switch_ticks(phase)
        assert len(set(ticks.values())) == 1 and ticks[1] is not None, (phase, ticks)
        switch = ticks[1]
        # Readiness counts from the (common) tick the phase began.
        last_ready = previous + max(ready[phase - 1].values())
        assert last_ready + n + MARGIN <= switch <= last_ready + 2 * n + MARGIN
        previous = switch
    assert all(b.phase == 3 for b in team.barriers.values())


@pytest.mark.parametrize("kind", KINDS)
def test_barrier_blocked_by_an_agent_never_ready(kind):
    n = 5
    for laggard in range(1, n + 1):
        ready = {i: (None if i == laggard else i) for i in range(1, n + 1)}
        team = Team(n, graph(kind, n), {0: ready})
        team.run(300)
        assert all(b.phase == 0 for b in team.barriers.values())
        assert all(b.switch_at == -1 for b in team.barriers.values())
        # Everyone knows exactly the others are ready.
        expected = ((1 << n) - 1) & ~(1 << (laggard - 1))
        assert all(b.ready == expected for b in team.barriers.values())


def _reference_switch(n, edges, ready):
    team = Team(n, edges, {0: ready})
    team.run(200)
    ticks = team.switch_ticks(1)
    assert len(set(ticks.values())) == 1
    return ticks[1]


@pytest.mark.parametrize("kind", ["path", "ring", "star"])
def test_barrier_catch_up_after_a_blackout(kind):
    """Robot 3 hears nothing from the moment anyone is ready until the team has switched."""
    n, deaf = 6, 3
    edges = graph(kind, n)
    ready = {i: 5 + 3 * i for i in range(1, n + 1)}
    switch = _reference_switch(n, edges, ready)
    team = Team(n, edges, {0: ready}, drop=lambda tick, s, r: r == deaf and 5 <= tick <= switch)
    team.run(switch + 4 * n + MARGIN)
    ticks = team.switch_ticks(1)
    assert all(b.phase == 1 for b in team.barriers.values())
    if kind == "path":
        # Robot 3 is the only relay between {1, 2} and {4, 5, 6}: nobody can learn that all
        # are ready during the blackout; afterwards the barrier runs as usual.
        assert len(set(ticks.values())) == 1, ticks
        assert switch + 1 + n + MARGIN <= ticks[1] <= switch + 1 + 2 * n + MARGIN
    else:
        assert ticks[deaf] == switch + 1  # catches up from its neighbours' next messages
        assert all(t == switch for i, t in ticks.items() if i != deaf), ticks


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_barrier_catch_up_with_random_drops(kind, seed):
    n = 7
    edges = graph(kind, n)
    rng = random.Random(seed)
    ready = {i: rng.randint(0, 30) for i in range(1, n + 1)}
    switch = _reference_switch(n, edges, ready)
    victim = rng.randint(1, n)
    lost = random.Random(seed + 100)
    team = Team(
        n,
        edges,
        {0: ready},
        drop=lambda tick, s, r: r == victim and tick < switch + 5 and lost.random() < 0.4,
    )
    team.run(switch + 10 * n)
    ticks = team.switch_ticks(1)
    assert all(t is not None and t >= switch for t in ticks.values()), ticks
    assert all(b.phase == 1 for b in team.barriers.values())


def test_barrier_step_by_hand():
    # n = 2, margin 0: robot 1 ready at tick 0 and hears robot 2 ready at tick 1.
    b = PhaseBarrier(1, 2, 0)
    assert b.step(0, True, []) is False
    assert b.ready == 0b01 and b.switch_at == -1
    view = Barrier(ready=0b10)  # robot 2's view of the barrier
    assert b.step(1, False, [view]) is False
    assert b.ready == 0b11 and b.switch_at == 1 + 2
    assert b.step(2, False, []) is False
    assert b.step(3, False, []) is True
    assert b.phase is Phase.INERTIA and b.ready == 0 and b.switch_at == -1
    # A neighbour already two phases on: catch up at once, own readiness not counted.
    ahead = Barrier(phase=Phase.DONE, ready=0b10)
    assert b.step(4, True, [ahead]) is True
    assert b.phase is Phase.DONE and b.ready == 0b10
    # Views of an earlier phase are ignored.
    stale = Barrier(phase=Phase.INERTIA, ready=0b11)
    assert b.step(5, False, [stale]) is False
    assert b.phase is Phase.DONE and b.ready == 0b10
    # The earlier of two proposals wins.
    c = PhaseBarrier(1, 2, 0)
    late = Barrier(ready=0b11, switch_at=9)
    early = Barrier(ready=0b11, switch_at=6)
    c.step(5, False, [late, early])
    assert c.switch_at == 6


@pytest.mark.parametrize("kind", KINDS)
def test_a_halt_reaches_every_robot_one_hop_per_tick(kind):
    """``halted`` is the highest phase: it spreads by catch-up, ready or not, and nothing
    leads out of it."""
    n, first = 6, 4
    team = Team(n, graph(kind, n), {0: dict.fromkeys(range(1, n + 1), 0)})
    team.run(3)
    team.barriers[first].halt()
    assert team.barriers[first].phase is Phase.HALTED
    hops = {first: 0}
    frontier = [first]
    while frontier:  # breadth-first distances from the halted robot
        nxt = []
        for i in frontier:
            for j in team.transport.neighbours[i]:
                if j not in hops:
                    hops[j] = hops[i] + 1
                    nxt.append(j)
        frontier = nxt
    team.run(n + 2 * MARGIN + n)
    for i, b in team.barriers.items():
        assert b.phase is Phase.HALTED
        if i != first:
            assert team.entered[i][Phase.HALTED] == 3 + hops[i]


# --------------------------------------------------------------------------------------------
# transport
# --------------------------------------------------------------------------------------------


def test_neighbour_map():
    got = neighbour_map(5, [(1, 2), (3, 2), (2, 1), (4, 2)])
    assert got == {1: (2,), 2: (1, 3, 4), 3: (2,), 4: (2,), 5: ()}
    assert neighbour_map(4, graph("ring", 4)) == {1: (2, 4), 2: (1, 3), 3: (2, 4), 4: (1, 3)}


@pytest.mark.parametrize("kind", KINDS)
def test_in_memory_transport_delivers_to_neighbours_only(kind):
    n = 6
    edges = graph(kind, n)
    adjacent = {(i, j) for i, j in edges} | {(j, i) for i, j in edges}
    transport = InMemoryTransport(n, edges)
    for sender in range(1, n + 1):
        transport.send(Share(sender=sender, tick=sender, velocity=(float(sender), 0.0), degree=0))
    for robot in range(1, n + 1):
        got = transport.receive(robot)
        senders = [s.sender for s in got]
        assert sorted(senders) == sorted(j for j in range(1, n + 1) if (robot, j) in adjacent)
        assert senders == sorted(senders)  # oldest first (sent in id order)
        assert all(s.velocity == (float(s.sender), 0.0) for s in got)
        assert transport.receive(robot) == []  # drained
    # Nothing sent since: still empty; a new message reaches only the neighbours.
    transport.send(Share(sender=1, tick=99, velocity=(0.0, 0.0), degree=0))
    for robot in range(1, n + 1):
        got = transport.receive(robot)
        assert [s.tick for s in got] == ([99] if (robot, 1) in adjacent else [])
