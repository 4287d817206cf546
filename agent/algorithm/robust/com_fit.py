"""Step 5 under noise: ``z_C`` from the load's rotation angle while the team pushes.

Under the common force ``s(t) f`` (eq. 17; the sign ``s = ±1`` reverses on the agreed clock,
:meth:`~agent.algorithm.phase_machine.PhaseMachine.push_sign`) the torque about the COM is
``n s (z_C⊥)ᵀ f``, so (eq. 18, as in :mod:`agent.algorithm.paper.com_regression`) with
``z_C(t) = R(α(t)) c``, ``α`` the rotation since the push began and ``c`` the offset then,

    θ̈ = φ(t)ᵀ c,      φ(t) = s(t) (n/J) R(−α(t)) Qᵀ f.

Integrating twice from the push's first instant ``t₀``,

    θ(t) = θ₀ + ω₀ (t − t₀) + Ψ(t)ᵀ c,      Ψ(t) = ∫_{t₀}^{t} ∫_{t₀}^{s} φ dr ds,

linear in ``(θ₀, ω₀, c_x, c_y)`` (a force ``a(t)`` that every robot adds to the push,
``push_damping``'s, adds ``(n/J) R(−α) Qᵀ a`` to ``φ``; with the drives' lag ``τ_d`` from Step 4,
``Ψ − τ_d ∫φ + τ_d² φ`` in place of ``Ψ``, as in :mod:`agent.algorithm.robust.mass_fit`): least
squares on the angle itself (tracked from the arc fits, :mod:`agent.algorithm.robust.arc_fit`),
never on a differentiated or filtered ω. Over an
interval ``h`` the regressor's integrals grow by the trapezoid ``∫φ ≈ h (φ₀ + φ₁)/2`` (made
exact for a uniform turn by :func:`~agent.platform.geometry.arc_factor`) and
``∫∫φ ≈ h ∫φ(t) + h² (φ₀/3 + φ₁/6)``. ``c`` is determined once the load has turned enough
for ``Ψ`` to span the plane (Prop. V.1: ω ≠ 0, f ≠ 0).

On a real floor the load turns against a friction torque ``−τ_c sgn ω``, and the team adds a
constant torque of its own that keeps it turning (:mod:`agent.algorithm.robust.phases`): while
the load turns one way (``s_ω``) both are a constant ``d`` in ``θ̈``, so a fifth column
``Σ_ω = ∫∫ s_ω`` with the unknown ``d`` takes them up (0 on a frictionless floor without that
torque). The brake the team adds to that torque as the turn nears ``max_turn_rate``, ``τ_b(t)``,
is known to every robot: its turn ``∫∫ τ_b / J`` is taken out of the angle. The torque of
friction's force about the COM vanishes to first order in ``‖ṗ_C‖ / (|ω| r)``
(docs/estimator.md, "Friction"), which the experiment keeps small.

Uncertainty: the fit's ``σ̂² M⁻¹`` for ``c``, scaled for the angle's correlated errors as in
:mod:`agent.algorithm.robust.inertia_fit`
(:data:`~agent.algorithm.robust.least_squares.CORRELATION_TIME`). It does not include the error
of ``Ĵ``, which scales ``c`` (``c ∝ J``).
"""

from __future__ import annotations

import math

from agent.algorithm.estimation.estimator import Covariance
from agent.algorithm.robust.least_squares import RunFit, Solution
from agent.platform.geometry import Vec2, arc_factor, largest_std, rotate


class ComFit(RunFit):
    """Least-squares ``z_C`` from the rotation angle while the team pushes with ``f``."""

    def __init__(
        self, n: int, moment: float, force: Vec2, forgetting: float = 1.0, lag: float = 0.0
    ):
        # rows [1, t − t₀, Ψ_x, Ψ_y, Σ_ω] (θ₀, ω₀, c_x, c_y, d) = α
        super().__init__(5, forgetting)
        k = n / moment
        self.k = k
        self.force = force
        self.inverse_moment = 1.0 / moment
        self.base = (k * force[1], -k * force[0])  # (n/J) Qᵀ f
        self.lag = lag
        self.started = False
        self._alpha = 0.0
        self._turned: Vec2 = (1.0, 0.0)
        """``(cos, sin)`` of ``−α`` at the last sample."""
        self._regressor: Vec2 = self.base
        """The regressor ``(n/J) R(−α) Qᵀ f`` at the last sample."""
        self._once: Vec2 = (0.0, 0.0)
        """``∫φ`` since the first sample."""
        self._twice: Vec2 = (0.0, 0.0)
        """``Ψ = ∫∫φ`` since the first sample."""
        self._column_once = 0.0
        self._column_twice = 0.0
        """The fifth column since the first sample, ``Σ_ω = ∫∫ sgn ω`` here (its
        integrand's first integral, then its second)."""
        self._torque_once = 0.0
        self._torque_twice = 0.0
        """``∫∫ τ/J`` since the first sample: the turn of the known torque, taken out of α."""

    def regressor(self, alpha: float) -> Vec2:
        """``φ = (n/J) R(−α) Qᵀ f``."""
        return rotate(self.base, -alpha)

    def update(
        self,
        alpha: float,
        sign: float,
        dt: float,
        *,
        added: Vec2 = (0.0, 0.0),
        spin: float = 1.0,
        torque: float = 0.0,
    ) -> None:
        """Feed the rotation ``α`` since the push began, at the end of an interval ``dt``
        during which the team pushed with the mean sign ``sign``, each robot added the
        mean force ``added``, the team a mean torque ``torque`` about the COM beyond the
        constant ``d`` (N m: the brake as the turn nears ``max_turn_rate``) and the load
        turned the way ``spin`` (the first call, at the push's first instant, starts)."""
        self._add_row(alpha, sign, dt, added, spin, torque)

    def _add_row(
        self, alpha: float, sign: float, dt: float, added: Vec2, column: float, torque: float
    ) -> None:
        """The row at ``α``: the regressor's integrals over the interval ``dt``, the fifth
        column's integrand ``column`` and the known ``torque`` (N m) over it; solves."""
        k = self.k
        ax, ay = k * added[1], -k * added[0]  # (n/J) Qᵀ a
        c, s = math.cos(-alpha), math.sin(-alpha)  # R(−α)
        bx, by = self.base
        px, py = c * bx - s * by, s * bx + c * by  # the regressor (n/J) R(−α) Qᵀ f
        ex, ey = c * ax - s * ay, s * ax + c * ay  # (n/J) R(−α) Qᵀ a
        if self.started:
            (c0, s0), (qx, qy) = self._turned, self._regressor  # at the last α
            p0x = sign * qx + (c0 * ax - s0 * ay)  # φ at the last α, and now
            p0y = sign * qy + (s0 * ax + c0 * ay)
            phx, phy = sign * px + ex, sign * py + ey
            (ox, oy), (tx, ty) = self._once, self._twice
            h = 0.5 * dt * arc_factor(alpha - self._alpha)
            dd = dt * dt
            self._twice = (
                tx + dt * ox + dd * (p0x / 3.0 + phx / 6.0),
                ty + dt * oy + dd * (p0y / 3.0 + phy / 6.0),
            )
            self._once = (ox + h * (p0x + phx), oy + h * (p0y + phy))
            self._column_twice += self._column_once * dt + 0.5 * column * dd
            self._column_once += column * dt
            u = torque * self.inverse_moment  # τ / J
            self._torque_twice += self._torque_once * dt + 0.5 * u * dd
            self._torque_once += u * dt
            self.t += dt
        self.started = True
        self._alpha, self._turned, self._regressor = alpha, (c, s), (px, py)
        (sx, sy), (ox, oy), lag = self._twice, self._once, self.lag
        lag2, lagged = lag * lag * sign, lag * lag
        self.fit.add(
            (
                1.0,
                self.t,
                sx - lag * ox + lag2 * px + lagged * ex,
                sy - lag * oy + lag2 * py + lagged * ey,
                self._column_twice,
            ),
            alpha - self._known_turn(torque * self.inverse_moment),
        )
        self._solve()

    def _known_turn(self, now: float) -> float:
        """The turn ``∫∫ τ/J`` of the known torque (``now``: ``τ/J`` over the last interval)."""
        return self._torque_twice

    @property
    def estimate(self) -> Vec2 | None:
        """``c``: ``z_C`` at the push's first instant, in ``W`` then."""
        fit = self._solution
        return None if fit is None else (fit.estimate[2], fit.estimate[3])

    @property
    def covariance(self) -> Covariance | None:
        """The covariance (m²) of :attr:`estimate`."""
        fit = self._solution
        if fit is None:
            return None
        return self._of_solution("covariance", self._covariance_of)

    def _covariance_of(self, fit: Solution) -> Covariance:
        (xx, xy), (yx, yy) = fit.covariance(self._scale, of=(2, 3))
        return ((xx, xy), (yx, yy))

    @property
    def std(self) -> float | None:
        """The standard deviation (m) of :attr:`estimate` along its least certain axis."""
        fit = self._solution
        if fit is None:
            return None
        k, inverse = self._scale * fit.variance, fit.inverse  # as :attr:`covariance`
        return largest_std(k * inverse[12], k * inverse[13], k * inverse[18])

    def com_offset(self, alpha: float) -> Vec2 | None:
        """``z_C = R(α) c`` after a rotation ``α``."""
        c = self.estimate
        return None if c is None else rotate(c, alpha)
