"""Step 1's excitation: set the load turning one way, with |ω| bounded away from zero,
without knowing any geometry.

1. *Kick*: for a short time each robot pushes with a seeded random force: the load starts
   turning one way or the other.
2. *Spin-up*: each robot applies ``f_i = k Σ_{j∈N_i} c(‖ż_ij‖) ż_ij`` with
   ``c(s) = 1 − s / v*``. Both ends of an edge see the same ``‖ż_ij‖``, so the edge terms cancel
   in pairs: **zero net force** whatever the speeds. With ``ż_ij = ω z_ij⊥`` the torque about any
   point is ``k ω Σ_edges c(|ω| ‖z_ij‖) ‖z_ij‖²`` (notes, Step 1): positive feedback on the
   turn the load already has while the contacts are slow, braking once they are fast, so
   ``|ω|`` settles at ``v* Σ‖z_ij‖² / Σ‖z_ij‖³`` with no overshoot and no agreement needed
   on when to stop.

   Each edge's term may be bounded by a cap both of its ends compute alike
   (:func:`capped_spin_up_force`): with ``max_force / max(d_i, d_j)``, ``d`` the robots' degrees,
   no robot's sum exceeds ``max_force``, so none is cut by its saturation, which would break the
   cancellation (a generated load of 47 kg under 4 robots, each robot's sum cut at
   ``max_force``, met a net force of about 9 N and travelled 3.7 m in Step 1).
"""

from __future__ import annotations

import math
import random
from collections.abc import Iterable

from agent.platform.geometry import Vec2


def kick_force(seed: int, robot: int, magnitude: float, attempt: int = 0) -> Vec2:
    """The seeded random push of ``robot``: a fixed direction, the given magnitude; another
    direction for each later ``attempt`` (a load the first did not move)."""
    stream = seed * 1_000_003 + robot if attempt == 0 else f"{seed}/{robot}/{attempt}"
    angle = random.Random(stream).uniform(-math.pi, math.pi)
    return (magnitude * math.cos(angle), magnitude * math.sin(angle))


def spin_up_force(gain: float, target_speed: float, relative_velocities: Iterable[Vec2]) -> Vec2:
    """``f_i = k Σ_j (1 − ‖ż_ij‖ / v*) ż_ij``."""
    fx = fy = 0.0
    for vx, vy in relative_velocities:
        c = gain * (1.0 - math.hypot(vx, vy) / target_speed)
        fx += c * vx
        fy += c * vy
    return (fx, fy)


def capped_spin_up_force(
    gain: float, target_speed: float, edges: Iterable[tuple[Vec2, float]], drive: float = 1.0
) -> Vec2:
    """:func:`spin_up_force` with each edge's term ``k c(‖ż_ij‖) ż_ij`` bounded in length by
    its cap: ``edges`` gives ``(ż_ij, cap_ij)`` per neighbour; the terms that speed the turn up
    (``c > 0``) are scaled by ``drive`` ∈ [0, 1]. With the same gain, cap and ``drive`` at
    both ends of an edge the terms still cancel in pairs."""
    fx = fy = 0.0
    for (vx, vy), cap in edges:
        speed = math.hypot(vx, vy)
        c = gain * (1.0 - speed / target_speed)
        if c > 0.0:
            c *= drive
        size = abs(c) * speed
        if size > cap:
            c *= cap / size
        fx += c * vx
        fy += c * vy
    return (fx, fy)
