"""Every input has a documented range, checked before anything starts.

Values that once gave tracebacks or hangs (a memory of 1e-300 s, a window of 1e300 s, 1e12
physics steps a second, a sensor at 1e-9 Hz, a start timeout of NaN, a team of 200, a port of
99999) get exit status 2 and one ``heft: error:`` line naming the key and its range. Every
declared range (:func:`agent.platform.config.bounded`) is tested at both ends: a value just
inside is accepted, one just outside refused with the key named; and the "Limits" section of
docs/configuration.md lists each of them. A busy port or no router (exit status 4) is in
tests/integration/test_endpoint_errors.py; the probes as ``heft`` processes in
tests/integration/test_heft_processes.py."""

from __future__ import annotations

import math
import re
import typing
from typing import Any

import pytest

from agent.algorithm.paper.tuning import PaperTuning
from agent.algorithm.robust.tuning import RobustTuning
from agent.algorithm.tuning import AgentTuning
from agent.node import AgentNodeConfig, load_agent_config
from agent.platform.config import MAX_ROBOTS, MAX_SEED, Bound, bounds
from agent.platform.heft import main
from agent.platform.zenoh_session import ZenohSettings
from bridge.admittance import AdmittanceSettings
from bridge.config import CanSettings
from simulator.polygon import polygon_diameter
from simulator.scenario import (
    MAX_COORDINATE,
    MAX_POSITION,
    MAX_VERTICES,
    MIN_DIAMETER,
    Actuators,
    Agvs,
    Floor,
    LoadChange,
    RunSettings,
    Sensors,
    _BodyTable,
    _GroundTable,
    load_scenario,
)
from tests.helpers.bad_input import paper, refused, robot_file, scenario_file
from tests.helpers.paths import PAPER, ROOT
from tests.helpers.tls import loadable_copy

RANGE = re.compile(r"[\[(][^,\]]+, [^\]]+\]")
"""A range as the messages write it: ``[10, 1000]``, ``(0, 3600]``, ``[1 tick, 60]``."""


# ------------------------------------------------------------------------------ the probes
def test_the_paper_scenario_and_the_deployed_configs_are_within_every_range(tmp_path) -> None:
    load_scenario(PAPER)
    for path in sorted((ROOT / "deploy" / "paper").glob("robot-*.toml")):
        load_agent_config(loadable_copy(path, tmp_path))  # (its TLS files: on robots only)


def test_generated_scenarios_are_within_every_range() -> None:
    from simulator.generate import generate_scenario, ring_scenario

    for seed in range(200):
        generate_scenario(seed)  # raises if out of range
    generate_scenario(MAX_SEED)
    for n in (4, 8, 16, MAX_ROBOTS):
        ring_scenario(n)


PROBES = {
    "memory of 1e-300 s": ({"agent.regression_memory_s": 1e-300}, "agent.regression_memory_s"),
    "window of 1e300 s": ({"agent.settle_window_s": 1e300}, "agent.settle_window_s"),
    "1e12 physics steps a second": ({"run.physics_hz": 1e12}, "run.physics_hz"),
    "a sensor at 1e-9 Hz": ({"sensors.rate_hz": 1e-9}, "sensors.rate_hz"),
    "201 physics steps a tick": ({"run.physics_hz": 20100.0}, "run.physics_hz"),
    "a run of ten hours": ({"run.max_time_s": 36000.0}, "run.max_time_s"),
}


@pytest.mark.parametrize("values, key", PROBES.values(), ids=PROBES.keys())
def test_scenario_probes_are_refused_before_the_run(tmp_path, capsys, values, key) -> None:
    line = refused(capsys, ["run", str(scenario_file(tmp_path, values)), "-q"], key)
    assert RANGE.search(line) or "at most" in line, line


def test_the_ticks_of_a_memory_are_named(tmp_path, capsys) -> None:
    path = scenario_file(tmp_path, {"agent.regression_memory_s": 1e-300})
    refused(capsys, ["run", str(path)], "0 (off) or", "[0.1, 3600] s", "sensors.rate_hz = 100")


@pytest.mark.parametrize(
    "values, key",
    [
        ({"tuning.regression_memory_s": 1e-300}, "agent.tuning.regression_memory_s"),
        ({"tuning.settle_window_s": 1e300}, "agent.tuning.settle_window_s"),
    ],
    ids=["memory of 1e-300 s", "window of 1e300 s"],
)
def test_robot_toml_probes_are_refused_before_the_agent_starts(
    tmp_path, capsys, values, key
) -> None:
    line = refused(capsys, ["agent", "--config", str(robot_file(tmp_path, values))], key)
    assert RANGE.search(line), line


def test_a_team_of_two_hundred_is_refused(tmp_path, capsys) -> None:
    contacts = [[-2.0 + 4.0 * k / 200, -1.0] for k in range(200)]
    edges = [[i, i + 1] for i in range(1, 200)]
    path = scenario_file(tmp_path, {"contacts.points": contacts, "graph.edges": edges})
    refused(capsys, ["run", str(path), "-q"], "contacts.points", f"2 to {MAX_ROBOTS}")


def test_an_agent_of_a_team_of_two_hundred_is_refused(tmp_path, capsys) -> None:
    path = robot_file(tmp_path, {"n": 200})
    refused(capsys, ["agent", "--config", str(path)], "agent.n", f"2 to {MAX_ROBOTS}")


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "-1", "0", "3600.000001", "1e9"])
def test_the_plants_start_timeout_is_a_finite_number_of_seconds(capsys, value) -> None:
    refused(capsys, ["sim", str(PAPER), f"--start-timeout={value}"], "--start-timeout", "(0, 3600]")


@pytest.mark.parametrize("value", ["-1", "600001"])
def test_the_plants_connect_timeout_is_bounded(capsys, value) -> None:
    argv = ["sim", str(PAPER), f"--connect-timeout-ms={value}"]
    refused(capsys, argv, "--connect-timeout-ms", "[0, 600000] ms")


@pytest.mark.parametrize("team", ["a/b", "x*", "$"])
def test_the_plants_team_name_is_checked_before_zenoh(capsys, team) -> None:
    refused(capsys, ["sim", str(PAPER), f"--team={team}"], "--team", "/ * $ ? #")


@pytest.mark.parametrize("value", ["nan", "inf", "-1", "10000.5"])
def test_the_added_delay_is_bounded(capsys, value) -> None:
    argv = ["run", str(PAPER), "--transport", "zenoh", f"--delay-ms={value}"]
    refused(capsys, argv, "--delay-ms", "[0, 10000]")


@pytest.mark.parametrize("value", ["nan", "-0.1", "1"])
def test_the_drop_probability_is_bounded(capsys, value) -> None:
    refused(capsys, ["run", str(PAPER), f"--drop={value}"], "--drop", "[0, 1)")


@pytest.mark.parametrize(
    "argv, key, text",
    [
        (["bench", "accuracy", "--repeat", "0"], "--repeat", "[1, 1000]"),
        (["bench", "accuracy", "-n", "1001"], "--repeat", "[1, 1000]"),
        (["bench", "generated", "--count", "0"], "--count", "[1, 1000]"),
        (["bench", "generated", "-n", "1001"], "--count", "[1, 1000]"),
        (["bench", "noise", "--generated", "0"], "--generated", "[1, 1000]"),
        (["bench", "sweep", "--generated", "1001"], "--generated", "[1, 1000]"),
        (["bench", "zenoh", "--sizes", "64"], "--sizes", "dividing 32"),
        (["bench", "zenoh", "--sizes", "2"], "--sizes", "n >= 3"),
        (["bench", "zenoh", "--sizes", "4,x"], "--sizes", "numbers like 4,8,16"),
        (["scenario", "generate", "-1"], "SEED", "[0, 2**63 - 1]"),
        (["scenario", "generate", str(MAX_SEED + 1)], "SEED", "[0, 2**63 - 1]"),
    ],
)
def test_numeric_options_are_range_checked(capsys, argv, key, text) -> None:
    refused(capsys, argv, key, text)


def test_the_largest_seed_generates_a_scenario(tmp_path, capsys) -> None:
    out = tmp_path / "big.toml"
    assert main(["scenario", "generate", str(MAX_SEED), "-o", str(out)]) == 0
    assert load_scenario(out).run.seed == MAX_SEED


@pytest.mark.parametrize("port", [0, 65536, 99999])
def test_a_port_outside_1_to_65535_is_refused(capsys, port) -> None:
    refused(capsys, ["router", "--listen", f"tcp/127.0.0.1:{port}"], "--listen", "65535")


# ------------------------------------------------------------------------------ every range
def just_inside(bound: Bound, low: float | None = None) -> list[float]:
    lo = bound.low if low is None else low
    first = math.nextafter(lo, math.inf) if bound.open_low and low is None else lo
    return [first, bound.high] + ([bound.off] if bound.off is not None else [])


def just_outside(bound: Bound, integer: bool, low: float | None = None) -> list[float]:
    if integer:
        return [int(bound.low) - 1, int(bound.high) + 1]
    if low is not None:  # a lower end counted in ticks
        below = low * (1 - 1e-6)
    else:
        below = bound.low if bound.open_low else math.nextafter(bound.low, -math.inf)
    return [below, math.nextafter(bound.high, math.inf)]


def _cases(table: str, cls: type, period_s: float = 0.01) -> list:
    """``(key, value, inside)`` at both ends of every declared range of ``cls`` (its table in
    the file: ``table``; ticks of ``period_s``)."""
    hints = typing.get_type_hints(cls)
    cases = []
    for name, bound in bounds(cls).items():
        key = f"{table}.{name}" if table else name
        low = bound.min_ticks * period_s if bound.min_ticks else None
        for value in just_inside(bound, low):
            cases.append(pytest.param(key, value, True, id=f"{key}={value}"))
        for value in just_outside(bound, hints[name] is int, low):
            cases.append(pytest.param(key, value, False, id=f"{key}={value}"))
    return cases


_BIG_POLYGON = [[5 * x, 5 * y] for x, y in paper()["body"]["polygon"]]
_BIG_CONTACTS = [[5 * x, 5 * y] for x, y in paper()["contacts"]["points"]]
_MAX_FORCE = {"agent.max_force": 1000.0}
COMPANIONS: dict[tuple[str, float], dict[str, Any]] = {
    # what else a value at one end of its range needs to make a valid scenario
    ("sensors.rate_hz", 10.0): {"run.physics_hz": 1000.0},
    ("run.physics_hz", 10.0): {"sensors.rate_hz": 10.0},
    ("run.physics_hz", 100000.0): {"sensors.rate_hz": 1000.0},
    ("body.mass", 0.01): {"body.moment": 0.05},
    ("body.mass", 10000.0): {"body.moment": 50000.0},
    ("body.moment", 0.0001): {"body.mass": 0.01},
    ("body.moment", 1e6): {
        "body.mass": 10000.0,
        "body.polygon": _BIG_POLYGON,
        "contacts.points": _BIG_CONTACTS,
        "body.com": [0.0, -0.695],
    },
    ("agent.kick_force", 1000.0): _MAX_FORCE,
    ("agent.inertia_force", 1000.0): _MAX_FORCE,
    ("agent.paper.push_min_force", 1000.0): _MAX_FORCE,
    ("agent.robust.push_force", 1000.0): _MAX_FORCE,
}


def _companions(key: str, value: float) -> dict[str, Any]:
    if key == "agent.max_force" and value < 3.0:  # the other forces are at most max_force
        forces = ("kick_force", "inertia_force", "paper.push_min_force", "robust.push_force")
        return {f"agent.{k}": value for k in forces}
    return COMPANIONS.get((key, value), {})


SCENARIO_CASES = [
    *_cases("body", _BodyTable),
    *_cases("sensors", Sensors),
    *_cases("actuators", Actuators),
    *_cases("floor", Floor),
    *_cases("ground", _GroundTable),
    *_cases("run", RunSettings),
    *_cases("agent", AgentTuning),
    *_cases("agent.paper", PaperTuning),
    *_cases("agent.robust", RobustTuning),
]


@pytest.mark.parametrize("key, value, inside", SCENARIO_CASES)
def test_every_scenario_range_at_both_ends(tmp_path, capsys, key, value, inside) -> None:
    values = {**_companions(key, value), key: value} if inside else {key: value}
    path = scenario_file(tmp_path, values)
    if inside:
        load_scenario(path)
    else:
        line = refused(capsys, ["run", str(path), "-q"], key)
        assert RANGE.search(line), line


ROBOT_CASES = [
    *_cases("", AgentNodeConfig),
    *_cases("zenoh", ZenohSettings),
    *_cases("tuning", AgentTuning),
    *_cases("tuning.paper", PaperTuning),
    *_cases("tuning.robust", RobustTuning),
]


@pytest.mark.parametrize("key, value, inside", ROBOT_CASES)
def test_every_robot_toml_range_at_both_ends(tmp_path, capsys, key, value, inside) -> None:
    values = {key: value}
    if inside and key.startswith("tuning."):  # the same companions as in a scenario's [agent]
        agent = _companions("agent." + key.removeprefix("tuning."), value)
        values = {k.replace("agent.", "tuning."): v for k, v in agent.items()} | values
    path = robot_file(tmp_path, values)
    if inside:
        load_agent_config(path)
    else:
        line = refused(capsys, ["agent", "--config", str(path)], f"agent.{key}")
        assert RANGE.search(line), line


@pytest.mark.parametrize(
    "period_s, window, inside",
    [(0.001, 0.001, True), (0.001, 0.000999, False), (0.1, 0.1, True), (0.1, 0.0999, False)],
)
def test_a_window_is_at_least_one_tick_of_the_robots_period(
    tmp_path, capsys, period_s, window, inside
) -> None:
    path = robot_file(tmp_path, {"period_s": period_s, "tuning.settle_window_s": window})
    if inside:
        load_agent_config(path)
    else:
        refused(capsys, ["agent", "--config", str(path)], "settle_window_s", "1 tick", "period_s")


@pytest.mark.parametrize(
    "values, inside",
    [
        ({"faults.delay_s": 10.0}, True),
        ({"faults.delay_s": 10.000001}, False),
        ({"faults.drop": 0.999}, True),
        ({"faults.drop": 1.0}, False),
        ({"n": MAX_ROBOTS, "robot": MAX_ROBOTS, "neighbours": [1]}, True),
        ({"n": MAX_ROBOTS + 1}, False),
        ({"n": 1}, False),
        ({"zenoh.connect": ["tcp/127.0.0.1:1", "tcp/127.0.0.1:65535"]}, True),
        ({"zenoh.connect": ["tcp/127.0.0.1:65536"]}, False),
        ({"zenoh.listen": ["tcp/127.0.0.1:0"]}, False),
    ],
)
def test_the_other_robot_toml_limits(tmp_path, capsys, values, inside) -> None:
    path = robot_file(tmp_path, values)
    if inside:
        load_agent_config(path)
    else:
        key = next(iter(values)).split(".")[0]
        refused(capsys, ["agent", "--config", str(path)], f"agent.{key}")


def test_the_push_direction_has_a_bounded_length(tmp_path, capsys) -> None:
    for direction, inside in (([0.001, 0.0], True), ([0.0, 1000.0], True), ([0.0, 0.0], False)):
        path = scenario_file(tmp_path, {"agent.push_direction": direction})
        if inside:
            load_scenario(path)
        else:
            refused(capsys, ["run", str(path)], "agent.push_direction", "[0.001, 1000]")
    path = scenario_file(tmp_path, {"agent.push_direction": [1000.0, 1.0]})
    refused(capsys, ["run", str(path)], "agent.push_direction")


def test_the_forces_are_at_most_max_force(tmp_path, capsys) -> None:
    path = scenario_file(tmp_path, {"agent.max_force": 5.0, "agent.kick_force": 5.5})
    refused(capsys, ["run", str(path)], "agent.kick_force", "at most max_force")


# ------------------------------------------------------------------------------ the body
def _square(half: float, **extra: Any) -> dict[str, Any]:
    """A square load of side ``2 half`` centred on the origin, robots at two opposite corners,
    moment and COM implied."""
    corners = [[-half, -half], [half, -half], [half, half], [-half, half]]
    return {
        "body.polygon": corners,
        "body.moment": None,
        "body.com": None,
        "contacts.points": [corners[0], corners[2]],
        "graph.edges": [[1, 2]],
        **extra,
    }


@pytest.mark.parametrize(
    "values, key, inside",
    [
        (_square(MAX_COORDINATE), "body.polygon", True),
        (_square(MAX_COORDINATE * (1 + 1e-9)), "body.polygon[0]", False),
        (_square(MIN_DIAMETER / 2 / math.sqrt(2)), "body.polygon", True),
        (_square(MIN_DIAMETER / 2 / math.sqrt(2) * 0.999), "body.polygon", False),
        ({"body.position": [MAX_POSITION, -MAX_POSITION]}, "body.position", True),
        ({"body.position": [0.0, MAX_POSITION + 0.001]}, "body.position", False),
        ({"body.com": [2.0, -1.0]}, "body.com", True),  # a corner of the bounding box
        ({"body.com": [2.001, 0.0]}, "body.com", False),
        ({"body.com": [0.0, 1e9]}, "body.com", False),
    ],
)
def test_the_loads_geometry_is_bounded(tmp_path, capsys, values, key, inside) -> None:
    path = scenario_file(tmp_path, values)
    if inside:
        load_scenario(path)
    else:
        refused(capsys, ["run", str(path)], key)


@pytest.mark.parametrize("count, inside", [(MAX_VERTICES, True), (MAX_VERTICES + 1, False)])
def test_the_polygon_has_at_most_a_thousand_vertices(tmp_path, capsys, count, inside) -> None:
    polygon = [
        [2 * math.cos(2 * math.pi * k / count), 2 * math.sin(2 * math.pi * k / count)]
        for k in range(count)
    ]
    values = {
        "body.polygon": polygon,
        "body.moment": None,
        "body.com": None,
        "contacts.points": [polygon[0], polygon[count // 2]],
        "graph.edges": [[1, 2]],
    }
    path = scenario_file(tmp_path, values)
    if inside:
        load_scenario(path)
    else:
        refused(capsys, ["run", str(path)], "body.polygon", f"3 to {MAX_VERTICES} vertices")


def test_the_moment_fits_the_load(tmp_path, capsys) -> None:
    """Its radius of gyration is 1 % to 100 % of the polygon's diameter."""
    data = paper()
    diameter = polygon_diameter([tuple(p) for p in data["body"]["polygon"]])
    mass = data["body"]["mass"]
    low, high = mass * (0.01 * diameter) ** 2, mass * diameter**2
    for moment, inside in ((low, True), (high, True), (low * 0.999, False), (high * 1.001, False)):
        path = scenario_file(tmp_path, {"body.moment": moment})
        if inside:
            load_scenario(path)
        else:
            refused(capsys, ["run", str(path)], "body.moment", "radius of gyration")


def test_a_team_of_thirty_two_is_accepted(tmp_path) -> None:
    polygon = paper()["body"]["polygon"]  # its bottom edge runs from (-2, -1) to (2, -1)
    contacts = [[-2.0 + 4.0 * k / (MAX_ROBOTS - 1), -1.0] for k in range(MAX_ROBOTS)]
    edges = [[i, i + 1] for i in range(1, MAX_ROBOTS)]
    values = {"contacts.points": contacts, "graph.edges": edges, "body.polygon": polygon}
    assert load_scenario(scenario_file(tmp_path, values)).n == MAX_ROBOTS


# ------------------------------------------------------------------------------ the docs
def _documented_limits() -> str:
    text = (ROOT / "docs" / "configuration.md").read_text(encoding="utf-8")
    start = text.index("\n## Limits\n")
    end = text.find("\n## ", start + 1)
    return text[start : end if end > 0 else None]


@pytest.mark.parametrize(
    "table, cls",
    [
        ("body", _BodyTable),
        ("sensors", Sensors),
        ("actuators", Actuators),
        ("floor", Floor),
        ("agvs", Agvs),
        ("agvs.admittance", AdmittanceSettings),
        ("ground", _GroundTable),
        ("run", RunSettings),
        ("events", LoadChange),
        ("agent", AgentTuning),
        ("agent.paper", PaperTuning),
        ("agent.robust", RobustTuning),
        ("robot.toml", AgentNodeConfig),
        ("zenoh", ZenohSettings),
        ("can", CanSettings),
        ("can.admittance", AdmittanceSettings),
    ],
)
def test_the_docs_list_every_range(table, cls) -> None:
    """Each declared range is written, as the messages write it, in a row of the Limits
    section that names its key (``key`` or ``table.key``); the agents' keys in the rows of
    their own table (``[agent]``, ``[agent.paper]``, ``[agent.robust]``)."""
    rows = _documented_limits().splitlines()
    if table.startswith("agent"):
        rows = _table_rows(rows, table)
    for key, bound in bounds(cls).items():
        named = re.compile(rf"`({re.escape(table)}\.)?{key}`")
        listed = [row for row in rows if named.search(row)]
        assert any(bound.text() in row for row in listed), (table, key, bound.text())


def test_the_docs_list_each_familys_keys_in_its_table_only() -> None:
    rows = _documented_limits().splitlines()
    for table, cls in (("agent.paper", PaperTuning), ("agent.robust", RobustTuning)):
        for key in bounds(cls):
            for other in ("agent", "agent.paper", "agent.robust"):
                named = [row for row in _table_rows(rows, other) if f"`{key}`" in row]
                assert bool(named) == (other == table), (key, other)


def _table_rows(rows: list[str], table: str) -> list[str]:
    """The body of the Limits table whose header names ``[table]`` first."""
    head = next(i for i, row in enumerate(rows) if row.startswith(f"| `[{table}]`"))
    end = next((i for i in range(head + 1, len(rows)) if not rows[i].startswith("|")), len(rows))
    return rows[head + 2 : end]
