"""Flow updating: consensus iterations that survive lost messages.

Both of the team's iterations — the centroid offsets (Aragues et al. [10]) and the average
consensus for ``w`` (eq. 16) — rest on a sum that must never change: ``Σ x_i = 0`` and
``Σ ξ_i = Σ r_i``. When a message is lost, the two ends of an edge apply different updates and
the sum drifts for good: every estimate is then off by the same constant.

Written as *flows* on the edges (Jesus, Baquero & Almeida, "Fault-tolerant aggregation by flow
updating", 2009), each robot keeps, for each neighbour ``j``, what has flowed from it to ``j``:
``F_ij``. Its estimate is its own input minus its outflows, ``x_i = r_i − Σ_j F_ij``, and an
update of the iteration is an update of the flows: ``F_ij ← F_ij − Δ_ij`` where ``Δ_ij`` is
edge ``ij``'s term of the iteration. Each robot sends its flows to its neighbours, and on
hearing from ``j`` takes ``F_ij = −F_ji``. The flows of an edge are then antisymmetric
whatever was lost, so the sum holds: the iteration converges to the same point as without loss.
Without loss the adopted flows equal one's own, and it is exactly the original iteration.

Flows are ``(x, y, s, g, hx, hy, q, ι, μ)``: a 2-vector for the centroid (in ``W`` at the
robot's current instant, turned with the load like the iterates), a scalar for ``w``, one for
the drives' mean gain ``ḡ``, a 2-vector (turned likewise) for the gain-weighted centroid
offsets' mean ``Σ g_i z_i / n``, a scalar for ``Σ g_i ‖z_i‖² / n``, and two for the team's
mass, the mean information ``ι`` of the robots' mass fits and their information-weighted mean
``μ`` (:mod:`agent.algorithm.estimation.centroid`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

Flow = tuple[float, float, float, float, float, float, float, float, float]
ZERO: Flow = (0.0,) * 9


class EdgeFlows:
    """One robot's outflows to each neighbour."""

    def __init__(self, neighbours: Iterable[int]):
        self.flows: dict[int, Flow] = dict.fromkeys(neighbours, ZERO)
        self._c, self._s = 1.0, 0.0

    def turn(self, angle: float) -> None:
        """Turn the vector parts with the load (they live in the co-rotating frame)."""
        self._c, self._s = c, s = math.cos(angle), math.sin(angle)
        if angle:
            for j, (x, y, f, g, hx, hy, q, i, mu) in self.flows.items():
                self.flows[j] = (
                    c * x - s * y,
                    s * x + c * y,
                    f,
                    g,
                    c * hx - s * hy,
                    s * hx + c * hy,
                    q,
                    i,
                    mu,
                )

    def turned(self, v: tuple[float, float]) -> tuple[float, float]:
        """``v`` turned by the angle of the last :meth:`turn`."""
        c, s = self._c, self._s
        return (c * v[0] - s * v[1], s * v[0] + c * v[1])

    def adopt(self, j: int, theirs: Flow) -> None:
        """``F_ij = −F_ji``, from ``j``'s latest message (its vector turned to our instant)."""
        self.flows[j] = tuple(-f for f in theirs)  # type: ignore[assignment]

    def push(self, j: int, delta: Flow) -> None:
        """``F_ij ← F_ij − Δ_ij``: move ``Δ_ij`` into this robot's estimate."""
        self.flows[j] = tuple(f - d for f, d in zip(self.flows[j], delta))  # type: ignore[assignment]

    def outflow(self) -> Flow:
        """``Σ_j F_ij``."""
        return tuple(map(sum, zip(ZERO, *self.flows.values())))  # type: ignore[return-value]
