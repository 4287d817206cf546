"""The load's rotation, agreed by the team: every robot's arcs averaged by consensus.

Each robot follows the load's rotation ``θ`` from its own edges (Step 1's arcs). Between two
instants, once every fresh edge's ``ẑ_ij`` is known, its own turn is the rotation of its closed
neighbourhood fitted with the neighbourhood's translation (:func:`neighbourhood_turn`):

    δ_i = Σ_j (Q (y_j − ȳ))ᵀ Δs_ji / D_i,    y_j = −ẑ_ij, y_i = 0, D_i = Σ_k ‖y_k − ȳ‖²,

with ``Δs_ij`` each arc's step over the interval, written with each arc's own turn across it so
that the radii's errors do not scale it. Its variance is ``σ_e² Δt² / (4 D_i)``. Robot ``i``'s
own velocity is in every ``ż_ij``; the fit weighs its noise once, by ``Q ȳ``. Until then, each
edge ``ij`` measures the turn ``δ_ij`` on its own
(:attr:`~agent.algorithm.robust.arc_fit.ArcRelativePosition.last_turn`), with a noise whose
variance is ``σ_e² Δt² / (2 r_ij²)`` once its circle is known (the arc's step across its
radius) and ``2 σ_e² / ‖ż_ij‖²`` before (two directions of ``ż_ij``), and the own turn is their
information-weighted mean

    δ_i = Σ_j λ_ij δ_ij / Σ_j λ_ij,    λ_ij = 1 / Var(δ_ij).

Summed over a run, one robot's turns drift as a random walk, and with them the direction of
every ``z_ij`` it turns forward (the ``z_ij``'s error across the edge, the larger part of it)
and the angles Steps 4, 5 and 7 fit. All robots measure the same ``θ``, so their levels may be
averaged without any lag: consensus on the level, with the own turn as its input
(the input-tracking form of eq. 16, :mod:`agent.algorithm.estimation.consensus`),

    θ_i(e) = θ_i(e−1) + δ_i(e) + Σ_{j∈N_i} a_ij [θ_j(e_j) − θ_i(e_j)],

where ``θ_j(e_j)`` is neighbour ``j``'s level at the instant ``e_j`` its latest message refers
to, compared with this robot's own level then (so a late message is no error), each message
used once. ``a_ij`` are the Metropolis weights times ``min(1, w_j / w_i)``, with ``w_i`` the
information of robot ``i``'s turns in ``D`` units (``σ_e² Δt² / (4 Var(δ_i))``, ``D_i`` for the
fit; the team quantity ``rotation_weight``), and scaled down for a level older than ``e − 1``
(:func:`~agent.algorithm.estimation.consensus.delay_factor`: a consensus on delayed states is
unstable at full gain). Since
``a_ij w_i = a_ji w_j``, the consensus keeps ``Σ_i w_i θ_i`` and adds ``Σ_i w_i δ_i`` to it at
every instant: the team's level sums the information-weighted mean of the robots' turns. The
true rotation cancels in every difference, so the disagreement between robots decays as the
graph's consensus does. A plain mean would give a robot at the end of the load whose
neighbours all lie one way (a star's centre, a path's end) as much say as one amid its
neighbours. On the generated loads of seeds 0–39 (their geometry alone: ``tests/unit/agent/
test_rotation.py``, the last test), the plain mean of the robots' turns from their edges walks
a median 1.19 times (up to 2.6 times) as far as the least-squares rotation from every robot's
velocity at once, the weighted mean of the neighbourhood fits 1.06 times (at most 1.29). Levels
start from 0 at instant 0 on every robot, so they agree from the start: before a robot's
circles are known its turns come from the directions of ``ż_ij``, whose noise the weights
discount.

The team's turn is as uncertain as the mean of the robots' own turns: ``Var = Σ_i Var(δ_i) / n²``
if they were independent, twice that as they are not (each edge's turn is in both its ends'),
so ``2 ν / n`` with ``ν`` the robots' mean ``Var(δ_i)`` (:func:`turn_variance`): the direction
filters' process noise. ``ν`` is the team quantity ``mean_turn_variance``, averaged in flow form
(:mod:`agent.algorithm.estimation.team_consensus`) with the own variance
(:func:`own_variance`) as input. Without flows, an average with input tracking whose messages
come late keeps for good an error of the order of the inputs' change meanwhile, and the first
turns (from ``ż_ij``'s directions) are far less certain than the last: on ``paper-floor.toml``
with every message 3 ticks late, the team's turn variance stayed at 0.014 rad² (1e-9 rad² with
messages on time), the direction filters followed every sample's noise, and Step 1 never
settled. The weighted mean of independent turns,
``1 / Σ_i λ_i``, is never more uncertain than their plain mean (``1 / mean(λ) ≤ mean(1 / λ)``):
the process noise errs on the safe side.

Levels are sent modulo ``2π`` (the team quantity ``rotation``) and compared by the wrapped
difference: the robots' disagreement is a small angle. Without the flow form of
:mod:`agent.algorithm.estimation.team_consensus` a lost message shifts the team's mean level
by ``a_ij`` times a disagreement of the order of one turn's noise: a negligible turn, once.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable

from agent.algorithm.estimation.consensus import delay_factor, metropolis_weight
from agent.platform.geometry import Vec2

MAX_TURN_WEIGHT = 1e3
"""rad⁻²: the largest weight of a turn measured from ``ż_ij``'s direction (before the edge's
circle is known), whose variance the measured noise may underestimate at the start."""


MAX_OWN_VARIANCE = 1.0
"""rad²: a robot's own turn's variance is taken as at most this (a turn of a slow edge, known
no better than to a radian), which bounds the consensus states sent (``Share``)."""


MIN_NOISE = 1e-12
"""m²/s²: the floor of a relative velocity's noise variance that turns are weighed by (a
noise-free run measures none)."""


def turn_weight(*, radius: float | None, speed2: float, noise: float, dt: float) -> float:
    """``λ_ij = 1 / Var(δ_ij)`` of one edge's turn over ``dt``: ``2 r² / (σ_e² Δt²)`` from
    its arc once its radius ``r`` is known, else ``‖ż_ij‖² / (2 σ_e²)`` (at most
    :data:`MAX_TURN_WEIGHT`); ``noise`` is ``σ_e²`` (m²/s²), ``speed2`` is ``‖ż_ij‖²``."""
    noise = max(noise, MIN_NOISE)
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


def neighbourhood_turn(
    edges: Iterable[tuple[Vec2, Vec2, float, Vec2]],
) -> tuple[float, float] | None:
    """``(δ_i, D_i)``: the least-squares turn of robot ``i``'s closed neighbourhood over one
    interval, from each fresh edge's ``(ẑ_ij, Δs_ij, δ_ij, ζ_ij)``: ``Δs_ij = ∫ ż_ij dt`` over
    the interval, ``δ_ij`` the turn its arc measured and ``ζ_ij`` the vector ``z_ij`` on
    its arc (``s − c``, at the interval's end; any length); ``None`` without edges.

    With ``y_i = 0``, ``y_j = −ẑ_ij`` (the contacts about ``p_Ci``), ``ȳ`` their mean over
    the ``m + 1`` robots and ``D_i = Σ_k ‖y_k − ȳ‖²``, the rotation of a rigid neighbourhood
    fitted with its translation (``Σ_k (y_k − ȳ) = 0``) is

        δ_i = Σ_j (Q (y_j − ȳ))ᵀ Δs_ji / D_i,    Δs_ji = −Δs_ij.

    Robot ``i``'s own velocity, in every ``ż_ij``, weighs ``Q ȳ`` in it, not ``Σ_j Q y_j /
    r_j²`` as in a mean of its edges' turns (large for a robot at the end of its neighbours).
    Its variance is ``σ_e² Δt² / (4 D_i)`` (``σ_e²`` the relative velocity's per axis, ``Δs``
    the trapezoid of two samples); one edge's is ``D = r²/2``: the arc's step.

    Split across each arc and along it, ``Δs_ji = r_j δ_ij Q u_j + ρ_j u_j`` with ``u_j =
    −ζ_ij / ‖ζ_ij‖`` (``(Q y_j)ᵀ u_j = 0``):

        δ_i = Σ_j c_j δ_ij − Σ_j (Q ȳ)ᵀ u_j ρ_j / D_i,    c_j = (y_j − ȳ)ᵀ y_j / D_i,

    with ``Σ_j c_j = 1``. The turn across each edge is its arc's, which an error of ``r̂_j``
    does not scale: a mean of the ``δ_ij`` with weights that add up to 1 is the load's turn
    whatever errors the ``ẑ_ij`` have (only the noise's weights depend on them), where
    ``Δs`` over ``ẑ`` would turn the team by ``1 + ε`` times the load, ``ε`` the radii's
    relative error, steadily over the run. ``ρ_j`` is taken along the arc's own ``z_ij``,
    whose direction errs by its centre's error: one fixed in ``W``, so that a turn across it
    leaks into ``ρ_j`` one way and the other as the load turns, where the filtered ``ẑ_ij``'s
    error turns with the load and would leak one way. (``ρ_j`` is not zero for a turn: the
    chord from one sample to the next leaves the arc by ``r_j δ_ij² / 2``, which
    ``Σ_j (Q ȳ)ᵀ y_j = (m + 1) (Q ȳ)ᵀ ȳ = 0`` cancels.)"""
    count = 1  # robot i's own y_i = 0 is in every sum below
    sum_x = sum_y = square = weighted = turned_x = turned_y = radial_x = radial_y = 0.0
    for (zx, zy), (sx, sy), turn, (ax, ay) in edges:  # (ax, ay): ζ_ij
        count += 1
        sum_x -= zx  # y_j = −ẑ_ij
        sum_y -= zy
        r2 = zx * zx + zy * zy
        square += r2
        weighted += r2 * turn
        turned_x -= zx * turn
        turned_y -= zy * turn
        a2 = ax * ax + ay * ay
        if not a2 > 0.0:
            return None
        # u_j ρ_j = −ζ (ζᵀ Δs_ij) / ‖ζ‖² (u_j = −ζ / ‖ζ‖, ρ_j = u_jᵀ Δs_ji): summed negated
        along = (ax * sx + ay * sy) / a2
        radial_x += ax * along
        radial_y += ay * along
    if count == 1:
        return None
    mx, my = sum_x / count, sum_y / count  # ȳ
    spread = square - count * (mx * mx + my * my)  # D_i = Σ_k ‖y_k‖² − (m + 1) ‖ȳ‖²
    if not spread > 0.0:
        return None
    mean = weighted - (mx * turned_x + my * turned_y)  # Σ_j (y_j − ȳ)ᵀ y_j δ_ij
    radial = my * radial_x - mx * radial_y  # (Q ȳ)ᵀ Σ_j u_j ρ_j, Q ȳ = (−ȳ_y, ȳ_x)
    return (mean - radial) / spread, spread


def wrapped(angle: float) -> float:
    """``angle`` in ``(−π, π]``: how a level is sent."""
    return math.remainder(angle, math.tau)


def own_variance(variance: float) -> float:
    """A robot's own turn's variance as the input of ``ν`` (within ``[0, MAX_OWN_VARIANCE]``)."""
    return min(max(variance, 0.0), MAX_OWN_VARIANCE)


def turn_variance(mean_variance: float, n: int) -> float:
    """``2 ν / n`` (rad²): the team's turn's variance, from the team's state of ``ν``."""
    return 2.0 * max(mean_variance, 0.0) / n


class RotationConsensus:
    """One robot's steps of the level ``θ_i`` of the load's rotation (see the module
    docstring). The caller keeps the level and its recent history: :meth:`update` reads it and
    returns the step."""

    def __init__(self, degree: int):
        self.degree = degree
        self._used: dict[int, int] = {}
        """Each neighbour's instant whose level was used last."""
        self._weights: dict[int, float] = {}
        """``a_ij`` by the neighbour's degree (Metropolis: the two degrees alone)."""

    def update(
        self,
        instant: int,
        turn: float,
        heard: Iterable[tuple[int, int, int, float, float]],
        level_at: Callable[[int], float | None],
        weight: float = 0.0,
    ) -> float:
        """Instant ``instant``: ``turn`` is ``δ_i`` since the previous one and ``weight`` its
        ``w_i`` (0: none yet); ``heard`` holds each neighbour's ``(j, degree, instant, level,
        w_j)`` from its latest message; ``level_at(e)`` gives this robot's own level at instant
        ``e`` (``None`` if forgotten). Returns the team's turn, the step ``θ_i(e) − θ_i(e−1)``."""
        correction = 0.0
        used, weights = self._used, self._weights
        for j, degree, level_instant, level, their_weight in heard:
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
            if weight > 0.0 and their_weight > 0.0:
                a *= min(1.0, their_weight / weight)  # a_ij w_i = a_ji w_j
            correction += a * wrapped(level - mine)
        return turn + correction
