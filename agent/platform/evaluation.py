"""Estimates judged against the truth: pure functions over protocol messages.

Whatever follows a run (the launcher's results, the dashboard, the benchmarks) judges the
robots' :class:`~agent.platform.protocol.Estimates` against the plant's
:class:`~agent.platform.protocol.Truth` of the same instant with these, so that every one of
them gives the same figures under the same names:

- :func:`final_instant`: the instant a run's estimates are evaluated at;
- :func:`robot_errors`: one robot's errors, :data:`ERROR_KEYS`, in SI units;
- :func:`team_errors`: the worst of each over the team;
- :func:`relative_position_split`: the team's ``z_ij`` errors split into the turn common to
  every edge, each edge's own turn and its length;
- :func:`scalar_interval`, :func:`planar_interval` and :func:`edges_interval`: a published
  uncertainty's 95 % interval and whether the truth lies inside it.

Conventions (those of :mod:`agent.platform.protocol`): ``contact_to_com`` of robot ``i`` is
``p_C − p_Ci``; ``relative_positions[j]`` is ``z_ij = p_Ci − p_Cj``; ``centroid_offset`` is
``z_i = p_Ci − p_G``; ``com_offset`` is ``z_C = p_G − p_C``, and ``com_observer`` observer
(24)'s ``ẑ_C``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

from agent.platform.geometry import Vec2, largest_std
from agent.platform.protocol import Cov2, Estimates, Phase, Truth

ERROR_KEYS = (
    "mass_rel",
    "moment_rel",
    "contact_to_com_m",
    "relative_positions_m",
    "centroid_offset_m",
    "com_offset_m",
    "com_observer_m",
    "omega_rad_s",
    "friction_torque_nm",
    "coulomb",
)
"""The errors of :func:`robot_errors`: ``mass_rel`` and ``moment_rel`` are relative
(``|m̂ − m| / m``, a fraction, not a percentage), the ``_m`` keys Euclidean distances in
metres, ``omega_rad_s`` is ``|ω̂ − ω|``, ``friction_torque_nm`` ``|τ̂_c − μ m g c|`` (N m, the
floor's friction torque on a spin: :attr:`~agent.platform.protocol.Truth.coulomb_torque`) and
``coulomb`` ``|μ̂ − μ|``. The first five are those the project's accuracy aims bound."""


class InPhase(Protocol):
    """A robot's phase and the tick it entered it, as its latest
    :class:`~agent.platform.protocol.Estimates` say (or, in one process, its agent)."""

    @property
    def phase(self) -> Phase: ...

    @property
    def phase_since(self) -> int: ...


def final_instant(latest: Sequence[InPhase | None], end_tick: int = 0) -> int | None:
    """The instant a run's estimates are evaluated at: the first at which every robot was
    done, ``t_f = max(end_tick, max_i phase_since_i)`` over each robot's latest estimates
    (``latest``: one entry per robot of the team), not before the scenario's ``end_tick`` (its
    load changes and hold); ``None`` while some robot is not done or has said nothing."""
    if not latest or any(est is None or est.phase != Phase.DONE for est in latest):
        return None
    return max(end_tick, *(est.phase_since for est in latest))  # type: ignore[union-attr]


def true_relative(truth: Truth, i: int, j: int) -> Vec2:
    """``z_ij = p_Ci − p_Cj`` from the plant's truth (robots are 1-based)."""
    (xi, yi), (xj, yj) = truth.contacts[i - 1], truth.contacts[j - 1]
    return (xi - xj, yi - yj)


def _known(value: float) -> float | None:
    """``value``, or None when it is not finite (an estimate that is not a number is none)."""
    return value if math.isfinite(value) else None


def _rel(estimate: float | None, truth: float) -> float | None:
    return None if estimate is None else _known(abs(estimate - truth) / abs(truth))


def _abs(estimate: float | None, truth: float) -> float | None:
    return None if estimate is None else _known(abs(estimate - truth))


def _dist(estimate: Sequence[float] | None, truth: Sequence[float]) -> float | None:
    return None if estimate is None else _known(math.dist(estimate, truth))


def _worst(values: Iterable[float | None]) -> float | None:
    """The largest of ``values``; None if any is None (the worst is then unknown) or none."""
    items = list(values)
    if not items or any(v is None for v in items):
        return None
    return max(items)  # type: ignore[type-var]


def robot_errors(
    est: Estimates | None, truth: Truth, neighbours: Iterable[int]
) -> dict[str, float | None]:
    """Robot ``est.robot``'s errors against ``truth`` (:data:`ERROR_KEYS`); None where it has
    no such estimate (all None for a robot that reported nothing).

    ``relative_positions_m`` is its worst ``‖ẑ_ij − z_ij‖`` over ``neighbours`` (robots of
    the truth), None if it lacks any of them."""
    if est is None:
        return dict.fromkeys(ERROR_KEYS)
    i = est.robot
    return {
        "mass_rel": _rel(est.mass, truth.mass),
        "moment_rel": _rel(est.moment, truth.moment),
        "contact_to_com_m": _dist(est.contact_to_com, truth.contact_to_com[i - 1]),
        "relative_positions_m": _worst(
            _dist(est.relative_positions.get(j), true_relative(truth, i, j)) for j in neighbours
        ),
        "centroid_offset_m": _dist(est.centroid_offset, truth.centroid_offsets[i - 1]),
        "com_offset_m": _dist(est.com_offset, truth.com_offset),
        "com_observer_m": _dist(est.com_observer, truth.com_offset),
        "omega_rad_s": None if est.omega is None else _known(abs(est.omega - truth.omega)),
        "friction_torque_nm": _abs(est.friction_torque, truth.coulomb_torque),
        "coulomb": _abs(est.coulomb, truth.ground_coulomb),
    }


def team_errors(
    estimates: Mapping[int, Estimates], truth: Truth, graph: Mapping[int, Iterable[int]]
) -> dict[str, float | None]:
    """The worst of each of :func:`robot_errors` over the team: the robots of ``graph`` (each
    robot's neighbours), with their ``estimates``; None where some robot has no such
    estimate (the worst is then unknown)."""
    rows = [robot_errors(estimates.get(i), truth, graph[i]) for i in graph]
    return {key: _worst(row[key] for row in rows) for key in ERROR_KEYS}


@dataclass(frozen=True)
class RelativePositionSplit:
    """The team's ``ẑ_ij`` errors split by what they are (:func:`relative_position_split`)."""

    common_turn: float
    """rad: the mean over every published edge of the angle from ``z_ij`` to ``ẑ_ij``: the
    turn that all of them share (a team's rotation misjudged), signed."""
    worst_length: float
    """m: the largest ``|‖ẑ_ij‖ − ‖z_ij‖|``."""
    worst_own: float
    """m: the largest ``‖ẑ_ij − z_ij‖`` once ``ẑ_ij`` is turned back by :attr:`common_turn`:
    what is left of each edge's error without the shared turn."""


def relative_position_split(
    estimates: Mapping[int, Estimates], truth: Truth, graph: Mapping[int, Iterable[int]]
) -> RelativePositionSplit | None:
    """Every robot's published ``ẑ_ij`` over its neighbours in ``graph``, against the truth:
    their angles' mean (each ``atan2`` of ``ẑ_ij`` less that of ``z_ij``, wrapped), the worst
    error of their lengths, and the worst error left with that mean turned out; ``None`` if
    some robot lacks an edge."""
    rows = []
    for i, neighbours in graph.items():
        est = estimates.get(i)
        for j in neighbours:
            found = None if est is None else est.relative_positions.get(j)
            if found is None or not all(map(math.isfinite, found)):
                return None
            rows.append((found, true_relative(truth, i, j)))
    if not rows:
        return None
    angles = [
        math.remainder(math.atan2(f[1], f[0]) - math.atan2(t[1], t[0]), math.tau) for f, t in rows
    ]
    common = math.fsum(angles) / len(angles)
    c, s = math.cos(-common), math.sin(-common)
    return RelativePositionSplit(
        common_turn=common,
        worst_length=max(abs(math.hypot(*f) - math.hypot(*t)) for f, t in rows),
        worst_own=max(math.dist((c * f[0] - s * f[1], s * f[0] + c * f[1]), t) for f, t in rows),
    )


# ------------------------------------------------------------------------------ intervals
SCALAR_95 = 1.959964
"""A normal scalar is within this many standard deviations 95 % of the time."""
PLANAR_95 = 5.991465
"""A planar normal vector's squared Mahalanobis distance is at most this 95 % of the time."""


def standard_deviation(value: float | None) -> float | None:
    """``value`` if it can be a standard deviation (a finite number ``≥ 0``), else None: an
    uncertainty that came over the network is used only then."""
    return value if value is not None and math.isfinite(value) and value >= 0.0 else None


def covariance(cov: Sequence[float] | None) -> Cov2 | None:
    """``cov`` ``(xx, xy, yy)`` if it can be a planar covariance (finite, positive
    semi-definite to rounding), else None."""
    if cov is None or len(cov) != 3 or not all(map(math.isfinite, cov)):
        return None
    xx, xy, yy = cov
    if xx < 0.0 or yy < 0.0 or xy * xy > xx * yy * (1.0 + 1e-9) + 1e-300:
        return None
    return (xx, xy, yy)


def distance2(error: Sequence[float], cov: Sequence[float]) -> float:
    """``eᵀ C⁻¹ e``: the squared Mahalanobis distance of a planar ``error`` under the
    covariance ``cov`` ``(xx, xy, yy)`` (0 for no error, infinite for an error outside a
    singular ``C``'s range)."""
    xx, xy, yy = cov
    ex, ey = error
    det = xx * yy - xy * xy
    if det <= 0.0:
        return 0.0 if ex == 0.0 and ey == 0.0 else math.inf
    return (yy * ex * ex - 2.0 * xy * ex * ey + xx * ey * ey) / det


Interval = tuple[float | None, bool | None]
"""A 95 % interval's half-width and whether the truth lies inside it (None: unknown)."""


def scalar_interval(estimate: float | None, std: float | None, truth: float | None) -> Interval:
    """``±1.96 σ`` about ``estimate``: its half-width and whether ``|estimate − truth|`` is
    within it (None without a ``truth``); ``(None, None)`` without an estimate or a
    standard deviation (:func:`standard_deviation`)."""
    std = standard_deviation(std)
    if estimate is None or std is None or not math.isfinite(half := SCALAR_95 * std):
        return None, None
    return half, None if truth is None else abs(estimate - truth) <= half


def planar_interval(estimate: Vec2 | None, cov: Sequence[float] | None, truth) -> Interval:
    """The 95 % ellipse ``eᵀ C⁻¹ e ≤ 5.99`` about ``estimate``: its half-width along its
    longest axis and whether ``truth`` is in it (None without a ``truth``); ``(None, None)``
    without an estimate or a covariance (:func:`covariance`)."""
    cov = covariance(cov)
    if estimate is None or cov is None:
        return None, None
    half = math.sqrt(PLANAR_95) * largest_std(*cov)
    if not math.isfinite(half):
        return None, None
    if truth is None:
        return half, None
    error = (estimate[0] - truth[0], estimate[1] - truth[1])
    return half, distance2(error, cov) <= PLANAR_95


def edges_interval(est: Estimates, truth: Truth | None) -> Interval:
    """Robot ``est.robot``'s ``ẑ_ij`` against their 95 % ellipses (:func:`planar_interval`),
    over the neighbours it published a covariance for (and, with a ``truth``, that are robots
    of it): the widest half-width, and whether every ``z_ij`` is inside."""
    i, n = est.robot, None if truth is None else len(truth.contacts)
    edges = [
        planar_interval(
            est.relative_positions.get(j), cov, None if n is None else true_relative(truth, i, j)
        )
        for j, cov in sorted(est.relative_positions_cov.items())
        if n is None or (1 <= j <= n and i <= n)
    ]
    edges = [e for e in edges if e[0] is not None]
    if not edges:
        return None, None
    inside = None if truth is None else all(e[1] for e in edges)
    return max(e[0] for e in edges), inside
