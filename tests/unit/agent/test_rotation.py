"""The team's rotation (agent/algorithm/estimation/rotation.py): the consensus on the robots' levels
averages their turns' noise away without lag, whatever the graph and however late a message."""

from __future__ import annotations

import dataclasses
import math
import random
import statistics

import pytest

from agent.algorithm.robust.rotation import (
    RotationConsensus,
    delay_factor,
    own_turn,
    turn_weight,
    wrapped,
)
from agent.platform.protocol import Share, decode, encode
from agent.platform.team import ConsensusState

LINE = {1: (2,), 2: (1, 3), 3: (2, 4), 4: (3,)}


def _run(graph, ticks: int, noise: float, seed: int, late: int = 0, mixing: bool = True):
    """Every robot sums the true turn plus its own white noise (robot ``i``'s of standard
    deviation ``i × noise``); each hears its neighbours' levels ``late`` instants late
    (``mixing=False``: it hears nothing). Returns the true rotation, the team and each
    robot's level."""
    rng = random.Random(seed)
    robots = {i: RotationConsensus(len(n), len(graph)) for i, n in graph.items()}
    history = {i: {-1: (0.0, 0.0)} for i in graph}
    levels = dict.fromkeys(graph, 0.0)
    theta = 0.0
    for e in range(ticks):
        true_turn = 0.01 * math.sin(0.003 * e) + 0.004
        theta += true_turn
        sent = {i: (e - 1 - late, history[i].get(e - 1 - late)) for i in graph}
        for i, consensus in robots.items():
            heard = [
                (j, len(graph[j]), sent[j][0], wrapped(sent[j][1][0]), sent[j][1][1])
                for j in graph[i]
                if mixing and sent[j][1] is not None and sent[j][0] >= 0
            ]
            own = i * noise
            level_at = lambda k, i=i: history[i].get(k, (None,))[0]  # noqa: E731
            step = consensus.update(e, true_turn + rng.gauss(0.0, own), own**2, heard, level_at)
            levels[i] += step
            history[i][e] = (levels[i], consensus.variance)
    return theta, robots, levels


@pytest.mark.parametrize("late", [0, 3, 10])
def test_the_team_level_averages_the_robots_noise(late: int) -> None:
    alone, together, spread = [], [], []
    for seed in range(40):
        theta, _, levels = _run(LINE, 2000, 0.001, seed, late=late, mixing=False)
        alone.append(levels[2] - theta)
        theta, team, levels = _run(LINE, 2000, 0.001, seed, late=late)
        together.append(levels[2] - theta)
        spread.append(max(levels.values()) - min(levels.values()))
    # Robot 2's level alone drifts as a random walk of 0.002 √2000 = 0.089 rad; the four
    # robots' mean, of √(1 + 4 + 9 + 16)/4 of 0.001 per instant, 0.68 of that. The levels
    # agree to within a few turns' noise (a few more when late).
    ratio = statistics.pstdev(together) / statistics.pstdev(alone)
    assert 0.5 < ratio < 0.85
    assert max(spread) < (0.02 if late == 0 else 0.08)
    # The team's turn variance, 2 ν / n with ν → the mean of (i × 0.001)².
    for robot in team.values():
        assert robot.turn_variance == pytest.approx(2 * 7.5e-6 / 4, rel=1e-6 if late == 0 else 0.05)


def test_without_noise_the_level_is_the_rotation_on_every_robot() -> None:
    theta, _, levels = _run(LINE, 500, 0.0, 0, late=2)
    for level in levels.values():
        assert level == pytest.approx(theta, abs=1e-12)


def test_each_message_is_used_once_and_a_forgotten_instant_not_at_all() -> None:
    consensus = RotationConsensus(1, 2)
    history = {0: 0.0}
    step = consensus.update(1, 0.1, None, [(2, 1, 0, 0.5, 0.0)], history.get)
    assert step == pytest.approx(0.1 + 0.5 * 0.5)  # a = 1 / (1 + 1)
    assert consensus.update(2, 0.1, None, [(2, 1, 0, 0.5, 0.0)], history.get) == pytest.approx(0.1)
    assert consensus.update(8, 0.1, None, [(2, 1, 7, 0.5, 0.0)], history.get) == pytest.approx(0.1)


def test_a_late_level_weighs_less() -> None:
    assert delay_factor(0) == 1.0 and delay_factor(-1) == 1.0
    assert delay_factor(1) == pytest.approx(0.5)
    consensus = RotationConsensus(1, 2)
    step = consensus.update(5, 0.0, None, [(2, 1, 3, 0.5, 0.0)], {3: 0.0}.get)  # one late
    assert step == pytest.approx(0.5 * 0.5 * 0.5)


def test_levels_are_compared_modulo_two_pi() -> None:
    consensus = RotationConsensus(1, 2)
    history = {4: math.pi - 0.01}
    # The neighbour's level, sent wrapped, is 0.02 rad ahead: just past -π.
    step = consensus.update(5, 0.0, None, [(2, 1, 4, wrapped(math.pi + 0.01), 0.0)], history.get)
    assert step == pytest.approx(0.5 * 0.02)


def test_own_turn_weighs_each_edge_by_its_information() -> None:
    assert own_turn([]) is None
    arc = turn_weight(radius=2.0, speed2=1.0, noise=1e-4, dt=0.01)
    short = turn_weight(radius=1.0, speed2=1.0, noise=1e-4, dt=0.01)
    assert arc == pytest.approx(4 * short)
    turn, variance = own_turn([(0.1, arc), (0.2, short)])
    assert turn == pytest.approx((0.4 + 0.2) / 5) and variance == pytest.approx(1 / (arc + short))
    # Before its circle is known an edge's turn is that of ż's direction: a slow edge
    # weighs little, and never more than MAX_TURN_WEIGHT.
    slow = turn_weight(radius=None, speed2=1e-4, noise=1e-4, dt=0.01)
    fast = turn_weight(radius=None, speed2=100.0, noise=1e-4, dt=0.01)
    assert slow == pytest.approx(0.5) and fast == 1e3


def test_the_level_crosses_the_wire_and_is_domain_checked() -> None:
    share = Share(1, 5, (0.0, 0.0), 1, instant=4, consensus=ConsensusState(rotation=-3.0))
    assert decode(Share, encode(share)).consensus.rotation == -3.0
    state = share.consensus
    for bad, message in (
        (4.0, "share.consensus.rotation"),
        (math.nan, "non-finite"),
        (-math.inf, "non-"),
    ):
        with pytest.raises(ValueError, match=message):
            changed = state._replace(rotation=bad)
            decode(Share, encode(dataclasses.replace(share, consensus=changed)))
    with pytest.raises(ValueError, match="share.consensus.mean_turn_variance"):
        changed = state._replace(mean_turn_variance=1e3)
        decode(Share, encode(dataclasses.replace(share, consensus=changed)))
