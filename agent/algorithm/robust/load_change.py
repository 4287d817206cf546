"""Is the load still the one estimated? Each probe's residuals, tested against the estimates.

Once the team is done (robust estimators) it probes the load in cycles
(:mod:`agent.algorithm.phase_machine`): the push's common force ``s f``, ``s = ±1`` on the agreed
clock. A robot's estimate of the COM's velocity (Step 6, eq. 7) is ``ṗ̂_C = ṗ_Ci − ω Q ô`` with
``ô = p_Ci − p̂_C`` its estimated offset from the COM. With the true offset ``o`` and
``δ = p̂_C − p_C`` (a vector of the load, ``R(θ − θ₀) δ₀`` after the load turned from its
angle ``θ₀`` at the probe's first instant ``t₀``),

    ṗ̂_C(t) = ṗ_C(t) + ω Q δ(t) = v₀ + κ (n f / m̂) (Σ(t) − τ_d s(t)) + ω(t) Q R(θ(t) − θ₀) δ₀,

``Σ(t) = ∫_{t₀}^{t} s dt``, ``τ_d`` the drives' lag (Step 4's fit), ``m̂`` Step 7's fit (as it
is, before the drives' gains: ``n ḡ f / (ḡ m̂)`` is the same acceleration). This is linear in
``(v₀ₓ, v₀ᵧ, κ, δ₀ₓ, δ₀ᵧ)``, two rows per instant (:class:`ProbeFit`). For the load the team
estimated, ``κ = 1`` and ``δ`` is the estimate's own error; a heavier or lighter load moves
``κ`` (``κ = m̂ / m``), a moved COM moves ``δ`` by as much, and the turn ``ω`` makes it show:
a COM 10 cm off turning at 0.5 rad/s adds a velocity of 5 cm/s that turns with the load.

At the probe's end the robot tests both against what it published (:meth:`ProbeFit.score`):

    d_m = |κ − 1| / √(σ_κ² + (σ_m / m̂)²),    d_C = √(δᵀ (Σ_δ + Σ_o)⁻¹ δ),

with the fit's ``σ̂² M⁻¹`` (the rows taken as independent: their errors are the odometry's
and ω's) and the published standard deviation of ``m̂`` and covariance of ``contact_to_com``
(``−ô``); the score is ``max(d_m, d_C)``. Above ``change_threshold`` the load has changed.
"""

from __future__ import annotations

import math

from agent.algorithm.robust.least_squares import LeastSquares, Solution
from agent.platform.geometry import Vec2, rotate, turned_covariance

Cov2 = tuple[float, float, float]
"""A 2×2 covariance ``(xx, xy, yy)``."""


class ProbeFit:
    """One probe's fit of ``(v₀, κ, δ₀)`` (see the module docstring)."""

    def __init__(self, n: int, mass: float, force: Vec2, lag: float, angle: float):
        self.fit = LeastSquares(5)
        self.acceleration = (n * force[0] / mass, n * force[1] / mass)
        """``n f / m̂``: the COM's acceleration under ``+f``, as estimated."""
        self.lag = lag
        self.angle0 = angle
        """The load's rotation angle at the probe's first instant."""
        self.angle = angle
        self._once = 0.0
        """``Σ = ∫ s dt`` since the probe's first instant."""

    def update(
        self, com_velocity: Vec2, omega: float, angle: float, sign: float, dt: float
    ) -> None:
        """Feed ``ṗ̂_C``, ``ω`` and the load's rotation at the end of an interval ``dt`` in which
        the team pushed with the mean sign ``sign`` (``dt = 0`` at the probe's first
        instant)."""
        self._once += sign * dt
        self.angle = angle
        pushed = self._once - self.lag * sign
        ax, ay = self.acceleration
        turn = angle - self.angle0
        c, s = math.cos(turn), math.sin(turn)
        # ω Q R(turn) δ₀ = ω (−s δx − c δy, c δx − s δy)
        self.fit.add((1.0, 0.0, ax * pushed, -omega * s, -omega * c), com_velocity[0])
        self.fit.add((0.0, 1.0, ay * pushed, omega * c, -omega * s), com_velocity[1])

    def solve(self) -> Solution | None:
        """The fit's solution (``None`` while it is not determined)."""
        return self.fit.solve()

    def score(self, mass_rel_std: float, offset_cov: Cov2) -> tuple[float, float] | None:
        """``(d_m, d_C)`` against the estimates' published relative standard deviation of
        ``m̂`` and covariance of ``contact_to_com`` (in ``W`` at the probe's last instant);
        ``None`` while the fit is not determined."""
        fit = self.fit.solve()
        if fit is None:
            return None
        cov = fit.covariance()
        _, _, kappa, dx, dy = fit.estimate
        d_m = abs(kappa - 1.0) / math.sqrt(cov[2][2] + mass_rel_std**2)
        # δ₀ and its covariance turned to the last instant, where Σ_o is given.
        turn = self.angle - self.angle0
        x, y = rotate((dx, dy), turn)
        (xx, xy), (_, yy) = turned_covariance(
            ((cov[3][3], cov[3][4]), (cov[4][3], cov[4][4])), turn
        )
        xx, xy, yy = xx + offset_cov[0], xy + offset_cov[1], yy + offset_cov[2]
        det = xx * yy - xy * xy
        if det <= 0.0:
            return None
        d_c = math.sqrt(max(0.0, (yy * x * x - 2 * xy * x * y + xx * y * y) / det))
        return d_m, d_c
