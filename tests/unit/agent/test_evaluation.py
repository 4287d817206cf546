"""Estimates judged against the truth (agent/platform/evaluation.py), by hand-made messages
whose errors are known: the keys and units every user shares, missing and non-finite
estimates, the worst over a team, and the final instant."""

from __future__ import annotations

import dataclasses
import math

import pytest

from agent.platform.evaluation import (
    ERROR_KEYS,
    PLANAR_95,
    SCALAR_95,
    covariance,
    distance2,
    edges_interval,
    final_instant,
    planar_interval,
    relative_position_split,
    robot_errors,
    scalar_interval,
    team_errors,
)
from agent.platform.protocol import GRAVITY, Estimates, Phase, Truth

# Three contacts around a COM at the origin: p_G = (0, 1/3), z_C = p_G − p_C = (0, 1/3).
CONTACTS = ((-1.0, 0.0), (1.0, 0.0), (0.0, 1.0))
TRUTH = Truth(
    tick=100,
    time_s=1.0,
    com_position=(0.0, 0.0),
    angle=0.0,
    com_velocity=(0.0, 0.0),
    omega=0.5,
    contacts=CONTACTS,
    contact_velocities=((0.0, 0.0),) * 3,
    contact_to_com=tuple((-x, -y) for x, y in CONTACTS),
    mass=4.0,
    moment=2.0,
    ground_coulomb=0.02,
    ground_static=0.03,
    friction_radius=0.5,
)
"""On a floor of μ = 2 %: a spin meets the friction torque μ m g c = 0.3924 N m."""
GRAPH = {1: (2,), 2: (1, 3), 3: (2,)}


def estimates(robot: int, **changes) -> Estimates:
    """Robot ``robot``'s exact estimates, but for ``changes``."""
    x, y = CONTACTS[robot - 1]
    exact = {
        "mass": 4.0,
        "moment": 2.0,
        "omega": 0.5,
        "contact_to_com": (-x, -y),
        "relative_positions": {
            j: (x - CONTACTS[j - 1][0], y - CONTACTS[j - 1][1]) for j in GRAPH[robot]
        },
        "centroid_offset": (x, y - 1 / 3),
        "com_offset": (0.0, 1 / 3),
        "com_observer": (0.0, 1 / 3),
        "friction_torque": 0.02 * 4.0 * GRAVITY * 0.5,
        "coulomb": 0.02,
    }
    return Estimates(robot=robot, tick=100, phase=Phase.DONE, **{**exact, **changes})


def test_errors_are_relative_for_m_and_j_metres_for_offsets_rad_s_for_omega() -> None:
    est = estimates(
        2,
        mass=4.1,
        moment=1.9,
        omega=0.45,
        contact_to_com=(-1.0, 0.003),
        relative_positions={1: (2.0, 0.004), 3: (1.0, -1.0)},
        centroid_offset=(1.0, -1 / 3 + 0.005),
        com_offset=(0.006, 1 / 3),
        com_observer=(0.0, 1 / 3 - 0.007),
        friction_torque=0.3924 + 0.01,
        coulomb=0.025,
    )
    found = robot_errors(est, TRUTH, GRAPH[2])
    assert tuple(found) == ERROR_KEYS
    assert found == pytest.approx(
        {
            "mass_rel": 0.025,
            "moment_rel": 0.05,
            "contact_to_com_m": 0.003,
            "relative_positions_m": 0.004,  # the worse of its two edges
            "centroid_offset_m": 0.005,
            "com_offset_m": 0.006,
            "com_observer_m": 0.007,
            "omega_rad_s": 0.05,
            "friction_torque_nm": 0.01,
            "coulomb": 0.005,
        }
    )
    exact = robot_errors(estimates(2), TRUTH, GRAPH[2])
    assert exact == pytest.approx(dict.fromkeys(ERROR_KEYS, 0.0), abs=1e-15)


def test_what_was_not_estimated_has_no_error() -> None:
    assert robot_errors(None, TRUTH, (2,)) == dict.fromkeys(ERROR_KEYS)
    early = robot_errors(Estimates(robot=1, tick=3, phase=Phase.EXCITE), TRUTH, (2,))
    assert early == dict.fromkeys(ERROR_KEYS)
    # One edge of two unknown: the worst over the neighbours is unknown.
    lacking = estimates(2, relative_positions={1: (2.0, 0.0)})
    assert robot_errors(lacking, TRUTH, GRAPH[2])["relative_positions_m"] is None
    assert robot_errors(lacking, TRUTH, (1,))["relative_positions_m"] == 0.0
    # An estimate that is not a number is none.
    found = robot_errors(estimates(1, mass=math.nan, com_offset=(math.inf, 0.0)), TRUTH, (2,))
    assert found["mass_rel"] is None and found["com_offset_m"] is None
    assert found["moment_rel"] == 0.0


def test_the_team_error_is_the_worst_robots_or_unknown() -> None:
    team = {1: estimates(1, mass=4.2), 2: estimates(2, mass=3.6), 3: estimates(3)}
    worst = team_errors(team, TRUTH, GRAPH)
    assert worst["mass_rel"] == pytest.approx(0.1) and worst["moment_rel"] == 0.0
    del team[3]
    assert team_errors(team, TRUTH, GRAPH) == dict.fromkeys(ERROR_KEYS)


def test_the_final_instant_is_the_first_at_which_every_robot_is_done() -> None:
    def done(robot: int, since: int) -> Estimates:
        return Estimates(robot=robot, tick=since + 5, phase=Phase.DONE, phase_since=since)

    team = [done(1, 840), done(2, 847), done(3, 845)]
    assert final_instant(team) == 847
    assert final_instant(team, end_tick=900) == 900  # not before the scenario's end
    pushing = Estimates(robot=2, tick=850, phase=Phase.PUSH, phase_since=627)
    assert final_instant([team[0], pushing, team[2]]) is None
    assert final_instant([team[0], None, team[2]]) is None  # robot 2 has said nothing
    assert final_instant([]) is None


# ------------------------------------------------------------------------------ intervals
def test_a_scalars_95_percent_interval_is_1_96_standard_deviations() -> None:
    assert scalar_interval(4.0, 0.5, None) == (SCALAR_95 * 0.5, None)  # no truth: not judged
    half, inside = scalar_interval(4.0 + 0.97, 0.5, 4.0)
    assert half == pytest.approx(0.98, abs=1e-4) and inside is True
    assert scalar_interval(4.0 + 0.99, 0.5, 4.0)[1] is False
    assert scalar_interval(3.01, 0.5, 4.0)[1] is False  # below as above
    assert scalar_interval(None, 0.5, 4.0) == (None, None)  # no estimate
    assert scalar_interval(4.0, None, 4.0) == (None, None)  # no uncertainty published


def test_a_vectors_95_percent_interval_is_its_ellipse() -> None:
    cov = (0.04, 0.0, 0.01)  # σ 0.2 m along x, 0.1 m along y
    half, inside = planar_interval((1.0, 0.0), cov, None)
    assert half == pytest.approx(math.sqrt(PLANAR_95) * 0.2) and inside is None
    # Along y, the ellipse reaches 0.245 m: 0.24 is inside, 0.25 not, whatever its x width.
    assert planar_interval((1.0, 0.24), cov, (1.0, 0.0))[1] is True
    assert planar_interval((1.0, 0.25), cov, (1.0, 0.0))[1] is False
    assert distance2((0.2, 0.0), cov) == pytest.approx(1.0)


def test_the_edges_interval_is_the_widest_and_holds_when_every_edge_is_inside() -> None:
    # Robot 2's true z_21 = (2, 0) and z_23 = (1, −1); its z_21 is 1 σ off.
    est = estimates(
        2,
        relative_positions={1: (2.01, 0.0), 3: (1.0, -1.0)},
        relative_positions_cov={1: (1e-4, 0.0, 1e-4), 3: (4e-4, 0.0, 1e-4)},
    )
    half, inside = edges_interval(est, TRUTH)
    assert half == pytest.approx(math.sqrt(PLANAR_95) * 0.02) and inside is True
    assert edges_interval(est, None) == (half, None)
    wrong = dataclasses.replace(est, relative_positions={1: (2.05, 0.0), 3: (1.0, -1.0)})
    assert edges_interval(wrong, TRUTH) == (half, False)  # edge 1 is 5 σ off
    assert edges_interval(estimates(1), TRUTH) == (None, None)  # no covariance published


@pytest.mark.parametrize("std", [math.nan, math.inf, -math.inf, -1e-9, 1e308], ids=str)
def test_a_standard_deviation_that_cannot_be_one_gives_no_interval(std) -> None:
    assert scalar_interval(4.0, std, 4.0) == (None, None)  # 1e308: 1.96 σ is not finite


@pytest.mark.parametrize(
    "cov",
    [(1.0, 2.0, 1.0), (-1.0, 0.0, 1.0), (math.nan, 0.0, 1.0), (1.0, math.inf, 1.0), (1.0, 0.0)],
    ids=str,
)
def test_a_covariance_that_cannot_be_one_gives_no_interval(cov) -> None:
    assert covariance(cov) is None
    assert planar_interval((1.0, 0.0), cov, (1.0, 0.0)) == (None, None)


def _turned(v, angle: float):
    c, s = math.cos(angle), math.sin(angle)
    return (c * v[0] - s * v[1], s * v[0] + c * v[1])


def test_the_split_of_the_relative_positions_errors() -> None:
    """Every ``ẑ_ij`` turned by 2 mrad and one lengthened by 3 mm: the common turn is the
    2 mrad, the worst length the 3 mm, and once the turn is taken out only the 3 mm is left;
    an edge turned alone is its own error; a missing edge leaves no split."""
    exact = {r: estimates(r) for r in GRAPH}
    turned = {
        r: dataclasses.replace(
            e, relative_positions={j: _turned(z, 2e-3) for j, z in e.relative_positions.items()}
        )
        for r, e in exact.items()
    }
    z = turned[2].relative_positions[3]
    longer = 1.0 + 3e-3 / math.hypot(*z)
    turned[2] = dataclasses.replace(
        turned[2],
        relative_positions={**turned[2].relative_positions, 3: (longer * z[0], longer * z[1])},
    )
    split = relative_position_split(turned, TRUTH, GRAPH)
    assert split.common_turn == pytest.approx(2e-3, rel=1e-9)
    assert split.worst_length == pytest.approx(3e-3, rel=1e-6)
    assert split.worst_own == pytest.approx(3e-3, rel=1e-6)
    # one edge of four turned by 8 mrad: the common turn is 2 mrad, the edge keeps 6 mrad of it
    alone = dict(exact)
    alone[1] = dataclasses.replace(exact[1], relative_positions={2: _turned((-2.0, 0.0), 8e-3)})
    split = relative_position_split(alone, TRUTH, GRAPH)
    assert split.common_turn == pytest.approx(2e-3, rel=1e-9)
    assert split.worst_length == pytest.approx(0.0, abs=1e-12)
    assert split.worst_own == pytest.approx(2.0 * 6e-3, rel=1e-4)
    missing = {**exact, 3: dataclasses.replace(exact[3], relative_positions={})}
    assert relative_position_split(missing, TRUTH, GRAPH) is None
