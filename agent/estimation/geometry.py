"""Planar vector algebra of the paper (Sec. II) and the rigid-body map Γ (eq. 4).

Conventions (paper eq. 3 and the notes): ``Q = [[0, -1], [1, 0]]``, ``v⊥ = Q v``, and the
planar cross product is ``a × b = (a⊥)ᵀ b``. For any two points of a rigid body,
``ż_ij = ω z_ij⊥``.

Vectors are ``(x, y)`` tuples of floats: an agent's step works on a handful of 2-vectors, where
plain floats are several times faster than small numpy arrays.
"""

from __future__ import annotations

import math

Vec2 = tuple[float, float]


def perp(v: Vec2) -> Vec2:
    """``v⊥ = Q v = (-v_y, v_x)`` (eq. 3)."""
    return (-v[1], v[0])


def dot(a: Vec2, b: Vec2) -> float:
    return a[0] * b[0] + a[1] * b[1]


def cross(a: Vec2, b: Vec2) -> float:
    """``a × b = (a⊥)ᵀ b = a_x b_y - a_y b_x``."""
    return a[0] * b[1] - a[1] * b[0]


def norm(v: Vec2) -> float:
    return math.hypot(v[0], v[1])


def add(a: Vec2, b: Vec2) -> Vec2:
    return (a[0] + b[0], a[1] + b[1])


def sub(a: Vec2, b: Vec2) -> Vec2:
    return (a[0] - b[0], a[1] - b[1])


def scale(s: float, v: Vec2) -> Vec2:
    return (s * v[0], s * v[1])


def rotate(v: Vec2, angle: float) -> Vec2:
    """``R(angle) v``: ``v`` turned counter-clockwise by ``angle`` radians."""
    c, s = math.cos(angle), math.sin(angle)
    return (c * v[0] - s * v[1], s * v[0] + c * v[1])


def angle_between(a: Vec2, b: Vec2) -> float:
    """The signed angle in ``(-π, π]`` that turns the direction of ``a`` onto that of ``b``."""
    return math.atan2(cross(a, b) + 0.0, dot(a, b))  # + 0.0: a -0.0 cross would give -π


def gamma(z1_before: Vec2, z2_before: Vec2, z1_after: Vec2) -> Vec2:
    """Fact III.1, eq. (4) with the notes' correction (denominator ``‖z_1(t')‖²``).

    ``z_1`` and ``z_2`` join two pairs of points of one rigid body. Knowing both at ``t'`` and
    ``z_1`` at ``t''``, the body's rotation between the instants maps ``z_2(t')`` to::

        z_2(t'') = [(z_2(t')ᵀ z_1(t')) z_1(t'') + (z_2(t')ᵀ z_1⊥(t')) z_1⊥(t'')] / ‖z_1(t')‖²
    """
    d = dot(z1_before, z1_before)
    a = dot(z2_before, z1_before) / d
    b = dot(z2_before, perp(z1_before)) / d
    p = perp(z1_after)
    return (a * z1_after[0] + b * p[0], a * z1_after[1] + b * p[1])


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
