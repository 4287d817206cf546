"""Step 2: each contact's offset from the contacts' centroid, ``z_i = p_Ci − p_G``.

Aragues et al. [10]: from ``x_i = 0`` iterate

    x_i ← x_i + Σ_{j∈N_i} a_ij (x_j − x_i + z_ij)

with symmetric weights ``a_ij`` (Metropolis, :mod:`agent.estimation.consensus`). Since
``z_ji = −z_ij`` the sum ``Σ x_i`` stays 0, and the fixed point is ``x_j − x_i + z_ij = 0`` on every
edge, i.e. ``x_i = z_i``.

The ``z_ij`` turn with the load, so the iteration must run in a frame fixed to the load (notes,
Step 2). Here every vector stays in the world frame ``W`` at the agent's current instant: before
each update, the agent turns its own previous iterate and each neighbour's (stamped with the
instant it refers to) by the load's rotation since then. That is the load-frame iteration
written in ``W``, and it needs no agreement on a reference instant. The agent runs it in flow
form (:mod:`agent.estimation.flows`), which keeps ``Σ x_i = 0`` when messages are lost.
"""

from __future__ import annotations

from collections.abc import Iterable

from agent.estimation.geometry import Vec2


def centroid_term(a: float, x_i: Vec2, x_j: Vec2, z_ij: Vec2) -> Vec2:
    """Edge ``ij``'s term of the update, ``a_ij (x_j − x_i + z_ij)``."""
    return (a * (x_j[0] - x_i[0] + z_ij[0]), a * (x_j[1] - x_i[1] + z_ij[1]))


def centroid_step(x_i: Vec2, neighbours: Iterable[tuple[float, Vec2, Vec2]]) -> Vec2:
    """One update of ``x_i`` from ``(a_ij, x_j, z_ij)`` triples, all in the same frame."""
    x, y = x_i
    for a, x_j, z_ij in neighbours:
        dx, dy = centroid_term(a, x_i, x_j, z_ij)
        x += dx
        y += dy
    return (x, y)
