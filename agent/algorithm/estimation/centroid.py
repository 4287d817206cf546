"""Step 2: each contact's offset from the contacts' centroid, ``z_i = p_Ci − p_G``, with the
average consensus (16) for Step 4's ``w = Σ_i ‖z_i‖²`` beside it, and the same for the drives'
gains (each robot's :class:`~agent.algorithm.estimation.drive_gain.DriveGain`): their mean ``ḡ``,
the weighted mean offset ``h = Σ g_i z_i / n`` (a vector of the load, turned with it like ``x_i``)
and ``q = Σ g_i ‖z_i‖² / n``. Steps 4, 5 and 7 assumed every robot applies its command; with
gains, the team's torque in Step 4 is ``±k n q`` (not ``±k w``), its force in Steps 5–7 is
``n ḡ f`` and the torque of that force about the COM is ``n (h + ḡ z_C) × f``.

The team's mass (Step 7) is a consensus on information rather than on point estimates: each
robot's own fit ``m_i`` with relative standard deviation ``ρ_i`` enters as the inputs
``ι_i = (ρ₀ / ρ_i)²`` (its information, in units of ``ρ₀ = 1 %``, at most
:data:`MAX_MASS_INFORMATION`) and ``ι_i m_i``; their averages give the information-weighted
mean ``m̂ = μ / ι = Σ ι_i m_i / Σ ι_i``. Its relative standard deviation is published as
``ρ₀ / √ι`` (``ι`` the mean information): that of a robot of average information, as if the
robots' errors were fully correlated. They are partly: the fits share the forces, the angle
and the gains, while each robot's own velocity noise averages out.

Aragues et al. [10]: from ``x_i = 0`` iterate

    x_i ← x_i + Σ_{j∈N_i} a_ij (x_j − x_i + z_ij)

with symmetric weights ``a_ij`` (Metropolis, :mod:`agent.algorithm.estimation.consensus`). Since
``z_ji = −z_ij`` the sum ``Σ x_i`` stays 0, and the fixed point is ``x_j − x_i + z_ij = 0`` on every
edge, i.e. ``x_i = z_i``. Eq. (16), sampled with the input ``r_i = ‖x_i‖²``, runs on the same
messages: ``ξ_i → Σ_i ‖z_i‖² / n = w / n``.

The ``z_ij`` turn with the load, so the iteration must run in a frame fixed to the load (notes,
Step 2). Here every vector stays in the world frame ``W`` at the robot's current instant: before
each update the robot turns its own previous iterate, and each neighbour's (stamped with the
instant it refers to), by the load's rotation since then. That is the load-frame iteration
written in ``W``, and it needs no agreement on a reference instant.

Both iterations run in flow form (:mod:`agent.algorithm.estimation.flows`): ``x_i = −Σ_j F_ij`` and
``ξ_i = ‖x_i‖² − Σ_j F^s_ij``; an update moves each edge's term ``Δ_ij`` into the estimate
(``F_ij ← F_ij − Δ_ij``), and hearing from ``j`` sets ``F_ij = −F_ji``. The flows of an edge are
then antisymmetric whatever messages were lost, so ``Σ x_i = 0`` and ``Σ ξ_i = Σ r_i`` hold
again as soon as messages get through, and the iterates converge to the same point as without
loss. Without loss this is exactly the iteration above.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Protocol

from agent.algorithm.estimation.consensus import consensus_term, metropolis_weight
from agent.algorithm.estimation.flows import EdgeFlows
from agent.platform.geometry import Vec2, rotate

if TYPE_CHECKING:
    from agent.platform.protocol import Share


MAX_MASS_INFORMATION = 1e4
"""A mass fit's information at most this many times that of a 1 % standard deviation (0.01 %):
more is not believed, and it bounds the consensus states and flows."""


def mass_input(mass: float | None, std: float | None) -> tuple[float, float]:
    """``(ι_i, ι_i m_i)`` for a robot's own mass fit ``mass`` with standard deviation ``std``
    (``(0, 0)``: no fit yet)."""
    if mass is None or std is None or mass <= 0.0:
        return (0.0, 0.0)
    information = MAX_MASS_INFORMATION if std <= 0.0 else (0.01 * mass / std) ** 2
    information = min(information, MAX_MASS_INFORMATION)
    return (information, information * mass)


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
        self.gain = 1.0
        """``γ_i`` → ``ḡ``, the drives' mean gain."""
        self.gain_centroid: Vec2 = (0.0, 0.0)
        """``η_i`` → ``Σ g_j z_j / n``, in ``W`` at the last update's instant."""
        self.gain_spread = 0.0
        """``κ_i`` → ``Σ g_j ‖z_j‖² / n``."""
        self.gain_input = 1.0
        """This robot's drive gain, the input of ``γ``'s consensus."""
        self.mass_information = 0.0
        """``ι_i`` → the robots' mean mass information."""
        self.mass_weighted = 0.0
        """``μ_i`` → the mean of ``ι_j m_j``."""
        self.mass_input: tuple[float, float] = (0.0, 0.0)
        """This robot's ``(ι_i, ι_i m_i)`` (:func:`mass_input`)."""
        self._adopted: dict[int, int] = {}
        """The tick of the message of each neighbour ``j`` whose ``F_ji`` was adopted last."""

    def update(self, turn: float, shares: Mapping[int, Share], frame: LoadFrame, dt: float) -> None:
        """One iteration at ``frame.instant``, ``turn`` (rad) after the previous one, on the
        neighbours' latest messages ``shares`` (by sender; their ``centroid`` is ``x_j``,
        ``spread`` is ``ξ_j``, ``gain``, ``gain_centroid`` and ``gain_spread`` the gain
        averages' states, ``mass_information`` and ``mass_weighted`` the mass's, ``flows``
        hold ``F_ji``). The iteration advances one step per update
        whatever ``dt``."""
        flows = self.flows
        flows.turn(turn)
        adopted = self._adopted
        for j, s in shares.items():
            if adopted.get(j) != s.tick:  # a message not heard before: F_ij = −F_ji
                adopted[j] = s.tick
                for k, fx, fy, fs, fg, fhx, fhy, fq, fi, fm in s.flows:
                    if k == self.robot:
                        since = frame.turned_since(s.instant)
                        vx, vy = rotate((fx, fy), since)
                        hx, hy = rotate((fhx, fhy), since)
                        flows.adopt(j, (vx, vy, fs, fg, hx, hy, fq, fi, fm))
        fx, fy, fs, fg, fhx, fhy, fq, fi, fm = flows.outflow()
        x = (-fx, -fy)
        g = self.gain_input
        norm2 = x[0] * x[0] + x[1] * x[1]
        xi = norm2 - fs
        gamma = g - fg
        eta = (g * x[0] - fhx, g * x[1] - fhy)
        kappa = g * norm2 - fq
        iota = self.mass_input[0] - fi
        mu = self.mass_input[1] - fm
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
                    eta_j = flows.turned(s.gain_centroid)
                else:
                    since = frame.turned_since(s.instant)
                    x_j = rotate(s.centroid, since)
                    eta_j = rotate(s.gain_centroid, since)
                dx, dy = centroid_term(a, x, x_j, frame.relative_position(j) or (0.0, 0.0))
            else:
                eta_j = eta
            delta = (
                dx,
                dy,
                consensus_term(a, xi, s.spread),
                consensus_term(a, gamma, s.gain),
                consensus_term(a, eta[0], eta_j[0]),
                consensus_term(a, eta[1], eta_j[1]),
                consensus_term(a, kappa, s.gain_spread),
                consensus_term(a, iota, s.mass_information),
                consensus_term(a, mu, s.mass_weighted),
            )
            flows.push(j, delta)
            fx, fy, fs, fg, fhx, fhy, fq, fi, fm = (
                f - d for f, d in zip((fx, fy, fs, fg, fhx, fhy, fq, fi, fm), delta)
            )
        self.centroid = (-fx, -fy)
        norm2 = fx * fx + fy * fy
        self.spread = norm2 - fs
        self.gain = g - fg
        self.gain_centroid = (-g * fx - fhx, -g * fy - fhy)
        self.gain_spread = g * norm2 - fq
        self.mass_information = self.mass_input[0] - fi
        self.mass_weighted = self.mass_input[1] - fm

    def team_mass(self, own: float) -> tuple[float, float] | None:
        """``(m̂, ρ)``: the team's mass ``μ / ι`` and its relative standard deviation
        ``ρ₀ / √ι``; ``None`` while ``ι`` is not positive or ``m̂`` is not within a factor of
        2 of this robot's ``own`` fit (the states of a consensus whose inputs have just
        appeared or gone, as at a restart, are not yet a weighted mean)."""
        iota, mu = self.mass_information, self.mass_weighted
        if iota <= 0.0 or own <= 0.0:
            return None
        mass = mu / iota
        if not 0.5 * own <= mass <= 2.0 * own:
            return None
        return (mass, 0.01 / math.sqrt(iota))

    @property
    def estimate(self) -> tuple[Vec2, float]:
        """``(x_i, ξ_i)``: ``z_i`` in ``W`` at the last update's instant, and ``w / n``."""
        return (self.centroid, self.spread)

    @property
    def covariance(self) -> None:
        """Not estimated yet."""
        return None

    def shared_flows(
        self,
    ) -> tuple[tuple[int, float, float, float, float, float, float, float, float, float], ...]:
        """``(j, F_x, F_y, F_s, F_g, F_hx, F_hy, F_q, F_ι, F_μ)`` per neighbour ``j``: the
        flows a message carries."""
        return tuple((j, *f) for j, f in self.flows.flows.items())
