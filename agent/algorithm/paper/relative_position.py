"""Step 1: the relative position ``z_ij = p_Ci − p_Cj`` from velocities only (Sec. IV).

Rigidity makes ``ż_ij ⟂ z_ij`` (eq. 9) and ``ż_ij = ω z_ij⊥``, so (eq. 10 with the notes'
correction) ``z_ij = −sign(ω) ‖z_ij‖ y_ij`` with the measured unit vector
``y_ij = ż_ij⊥ / ‖ż_ij‖``: only the constant distance ``‖z_ij‖`` is unknown. Differentiating,

    ẏ_ij = θ ż_ij,      θ = −1 / (sign(ω) ‖z_ij‖)                         (11)

a linear regression of the Appendix's kind (``y = y_ij``, ``u = ż_ij``). Prop. IV.1 solves it
by the instantaneous ratio (eq. 12, ``‖z_ij‖ = ‖ż_ij^f‖ / (k_f ‖y_ij − y_ij^f‖)``, sign from
``−sign[(ż_ij^f)ᵀ(y_ij − y_ij^f)]``); here the same filtered regression is solved by least
squares over all samples
(:class:`~agent.algorithm.paper.filtered_regression.FilteredRegression`), which is the same
estimator without noise and averages noise with it.

``y_ij`` reverses when ω changes sign. The estimator follows the reversals by continuity
(``y_ij(t_k)ᵀ y_ij(t_{k-1}) < 0``) and regresses ``σ y_ij``, which never jumps, where ``σ = ±1``
counts the reversals. Then ``θ = −1/(s₀ ‖z_ij‖)`` with ``s₀`` the sign of ω when estimation
began, and at any time::

    z_ij = σ y_ij / θ̂,      sign(ω) = −σ sign(θ̂).

Needs ``‖z_ij‖ > 0`` and ω ≠ 0 (the load must turn) while it learns. ``∫ż_ij dt`` over a
sampling interval is the trapezoid rule corrected for the load's turn over it
(:func:`~agent.platform.geometry.arc_factor`), so the estimate stays exact at speed.
"""

from __future__ import annotations

import math

from agent.algorithm.paper.filtered_regression import FilteredRegression
from agent.platform.geometry import Vec2, angle_between, arc_factor


class RelativePosition:
    """Estimates one edge's ``z_ij`` from the samples of ``ż_ij = ṗ_Ci − ṗ_Cj``."""

    def __init__(self, filter_gain: float, forgetting: float = 1.0, min_speed: float = 1e-6):
        self.regression = FilteredRegression(
            filter_gain, outputs=2, params=1, forgetting=forgetting
        )
        self.learning = True
        """While ``False`` the distance is frozen and only the direction is tracked."""
        self.min_speed = min_speed
        """m/s: a sample with ``‖ż_ij‖`` at most this is not used (``y_ij`` is undefined)."""
        self.moving = False
        """Whether the last sample was used (the edge was turning: ``‖ż_ij‖ > min_speed``)."""
        self.sigma = 1.0
        """``σ = ±1``: the reversals of ``y_ij`` followed so far."""
        self.zdot: Vec2 = (0.0, 0.0)
        """``ż_ij`` at the last sample used."""
        self.direction: Vec2 | None = None
        """``σ y_ij`` at the last sample used: the direction of ``−sign(ω₀) z_ij``."""
        self.last_turn = 0.0
        """The load's rotation (rad) between the last two samples used."""
        self.last_dt = 0.0
        """s: the interval between the last two samples used."""
        self._theta: float | None = None
        """``θ̂ = −1/(s₀ ‖z_ij‖)``, solved after each update that learns (kept in between)."""

    def update(self, zdot: Vec2, dt: float) -> None:
        """Feed ``ż_ij`` sampled ``dt`` after the last sample used (see :attr:`moving`); the
        first sample used only starts the filters."""
        speed = math.hypot(zdot[0], zdot[1])
        if speed <= self.min_speed:
            self.moving = False
            return  # y_ij undefined: the load is not turning; wait.
        self.moving = True
        y = (-zdot[1] / speed, zdot[0] / speed)
        if (
            self.direction is not None
            and self.sigma * (y[0] * self.direction[0] + y[1] * self.direction[1]) < 0.0
        ):
            self.sigma = -self.sigma
        ty = (self.sigma * y[0], self.sigma * y[1])
        if not self.regression.started:
            self.regression.start(ty)
            self.last_turn = self.last_dt = 0.0
        else:
            self.last_turn = angle_between(self.direction, ty)
            self.last_dt = dt
            if self.learning:
                # ∫ż_ij dt over the interval: trapezoid, made exact for a uniform turn.
                h = 0.5 * dt * arc_factor(self.last_turn)
                self.regression.update(
                    ty, ((h * (self.zdot[0] + zdot[0]),), (h * (self.zdot[1] + zdot[1]),)), dt
                )
                self._theta = self._solve()
        self.direction = ty
        self.zdot = zdot

    def _solve(self) -> float | None:
        est = self.regression.estimate
        if est is None or est[0] == 0.0:
            return None
        return est[0]

    @property
    def estimate(self) -> Vec2 | None:
        """``z_ij = σ y_ij / θ̂`` at the last sample used, in ``W`` then."""
        theta = self._theta
        if theta is None or self.direction is None:
            return None
        return (self.direction[0] / theta, self.direction[1] / theta)

    @property
    def covariance(self) -> None:
        """Not estimated yet."""
        return None

    @property
    def distance(self) -> float | None:
        """``‖z_ij‖ = 1/|θ̂|``, or ``None`` before the data determine it."""
        theta = self._theta
        return None if theta is None else 1.0 / abs(theta)
