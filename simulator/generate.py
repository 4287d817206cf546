"""Random scenarios, deterministic per seed, for property tests of generality.

``generate_scenario(seed)`` draws 3–8 robots, a communication graph (line, ring, star or
random: a random spanning tree plus a few extra edges), a convex or concave load 1–4 m
across with mass in [1, 50] kg, an explicit or implied moment of inertia and COM, contacts at
random places along the boundary (at least 0.2 m apart) and a random initial pose. The graph
kind cycles with the seed (``seed % 4``) and so does convexity (``seed // 4 % 2``), so any
eight consecutive seeds cover every combination. Each runs the paper's estimators, the
reference (:data:`~agent.algorithm.tuning.PAPER_REFERENCE`): ``heft bench generated`` runs the
default ones on the same loads.

Command line: ``heft scenario generate SEED [-o FILE]`` writes the scenario as TOML.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from agent.algorithm.tuning import PAPER_REFERENCE
from simulator.polygon import (
    distance_to_boundary,
    point_in_polygon,
    polygon_area_centroid_moment,
    polygon_diameter,
)
from simulator.scenario import Scenario, parse_scenario

GRAPH_KINDS = ("line", "ring", "star", "random")
CONVEX_SHAPES = ("hull", "rectangle", "ellipse")
CONCAVE_SHAPES = ("notch", "L", "star")
MIN_CONTACT_GAP = 0.2
"""m: generated contacts are at least this far apart."""
SIZE_RANGE = (1.0, 4.0)
"""m: range of the load's diameter."""
MASS_RANGE = (1.0, 50.0)
MOMENT_FACTOR_RANGE = (0.7, 1.4)
"""An explicit moment is the uniform-density one times a factor in this range."""

Rng = np.random.Generator
Array = np.ndarray


# --------------------------------------------------------------------------------------------
# Shapes: counter-clockwise vertex arrays of arbitrary scale, placed later
# --------------------------------------------------------------------------------------------


def _convex_hull(points: Array) -> Array:
    """Counter-clockwise convex hull (Andrew's monotone chain)."""
    pts = sorted(map(tuple, points))

    def half(seq: list[tuple[float, float]]) -> list[tuple[float, float]]:
        chain: list[tuple[float, float]] = []
        for p in seq:
            while (
                len(chain) >= 2
                and (
                    (chain[-1][0] - chain[-2][0]) * (p[1] - chain[-2][1])
                    - (chain[-1][1] - chain[-2][1]) * (p[0] - chain[-2][0])
                )
                <= 0
            ):
                chain.pop()
            chain.append(p)
        return chain

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _hull_shape(rng: Rng) -> Array:
    points = rng.normal(size=(int(rng.integers(6, 15)), 2)) * [1.0, rng.uniform(0.4, 1.0)]
    return _convex_hull(points)


def _rectangle_shape(rng: Rng) -> Array:
    a = rng.uniform(0.3, 1.0)
    return np.array([[-1.0, -a], [1.0, -a], [1.0, a], [-1.0, a]])


def _ellipse_shape(rng: Rng) -> Array:
    count = int(rng.integers(8, 17))
    angles = 2 * np.pi * (np.arange(count) + rng.uniform(-0.3, 0.3, count)) / count
    return np.column_stack([np.cos(angles), rng.uniform(0.4, 1.0) * np.sin(angles)])


def _notch_shape(rng: Rng) -> Array:
    """A 2 × 2b plate with a rectangular notch cut from its upper side."""
    b = rng.uniform(0.3, 0.8)
    width = rng.uniform(0.3, 1.4)
    centre = rng.uniform(-1.0, 1.0) * (0.9 - width / 2)
    depth = rng.uniform(0.2, 0.7) * 2 * b
    left, right, bottom = centre - width / 2, centre + width / 2, b - depth
    return np.array(
        [[-1, -b], [1, -b], [1, b], [right, b], [right, bottom], [left, bottom], [left, b], [-1, b]]
    )


def _l_shape(rng: Rng) -> Array:
    height = rng.uniform(0.6, 1.2)
    tx, ty = rng.uniform(0.3, 0.6), rng.uniform(0.3, 0.6) * height
    return np.array([[0, 0], [1, 0], [1, ty], [tx, ty], [tx, height], [0, height]])


def _star_shape(rng: Rng) -> Array:
    """A star-shaped polygon with alternating outer and inner radii."""
    tips = int(rng.integers(5, 9))
    count = 2 * tips
    angles = 2 * np.pi * (np.arange(count) + rng.uniform(-0.2, 0.2, count)) / count
    radii = np.where(np.arange(count) % 2 == 0, 1.0, rng.uniform(0.45, 0.75))
    return np.column_stack([radii * np.cos(angles), radii * np.sin(angles)])


_SHAPES: dict[str, Callable[[Rng], Array]] = {
    "hull": _hull_shape,
    "rectangle": _rectangle_shape,
    "ellipse": _ellipse_shape,
    "notch": _notch_shape,
    "L": _l_shape,
    "star": _star_shape,
}


def _as_points(array: Array, digits: int = 6) -> list[tuple[float, float]]:
    return [(round(float(x), digits), round(float(y), digits)) for x, y in array]


def _place(shape: Array, size: float, rng: Rng) -> list[tuple[float, float]]:
    """Scale to diameter ``size``, rotate at random and offset the load frame's origin."""
    scaled = shape * (size / polygon_diameter(_as_points(shape, 12)))
    turn = rng.uniform(-np.pi, np.pi)
    rotation = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    centred = scaled - scaled.mean(axis=0)
    return _as_points(centred @ rotation.T + rng.uniform(-0.1, 0.1, 2) * size)


# --------------------------------------------------------------------------------------------
# Contacts, graph, inertia
# --------------------------------------------------------------------------------------------


def _contacts(polygon: list[tuple[float, float]], n: int, rng: Rng) -> list[tuple[float, float]]:
    """``n`` boundary points drawn by arc length, pairwise at least MIN_CONTACT_GAP apart."""
    vertices = np.array(polygon)
    steps = np.roll(vertices, -1, axis=0) - vertices
    lengths = np.hypot(steps[:, 0], steps[:, 1])
    cumulative = np.concatenate([[0.0], np.cumsum(lengths)])
    perimeter = cumulative[-1]
    gap = 1.05 * MIN_CONTACT_GAP  # spacing along the boundary; straight lines may be shorter
    for _ in range(1000):
        arcs = np.sort(rng.uniform(0, perimeter - n * gap, n)) + gap * np.arange(n)
        arcs = (arcs + rng.uniform(0, perimeter)) % perimeter
        index = np.clip(np.searchsorted(cumulative, arcs, side="right") - 1, 0, len(polygon) - 1)
        t = (arcs - cumulative[index]) / lengths[index]
        points = _as_points(vertices[index] + t[:, None] * steps[index])
        if min(math.dist(p, q) for i, p in enumerate(points) for q in points[i + 1 :]) >= (
            MIN_CONTACT_GAP
        ):
            return [points[i] for i in rng.permutation(n)]
    raise RuntimeError("could not place the contacts")  # pragma: no cover


def _edges(kind: str, n: int, rng: Rng) -> list[list[int]]:
    """Edges of a connected graph of the given kind over robots 1..n, labels shuffled."""
    order = [int(r) + 1 for r in rng.permutation(n)]
    if kind == "line":
        pairs = list(zip(order, order[1:], strict=False))
    elif kind == "ring":
        pairs = list(zip(order, order[1:] + order[:1], strict=True))
    elif kind == "star":
        pairs = [(order[0], r) for r in order[1:]]
    elif kind == "random":
        pairs = _random_graph(order, rng)
    else:
        raise ValueError(f"unknown graph kind {kind!r}")
    return sorted([min(p), max(p)] for p in pairs)


def _random_graph(order: list[int], rng: Rng) -> list[tuple[int, int]]:
    """A random spanning tree over ``order`` plus at least one extra edge."""
    n = len(order)
    pairs: set[tuple[int, int]] = set()
    for k in range(1, n):
        parent = order[int(rng.integers(0, k))]
        pairs.add((min(parent, order[k]), max(parent, order[k])))
    extra = int(rng.integers(1, n // 2 + 1))
    target = min(len(pairs) + extra, n * (n - 1) // 2)
    while len(pairs) < target:
        a, b = (int(r) + 1 for r in rng.choice(n, size=2, replace=False))
        pairs.add((min(a, b), max(a, b)))
    return sorted(pairs)


def _com_inside(
    polygon: list[tuple[float, float]], centroid: tuple[float, float], size: float, rng: Rng
) -> tuple[float, float]:
    """The centroid plus a random offset, kept inside the polygon with a margin."""
    margin = 0.02 * size
    for _ in range(200):
        r, theta = rng.uniform(0, 0.15 * size), rng.uniform(-np.pi, np.pi)
        p = _as_points(np.array([centroid]) + r * np.array([np.cos(theta), np.sin(theta)]))[0]
        if point_in_polygon(p, polygon) and distance_to_boundary(p, polygon) >= margin:
            return p
    low, high = np.min(polygon, axis=0), np.max(polygon, axis=0)
    while True:  # the centroid of a concave shape can be outside it: any inside point will do
        p = _as_points(rng.uniform(low, high)[None, :])[0]
        if point_in_polygon(p, polygon) and distance_to_boundary(p, polygon) >= margin:
            return p


def _body(rng: Rng, concave: bool) -> tuple[dict[str, Any], str, float]:
    """The ``[body]`` table, the shape's name and its size."""
    shape = str(rng.choice(CONCAVE_SHAPES if concave else CONVEX_SHAPES))
    size = float(rng.uniform(*SIZE_RANGE))
    polygon = _place(_SHAPES[shape](rng), size, rng)
    mass = round(float(rng.uniform(*MASS_RANGE)), 3)
    _, centroid, uniform_moment = polygon_area_centroid_moment(polygon, mass)
    table: dict[str, Any] = {"polygon": polygon, "mass": mass}
    if rng.random() < 0.5:
        table["moment"] = float(f"{uniform_moment * rng.uniform(*MOMENT_FACTOR_RANGE):.6g}")
    if rng.random() < 0.5:
        table["com"] = _com_inside(polygon, centroid, size, rng)
    table["position"] = _as_points(rng.uniform(-2.0, 2.0, (1, 2)))[0]
    table["angle"] = round(float(rng.uniform(-np.pi, np.pi)), 6)
    return table, shape, size


def generate_scenario(seed: int) -> Scenario:
    """A random valid scenario, the same for the same ``seed`` (``numpy.random.default_rng``).

    The graph kind is ``GRAPH_KINDS[seed % 4]``; the load is concave when ``seed // 4`` is odd.
    The scenario is built through :func:`parse_scenario`, so it passes the same validation as
    a file.
    """
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    rng = np.random.default_rng(seed)
    kind = GRAPH_KINDS[seed % len(GRAPH_KINDS)]
    concave = (seed // len(GRAPH_KINDS)) % 2 == 1
    n = int(rng.integers(3, 9))
    body, shape, _ = _body(rng, concave)
    data = {
        "name": f"generated-{seed}",
        "description": (
            f"Generated by simulator.generate (seed {seed}): {kind} graph, "
            f"{'concave' if concave else 'convex'} {shape} load."
        ),
        "body": body,
        "contacts": {"points": _contacts(body["polygon"], n, rng)},
        "graph": {"edges": _edges(kind, n, rng)},
        "run": {"seed": seed},
        "agent": dict(PAPER_REFERENCE),
    }
    return parse_scenario(data, source=f"generated-{seed}")


def ring_scenario(n: int, *, name: str | None = None) -> Scenario:
    """``n`` robots evenly spaced around a round 3 m load, talking in a ring (for benchmarks
    that grow the team): a 32-sided polygon of 10 kg, moment implied, COM off-centre; the
    paper's estimators, as :func:`generate_scenario`'s."""
    if not 3 <= n <= 32 or 32 % n:
        raise ValueError(f"ring_scenario needs n dividing 32 with n >= 3, got {n}")
    sides = 32
    polygon = [
        (
            round(1.5 * math.cos(2 * math.pi * k / sides), 9),
            round(1.5 * math.sin(2 * math.pi * k / sides), 9),
        )
        for k in range(sides)
    ]
    data = {
        "name": name or f"ring-{n}",
        "description": f"{n} robots around a round load, ring graph",
        "body": {"polygon": polygon, "mass": 10.0, "com": [0.2, -0.1]},
        "contacts": {"points": [polygon[k * sides // n] for k in range(n)]},
        "graph": {"edges": [[i, i % n + 1] for i in range(1, n + 1)]},
        "agent": dict(PAPER_REFERENCE),
    }
    return parse_scenario(data, data["name"])
