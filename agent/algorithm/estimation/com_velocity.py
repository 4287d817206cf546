"""Step 6: the velocity of the centre of mass from one robot's own data, eq. (7)::

ṗ_C = ṗ_Ci − ω (p_Ci − p_C)⊥,      p_Ci − p_C = z_i + z_C   (eq. 6)
"""

from __future__ import annotations

from agent.platform.geometry import Vec2


def com_velocity(contact_velocity: Vec2, omega: float, contact_from_com: Vec2) -> Vec2:
    """``ṗ_C`` from ``ṗ_Ci``, ``ω`` and ``p_Ci − p_C`` (eq. 7)."""
    return (
        contact_velocity[0] + omega * contact_from_com[1],
        contact_velocity[1] - omega * contact_from_com[0],
    )
