"""The load's rotation, agreed by the team: every robot's arcs averaged by consensus.

Each robot follows the load's rotation ``θ`` from its own edges (Step 1's arcs): between two
instants each edge ``ij`` measures the turn ``δ_ij`` (:attr:`~agent.algorithm.robust.arc_fit.
ArcRelativePosition.last_turn`), with a noise whose variance is ``σ_e² Δt² / (2 r_ij²)`` once
its circle is known (the arc's step across its radius) and ``2 σ_e² / ‖ż_ij‖²`` before (two
directions of ``ż_ij``). The robot's own turn is their information-weighted mean

    δ_i = Σ_j λ_ij δ_ij / Σ_j λ_ij,    λ_ij = 1 / Var(δ_ij).

Summed over a run, one robot's turns drift as a random walk, and with them the direction of
every ``z_ij`` it turns forward (the ``z_ij``'s error across the edge, the larger part of it)
and the angles Steps 4, 5 and 7 fit. All robots measure the same ``θ``, so their levels may be
averaged without any lag: consensus on the level, with the own turn as its input
(the input-tracking form of eq. 16, :mod:`agent.algorithm.estimation.consensus`),

    θ_i(e) = θ_i(e−1) + δ_i(e) + Σ_{j∈N_i} a_ij [θ_j(e_j) − θ_i(e_j)],

where ``θ_j(e_j)`` is neighbour ``j``'s level at the instant ``e_j`` its latest message refers
to, compared with this robot's own level then (so a late message is no error), each message
used once, and ``a_ij`` the Metropolis weights, scaled down for a level older than ``e − 1``
(:func:`delay_factor`: a consensus on delayed states is unstable at full gain). The true
rotation cancels in every difference: the disagreement between robots decays as the graph's
consensus does, while the team's mean level sums the mean of the robots' turns, whose random
walk has about ``1 / (n − 1)`` of one edge's variance (a spanning tree's ``n − 1`` edges
measure it independently). Levels start
from 0 at instant 0 on every robot, so they agree from the start: before a robot's circles are
known its turns come from the directions of ``ż_ij``, whose noise the weights discount.

The team's turn is as uncertain as the mean of the robots' own turns: ``Var = Σ_i Var(δ_i) / n²``
if they were independent, twice that as they are not (each edge's turn is in both its ends'),
so ``2 ν / n`` with ``ν`` the robots' mean ``Var(δ_i) = 1 / Σ_j λ_ij``, averaged by the same
consensus with the own variance as input: the direction filters' process noise
(:attr:`RotationConsensus.turn_variance`).

Levels are sent modulo ``2π`` (the team quantity ``rotation``) and compared by the wrapped
difference: the robots' disagreement is a small angle. Without the flow form of
:mod:`agent.algorithm.estimation.team_consensus` a lost message shifts the team's mean level
by ``a_ij`` times a disagreement of the order of one turn's noise: a negligible turn, once.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterable

from agent.algorithm.estimation.consensus import metropolis_weight

MAX_TURN_WEIGHT = 1e3
"""rad⁻²: the largest weight of a turn measured from ``ż_ij``'s direction (before the edge's
circle is known), whose variance the measured noise may underestimate at the start."""


MAX_OWN_VARIANCE = 1.0
"""rad²: a robot's own turn's variance is taken as at most this (a turn of a slow edge, known
no better than to a radian), which bounds the consensus states sent (``Share``)."""


def turn_weight(*, radius: float | None, speed2: float, noise: float, dt: float) -> float:
    """``λ_ij = 1 / Var(δ_ij)`` of one edge's turn over ``dt``: ``2 r² / (σ_e² Δt²)`` from
    its arc once its radius ``r`` is known, else ``‖ż_ij‖² / (2 σ_e²)`` (at most
    :data:`MAX_TURN_WEIGHT`); ``noise`` is ``σ_e²`` (m²/s²), ``speed2`` is ``‖ż_ij‖²``."""
    noise = max(noise, 1e-12)
    if radius is not None:
        return 2.0 * radius * radius / (noise * dt * dt)
    return min(0.5 * speed2 / noise, MAX_TURN_WEIGHT)


def own_turn(turns: Iterable[tuple[float, float]]) -> tuple[float, float] | None:
    """``(δ_i, Var(δ_i))``: the weighted mean of ``(δ_ij, λ_ij)`` pairs and its variance
    ``1 / Σ_j λ_ij``; ``None`` if there are none."""
    total = weight = 0.0
    for turn, w in turns:
        total += w * turn
        weight += w
    return (total / weight, 1.0 / weight) if weight > 0.0 else None


@functools.cache
def delay_factor(delay: int) -> float:
    """``ρ_d = sin(π / (2 (2d + 1)))`` for a level ``d ≥ 0`` instants older than the
    previous instant. ``x ← x − c x(k−d)`` is stable for ``c < 2 ρ_d``, and a Metropolis
    graph's ``c`` (an eigenvalue of ``I − A``) is below 2: so the consensus stays stable
    however late the levels (``ρ_0 = 1``: on time, the plain weights)."""
    return math.sin(math.pi / (2.0 * (2.0 * max(delay, 0) + 1.0)))


def wrapped(angle: float) -> float:
    """``angle`` in ``(−π, π]``: how a level is sent."""
    return math.remainder(angle, math.tau)


class RotationConsensus:
    """One robot's steps of the level ``θ_i`` of the load's rotation, and the mean variance
    ``ν_i`` of the robots' turns (see the module docstring). The caller keeps the level and
    its recent history: :meth:`update` reads it and returns the step."""

    def __init__(self, degree: int, n: int):
        self.degree = degree
        self.n = n
        self.variance = 0.0
        """``ν_i`` (rad²): → the robots' mean ``Var(δ_i)``."""
        self._variance_input = 0.0
        """This robot's own ``Var(δ_i)``, the input of ``ν``'s consensus."""
        self._used: dict[int, int] = {}
        """Each neighbour's instant whose level was used last."""
        self._weights: dict[int, float] = {}
        """``a_ij`` by the neighbour's degree (Metropolis: the two degrees alone)."""

    @property
    def turn_variance(self) -> float:
        """``2 ν / n`` (rad²): the team's turn's variance."""
        return 2.0 * max(self.variance, 0.0) / self.n

    def update(
        self,
        instant: int,
        turn: float,
        variance: float | None,
        heard: Iterable[tuple[int, int, int, float, float]],
        level_at: Callable[[int], float | None],
    ) -> float:
        """Instant ``instant``: ``turn`` is ``δ_i`` since the previous one and ``variance``
        its variance (``None``: as before); ``heard`` holds each neighbour's ``(j, degree,
        instant, level, ν_j)`` from its latest message; ``level_at(e)`` gives this robot's
        own level at instant ``e`` (``None`` if forgotten). Returns the team's turn, the step
        ``θ_i(e) − θ_i(e−1)``."""
        correction = variance_change = 0.0
        used, weights = self._used, self._weights
        for j, degree, level_instant, level, their_variance in heard:
            if level_instant < 0 or used.get(j) == level_instant:
                continue
            mine = level_at(level_instant)
            if mine is None:
                continue
            used[j] = level_instant
            a = weights.get(degree)
            if a is None:
                a = weights[degree] = metropolis_weight(self.degree, degree)
            delay = instant - 1 - level_instant
            if delay > 0:  # (ρ_0 = 1: a level on time keeps the plain weight)
                a *= delay_factor(delay)
            correction += a * wrapped(level - mine)
            variance_change += a * (their_variance - self.variance)
        if variance is not None:
            variance = min(max(variance, 0.0), MAX_OWN_VARIANCE)
            variance_change += variance - self._variance_input
            self._variance_input = variance
        self.variance += variance_change
        return turn + correction
