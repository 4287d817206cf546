"""Step 4's force law: the torque that spins the load up without pushing it (Sec. V-A).

With ``Σ_i z_i = 0``, the forces ``f_i = k z_i⊥`` (eq. 14, scaled by a gain ``k`` common to the
team and signed to speed up the turn the load already has) add up to zero net force and a
torque ``k Σ_i ‖z_i‖² = k w`` about any point, so (eq. 15) ``ω̇ = (k w) / J``. Each family
estimates ``J`` from it its own way (:mod:`agent.algorithm.paper.inertia`,
:mod:`agent.algorithm.robust.inertia_fit`).
"""

from __future__ import annotations

from agent.platform.geometry import Vec2


def inertia_force(gain: float, centroid_offset: Vec2) -> Vec2:
    """``f_i = k z_i⊥`` (eq. 14)."""
    return (-gain * centroid_offset[1], gain * centroid_offset[0])
