"""Step 5 under noise: ``z_C`` from the load's rotation angle while the team pushes.

Under the common force ``s(t) f`` (eq. 17; the sign ``s = ±1`` reverses on the agreed clock,
:meth:`~agent.algorithm.phase_machine.PhaseMachine.push_sign`) the torque about the COM is
``n s (z_C⊥)ᵀ f``, so (eq. 18, as in :mod:`agent.algorithm.paper.com_regression`) with
``z_C(t) = R(α(t)) c``, ``α`` the rotation since the push began and ``c`` the offset then,

    θ̈ = φ(t)ᵀ c,      φ(t) = s(t) (n/J) R(−α(t)) Qᵀ f.

Integrating twice from the push's first instant ``t₀``,

    θ(t) = θ₀ + ω₀ (t − t₀) + Ψ(t)ᵀ c,      Ψ(t) = ∫_{t₀}^{t} ∫_{t₀}^{s} φ dr ds,

linear in ``(θ₀, ω₀, c_x, c_y)`` (a force ``a(t)`` that every robot adds to the push,
``push_damping``'s, adds ``(n/J) R(−α) Qᵀ a`` to ``φ``): least squares on the angle itself
(tracked from the arc fits, :mod:`agent.algorithm.robust.arc_fit`), never on a differentiated
or filtered ω.

The drives' lag ``τ_d`` (Step 4's fit) acts on the forces in ``W``: the load feels
``y = K[s f + a]``, ``τ_d ẏ + y = s f + a``, and its torque about the COM is ``z_C(t) × y(t)``
with ``z_C`` turning with the load. So ``φ`` takes the drives' response ``K[s]`` (and ``K[a]``)
in place of the sign, averaged over each interval ``h`` with the command ``u`` held,
``ȳ = u + (y₀ − u)(τ_d/h)(1 − e^{−h/τ_d})`` (exact for a first-order lag), and turns that with
the load. (Lagging ``φ`` itself, ``Ψ − τ_d ∫φ + τ_d² φ``, as
:mod:`agent.algorithm.robust.mass_fit` does for a load that hardly turns, lags the turn of
``z_C`` too: a rotation of the push by ``τ_d ω`` about the COM. With little noise (1 mm/s,
0.05 N), 20 ms drives and the paper's load turning at 1 rad/s, that put Step 5's offset
2.6–3.1 mm off, this 0.6–1.3 mm: docs/benchmarks.md, "Step 5's model".) The
response starts at zero at ``t₀``; where the drives were already pushing, the two differ by a
transient whose double integral is linear in ``t`` once it has died out, which ``θ₀`` and
``ω₀`` take up. The known torque below goes through the same response. Over an
interval ``h`` the regressor's integrals grow by the trapezoid ``∫φ ≈ h (φ₀ + φ₁)/2`` (made
exact for a uniform turn by :func:`~agent.platform.geometry.arc_factor`) and
``∫∫φ ≈ h ∫φ(t) + h² (φ₀/3 + φ₁/6)``. ``c`` is determined once the load has turned enough
for ``Ψ`` to span the plane (Prop. V.1: ω ≠ 0, f ≠ 0).

On a real floor the load turns against a friction torque ``−τ_c sgn ω``, and the team adds a
constant torque of its own that keeps it turning (:mod:`agent.algorithm.robust.phases`): while
the load turns one way (``s_ω``) both are a constant ``d`` in ``θ̈``, so a fifth column
``Σ_ω = ∫∫ s_ω`` with the unknown ``d`` takes them up (0 on a frictionless floor without that
torque). The brake the team adds to that torque as the turn nears ``max_turn_rate``, ``τ_b(t)``,
is known to every robot: its turn through the drives, ``∫∫ K[τ_b] / J``, is taken out of the
angle.

The floor's torque is ``−τ_c sgn ω`` only while the COM is slow against the supports' speed:
as the COM moves, it falls, as ``ρ d`` with Step 7's drag ``d = ω / √(‖ṗ_C‖² + ω² ρ² + v₀²)``
(:mod:`agent.algorithm.robust.hold_fit`, ``ρ = √(w/n)``), and the push swings ``ṗ_C`` with
its sign, so its fall is correlated with ``Ψ``. A sixth column ``∫∫ (ρ d − s_ω)`` takes it up
(its coefficient ``−τ_c/J``; the fifth keeps the constant), with ``ṗ_C`` from the robot's own
velocity, ``ω`` and the fit's ``ẑ_C`` so far (eq. 7; the centroid's before there is one). The
difference rather than ``∫∫ ρ d`` itself: the two nearly agree while the COM is slow, and the
normal equations of nearly equal columns lose the residual to cancellation. Without it, on
generated loads on floors, Step 5's ``ẑ_C`` was off by several times more than with it (see
docs/benchmarks.md, "Step 5's model").

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
        self,
        n: int,
        moment: float,
        force: Vec2,
        forgetting: float = 1.0,
        lag: float = 0.0,
        falling: bool = False,
    ):
        # rows [1, t − t₀, Ψ_x, Ψ_y, Σ_ω] (θ₀, ω₀, c_x, c_y, d) = α, with ``falling`` a sixth
        # column ∫∫ (ρ d − s_ω) (its coefficient −τ_c/J)
        super().__init__(6 if falling else 5, forgetting)
        self.falling = falling
        """Whether the fit has the sixth column, the friction torque's fall (Step 5's)."""
        self._fall = 0.0
        self._fall_once = 0.0
        self._fall_twice = 0.0
        """The sixth column's integrand ``ρ d − s_ω`` at the last sample, its first integral
        and its second."""
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
        """``∫∫ K[τ]/J`` since the first sample: the turn of the known torque through the
        drives, taken out of α."""
        self._response: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0)
        """The drives' response ``K[·]`` to the push's sign, the added force (x, y) and the
        known torque, at the last sample (zero at the first)."""
        self._response_dt = 0.0
        self._decay = (0.0, 0.0)
        """The interval ``h`` that the response's decay and mean share,
        ``(e^{−h/τ_d}, (τ_d/h)(1 − e^{−h/τ_d}))``, were computed for, and they."""

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
        fall: float = 0.0,
    ) -> None:
        """Feed the rotation ``α`` since the push began, at the end of an interval ``dt``
        during which the team pushed with the mean sign ``sign``, each robot added the
        mean force ``added``, the team a mean torque ``torque`` about the COM beyond the
        constant ``d`` (N m: the brake as the turn nears ``max_turn_rate``), the load
        turned the way ``spin`` and the sixth column's integrand ``ρ d − s_ω`` was ``fall``
        at the end of it (the first call, at the push's first instant, starts)."""
        self._add_row(alpha, sign, dt, added, spin, torque, fall)

    def _add_row(
        self,
        alpha: float,
        sign: float,
        dt: float,
        added: Vec2,
        column: float,
        torque: float,
        fall: float = 0.0,
    ) -> None:
        """The row at ``α``: the regressor's integrals over the interval ``dt``, the fifth
        column's integrand ``column``, the sixth's ``fall`` (trapezoid) and the known
        ``torque`` (N m) over it, the push and the torque through the drives' lag
        (:meth:`_through_drives`); solves."""
        if self.started and self.lag > 0.0:
            sign, added, torque = self._through_drives(dt, sign, added, torque)
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
            if self.falling:
                d0 = self._fall
                self._fall_twice += self._fall_once * dt + dd * (d0 / 3.0 + fall / 6.0)
                self._fall_once += 0.5 * dt * (d0 + fall)
            self.t += dt
        self._fall = fall
        self.started = True
        self._alpha, self._turned, self._regressor = alpha, (c, s), (px, py)
        sx, sy = self._twice
        row = (1.0, self.t, sx, sy, self._column_twice)
        if self.falling:
            row = (*row, self._fall_twice)
        self.fit.add(row, alpha - self._known_turn())
        self._solve()

    def _through_drives(
        self, dt: float, sign: float, added: Vec2, torque: float
    ) -> tuple[float, Vec2, float]:
        """The push's sign, the added force and the known torque as the drives apply them
        over an interval ``dt`` with these commanded: the means of their first-order responses
        (see the module docstring), which the interval leaves where it ends."""
        if dt != self._response_dt:  # the intervals are one tick but for late instants
            decay = math.exp(-dt / self.lag)
            self._response_dt, self._decay = dt, (decay, self.lag / dt * (1.0 - decay))
        decay, share = self._decay
        commanded = (sign, added[0], added[1], torque)
        before = self._response
        self._response = tuple(u + (y - u) * decay for u, y in zip(commanded, before))
        s, ax, ay, tau = (u + (y - u) * share for u, y in zip(commanded, before))
        return s, (ax, ay), tau

    def _known_turn(self) -> float:
        """The turn ``∫∫ K[τ]/J`` of the known torque through the drives."""
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
        p = self.fit.params
        return largest_std(k * inverse[2 * p + 2], k * inverse[2 * p + 3], k * inverse[3 * p + 3])

    def com_offset(self, alpha: float) -> Vec2 | None:
        """``z_C = R(α) c`` after a rotation ``α``."""
        c = self.estimate
        return None if c is None else rotate(c, alpha)
