"""Step 2: each contact's offset from the contacts' centroid, ``z_i = p_Ci − p_G``, with the
average consensus (16) for Step 4's ``w = Σ_i ‖z_i‖²`` beside it.

Aragues et al. [10]: from ``x_i = 0`` iterate

    x_i ← x_i + Σ_{j∈N_i} a_ij (x_j − x_i + z_ij)

with symmetric weights ``a_ij`` (Metropolis, :mod:`agent.estimation.consensus`). Since
``z_ji = −z_ij`` the sum ``Σ x_i`` stays 0, and the fixed point is ``x_j − x_i + z_ij = 0`` on every
edge, i.e. ``x_i = z_i``. Eq. (16), sampled with the input ``r_i = ‖x_i‖²``, runs on the same
messages: ``ξ_i → Σ_i ‖z_i‖² / n = w / n``.

The ``z_ij`` turn with the load, so the iteration must run in a frame fixed to the load (notes,
Step 2). Here every vector stays in the world frame ``W`` at the robot's current instant: before
each update the robot turns its own previous iterate, and each neighbour's (stamped with the
instant it refers to), by the load's rotation since then. That is the load-frame iteration
written in ``W``, and it needs no agreement on a reference instant.

Both iterations run in flow form (:mod:`agent.estimation.flows`): ``x_i = −Σ_j F_ij`` and
``ξ_i = ‖x_i‖² − Σ_j F^s_ij``; an update moves each edge's term ``Δ_ij`` into the estimate
(``F_ij ← F_ij − Δ_ij``), and hearing from ``j`` sets ``F_ij = −F_ji``. The flows of an edge are
then antisymmetric whatever messages were lost, so ``Σ x_i = 0`` and ``Σ ξ_i = Σ r_i`` hold
again as soon as messages get through, and the iterates converge to the same point as without
loss. Without loss this is exactly the iteration above.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Protocol

from agent.estimation.consensus import consensus_term, metropolis_weight
from agent.estimation.flows import EdgeFlows
from agent.estimation.geometry import Vec2, rotate

if TYPE_CHECKING:
    from agent.protocol import Share


def centroid_term(a: float, x_i: Vec2, x_j: Vec2, z_ij: Vec2) -> Vec2:
    """Edge ``ij``'s term of the update, ``a_ij (x_j − x_i + z_ij)``."""
    return (a * (x_j[0] - x_i[0] + z_ij[0]), a * (x_j[1] - x_i[1] + z_ij[1]))


class LoadFrame(Protocol):
    """The load's motion as the robot knows it: what brings a vector of the load to the
    current instant (Steps 1 and 3)."""

    instant: int
    """The current instant (the one the update is for)."""

    def turned_since(self, instant: int) -> float:
        """The load's rotation (rad) from ``instant`` to the current instant."""
        ...

    def relative_position(self, j: int) -> Vec2 | None:
        """``z_ij`` in ``W`` at the current instant, ``None`` while unknown."""
        ...


class CentroidConsensus:
    """One robot's ``x_i`` (→ ``z_i``) and ``ξ_i`` (→ ``w / n``), in flow form."""

    def __init__(self, robot: int, neighbours: Sequence[int]):
        self.robot = robot
        self.neighbours = tuple(neighbours)
        self.degree = len(self.neighbours)
        self.flows = EdgeFlows(self.neighbours)
        self.centroid: Vec2 = (0.0, 0.0)
        """``x_i``, in ``W`` at the last update's instant."""
        self.spread = 0.0
        """``ξ_i``."""
        self._adopted: dict[int, int] = {}
        """The tick of the message of each neighbour ``j`` whose ``F_ji`` was adopted last."""

    def update(self, turn: float, shares: Mapping[int, Share], frame: LoadFrame, dt: float) -> None:
        """One iteration at ``frame.instant``, ``turn`` (rad) after the previous one, on the
        neighbours' latest messages ``shares`` (by sender; their ``centroid`` is ``x_j``,
        ``spread`` is ``ξ_j``, ``flows`` hold ``F_ji``). The iteration advances one step per
        update whatever ``dt``."""
        flows = self.flows
        flows.turn(turn)
        adopted = self._adopted
        for j, s in shares.items():
            if adopted.get(j) != s.tick:  # a message not heard before: F_ij = −F_ji
                adopted[j] = s.tick
                for k, fx, fy, fs in s.flows:
                    if k == self.robot:
                        vx, vy = rotate((fx, fy), frame.turned_since(s.instant))
                        flows.adopt(j, (vx, vy, fs))
        fx, fy, fs = flows.outflow()
        x = (-fx, -fy)
        xi = x[0] * x[0] + x[1] * x[1] - fs
        previous = frame.instant - 1
        for j in self.neighbours:
            s = shares.get(j)
            if s is None:
                continue
            a = metropolis_weight(self.degree, s.degree)
            dx = dy = 0.0
            if s.centroid is not None:
                # Usually one tick old: turned by this update's turn, already applied to the flows.
                if s.instant == previous:
                    x_j = flows.turned(s.centroid)
                else:
                    x_j = rotate(s.centroid, frame.turned_since(s.instant))
                dx, dy = centroid_term(a, x, x_j, frame.relative_position(j) or (0.0, 0.0))
            ds = consensus_term(a, xi, s.spread)
            flows.push(j, dx, dy, ds)
            fx -= dx
            fy -= dy
            fs -= ds
        self.centroid = (-fx, -fy)
        self.spread = fx * fx + fy * fy - fs

    @property
    def estimate(self) -> tuple[Vec2, float]:
        """``(x_i, ξ_i)``: ``z_i`` in ``W`` at the last update's instant, and ``w / n``."""
        return (self.centroid, self.spread)

    @property
    def covariance(self) -> None:
        """Not estimated yet."""
        return None

    def shared_flows(self) -> tuple[tuple[int, float, float, float], ...]:
        """``(j, F_x, F_y, F_s)`` per neighbour ``j``: the flows a message carries."""
        return tuple((j, *f) for j, f in self.flows.flows.items())
