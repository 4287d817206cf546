"""Planar vector algebra of the paper (Sec. II).

Conventions (paper eq. 3 and the notes): ``Q = [[0, -1], [1, 0]]``, ``v⊥ = Q v``, and the
planar cross product is ``a × b = (a⊥)ᵀ b``. For any two points of a rigid body,
``ż_ij = ω z_ij⊥``.

The rigid-body map Γ of eq. (4) (Fact III.1) turns a vector of the load from one instant to
another; the agent applies it as :func:`rotate` by the load's rotation between the instants,
which it tracks (Step 3), so Γ itself is never formed.

Vectors are ``(x, y)`` tuples of floats: an agent's step works on a handful of 2-vectors, where
plain floats are several times faster than small numpy arrays.
"""

from __future__ import annotations

import math

Vec2 = tuple[float, float]


def dot(a: Vec2, b: Vec2) -> float:
    return a[0] * b[0] + a[1] * b[1]


def cross(a: Vec2, b: Vec2) -> float:
    """``a × b = (a⊥)ᵀ b = a_x b_y - a_y b_x``."""
    return a[0] * b[1] - a[1] * b[0]


def rotate(v: Vec2, angle: float) -> Vec2:
    """``R(angle) v``: ``v`` turned counter-clockwise by ``angle`` radians."""
    c, s = math.cos(angle), math.sin(angle)
    return (c * v[0] - s * v[1], s * v[0] + c * v[1])


def turned_covariance(cov, angle: float):
    """``R C Rᵀ`` for a 2×2 covariance ``C`` (nested pairs) and ``R`` the rotation by
    ``angle``: the covariance of a vector turned by ``angle``."""
    (a, b), (_, d) = cov
    if angle == 0.0:
        return ((a, b), (b, d))
    c, s = math.cos(angle), math.sin(angle)
    xx = c * c * a - 2 * c * s * b + s * s * d
    xy = c * s * (a - d) + (c * c - s * s) * b
    yy = s * s * a + 2 * c * s * b + c * c * d
    return ((xx, xy), (xy, yy))


def largest_std(xx: float, xy: float, yy: float) -> float:
    """The standard deviation along the least certain axis of a planar covariance
    ``[[xx, xy], [xy, yy]]``: the square root of its larger eigenvalue."""
    return math.sqrt(max(0.5 * (xx + yy) + math.hypot(0.5 * (xx - yy), xy), 0.0))


def angle_between(a: Vec2, b: Vec2) -> float:
    """The signed angle in ``(-π, π]`` that turns the direction of ``a`` onto that of ``b``."""
    ax, ay = a
    bx, by = b
    # atan2(a × b, a · b); + 0.0: a -0.0 cross would give -π
    return math.atan2(ax * by - ay * bx + 0.0, ax * bx + ay * by)


def arc_factor(turn: float) -> float:
    """``tan(φ/2) / (φ/2)``: the trapezoid rule's error for a vector that turns uniformly.

    A vector of constant length turning uniformly by ``φ`` over an interval has the integral
    ``dt · sin(φ/2)/(φ/2)`` times its mid-interval value, while the trapezoid of its end values
    gives ``dt · cos(φ/2)`` times it; multiplying the trapezoid by this factor makes it exact.
    """
    half = 0.5 * turn
    if abs(half) < 1e-4:
        return 1.0 + half * half / 3.0
    return math.tan(half) / half
