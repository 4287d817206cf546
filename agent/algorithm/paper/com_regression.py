"""Step 5 by least squares: ``z_C`` from the same measurements as observer (24).

Under a common force ``f`` (eq. 17), eq. (18) gives ``ω̇ = (n/J) z_C⊥ᵀ f`` (times the force's
sign ``s = ±1`` when it reverses, which the regressor carries). The offset
``z_C`` is constant in the load: ``z_C(t) = R(α(t)) c``, with ``α`` the load's rotation since a
reference instant (each robot tracks it from its relative positions) and ``c`` the offset at
that instant. Since ``(Q R c)ᵀ f = cᵀ R(−α) Qᵀ f``,

    ω̇ = φ(t)ᵀ c,      φ(t) = (n/J) R(−α(t)) Qᵀ f,

a linear regression in the constant ``c`` with a known regressor: the Appendix's filtered
regression (eq. 26) with two parameters. ``c`` is determined as soon as the load has turned
enough for ``φ`` to span the plane — the observability condition of Prop. V.1 (ω ≠ 0, f ≠ 0).
"""

from __future__ import annotations

from agent.algorithm.paper.filtered_regression import FilteredRegression
from agent.platform.geometry import Vec2, arc_factor, rotate


class ComRegression:
    """Least-squares estimate of ``z_C`` while the team pushes with a common force ``f``."""

    def __init__(
        self, filter_gain: float, n: int, moment: float, force: Vec2, forgetting: float = 1.0
    ):
        k = n / moment
        self.base = (k * force[1], -k * force[0])  # (n/J) Qᵀ f
        self.regression = FilteredRegression(
            filter_gain, outputs=1, params=2, forgetting=forgetting
        )
        self._phi: Vec2 = self.base
        self._alpha = 0.0

    def regressor(self, alpha: float) -> Vec2:
        """``φ = (n/J) R(−α) Qᵀ f``."""
        return rotate(self.base, -alpha)

    @property
    def started(self) -> bool:
        """Whether the first sample has started the filters."""
        return self.regression.started

    def update(self, omega: float, alpha: float, sign: float, dt: float) -> None:
        """Feed ``ω`` and the rotation ``α`` since the reference instant at the end of an
        interval ``dt`` over which the force's mean sign was ``sign`` (the first call, at the
        reference instant, starts the filters)."""
        phi = self.regressor(alpha)
        if not self.regression.started:
            self.regression.start((omega,))
        else:
            # ∫φ dt: trapezoid, made exact for a uniform turn of the load over the interval.
            h = 0.5 * sign * dt * arc_factor(alpha - self._alpha)
            p0 = self._phi
            self.regression.update((omega,), ((h * (p0[0] + phi[0]), h * (p0[1] + phi[1])),), dt)
        self._phi = phi
        self._alpha = alpha

    @property
    def estimate(self) -> Vec2 | None:
        """``c``: ``z_C`` at the reference instant, in ``W`` then."""
        est = self.regression.estimate
        return None if est is None else (est[0], est[1])

    @property
    def covariance(self) -> None:
        """Not estimated yet."""
        return None

    def com_offset(self, alpha: float) -> Vec2 | None:
        """``z_C = R(α) c`` after a rotation ``α`` (eq. 6 with the rotation written out)."""
        c = self.estimate
        return None if c is None else rotate(c, alpha)
