"""Scenario files: loading, validation, geometry, TOML round trips and generated scenarios."""

from __future__ import annotations

import copy
import dataclasses
import math
import re
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.algorithm.tuning import PAPER_REFERENCE, AgentTuning, Estimators
from agent.platform.config import ConfigError, from_table
from agent.platform.heft import main
from bridge.admittance import AdmittanceSettings
from simulator.generate import GRAPH_KINDS, generate_scenario
from simulator.polygon import polygon_area_centroid_moment
from simulator.scenario import (
    Agvs,
    Scenario,
    ScenarioError,
    load_scenario,
    parse_scenario,
    scenario_to_toml,
)
from tests.helpers.paths import PAPER

PAPER_POLYGON = [
    (-2, -1),
    (2, -1),
    (2, 1),
    (1.25, 1),
    (1.25, 0.5),
    (-1.25, 0.5),
    (-1.25, 1),
    (-2, 1),
]


def base() -> dict[str, Any]:
    """A small valid scenario: a 2 m square held at four boundary points, line graph."""
    return {
        "name": "base",
        "body": {"polygon": [[-1, -1], [1, -1], [1, 1], [-1, 1]], "mass": 2.0},
        "contacts": {"points": [[-1, -0.5], [0.5, -1], [1, 0.5], [-0.5, 1]]},
        "graph": {"edges": [[1, 2], [2, 3], [3, 4]]},
        "sensors": {"rate_hz": 100},
        "run": {"seed": 3},
    }


# --------------------------------------------------------------------------------------------
# The paper's scenario
# --------------------------------------------------------------------------------------------


def test_paper_scenario_loads_with_the_papers_values() -> None:
    s = load_scenario(PAPER)
    assert s.name == "paper"
    assert s.n == 4
    assert s.body.polygon == tuple((float(x), float(y)) for x, y in PAPER_POLYGON)
    assert s.body.mass == 5.0
    assert s.body.moment == 12.3795 and s.body.moment_given
    assert not s.body.com_given
    assert s.body.com == pytest.approx((0.0, -0.138889), abs=1e-6)
    assert s.contacts == ((-2.0, 0.4), (-1.0, -1.0), (1.2, -1.0), (2.0, 0.6))
    assert s.edges == ((1, 2), (2, 3), (3, 4))
    assert [s.neighbours(i) for i in range(1, 5)] == [(2,), (1, 3), (2, 4), (3,)]
    assert s.sensors.rate_hz == 100.0
    assert s.sensors.velocity_noise_std == 0.0 and s.sensors.force_noise_std == 0.0
    assert s.run.seed == 1
    assert s.period_s == pytest.approx(0.01)
    assert s.substeps == 10
    # the paper's estimators, the reference, and the defaults but for their keys
    assert s.agent == from_table(AgentTuning, PAPER_REFERENCE, "agent")
    assert s.agent.estimator is Estimators.PAPER and AgentTuning().estimator is Estimators.ROBUST
    assert s.body.position == (0.0, 0.0) and s.body.angle == 0.0


# --------------------------------------------------------------------------------------------
# Geometry
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("a", "b", "mass"), [(1.0, 1.0, 1.0), (4.0, 2.0, 5.0), (0.3, 2.5, 7.0)])
def test_rectangle_area_centroid_moment(a: float, b: float, mass: float) -> None:
    x0, y0 = 3.0, -2.0
    rect = [(x0, y0), (x0 + a, y0), (x0 + a, y0 + b), (x0, y0 + b)]
    area, centroid, moment = polygon_area_centroid_moment(rect, mass)
    assert area == pytest.approx(a * b)
    assert centroid == pytest.approx((x0 + a / 2, y0 + b / 2))
    assert moment == pytest.approx(mass * (a * a + b * b) / 12)


def test_clockwise_polygon_has_negative_area_and_same_moment() -> None:
    area, centroid, moment = polygon_area_centroid_moment(PAPER_POLYGON[::-1], 5.0)
    ccw_area, ccw_centroid, ccw_moment = polygon_area_centroid_moment(PAPER_POLYGON, 5.0)
    assert area == pytest.approx(-ccw_area)
    assert centroid == pytest.approx(ccw_centroid)
    assert moment == pytest.approx(ccw_moment)


def test_notched_plate_by_parallel_axis_theorem() -> None:
    mass = 5.0
    density = mass / (8.0 - 1.25)
    plate_mass, notch_mass = 8.0 * density, 1.25 * density
    plate_j = plate_mass * (4.0**2 + 2.0**2) / 12  # about (0, 0)
    notch_y = 0.75
    notch_j = notch_mass * (2.5**2 + 0.5**2) / 12 + notch_mass * notch_y**2  # about (0, 0)
    com_y = -notch_mass * notch_y / mass
    expected = plate_j - notch_j - mass * com_y**2

    area, centroid, moment = polygon_area_centroid_moment(PAPER_POLYGON, mass)
    assert area == pytest.approx(6.75)
    assert centroid == pytest.approx((0.0, com_y), abs=1e-12)
    assert moment == pytest.approx(expected, rel=1e-12)
    assert moment == pytest.approx(8.76, abs=0.005)


@given(
    st.floats(-100, 100),
    st.floats(-100, 100),
    st.floats(-math.pi, math.pi),
    st.floats(0.1, 100),
)
def test_moment_is_invariant_under_rigid_motion(
    dx: float, dy: float, turn: float, m: float
) -> None:
    c, s = math.cos(turn), math.sin(turn)
    moved = [(c * x - s * y + dx, s * x + c * y + dy) for x, y in PAPER_POLYGON]
    area, centroid, moment = polygon_area_centroid_moment(moved, m)
    _, (cx, cy), reference = polygon_area_centroid_moment(PAPER_POLYGON, m)
    assert area == pytest.approx(6.75)
    assert centroid == pytest.approx((c * cx - s * cy + dx, s * cx + c * cy + dy), abs=1e-9)
    assert moment == pytest.approx(reference, rel=1e-9)


# --------------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------------


def test_base_scenario_is_valid() -> None:
    s = parse_scenario(base())
    assert s.n == 4
    assert not s.body.moment_given and not s.body.com_given
    assert s.body.moment == pytest.approx(2.0 * (4 + 4) / 12)
    assert s.body.com == pytest.approx((0.0, 0.0))
    assert s.neighbours(2) == (1, 3)


def put(path: str, value: Any) -> Callable[[dict[str, Any]], None]:
    """A mutation setting the dotted key ``path``."""

    def mutate(data: dict[str, Any]) -> None:
        *tables, key = path.split(".")
        target = data
        for table in tables:
            target = target.setdefault(table, {})
        target[key] = value

    return mutate


def drop(path: str) -> Callable[[dict[str, Any]], None]:
    """A mutation deleting the dotted key ``path``."""

    def mutate(data: dict[str, Any]) -> None:
        *tables, key = path.split(".")
        target = data
        for table in tables:
            target = target[table]
        del target[key]

    return mutate


SQUARE_CONTACTS = [[-1, -0.5], [0.5, -1], [1, 0.5], [-0.5, 1]]

INVALID = [
    # (id, mutation, key the message must start with, other text it must contain)
    ("unknown top-level key", put("colour", "red"), "colour", "unknown key"),
    ("unknown body key", put("body.density", 1.0), "body.density", "unknown key"),
    ("unknown contacts key", put("contacts.normals", []), "contacts.normals", "unknown key"),
    ("unknown graph key", put("graph.directed", True), "graph.directed", "unknown key"),
    ("unknown sensors key", put("sensors.bias", 0.0), "sensors.bias", "unknown key"),
    ("unknown run key", put("run.steps", 3), "run.steps", "unknown key"),
    ("unknown agent key", put("agent.gain", 1.0), "agent.gain", "unknown key"),
    ("missing name", drop("name"), "name", "missing"),
    ("empty name", put("name", " "), "name", "non-empty"),
    ("name not a string", put("name", 3), "name", "string"),
    ("description not a string", put("description", 3), "description", "string"),
    ("missing body", drop("body"), "body", "missing"),
    ("body not a table", put("body", 3), "body", "table"),
    ("missing polygon", drop("body.polygon"), "body.polygon", "missing"),
    ("missing mass", drop("body.mass"), "body.mass", "missing"),
    ("missing contacts", drop("contacts.points"), "contacts.points", "missing"),
    ("missing edges", drop("graph.edges"), "graph.edges", "missing"),
    ("two vertices", put("body.polygon", [[0, 0], [1, 0]]), "body.polygon", "3 to 1000 vertices"),
    (
        "infinite vertex",
        put("body.polygon", [[-1, -1], [math.inf, -1], [1, 1], [-1, 1]]),
        "body.polygon[1][0]",
        "finite",
    ),
    (
        "nan vertex",
        put("body.polygon", [[-1, -1], [1, -1], [1, math.nan], [-1, 1]]),
        "body.polygon[2][1]",
        "finite",
    ),
    ("vertex not a pair", put("body.polygon", [[0, 0], [1], [0, 1]]), "body.polygon[1]", "2"),
    (
        "zero area",
        put("body.polygon", [[-1, -1], [0, 0], [1, 1], [2, 2]]),
        "body.polygon",
        "zero area",
    ),
    (
        "self-intersecting",
        put("body.polygon", [[-1, -1], [1, 1], [1, -1], [-1, 2]]),
        "body.polygon",
        "self-intersecting",
    ),
    (
        "vertex touching an edge",
        put("body.polygon", [[-1, -1], [1, -1], [1, 1], [0, -1], [-1, 1]]),
        "body.polygon",
        "self-intersecting",
    ),
    (
        "repeated vertex",
        put("body.polygon", [[-1, -1], [1, -1], [1, 1], [1, -1], [-1, 1]]),
        "body.polygon[3]",
        "repeats",
    ),
    (
        "clockwise",
        put("body.polygon", [[-1, 1], [1, 1], [1, -1], [-1, -1]]),
        "body.polygon",
        "counter-clockwise",
    ),
    ("negative mass", put("body.mass", -1), "body.mass", "in [0.01, 10000] kg, got -1"),
    ("zero mass", put("body.mass", 0.0), "body.mass", "[0.01, 10000]"),
    ("mass not a number", put("body.mass", "heavy"), "body.mass", "number"),
    ("negative moment", put("body.moment", -2.0), "body.moment", "[0.0001, 1000000]"),
    ("zero moment", put("body.moment", 0), "body.moment", "[0.0001, 1000000]"),
    ("com of 3 values", put("body.com", [0, 0, 0]), "body.com", "2 values"),
    ("position not a pair", put("body.position", 1.0), "body.position", "list"),
    ("angle not a number", put("body.angle", "up"), "body.angle", "number"),
    ("one contact", put("contacts.points", [[-1, 0]]), "contacts.points", "2 to 32"),
    (
        "contacts too close",
        put("contacts.points", [[-1, -0.5], [0.5, -1], [-1, -0.47]]),
        "contacts.points[2]",
        "0.05 m apart",
    ),
    (
        "contact off the boundary",
        put("contacts.points", [[-1, -0.5], [0.5, -1], [0.2, 0.1], [-0.5, 1]]),
        "contacts.points[2]",
        "boundary",
    ),
    (
        "contact far outside",
        put("contacts.points", [[-1, -0.5], [3.0, 0.0], [1, 0.5], [-0.5, 1]]),
        "contacts.points[1]",
        "boundary",
    ),
    ("edge beyond n", put("graph.edges", [[1, 2], [2, 3], [3, 5]]), "graph.edges[2]", "robot 5"),
    (
        "edge robot 0",
        put("graph.edges", [[0, 1], [1, 2], [2, 3], [3, 4]]),
        "graph.edges[0]",
        "robot 0",
    ),
    (
        "self-loop",
        put("graph.edges", [[1, 2], [2, 2], [2, 3], [3, 4]]),
        "graph.edges[1]",
        "self-loop",
    ),
    (
        "duplicate edge",
        put("graph.edges", [[1, 2], [2, 3], [3, 4], [2, 1]]),
        "graph.edges[3]",
        "duplicate of graph.edges[0]",
    ),
    (
        "not connected",
        put("graph.edges", [[1, 2], [3, 4]]),
        "graph.edges",
        "not connected (robot 3 unreachable)",
    ),
    ("robot without edge", put("graph.edges", [[1, 2], [2, 3]]), "graph.edges", "robot 4"),
    ("no edges", put("graph.edges", []), "graph.edges", "no edge"),
    ("edge not a pair", put("graph.edges", [[1, 2, 3]]), "graph.edges[0]", "2 values"),
    ("edge of floats", put("graph.edges", [[1.0, 2.0]]), "graph.edges[0][0]", "integer"),
    ("zero rate", put("sensors.rate_hz", 0), "sensors.rate_hz", "[10, 1000]"),
    ("negative rate", put("sensors.rate_hz", -100.0), "sensors.rate_hz", "[10, 1000]"),
    (
        "negative velocity noise",
        put("sensors.velocity_noise_std", -0.1),
        "sensors.velocity_noise_std",
        "[0, 1] m/s",
    ),
    (
        "negative force noise",
        put("sensors.force_noise_std", -1),
        "sensors.force_noise_std",
        "[0, 100] N",
    ),
    ("physics not a multiple", put("run.physics_hz", 250.0), "run.physics_hz", "multiple"),
    ("physics slower than sensors", put("run.physics_hz", 50.0), "run.physics_hz", "multiple"),
    ("zero physics rate", put("run.physics_hz", 0.0), "run.physics_hz", "[10, 100000]"),
    ("zero max time", put("run.max_time_s", 0.0), "run.max_time_s", "positive"),
    ("negative max time", put("run.max_time_s", -5), "run.max_time_s", "positive"),
    ("negative seed", put("run.seed", -1), "run.seed", "non-negative"),
    ("float seed", put("run.seed", 1.5), "run.seed", "integer"),
    ("bad agent value", put("agent.max_force", -1.0), "agent.max_force", "positive"),
    (
        "negative lag",
        put("actuators.time_constant_s", -0.01),
        "actuators.time_constant_s",
        "[0, 1] s",
    ),
    ("gain error", put("actuators.gain_error_std", 0.5), "actuators.gain_error_std", "[0, 0.3]"),
    (
        "a gain per robot",
        put("actuators.gains", [1.0, 1.0]),
        "actuators.gains",
        "one gain per robot",
    ),
    ("gain out of range", put("actuators.gains", [1, 1, 2, 1]), "actuators.gains[2]", "[0.5, 1.5]"),
    ("unknown actuator key", put("actuators.delay_s", 0.1), "actuators.delay_s", "unknown key"),
    ("agv profile", put("agvs.profile", "torque"), "agvs.profile", "force, velocity"),
    ("agv key", put("agvs.stiffness", 1000.0), "agvs.stiffness", "unknown key"),
    (
        "agv speed loop",
        put("agvs.speed_time_constant_s", 0.0),
        "agvs.speed_time_constant_s",
        "[0.001, 1] s",
    ),
    ("agv accel", put("agvs.max_accel", 0.0), "agvs.max_accel", "(0, 100] m/s²"),
    ("agv stiffness", put("agvs.contact_stiffness", 1.0), "agvs.contact_stiffness", "N/m"),
    ("agv bias", put("agvs.sensor_bias_std", -0.1), "agvs.sensor_bias_std", "[0, 100] N"),
    ("admittance", put("agvs.admittance.mass", 0.0), "agvs.admittance.mass", "[0.01, 1000] kg"),
    ("admittance key", put("agvs.admittance.gain", 1.0), "agvs.admittance.gain", "unknown key"),
    ("agvs not a table", put("agvs", 1), "agvs", "expected a table"),
]


@pytest.mark.parametrize(
    ("mutate", "key", "text"), [case[1:] for case in INVALID], ids=[case[0] for case in INVALID]
)
def test_invalid_scenario_names_the_key(
    mutate: Callable[[dict[str, Any]], None], key: str, text: str
) -> None:
    data = copy.deepcopy(base())
    mutate(data)
    with pytest.raises(ScenarioError) as caught:
        parse_scenario(data, source="base.toml")
    message = str(caught.value)
    assert message.startswith(f"base.toml: {key}: "), message
    assert text in message
    assert "\n" not in message
    assert isinstance(caught.value, ConfigError)


def test_valid_variations_are_accepted() -> None:
    data = base()
    data["body"].update(moment=1.5, com=[0.1, -0.2], position=[3, 4], angle=0.5)
    data["contacts"]["points"][0] = [-1.04, -0.5]  # slightly off the boundary: tolerated
    data["graph"]["edges"] = [[2, 1], [3, 2], [4, 3], [1, 4]]
    data["run"] = {"seed": 0, "physics_hz": 500, "max_time_s": 10}
    data["agent"] = {"paper": {"push_min_force": 2.0}}
    data["description"] = "variations"
    s = parse_scenario(data)
    assert s.body.moment == 1.5 and s.body.moment_given
    assert s.body.com == (0.1, -0.2) and s.body.com_given
    assert s.body.position == (3.0, 4.0) and s.body.angle == 0.5
    assert s.neighbours(1) == (2, 4)
    assert s.substeps == 5
    assert s.agent.paper.push_min_force == 2.0
    assert s.description == "variations"


def velocity_agvs(data: dict[str, Any], **agvs: Any) -> dict[str, Any]:
    data["agvs"] = {"profile": "velocity", **agvs}
    return data


def test_agvs_default_to_force_drives_and_a_force_profile_changes_nothing() -> None:
    plain = parse_scenario(base())
    assert plain.agvs == Agvs() and not plain.agvs.velocity
    data = base()
    data["agvs"] = {"profile": "force"}
    assert parse_scenario(data) == plain
    assert "[agvs]" not in scenario_to_toml(plain)


def test_velocity_agvs_are_read_with_their_admittance_loop() -> None:
    data = velocity_agvs(base(), contact_stiffness=8000.0, admittance={"mass": 4.0})
    agvs = parse_scenario(data).agvs
    assert agvs.velocity and agvs.contact_stiffness == 8000.0
    assert agvs.admittance == AdmittanceSettings(mass=4.0)
    assert agvs.speed_time_constant_s == 0.05 and agvs.sensor_bias_std == 0.3


def test_velocity_agvs_refuse_force_drives() -> None:
    data = velocity_agvs(base())
    data["actuators"] = {"time_constant_s": 0.02}
    with pytest.raises(ScenarioError, match=r"^base\.toml: actuators: models force drives"):
        parse_scenario(data, source="base.toml")
    data["agvs"]["profile"] = "force"
    assert parse_scenario(data).actuators.time_constant_s == 0.02


def test_the_physics_rate_must_resolve_the_contacts() -> None:
    """The base scenario (2 kg, a 2 m square): λ = Σ (2/m + r²/J) = 4 + 4 · 1.25 / (4/3) = 7.75
    per kg, so 10 000 N/m rings at √(77 500) = 278 rad/s: at least 557 Hz of physics."""
    data = velocity_agvs(base(), contact_stiffness=10_000.0)
    data["run"]["physics_hz"] = 600.0
    assert parse_scenario(data).run.physics_hz == 600.0
    data["run"]["physics_hz"] = 500.0
    with pytest.raises(ScenarioError) as caught:
        parse_scenario(data, source="base.toml")
    assert str(caught.value) == (
        "base.toml: run.physics_hz: expected at least 556.8 Hz for agvs.contact_stiffness ="
        " 10000 N/m on this load, got 500.0"
    )
    data = velocity_agvs(base(), contact_damping=200.0)
    with pytest.raises(ScenarioError, match="agvs.contact_damping = 200 N s/m"):
        parse_scenario(data)


def test_paper_velocity_is_paper_noisy_on_velocity_commanded_agvs() -> None:
    noisy = load_scenario(PAPER.with_name("paper-noisy.toml"))
    velocity = load_scenario(PAPER.with_name("paper-velocity.toml"))
    assert velocity.agvs.velocity and velocity.actuators.ideal
    assert velocity.agvs.admittance == AdmittanceSettings()
    same = dataclasses.replace(
        velocity, name=noisy.name, agvs=noisy.agvs, actuators=noisy.actuators
    )
    assert same == noisy


# --------------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------------


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "nowhere.toml"
    with pytest.raises(ScenarioError, match=r"nowhere\.toml: no such file") as caught:
        load_scenario(path)
    assert "\n" not in str(caught.value)


def test_directory_is_not_a_file(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(tmp_path)


@pytest.mark.parametrize(
    "text", ['name = "x"\n[body\n', "name = \n", b"\xff\xfe".decode("latin-1")]
)
def test_invalid_toml(tmp_path: Path, text: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="latin-1")
    with pytest.raises(ScenarioError, match="not valid TOML") as caught:
        load_scenario(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: ")
    assert "\n" not in message


def test_file_errors_are_prefixed_by_the_path(tmp_path: Path) -> None:
    text = PAPER.read_text(encoding="utf-8").replace("[[1, 2], [2, 3], [3, 4]]", "[[1, 2], [3, 4]]")
    path = tmp_path / "paper.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path)
    assert str(caught.value) == (
        f"{path}: graph.edges: the graph is not connected (robot 3 unreachable)"
    )


# --------------------------------------------------------------------------------------------
# Round trips
# --------------------------------------------------------------------------------------------


def round_trip(s: Scenario) -> Scenario:
    return parse_scenario(tomllib.loads(scenario_to_toml(s)), source=s.name)


def test_paper_round_trip() -> None:
    s = load_scenario(PAPER)
    assert round_trip(s) == s


def test_round_trip_of_every_option() -> None:
    data = base()
    data["body"].update(moment=1.5, com=[0.1, -0.2], position=[3, 4], angle=0.1 + 0.2)
    data["description"] = 'quotes " and \\ backslash\nnew line, tab\t, é, \x7f'
    data["sensors"] = {"rate_hz": 50.0, "velocity_noise_std": 1e-3, "force_noise_std": 0.02}
    data["run"] = {"seed": 12, "physics_hz": 1e3, "max_time_s": 1 / 3}
    data["agent"] = {"push_direction": [1.0, 0.0], "switch_margin_ticks": 4}
    data["actuators"] = {"time_constant_s": 0.02, "gains": [0.98, 1.02, 1.0, 1.01]}
    s = parse_scenario(data)
    assert s.actuators.gains == (0.98, 1.02, 1.0, 1.01) and not s.actuators.ideal
    assert round_trip(s) == s


def test_round_trip_of_velocity_agvs() -> None:
    agvs = {"speed_time_constant_s": 0.1, "max_accel": 1.5, "max_speed": 2.0}
    agvs |= {"contact_stiffness": 1e3, "contact_damping": 0.1 + 0.2, "sensor_bias_std": 0.0}
    agvs["admittance"] = {"mass": 2.5, "damping": 10.0, "tare_samples": 7}
    s = parse_scenario(velocity_agvs(base(), **agvs))
    assert s.agvs.admittance.tare_samples == 7
    assert round_trip(s) == s
    assert round_trip(parse_scenario(velocity_agvs(base()))) == parse_scenario(
        velocity_agvs(base())
    )
    assert round_trip(load_scenario(PAPER.with_name("paper-velocity.toml"))).agvs.velocity


@pytest.mark.parametrize("seed", range(30))
def test_generated_round_trip(seed: int) -> None:
    s = generate_scenario(seed)
    assert round_trip(s) == s


# --------------------------------------------------------------------------------------------
# Generated scenarios
# --------------------------------------------------------------------------------------------


def is_convex(polygon: tuple[tuple[float, float], ...]) -> bool:
    count = len(polygon)
    for i in range(count):
        (ax, ay), (bx, by), (cx, cy) = (polygon[(i + k) % count] for k in range(3))
        if (bx - ax) * (cy - by) - (by - ay) * (cx - bx) < 0:
            return False
    return True


def graph_kind(s: Scenario) -> str:
    kind = re.search(r"(\w+) graph", s.description)
    assert kind is not None
    return kind.group(1)


def check_graph_kind(s: Scenario) -> None:
    degrees = [len(s.neighbours(i)) for i in range(1, s.n + 1)]
    kind = graph_kind(s)
    if kind == "line":
        assert len(s.edges) == s.n - 1 and max(degrees) <= 2
    elif kind == "ring":
        assert len(s.edges) == s.n and set(degrees) == {2}
    elif kind == "star":
        assert len(s.edges) == s.n - 1 and max(degrees) == s.n - 1
    else:
        assert kind == "random" and len(s.edges) >= s.n


GENERATED = [generate_scenario(seed) for seed in range(100)]


def test_generated_scenarios_are_valid_and_cover_every_case() -> None:
    kinds, convex, ns, moments, coms = set(), set(), set(), set(), set()
    for seed, s in enumerate(GENERATED):
        assert s.name == f"generated-{seed}"
        assert parse_scenario(tomllib.loads(scenario_to_toml(s))) == s
        check_graph_kind(s)
        assert 1.0 <= max(math.dist(p, q) for p in s.body.polygon for q in s.body.polygon) <= 4.0
        assert 1.0 <= s.body.mass <= 50.0
        assert min(math.dist(p, q) for i, p in enumerate(s.contacts) for q in s.contacts[:i]) >= 0.2
        _, centroid, uniform = polygon_area_centroid_moment(s.body.polygon, s.body.mass)
        if s.body.moment_given:
            assert 0.7 * uniform * (1 - 1e-5) <= s.body.moment <= 1.4 * uniform * (1 + 1e-5)
        if not s.body.com_given:
            assert s.body.com == centroid
        kinds.add(graph_kind(s))
        convex.add(is_convex(s.body.polygon))
        ns.add(s.n)
        moments.add(s.body.moment_given)
        coms.add(s.body.com_given)
    assert kinds == set(GRAPH_KINDS)
    assert convex == {True, False}
    assert ns == set(range(3, 9))
    assert moments == {True, False} and coms == {True, False}


def test_generation_is_deterministic() -> None:
    assert generate_scenario(17) == GENERATED[17]
    assert generate_scenario(17) != GENERATED[18]


def test_generate_command_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "g.toml"
    assert main(["scenario", "generate", "7", "-o", str(path)]) == 0
    assert load_scenario(path) == GENERATED[7]
    assert main(["scenario", "generate", "7"]) == 0
    assert parse_scenario(tomllib.loads(capsys.readouterr().out)) == GENERATED[7]
