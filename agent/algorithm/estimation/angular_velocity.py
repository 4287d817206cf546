"""Step 3: the load's angular velocity from one relative position, eq. (5).

With ``z_ij`` known, the rigid-body relation ``ż_ij = ω z_ij⊥`` gives (notes' correction of
eq. 5, which needs no separate sign)::

    ω = (z_ij⊥)ᵀ ż_ij / ‖z_ij‖²
"""

from __future__ import annotations

from agent.platform.geometry import Vec2


def angular_velocity(z_ij: Vec2, zdot_ij: Vec2) -> float:
    """``ω`` from a relative position ``z_ij`` and relative velocity ``ż_ij`` (eq. 5)."""
    return (z_ij[0] * zdot_ij[1] - z_ij[1] * zdot_ij[0]) / (z_ij[0] ** 2 + z_ij[1] ** 2)
