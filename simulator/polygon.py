"""Plane polygons in the load frame: area, centroid and moment of a uniform lamina, diameter,
distances and containment, simplicity, and cells of a grid clipped to a polygon.

Points are ``(x, y)`` tuples of floats; a polygon is a sequence of its vertices, counter-clockwise
when its signed area is positive.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from agent.platform.geometry import Vec2


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


def first_self_intersection(polygon: Sequence[Vec2]) -> tuple[int, int] | None:
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


def clipped_to_box(polygon: Sequence[Vec2], low: Vec2, high: Vec2) -> list[Vec2]:
    """The part of ``polygon`` inside the box ``[low, high]`` (Sutherland–Hodgman: the box is
    convex, the polygon may be concave). Where the part falls apart into pieces, they come
    joined by edges of zero area, so the shoelace sums of the result (its area, its centroid)
    are those of the whole part; empty when nothing is inside."""
    part = list(polygon)
    sides = ((0, low[0], True), (0, high[0], False), (1, low[1], True), (1, high[1], False))
    for axis, bound, keep_above in sides:  # each side's half-plane in turn
        if not part:
            break
        inside = [(p[axis] >= bound) == keep_above for p in part]
        clipped: list[Vec2] = []
        for k, p in enumerate(part):
            q, q_inside = part[k - 1], inside[k - 1]
            if inside[k] != q_inside:
                s = (bound - q[axis]) / (p[axis] - q[axis])
                cut = (q[0] + s * (p[0] - q[0]), q[1] + s * (p[1] - q[1]))
                clipped.append((bound, cut[1]) if axis == 0 else (cut[0], bound))
            if inside[k]:
                clipped.append(p)
        part = clipped
    return part


def area_cells(polygon: Sequence[Vec2], count: int) -> list[tuple[Vec2, float]]:
    """The polygon cut into about ``count`` cells of equal size or less: a grid over its
    bounding box of ``⌈w/h_c⌉ × ⌈h/h_c⌉`` cells, ``h_c = √(A/count)`` (so a concave or slanted
    polygon keeps its share), each clipped to the polygon. Each cell present as its part's
    centroid and area, row by row; their areas sum to the polygon's and their first moments
    to its centroid's (exactly but for rounding, since each part's are exact)."""
    xs, ys = [p[0] for p in polygon], [p[1] for p in polygon]
    area = polygon_signed_area(polygon)
    side = math.sqrt(area / count)
    x0, y0, width, height = min(xs), min(ys), max(xs) - min(xs), max(ys) - min(ys)
    columns, rows = max(1, math.ceil(width / side)), max(1, math.ceil(height / side))
    cells = []
    for j in range(rows):
        for i in range(columns):
            low = (x0 + width * i / columns, y0 + height * j / rows)
            high = (x0 + width * (i + 1) / columns, y0 + height * (j + 1) / rows)
            part = clipped_to_box(polygon, low, high)
            if len(part) < 3 or polygon_signed_area(part) <= 1e-12 * area:
                continue  # outside the polygon, or a sliver of no weight
            part_area, centroid, _ = polygon_area_centroid_moment(part, 1.0)
            cells.append((centroid, part_area))
    return cells
