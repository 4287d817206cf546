"""Scenarios: the load, where the robots hold it, who talks to whom, the sensors, the run.

A scenario is a TOML file (``simulator/scenarios/paper.toml`` is the paper's Sec. VI case)::

    name = "paper"
    [body]
    polygon = [[x, y], ...]   # load frame, metres, counter-clockwise; may be concave
    mass = 5.0                # kg
    moment = 12.3795          # kg m² about the COM; omitted -> uniform density over the polygon
    com = [x, y]              # load frame; omitted -> the polygon's area centroid
    [contacts]
    points = [[x, y], ...]    # load frame; robot 1..n in this order, on or near the boundary
    [graph]
    edges = [[1, 2], [2, 3]]  # undirected, connected
    [sensors]
    rate_hz = 100
    [run]
    seed = 1

:func:`load_scenario` reads a file and :func:`parse_scenario` a table already decoded; both
return a validated, frozen :class:`Scenario` or raise :class:`ScenarioError`, whose one-line
message names the offending key. :func:`scenario_to_toml` writes a scenario back.
Tables are turned into dataclasses by :func:`agent.config.from_table`.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tomllib
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agent.config import AgentTuning, ConfigError, from_table, non_negative, positive

Vec2 = tuple[float, float]

MIN_CONTACT_SPACING = 0.05
"""m: two contacts must be at least this far apart."""
BOUNDARY_TOLERANCE = 0.05
"""m: a contact may lie up to ``max(BOUNDARY_TOLERANCE, BOUNDARY_FRACTION · diameter)`` off
the load's boundary."""
BOUNDARY_FRACTION = 0.02
"""Fraction of the polygon's diameter allowed between a contact and the boundary."""


class ScenarioError(ConfigError):
    """A scenario is invalid or unreadable. ``str()`` is one line naming the key, prefixed by
    the source (the file path when loading a file), e.g.
    ``paper.toml: graph.edges: the graph is not connected (robot 4 unreachable)``."""

    def __init__(self, message: str) -> None:
        super().__init__(" ".join(str(message).splitlines()))


# --------------------------------------------------------------------------------------------
# The scenario
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Body:
    """The load: its shape, mass, moment of inertia, COM and initial pose."""

    polygon: tuple[Vec2, ...]
    """Vertices in the load frame (m), counter-clockwise, simple, possibly concave."""
    mass: float
    """kg."""
    moment: float
    """kg m², about the COM."""
    com: Vec2
    """Centre of mass in the load frame (m)."""
    position: Vec2 = (0.0, 0.0)
    """Initial position of the load frame's origin in the world frame ``W`` (m)."""
    angle: float = 0.0
    """Initial angle of the load frame in ``W`` (rad)."""
    moment_given: bool = True
    """False when the file omitted ``moment``: it is then the polygon's moment for uniform
    density about its area centroid (also when ``com`` is given elsewhere)."""
    com_given: bool = True
    """False when the file omitted ``com`` and it is the polygon's area centroid."""


@dataclass(frozen=True)
class Sensors:
    """What the robots sense: sample rate and white measurement noise."""

    rate_hz: float = 100.0
    """Sensor (and agent) tick rate."""
    velocity_noise_std: float = 0.0
    """m/s per axis, white, on each contact-point velocity."""
    force_noise_std: float = 0.0
    """N per axis, white, on each measured force."""

    def validate(self, where: str) -> None:
        """Raise :class:`ConfigError` unless the rate is positive and the noises are >= 0."""
        positive(where, rate_hz=self.rate_hz)
        non_negative(
            where,
            velocity_noise_std=self.velocity_noise_std,
            force_noise_std=self.force_noise_std,
        )


@dataclass(frozen=True)
class RunSettings:
    """How a run is simulated."""

    seed: int = 1
    """Seed of every random draw of the run (noise, the agents' kicks)."""
    physics_hz: float = 1000.0
    """Physics step rate; an integer multiple of ``sensors.rate_hz``."""
    max_time_s: float = 60.0
    """Simulated-time limit of a run (s)."""

    def validate(self, where: str) -> None:
        """Raise :class:`ConfigError` unless seed >= 0 and the rates and times are positive."""
        if self.seed < 0:
            raise ConfigError(f"{where}.seed: expected a non-negative integer, got {self.seed!r}")
        positive(where, physics_hz=self.physics_hz, max_time_s=self.max_time_s)


@dataclass(frozen=True)
class Scenario:
    """A validated scenario: robot ``i`` (1-based) holds the load at ``contacts[i - 1]``."""

    name: str
    body: Body
    contacts: tuple[Vec2, ...]
    """Contact points in the load frame, robot 1..n in this order."""
    edges: tuple[tuple[int, int], ...]
    """Undirected communication graph over robots 1..n, connected."""
    sensors: Sensors = Sensors()
    run: RunSettings = RunSettings()
    agent: AgentTuning = AgentTuning()
    description: str = ""

    @property
    def n(self) -> int:
        """Number of robots (one per contact)."""
        return len(self.contacts)

    @property
    def period_s(self) -> float:
        """Sensor period (s)."""
        return 1.0 / self.sensors.rate_hz

    @property
    def substeps(self) -> int:
        """Physics steps per sensor tick."""
        return round(self.run.physics_hz / self.sensors.rate_hz)

    def neighbours(self, robot: int) -> tuple[int, ...]:
        """The graph neighbours of ``robot`` (1-based), sorted."""
        if not 1 <= robot <= self.n:
            raise ValueError(f"robot {robot} does not exist (robots are 1..{self.n})")
        found = {j for i, j in self.edges if i == robot} | {i for i, j in self.edges if j == robot}
        return tuple(sorted(found))


# --------------------------------------------------------------------------------------------
# Geometry
# --------------------------------------------------------------------------------------------


def polygon_area_centroid_moment(
    polygon: Sequence[Sequence[float]], mass: float
) -> tuple[float, Vec2, float]:
    """Area, area centroid and moment of inertia about the centroid of a uniform lamina.

    Shoelace formulas, valid for any simple polygon (convex or not). The area is signed:
    positive when the vertices are counter-clockwise. The moment is for total mass ``mass``
    spread uniformly over the polygon. Raises :class:`ValueError` for a zero-area polygon.
    """
    points = [(float(x), float(y)) for x, y in polygon]
    # Work relative to the vertex mean: same result, less cancellation far from the origin.
    ox = math.fsum(x for x, _ in points) / len(points)
    oy = math.fsum(y for _, y in points) / len(points)
    shifted = [(x - ox, y - oy) for x, y in points]
    twice_area = sum_x = sum_y = sum_r2 = 0.0
    for (x0, y0), (x1, y1) in zip(shifted, shifted[1:] + shifted[:1], strict=True):
        cross = x0 * y1 - x1 * y0
        twice_area += cross
        sum_x += (x0 + x1) * cross
        sum_y += (y0 + y1) * cross
        sum_r2 += cross * (x0 * x0 + x0 * x1 + x1 * x1 + y0 * y0 + y0 * y1 + y1 * y1)
    if twice_area == 0.0:
        raise ValueError("the polygon has zero area")
    area = twice_area / 2.0
    cx, cy = sum_x / (3.0 * twice_area), sum_y / (3.0 * twice_area)
    moment_about_mean = mass * sum_r2 / (12.0 * area)
    moment = moment_about_mean - mass * (cx * cx + cy * cy)
    return area, (cx + ox, cy + oy), moment


def polygon_signed_area(polygon: Sequence[Sequence[float]]) -> float:
    """Shoelace area of ``polygon``: positive when its vertices are counter-clockwise."""
    count = len(polygon)
    return 0.5 * math.fsum(
        polygon[i][0] * polygon[(i + 1) % count][1] - polygon[(i + 1) % count][0] * polygon[i][1]
        for i in range(count)
    )


def polygon_diameter(polygon: Sequence[Vec2]) -> float:
    """Largest distance between two vertices (the polygon's diameter)."""
    return max(
        (math.dist(p, q) for i, p in enumerate(polygon) for q in polygon[i + 1 :]), default=0.0
    )


def boundary_tolerance(polygon: Sequence[Vec2]) -> float:
    """How far (m) a contact may lie from the boundary of ``polygon``."""
    return max(BOUNDARY_TOLERANCE, BOUNDARY_FRACTION * polygon_diameter(polygon))


def _edges_of(polygon: Sequence[Vec2]) -> list[tuple[Vec2, Vec2]]:
    return [(polygon[i], polygon[(i + 1) % len(polygon)]) for i in range(len(polygon))]


def _segment_distance(p: Vec2, a: Vec2, b: Vec2) -> float:
    dx, dy = b[0] - a[0], b[1] - a[1]
    length2 = dx * dx + dy * dy
    t = 0.0 if length2 == 0 else ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / length2
    t = min(1.0, max(0.0, t))
    return math.hypot(p[0] - a[0] - t * dx, p[1] - a[1] - t * dy)


def distance_to_boundary(point: Vec2, polygon: Sequence[Vec2]) -> float:
    """Distance (m) from ``point`` to the nearest point of the polygon's boundary."""
    return min(_segment_distance(point, a, b) for a, b in _edges_of(polygon))


def point_in_polygon(point: Vec2, polygon: Sequence[Vec2]) -> bool:
    """Whether ``point`` lies inside the simple polygon (even-odd rule)."""
    x, y = point
    inside = False
    for (x0, y0), (x1, y1) in _edges_of(polygon):
        if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
            inside = not inside
    return inside


def _orient(a: Vec2, b: Vec2, c: Vec2) -> float:
    """Twice the signed area of triangle ``abc`` (> 0 when counter-clockwise)."""
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def _within_box(a: Vec2, b: Vec2, p: Vec2) -> bool:
    return min(a[0], b[0]) <= p[0] <= max(a[0], b[0]) and min(a[1], b[1]) <= p[1] <= max(a[1], b[1])


def segments_intersect(p1: Vec2, p2: Vec2, q1: Vec2, q2: Vec2) -> bool:
    """Whether closed segments ``p1p2`` and ``q1q2`` share a point (crossing or touching)."""
    d1, d2 = _orient(q1, q2, p1), _orient(q1, q2, p2)
    d3, d4 = _orient(p1, p2, q1), _orient(p1, p2, q2)
    if d1 * d2 < 0 and d3 * d4 < 0:
        return True
    return (
        (d1 == 0 and _within_box(q1, q2, p1))
        or (d2 == 0 and _within_box(q1, q2, p2))
        or (d3 == 0 and _within_box(p1, p2, q1))
        or (d4 == 0 and _within_box(p1, p2, q2))
    )


def _first_self_intersection(polygon: Sequence[Vec2]) -> tuple[int, int] | None:
    """Indices ``(i, j)`` of two edges (edge ``i`` runs from vertex ``i`` to ``i + 1``) that
    meet where they should not, or None for a simple polygon."""
    edges = _edges_of(polygon)
    count = len(edges)
    for i in range(count):
        a, v = edges[i]
        b = edges[(i + 1) % count][1]
        # Adjacent edges share vertex v; they overlap when they fold back along one line.
        if (
            _orient(a, v, b) == 0
            and (a[0] - v[0]) * (b[0] - v[0]) + (a[1] - v[1]) * (b[1] - v[1]) > 0
        ):
            return i, (i + 1) % count
        for j in range(i + 2, count):
            if i == 0 and j == count - 1:
                continue  # adjacent through vertex 0
            if segments_intersect(*edges[i], *edges[j]):
                return i, j
    return None


# --------------------------------------------------------------------------------------------
# Parsing and validation
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _BodyTable:
    """The ``[body]`` table as written. ``moment`` and ``com`` are optional: their defaults
    here are placeholders, whether they were given is read from the table's keys."""

    polygon: tuple[Vec2, ...]
    mass: float
    moment: float = 1.0
    com: Vec2 = (0.0, 0.0)
    position: Vec2 = (0.0, 0.0)
    angle: float = 0.0


@dataclass(frozen=True)
class _ContactsTable:
    points: tuple[Vec2, ...]


@dataclass(frozen=True)
class _GraphTable:
    edges: tuple[tuple[int, int], ...]


_TOP_LEVEL: dict[str, str | None] = {
    # key -> what is expected when it is required, None when it is optional
    "name": "a string",
    "description": None,
    "body": "a table",
    "contacts": "a table",
    "graph": "a table",
    "sensors": None,
    "run": None,
    "agent": None,
}


def _check_top_level(data: Any) -> None:
    if not isinstance(data, Mapping):
        raise ScenarioError(f"expected a table at the top level, got {type(data).__name__}")
    unknown = sorted(set(data) - set(_TOP_LEVEL))
    if unknown:
        raise ScenarioError(f"{unknown[0]}: unknown key (expected one of: {', '.join(_TOP_LEVEL)})")
    for key, expected in _TOP_LEVEL.items():
        if expected is not None and key not in data:
            raise ScenarioError(f"{key}: missing (expected {expected})")


def _check_text(data: Mapping[str, Any], key: str, nonempty: bool) -> str:
    value = data.get(key, "")
    if not isinstance(value, str):
        raise ScenarioError(f"{key}: expected a string, got {value!r}")
    if nonempty and not value.strip():
        raise ScenarioError(f"{key}: expected a non-empty string")
    return value


def _check_polygon(polygon: tuple[Vec2, ...], key: str) -> None:
    """Raise unless ``polygon`` is a simple, counter-clockwise polygon of nonzero area."""
    if len(polygon) < 3:
        raise ScenarioError(f"{key}: expected at least 3 vertices, got {len(polygon)}")
    for j, q in enumerate(polygon):
        for i in range(j):
            if polygon[i] == q:
                raise ScenarioError(f"{key}[{j}]: repeats vertex {key}[{i}] {list(q)}")
    area = polygon_signed_area(polygon)
    if abs(area) <= 1e-12 * polygon_diameter(polygon) ** 2:
        raise ScenarioError(f"{key}: the polygon has zero area")
    crossing = _first_self_intersection(polygon)
    if crossing is not None:
        i, j = crossing
        count = len(polygon)
        raise ScenarioError(
            f"{key}: the polygon is self-intersecting (edge {i}->{(i + 1) % count} meets "
            f"edge {j}->{(j + 1) % count}); expected a simple polygon"
        )
    if area < 0:
        raise ScenarioError(f"{key}: the vertices are clockwise; they must be counter-clockwise")


def _parse_body(table: Any) -> Body:
    raw = from_table(_BodyTable, table, "body")
    moment_given, com_given = "moment" in table, "com" in table
    _check_polygon(raw.polygon, "body.polygon")
    positive("body", mass=raw.mass, moment=raw.moment)
    _, centroid, uniform_moment = polygon_area_centroid_moment(raw.polygon, raw.mass)
    return Body(
        polygon=raw.polygon,
        mass=raw.mass,
        moment=raw.moment if moment_given else uniform_moment,
        com=raw.com if com_given else centroid,
        position=raw.position,
        angle=raw.angle,
        moment_given=moment_given,
        com_given=com_given,
    )


def _parse_contacts(table: Any, polygon: tuple[Vec2, ...]) -> tuple[Vec2, ...]:
    points = from_table(_ContactsTable, table, "contacts").points
    if len(points) < 2:
        raise ScenarioError(f"contacts.points: expected at least 2 contacts, got {len(points)}")
    tolerance = boundary_tolerance(polygon)
    for i, point in enumerate(points):
        distance = distance_to_boundary(point, polygon)
        if distance > tolerance:
            raise ScenarioError(
                f"contacts.points[{i}]: robot {i + 1}'s contact {list(point)} is "
                f"{distance:.3g} m from the load's boundary; expected at most {tolerance:.3g} m"
            )
    for j, q in enumerate(points):
        for i in range(j):
            distance = math.dist(points[i], q)
            if distance < MIN_CONTACT_SPACING:
                raise ScenarioError(
                    f"contacts.points[{j}]: {distance:.3g} m from contacts.points[{i}]; "
                    f"contacts must be at least {MIN_CONTACT_SPACING} m apart"
                )
    return points


def _parse_edges(table: Any, n: int) -> tuple[tuple[int, int], ...]:
    edges = from_table(_GraphTable, table, "graph").edges
    seen: dict[tuple[int, int], int] = {}
    for k, (i, j) in enumerate(edges):
        key = f"graph.edges[{k}]"
        for robot in (i, j):
            if not 1 <= robot <= n:
                raise ScenarioError(
                    f"{key}: robot {robot} does not exist (robots are 1..{n}, one per contact)"
                )
        if i == j:
            raise ScenarioError(f"{key}: self-loop on robot {i}")
        pair = (min(i, j), max(i, j))
        if pair in seen:
            raise ScenarioError(
                f"{key}: duplicate of graph.edges[{seen[pair]}] (edges are undirected)"
            )
        seen[pair] = k
    _check_connected(edges, n)
    return edges


def _check_connected(edges: tuple[tuple[int, int], ...], n: int) -> None:
    adjacency: dict[int, set[int]] = {robot: set() for robot in range(1, n + 1)}
    for i, j in edges:
        adjacency[i].add(j)
        adjacency[j].add(i)
    for robot, neighbours in adjacency.items():
        if not neighbours:
            raise ScenarioError(f"graph.edges: robot {robot} has no edge")
    reached = {1}
    queue = deque([1])
    while queue:
        for other in adjacency[queue.popleft()] - reached:
            reached.add(other)
            queue.append(other)
    if len(reached) < n:
        missing = min(set(adjacency) - reached)
        raise ScenarioError(
            f"graph.edges: the graph is not connected (robot {missing} unreachable)"
        )


def _check_rates(sensors: Sensors, run: RunSettings) -> None:
    ratio = run.physics_hz / sensors.rate_hz
    if round(ratio) < 1 or abs(ratio - round(ratio)) > 1e-9 * ratio:
        raise ScenarioError(
            f"run.physics_hz: expected a positive integer multiple of sensors.rate_hz "
            f"({sensors.rate_hz!r}), got {run.physics_hz!r}"
        )


def _parse(data: Any) -> Scenario:
    _check_top_level(data)
    name = _check_text(data, "name", nonempty=True)
    description = _check_text(data, "description", nonempty=False)
    body = _parse_body(data["body"])
    contacts = _parse_contacts(data["contacts"], body.polygon)
    edges = _parse_edges(data["graph"], len(contacts))
    sensors = from_table(Sensors, data.get("sensors", {}), "sensors")
    run = from_table(RunSettings, data.get("run", {}), "run")
    _check_rates(sensors, run)
    agent = from_table(AgentTuning, data.get("agent", {}), "agent")
    return Scenario(name, body, contacts, edges, sensors, run, agent, description)


def parse_scenario(data: Mapping[str, Any], source: str = "<scenario>") -> Scenario:
    """Validate a decoded TOML table and build the :class:`Scenario`.

    Raises :class:`ScenarioError` (``"<source>: <key>: <what was expected>"``).
    """
    try:
        return _parse(data)
    except ConfigError as err:
        raise ScenarioError(f"{source}: {err}") from err


def load_scenario(path: str | os.PathLike[str]) -> Scenario:
    """Read and validate a scenario file; errors are prefixed by the path as given."""
    source = os.fspath(path)
    try:
        raw = Path(path).read_bytes()
    except FileNotFoundError:
        raise ScenarioError(f"{source}: no such file") from None
    except OSError as err:
        raise ScenarioError(f"{source}: cannot read the file ({err.strerror or err})") from err
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as err:
        raise ScenarioError(f"{source}: not valid TOML (not UTF-8 text: {err.reason})") from err
    except tomllib.TOMLDecodeError as err:
        raise ScenarioError(f"{source}: not valid TOML: {err}") from err
    return parse_scenario(data, source)


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------

_ESCAPES = {
    '"': '\\"',
    "\\": "\\\\",
    "\b": "\\b",
    "\t": "\\t",
    "\n": "\\n",
    "\f": "\\f",
    "\r": "\\r",
}


def _toml_string(text: str) -> str:
    out = []
    for char in text:
        if char in _ESCAPES:
            out.append(_ESCAPES[char])
        elif ord(char) < 0x20 or ord(char) == 0x7F:
            out.append(f"\\u{ord(char):04x}")
        else:
            out.append(char)
    return '"' + "".join(out) + '"'


def _toml_value(value: Any) -> str:
    """One TOML value: booleans, integers, floats (``repr``, exact), strings, arrays."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {value!r} as TOML")


def _toml_points(key: str, points: Sequence[Vec2]) -> list[str]:
    return [f"{key} = ["] + [f"    {_toml_value(p)}," for p in points] + ["]"]


def _toml_fields(obj: Any, only_changed: bool = False) -> list[str]:
    default = type(obj)()
    return [
        f"{f.name} = {_toml_value(getattr(obj, f.name))}"
        for f in dataclasses.fields(obj)
        if not only_changed or getattr(obj, f.name) != getattr(default, f.name)
    ]


def _toml_body(body: Body) -> list[str]:
    lines = ["[body]", *_toml_points("polygon", body.polygon), f"mass = {body.mass!r}"]
    if body.moment_given:
        lines.append(f"moment = {body.moment!r}")
    else:
        lines.append(f"# moment omitted: uniform density over the polygon gives {body.moment!r}")
    if body.com_given:
        lines.append(f"com = {_toml_value(body.com)}")
    else:
        lines.append(f"# com omitted: the polygon's area centroid {_toml_value(body.com)}")
    lines += [f"position = {_toml_value(body.position)}", f"angle = {body.angle!r}"]
    return lines


def scenario_to_toml(s: Scenario) -> str:
    """TOML text that :func:`parse_scenario` reads back to a scenario equal to ``s``.

    ``moment`` and ``com`` are written when the scenario gave them; when they were implied
    (uniform density), they are written as comments so that reading the text back implies
    them again, to the same values. ``[agent]`` lists only the values that differ from the
    defaults.
    """
    lines = [f"name = {_toml_value(s.name)}"]
    if s.description:
        lines.append(f"description = {_toml_value(s.description)}")
    lines += ["", *_toml_body(s.body), "", "[contacts]", *_toml_points("points", s.contacts)]
    lines += ["", "[graph]", f"edges = {_toml_value(s.edges)}"]
    lines += ["", "[sensors]", *_toml_fields(s.sensors), "", "[run]", *_toml_fields(s.run)]
    agent = _toml_fields(s.agent, only_changed=True)
    if agent:
        lines += ["", "[agent]", *agent]
    return "\n".join(lines) + "\n"
