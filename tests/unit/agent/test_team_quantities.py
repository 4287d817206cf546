"""The team's quantities are declared once (``agent/platform/team.py``): the share's wire layout,
its domain checks and the flow-form consensus all follow from the declarations.

A new quantity is shown here the way a family would add one: one declaration, its input (what
each robot contributes) and where it is read. Nothing else: the share carries it, the decoder
checks it, the consensus averages it and keeps its sum through lost messages.
"""

from __future__ import annotations

import dataclasses
import math
import random

import pytest

from agent.algorithm.estimation.team_consensus import TeamConsensus
from agent.platform.protocol import (
    SHARE_WIRE,
    Barrier,
    DecodeError,
    Phase,
    Share,
    ShareWire,
    decode,
    encode,
)
from agent.platform.team import (
    TEAM_QUANTITIES,
    Averaging,
    ConsensusState,
    TeamQuantity,
    consensus_state_type,
    flow_width,
)

TEMPERATURE = TeamQuantity(
    "mean_temperature", 1, 1000.0, Averaging.MEAN, doc="the robots' mean motor temperature"
)
"""The new quantity: one declaration."""
EXTENDED = (*TEAM_QUANTITIES, TEMPERATURE)
WIRE = ShareWire(EXTENDED)

CONTACTS = {1: (-2.0, 0.4), 2: (-1.0, -1.0), 3: (1.2, -1.0), 4: (2.0, 0.6)}
"""The paper's contacts in a load that does not turn: ``z_ij`` known exactly."""
EDGES = ((1, 2), (2, 3), (3, 4))
TEMPERATURES = {1: 20.0, 2: 22.0, 3: 25.0, 4: 31.0}


def neighbours_of(i: int) -> tuple[int, ...]:
    return tuple(sorted({b for a, b in EDGES if a == i} | {a for a, b in EDGES if b == i}))


class StillLoad:
    """A load that does not turn: ``z_ij`` from the contacts."""

    def __init__(self, robot: int):
        self.robot = robot
        self.instant = 0

    def turned_since(self, instant: int) -> float:
        return 0.0

    def relative_position(self, j: int):
        (xi, yi), (xj, yj) = CONTACTS[self.robot], CONTACTS[j]
        return (xi - xj, yi - yj)


def inputs_with_temperature(robot: int):
    """The paper family's inputs (ideal drives, no mass) and the robot's temperature."""

    def inputs(x):
        norm2 = x[0] * x[0] + x[1] * x[1]
        return (
            *(norm2, 1.0, x[0], x[1], norm2, *(0.0,) * 10),
            TEMPERATURES[robot],
        )

    return inputs


def run_team(ticks: int, drop: float = 0.0, seed: int = 1) -> dict[int, TeamConsensus]:
    """Four robots exchanging shares for ``ticks`` iterations, each message lost with
    probability ``drop``; every share crosses the wire (encoded and decoded)."""
    rng = random.Random(seed)
    team = {
        i: TeamConsensus(i, neighbours_of(i), inputs_with_temperature(i), EXTENDED)
        for i in CONTACTS
    }
    frames = {i: StillLoad(i) for i in CONTACTS}
    heard: dict[int, dict[int, Share]] = {i: {} for i in CONTACTS}
    for tick in range(1, ticks + 1):
        sent = {}
        for i, c in team.items():
            share = Share(
                i, tick, (0.0, 0.0), c.degree, tick - 1, Barrier(), c.state, c.shared_flows()
            )
            sent[i] = WIRE.unpack(WIRE.pack(share))
        for i, c in team.items():
            for j in c.neighbours:
                if rng.random() >= drop:
                    heard[i][j] = sent[j]
            frames[i].instant = tick
            c.update(0.0, heard[i], frames[i])
    return team


def test_a_new_quantity_crosses_the_wire_and_is_checked() -> None:
    state = consensus_state_type(EXTENDED)(centroid_offset=(0.5, -0.25), mean_temperature=23.5)
    share = Share(
        3,
        9,
        (0.1, 0.0),
        2,
        8,
        Barrier(Phase.INERTIA, 5, 12),
        state,
        ((2, *[0.5] * flow_width(EXTENDED)),),
    )
    assert flow_width(EXTENDED) == flow_width() + 1  # a flow-form mean: one more flow number
    assert WIRE.unpack(WIRE.pack(share)) == share
    WIRE.check(share)
    hot = dataclasses.replace(share, consensus=state._replace(mean_temperature=1e4))
    with pytest.raises(
        DecodeError, match=r"share\.consensus\.mean_temperature = 10000\.0 is outside"
    ):
        WIRE.check(hot)
    # Robots that declare different quantities refuse each other's shares, and say why.
    with pytest.raises(DecodeError, match="team quantities of layout"):
        SHARE_WIRE.unpack(WIRE.pack(share))


def test_a_new_quantity_is_averaged_by_the_consensus_and_its_sum_kept_through_losses() -> None:
    mean = sum(TEMPERATURES.values()) / len(TEMPERATURES)
    assert run_team(3)[1]["mean_temperature"] != pytest.approx(mean, abs=0.5)  # not at once
    for drop in (0.0, 0.3):
        team = run_team(400, drop=drop)
        for i, c in team.items():
            assert c["mean_temperature"] == pytest.approx(mean, abs=1e-6), (drop, i)
            # Step 2 still converges beside it: x_i → z_i = p_Ci − p_G.
            gx = sum(p[0] for p in CONTACTS.values()) / 4
            gy = sum(p[1] for p in CONTACTS.values()) / 4
            z_i = (CONTACTS[i][0] - gx, CONTACTS[i][1] - gy)
            assert math.dist(c.centroid, z_i) < 1e-6, (drop, i)


def test_the_declared_quantities_are_the_shares_fields_and_domains() -> None:
    assert ConsensusState._fields == tuple(q.name for q in TEAM_QUANTITIES)
    far = ConsensusState(centroid_offset=(20_000.0, 0.0))
    share = Share(1, 2, (0.0, 0.0), 1, 1, Barrier(), far)
    with pytest.raises(DecodeError, match=r"share\.consensus\.centroid_offset"):
        decode(Share, encode(share))
    ok = Share(1, 2, (0.0, 0.0), 1, 1, Barrier(), ConsensusState(rotation=math.pi))
    assert decode(Share, encode(ok)) == ok
    with pytest.raises(DecodeError, match=r"share\.consensus\.rotation"):
        decode(
            Share, encode(Share(1, 2, (0.0, 0.0), 1, 1, Barrier(), ConsensusState(rotation=3.2)))
        )


def test_a_mean_whose_inputs_appear_one_robot_at_a_time_stays_on_the_wire() -> None:
    """The robots' ``ẑ_C`` reach the team's mean as each robot gets one (``ζ_i`` from 0 to 1, a
    tick apart): the states overshoot the inputs' range while they converge, and every share
    must still pass the domain checks (a bound of 1 on ``mean_com_weight`` refused them, and a
    team over Zenoh stalled)."""
    wire = ShareWire(TEAM_QUANTITIES)
    tick = [0]

    def inputs_of(robot: int):
        def inputs(x):
            norm2 = x[0] * x[0] + x[1] * x[1]
            held = (1.0, 0.3, -0.2) if tick[0] >= 3 * robot else (0.0, 0.0, 0.0)
            return (norm2, 1.0, x[0], x[1], norm2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, *held, 0.0)

        return inputs

    team = {i: TeamConsensus(i, neighbours_of(i), inputs_of(i)) for i in CONTACTS}
    frames = {i: StillLoad(i) for i in CONTACTS}
    heard: dict[int, dict[int, Share]] = {i: {} for i in CONTACTS}
    most = 0.0
    for k in range(1, 200):
        tick[0] = k
        sent = {}
        for i, c in team.items():
            share = Share(i, k, (0.0, 0.0), c.degree, k - 1, Barrier(), c.state, c.shared_flows())
            wire.check(share)
            sent[i] = wire.unpack(wire.pack(share))
            most = max(most, c["mean_com_weight"])
        for i, c in team.items():
            for j in c.neighbours:
                heard[i][j] = sent[j]
            frames[i].instant = k
            c.update(0.0, heard[i], frames[i])
    assert most > 1.0  # overshot
    for c in team.values():
        assert c["mean_com_weight"] == pytest.approx(1.0, abs=1e-6)
        weighted = c["mean_weighted_com"]
        assert weighted == pytest.approx((0.3, -0.2), abs=1e-6)


@pytest.mark.parametrize("late", [0, 3])
def test_the_turns_mean_variance_follows_its_falling_inputs_however_late_the_messages(
    late: int,
) -> None:
    """``ν`` (``mean_turn_variance``) is the direction filters' process noise: each robot's
    turn variance falls by orders of magnitude once its circles are known (here from 1e-3 to
    1e-9 rad², at another instant on each robot), and every message arrives ``late`` instants
    late. In flow form ``ν`` reaches the new mean on every robot; averaged without flows (with
    input tracking) it kept an error of the order of the old inputs for good."""
    falls = {1: 30, 2: 45, 3: 60, 4: 80}
    final = {1: 1e-9, 2: 2e-9, 3: 4e-9, 4: 1e-9}

    def inputs_of(robot: int, instant):
        def inputs(x):
            norm2 = x[0] * x[0] + x[1] * x[1]
            variance = 1e-3 if instant[0] < falls[robot] else final[robot]
            return (norm2, 1.0, x[0], x[1], norm2, *(0.0,) * 9, variance)

        return inputs

    instant = [0]
    team = {i: TeamConsensus(i, neighbours_of(i), inputs_of(i, instant)) for i in CONTACTS}
    frames = {i: StillLoad(i) for i in CONTACTS}
    sent: list[dict[int, Share]] = []
    for tick in range(1, 1500):
        instant[0] = tick
        sent.append(
            {
                i: Share(
                    i, tick, (0.0, 0.0), c.degree, tick - 1, Barrier(), c.state, c.shared_flows()
                )
                for i, c in team.items()
            }
        )
        arrived = sent[-1 - late] if len(sent) > late else {}
        for i, c in team.items():
            frames[i].instant = tick
            c.update(0.0, {j: arrived[j] for j in c.neighbours if j in arrived}, frames[i])
    mean = sum(final.values()) / len(final)
    for c in team.values():
        assert c["mean_turn_variance"] == pytest.approx(mean, rel=1e-3)
