"""Force bounds: no commanded force leaves an agent larger than the configured maximum."""

from __future__ import annotations

import math

from agent.platform.protocol import Vec2


def saturate(force: Vec2, max_force: float) -> Vec2:
    """Scale ``force`` down to magnitude ``max_force`` if it is larger (direction kept); a
    non-finite force becomes zero."""
    mag = math.hypot(force[0], force[1])
    if not math.isfinite(mag):
        return (0.0, 0.0)
    if mag <= max_force:
        return force
    s = max_force / mag
    return (force[0] * s, force[1] * s)
