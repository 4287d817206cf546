"""What the team's messages do not say but a display wants: the load's outline and the graph.

The protocol carries the truth of the contacts and the COM, never the load's polygon; the page
draws the outline when it knows the scenario (``heft dashboard --scenario FILE``, or from a
recording made with one). :class:`LoadGeometry` is that knowledge, in a form that a recording
stores as MCAP metadata (strings) and reads back with every value checked.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

from agent.platform.config import MAX_ROBOTS
from agent.platform.geometry import Vec2

METADATA_NAME = "heft.load"
"""The MCAP metadata record holding a recording's :class:`LoadGeometry`."""
MAX_VERTICES = 1000
MAX_COORDINATE = 1000.0
MAX_END_TICK = 10**9


class GeometryError(ValueError):
    """A load geometry that is not one (from a recording's metadata)."""


@dataclass(frozen=True)
class LoadGeometry:
    """The load's polygon about its COM (load frame, metres) and the communication graph."""

    name: str
    n: int
    outline: tuple[Vec2, ...]
    """Polygon vertices minus the COM, in the load frame: at truth pose ``(p_C, θ)`` vertex
    ``v`` is at ``p_C + R(θ) v`` in ``W``."""
    edges: tuple[tuple[int, int], ...]
    """Undirected edges ``(i, j)``, ``i < j``."""
    period_s: float
    """The sensor period: tick ``k`` is at ``k · period_s``."""
    end_tick: int = 0
    """The first tick at which the run may end (the scenario's load changes and hold:
    :attr:`simulator.scenario.Scenario.end_tick`); the final instant is not before it."""

    @classmethod
    def from_scenario(cls, scenario) -> LoadGeometry:
        """The geometry of a :class:`simulator.scenario.Scenario`."""
        cx, cy = scenario.body.com
        return cls(
            name=scenario.name,
            n=scenario.n,
            outline=tuple((x - cx, y - cy) for x, y in scenario.body.polygon),
            edges=tuple(sorted((min(e), max(e)) for e in scenario.edges)),
            period_s=scenario.period_s,
            end_tick=scenario.end_tick,
        )

    def world_outline(self, com: Vec2, angle: float) -> list[Vec2]:
        """The polygon in ``W`` with the COM at ``com`` and the load frame at ``angle``."""
        c, s = math.cos(angle), math.sin(angle)
        return [(com[0] + c * x - s * y, com[1] + s * x + c * y) for x, y in self.outline]

    def to_metadata(self) -> dict[str, str]:
        return {
            "name": self.name,
            "n": str(self.n),
            "outline": json.dumps(self.outline),
            "edges": json.dumps(self.edges),
            "period_s": repr(self.period_s),
            "end_tick": str(self.end_tick),
        }

    @classmethod
    def from_metadata(cls, data: dict[str, str]) -> LoadGeometry:
        """The geometry a recording stored; :class:`GeometryError` unless every value is
        within its range."""
        try:
            n = int(data["n"])
            outline = tuple((float(x), float(y)) for x, y in json.loads(data["outline"]))
            edges = tuple((int(i), int(j)) for i, j in json.loads(data["edges"]))
            period_s = float(data["period_s"])
            name = str(data["name"])[:200]
            end_tick = int(data.get("end_tick", "0"))  # (not in older recordings)
        except (KeyError, TypeError, ValueError) as err:
            raise GeometryError(f"{METADATA_NAME}: malformed ({err})") from None
        if not 2 <= n <= MAX_ROBOTS:
            raise GeometryError(f"{METADATA_NAME}: n = {n} is outside [2, {MAX_ROBOTS}]")
        if not 3 <= len(outline) <= MAX_VERTICES or not all(
            math.isfinite(v) and abs(v) <= MAX_COORDINATE for p in outline for v in p
        ):
            raise GeometryError(f"{METADATA_NAME}: outline is not a polygon within range")
        if not all(1 <= i < j <= n for i, j in edges) or len(edges) > n * (n - 1) // 2:
            raise GeometryError(f"{METADATA_NAME}: edges are not those of robots 1..{n}")
        if not (math.isfinite(period_s) and 0.0001 <= period_s <= 1.0):
            raise GeometryError(f"{METADATA_NAME}: period_s = {period_s} is outside range")
        if not 0 <= end_tick <= MAX_END_TICK:
            raise GeometryError(f"{METADATA_NAME}: end_tick = {end_tick} is outside range")
        return cls(name, n, outline, edges, period_s, end_tick)
