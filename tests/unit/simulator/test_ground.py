"""The scenario's ``[ground]`` table: what the load rests on and with which loads.

The normal loads are those of statics (their sum the weight, their centre the COM) for the
polygon's area and for given supports, with the least ``Σ N_k² / k_k`` (a linear pressure over
the area, equal springs under given supports); the area's cells give a pure spin's friction
radius within 1 % of the continuous one; bad keys get one line naming them; a scenario with a
``[ground]`` table writes back to itself.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from agent.platform.protocol import GRAVITY
from simulator.polygon import area_cells, polygon_area_centroid_moment
from simulator.scenario import (
    DEFAULT_SUPPORT_CELLS,
    Ground,
    ScenarioError,
    load_scenario,
    parse_scenario,
    scenario_to_toml,
)
from tests.helpers.bad_input import paper, refused, scenario_file, with_values
from tests.helpers.paths import PAPER

CASTERS = [[-1.8, -0.8], [1.8, -0.8], [1.8, 0.8], [-1.8, 0.8]]


def with_ground(ground: dict[str, Any], values: dict[str, Any] | None = None) -> dict[str, Any]:
    """The paper's scenario as tables, with ``values`` set and ``[ground]`` = ``ground``."""
    return {**with_values(paper(), values or {}), "ground": ground}


def statics(ground: Ground, mass: float, com: tuple[float, float]) -> tuple[float, np.ndarray]:
    """``Σ N_k / m g`` and ``Σ N_k s_k / m g``: 1 and the COM when the loads are in statics."""
    normal = np.array(ground.loads(mass, com).normal)
    weight = mass * GRAVITY
    return normal.sum() / weight, normal.dot(np.array(ground.supports)) / weight


# ------------------------------------------------------------------------------ statics
@pytest.mark.parametrize(
    "com", [None, [0.0, -0.139], [0.3, -0.25]], ids=["centroid", "paper", "off"]
)
def test_the_areas_loads_are_in_statics_with_a_linear_pressure(com) -> None:
    """Over the polygon's area: ``Σ N_k = m g``, ``Σ N_k s_k = m g p_C``, and each cell's load
    over its area is one plane ``a + bᵀ s`` (uniform when the COM is the centroid)."""
    scenario = parse_scenario(with_ground({"coulomb": 0.3}, {"body.com": com}))
    ground, body = scenario.ground, scenario.body
    assert not ground.supports_given
    assert DEFAULT_SUPPORT_CELLS <= len(ground.supports) <= 1.5 * DEFAULT_SUPPORT_CELLS
    total, centre = statics(ground, body.mass, body.com)
    assert total == pytest.approx(1.0, rel=1e-12)
    assert centre == pytest.approx(body.com, abs=1e-12)
    pressure = np.array(ground.loads(body.mass, body.com).normal) / np.array(ground.stiffness)
    plane = np.column_stack((np.ones(len(pressure)), np.array(ground.supports)))
    fit, residual, *_ = np.linalg.lstsq(plane, pressure, rcond=None)
    assert np.abs(plane.dot(fit) - pressure).max() <= 1e-9 * pressure.mean()
    if com is None:
        assert np.ptp(pressure) <= 1e-12 * pressure.mean()
    assert sum(ground.stiffness) == pytest.approx(polygon_area_centroid_moment(body.polygon, 1)[0])


def test_given_supports_carry_the_least_norm_loads_of_statics() -> None:
    """Four casters under an off-centre COM: statics, and the loads a plane over the
    supports (equal springs), the least ``Σ N_k²`` of those in statics."""
    scenario = parse_scenario(with_ground({"coulomb": 0.02, "supports": CASTERS}))
    ground, body = scenario.ground, scenario.body
    total, centre = statics(ground, body.mass, body.com)
    assert total == pytest.approx(1.0, rel=1e-12)
    assert centre == pytest.approx(body.com, abs=1e-12)
    normal = ground.loads(body.mass, body.com).normal
    # the lower two carry more, the upper two less, by the COM's 0.139 m below the centre
    assert normal[0] == normal[1] > normal[2] == normal[3] > 0
    assert normal[0] + normal[3] == pytest.approx(body.mass * GRAVITY / 2)
    assert normal[0] == pytest.approx(body.mass * GRAVITY * (1 + 0.138889 / 0.8) / 4, rel=1e-5)


def test_the_friction_figures_are_the_loads_moments() -> None:
    scenario = parse_scenario(with_ground({"coulomb": 0.02, "supports": CASTERS}))
    ground, body = scenario.ground, scenario.body
    loads = ground.loads(body.mass, body.com)
    arms = [math.dist(s, body.com) for s in ground.supports]
    weight = body.mass * GRAVITY
    assert loads.friction_radius == pytest.approx(
        sum(n * r for n, r in zip(loads.normal, arms)) / weight
    )
    assert loads.viscous_radius2 == pytest.approx(
        sum(n * r * r for n, r in zip(loads.normal, arms)) / weight
    )
    assert loads.friction_radius**2 <= loads.viscous_radius2


@pytest.mark.parametrize(
    "polygon",
    [
        [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)],
        [(-2.0, -0.1), (2.0, -0.1), (2.0, 0.1), (-2.0, 0.1)],
        [(0.0, 0.0), (3.0, 0.0), (0.0, 1.0)],
        [(0, 0), (2, 0), (2, 0.5), (0.5, 0.5), (0.5, 2), (0, 2)],
        [(-2, -1), (2, -1), (2, 1), (1.25, 1), (1.25, 0.5), (-1.25, 0.5), (-1.25, 1), (-2, 1)],
    ],
    ids=["square", "bar", "triangle", "L", "paper"],
)
def test_the_areas_cells_give_a_spins_friction_within_one_percent(polygon) -> None:
    """``Σ a_k ‖s_k − p_C‖ / A`` of the cells against a 40 000-cell reference of
    ``∫ ‖s − p_C‖ dA / A``, the continuous friction radius under a uniform pressure."""
    _, centroid, _ = polygon_area_centroid_moment(polygon, 1.0)

    def radius(cells):
        return sum(a * math.dist(c, centroid) for c, a in cells) / sum(a for _, a in cells)

    reference = radius(area_cells(polygon, 40_000))
    assert radius(area_cells(polygon, DEFAULT_SUPPORT_CELLS)) == pytest.approx(reference, rel=0.01)


# ------------------------------------------------------------------------------ bad keys
BAD = {
    "a negative coulomb": ({"coulomb": -0.1}, "ground.coulomb", "[0, 2]"),
    "a coulomb above 2": ({"coulomb": 2.5}, "ground.coulomb", "[0, 2]"),
    "a static below the coulomb": (
        {"coulomb": 0.3, "static": 0.2},
        "ground.static",
        "at least ground.coulomb",
    ),
    "a negative viscous": ({"viscous": -1.0}, "ground.viscous", "N s/m"),
    "an unknown key": ({"rolling": 0.02}, "ground.rolling", "unknown key"),
    "two supports": ({"supports": [[-1.0, 0.0], [1.0, 0.0]]}, "ground.supports", "3 to 100"),
    "supports on a line": (
        {"supports": [[-1.0, 0.0], [0.0, 0.0], [1.0, 0.0]]},
        "ground.supports",
        "one line",
    ),
    "a support off the load": (
        {"supports": [[-1.0, -0.5], [1.0, -0.5], [0.0, 3.0]]},
        "ground.supports[2]",
        "off the load",
    ),
    "a support twice": (
        {"supports": [[-1.0, -0.5], [1.0, -0.5], [-1.0, -0.5]]},
        "ground.supports[2]",
        "repeats",
    ),
    "a COM outside the supports": (
        {"supports": [[-1.8, 0.2], [1.8, 0.2], [1.8, 0.8]]},
        "ground.supports[",
        "less than nothing",
    ),
    "not a table": (0.3, "ground", "expected a table"),
}


@pytest.mark.parametrize("ground, key, words", BAD.values(), ids=BAD.keys())
def test_a_bad_ground_is_refused_naming_its_key(tmp_path, capsys, ground, key, words) -> None:
    data = with_ground(ground)
    with pytest.raises(ScenarioError, match=f"^<scenario>: {key}".replace("[", r"\[")):
        parse_scenario(data)
    path = scenario_file(tmp_path, {}, base=data)
    refused(capsys, ["run", str(path), "-q"], key, words)


def test_a_com_too_far_off_for_the_whole_area_is_refused_naming_body_com() -> None:
    """Without supports the load rests on its whole area: a COM near one end would need the
    floor to pull the other end down."""
    data = with_ground({"coulomb": 0.3}, {"body.com": [1.9, -0.9], "body.moment": 12.0})
    with pytest.raises(ScenarioError, match="body.com: .* give ground.supports"):
        parse_scenario(data)


def test_a_change_that_lifts_a_support_is_refused_naming_the_event() -> None:
    data = with_ground({"coulomb": 0.02, "supports": CASTERS})
    data["events"] = [{"at_s": 5.0, "com": [1.9, 0.9]}]
    with pytest.raises(ScenarioError, match=r"events\[0\]: ground.supports\[0\]: would carry"):
        parse_scenario(data)


# ------------------------------------------------------------------------------ files
def test_the_floor_scenarios_load() -> None:
    floor = load_scenario(PAPER.parent / "paper-floor.toml")
    noisy = load_scenario(PAPER.parent / "paper-noisy.toml")
    assert (floor.body, floor.contacts, floor.sensors, floor.actuators, floor.agent) == (
        noisy.body,
        noisy.contacts,
        noisy.sensors,
        noisy.actuators,
        noisy.agent,
    )
    assert (floor.ground.coulomb, floor.ground.static) == (0.02, 0.03)
    pallet = load_scenario(PAPER.parent / "pallet.toml")
    weight = pallet.body.mass * GRAVITY
    assert (pallet.ground.coulomb, pallet.ground.static) == (0.3, 0.35)
    # the team can break it away: n robots at max_force push well past μ_s m g
    assert pallet.n * pallet.agent.robust.push_force > 1.5 * pallet.ground.static * weight
    assert pallet.n * pallet.agent.max_force > 2 * pallet.ground.static * weight


@pytest.mark.parametrize("ground", [{"coulomb": 0.3, "viscous": 2.0}, {"supports": CASTERS}])
def test_a_scenario_on_a_ground_writes_back_to_itself(ground) -> None:
    import tomllib

    scenario = parse_scenario(with_ground(ground))
    assert parse_scenario(tomllib.loads(scenario_to_toml(scenario))) == scenario
