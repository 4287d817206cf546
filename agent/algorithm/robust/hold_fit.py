"""Step 5 refined in Step 7: ``z_C`` from the torque that holds the load's turn while it translates.

In Step 7's stage the team pushes with a common force ``c(t)`` and holds the load's turn: each
robot adds eq. (14)'s ``(τ_h/w) z_i⊥``, the holding torque ``τ_h = −n ẑ_C × c − b ω̂ w``
(:meth:`~agent.algorithm.robust.phases.RobustPhases._not_turning`), which puts the common
force's line of action through the team's ``ẑ_C`` (the consensus of the robots' own:
:attr:`~agent.algorithm.robust.pipeline.RobustPipeline.com_offset_now`) and damps what turn is
left. The common force acts at the contacts' centroid, so about
the true COM

    J θ̈ = n z_C × c + τ_h − β d,      d = ω / √(‖ṗ_C‖² + ω² ρ² + v₀²):

a COM off by ``δ`` turns the load by ``n δ × c / J`` against the torque that holds it. As in
Step 5 (:mod:`agent.algorithm.robust.com_fit`, eq. 18), with ``z_C(t) = R(α(t)) c₀`` and
``α`` the rotation since the push began, the angle is linear in ``(θ₀, ω₀, c₀, β/J)``:

    θ(t) − K[∫∫ τ_h/J] = θ₀ + ω₀ (t − t₀) + Ψ(t)ᵀ c₀ − (β/J) ∫∫ d,

``Ψ`` Step 5's regressor's double integral for the common force ``c(t) = s(t) f + a(t)``.
``K`` is the drives' first-order response (their lag ``τ_d``, Step 4's) on the known torque,
as on the push (:mod:`agent.algorithm.robust.com_fit`): the holding torque cancels most of the
push's, and what turns the load is the small difference of two large torques (with the push
lagged and the known torque not, generated load 13's estimate moved the wrong way by 4.4 cm
on the noise benchmark's floor). The holding torque is what this robot
commanded, scaled by the drives' torque gain (:mod:`agent.algorithm.robust.team_mass`), and
every robot's is the same: each takes the team's ``ẑ_C``. (When each took its own Step 5
``ẑ_C``, the difference was a torque ``n ε × c`` that the fit took into ``c₀``, 2–7 mm on
generated loads 8 and 13, and a net force that the mass fit did not model.)

Friction: while the load translates without turning, every support moves with the COM, and
Coulomb friction is a force ``−μ m g ṗ̂_C`` through the COM, no torque (``Σ N_s r_s = 0``). A
small turn ``ω`` tilts each support's velocity by ``ω r_s⊥ / ‖ṗ_C‖``, a torque of
``−μ ω Σ N_s (r_s · ṗ̂_C)² / ‖ṗ_C‖`` about the COM to first order, which becomes Step 5's
``−τ_c sgn ω`` as the COM stops (``‖ṗ_C‖ ≪ |ω| ρ``): ``d`` goes from one to the other,
``ρ = √(w/n)`` the contacts' root-mean-square distance from their centroid and ``v₀``
(:data:`SPEED_FLOOR`) a floor for a load at rest. ``β`` (``μ Σ N_s (r_s · ṗ̂_C)²``) is
fitted.

Two directions: with the common force along one direction ``f`` alone, ``Ψ`` stays along
``(n/J) Qᵀ f`` (the load hardly turns), and the fit sees only the component of ``c₀`` across
the push. So the stage's common force adds ``s'(t) Q f`` at half the reversal period
(:meth:`~agent.algorithm.robust.phases.RobustPhases._push_force`), which the fit takes as the
force each robot added, ``a(t)``.

Step 5's estimate is the prior: ``c₀ ~ N(ĉ₅, k P₅)``, ``P₅`` its fit's covariance and ``k``
the factor calibrated for it (:data:`~agent.algorithm.robust.uncertainty.STEP5_COM_VARIANCE`),
combined with the rows in
information form (:meth:`~agent.algorithm.robust.least_squares.LeastSquares.solve_with_prior`),
the rows' covariance scaled for the angle's correlated errors as in Step 5. What the stage
does not observe (a short stage, a push that saturates) stays Step 5's.
"""

from __future__ import annotations

import math

from agent.algorithm.robust.com_fit import ComFit
from agent.platform.geometry import Vec2

SPEED_FLOOR = 1e-3
"""m/s: ``v₀`` in the drag's denominator, for a load that neither moves nor turns."""
HELD_TURN = 0.04
"""rad: a stage in which the load turned further than this from where it began was not held
(:attr:`HoldFit.held`), and this fit, whose model is a load that hardly turns, gives no
estimate: Step 5's stands. Over the 80 runs of ``heft bench noise --generated 40
--coulomb-range 0.005 0.03`` with ``--first-seed 0`` and ``40`` (2026-11-28) every stage
turned less than 0.033 rad but three: generated load 23's 0.044 rad, 11's 0.071 rad (this
fit put its ``ẑ_C`` 20 mm off, three standard deviations) and 47's 0.385 rad (see
:data:`~agent.algorithm.robust.pipeline.SWUNG_TURN`)."""


class HoldFit(ComFit):
    """``z_C`` from the turn of a load held from turning while the team pushes it (Step 7's
    stage), Step 5's estimate its prior."""

    def __init__(
        self,
        n: int,
        moment: float,
        force: Vec2,
        lag: float,
        prior: Vec2,
        prior_covariance: tuple[tuple[float, float], tuple[float, float]],
    ):
        # rows [1, t − t₀, Ψ_x, Ψ_y, ∫∫d] (θ₀, ω₀, c_x, c_y, −β/J) = α − K[∫∫τ_h/J]
        super().__init__(n, moment, force, lag=lag)
        (a, b), (_, d) = prior_covariance
        det = a * d - b * b
        self.prior = prior
        self._information = (d / det, -b / det, -b / det, a / det) if det > 0.0 else None
        """The prior's information matrix (row-major), ``None`` for a degenerate prior."""
        self._alpha_first = 0.0
        self._angle_once = 0.0
        """``∫(α − α₀)`` since the first sample (``α₀`` its angle)."""
        self._damping = 0.0
        """``D/J`` (1/s), the holding torque's damping over ``J``."""
        self.turned = 0.0
        """rad: the load's largest turn from where the stage began."""
        self._range = (0.0, 0.0)
        """rad: the least and the largest turn from where the stage began."""
        self.swung = 0.0
        """rad: the most the load has turned back from its furthest turn either way since the
        stage began (a turn one way, left from Step 5's stage, is no swing)."""

    def update(
        self,
        alpha: float,
        sign: float,
        dt: float,
        *,
        added: Vec2 = (0.0, 0.0),
        drag: float = 0.0,
        torque: float = 0.0,
        damping: float = 0.0,
    ) -> None:
        """Feed the rotation ``α`` since the push began, at the end of an interval ``dt``
        during which the team pushed with the mean sign ``sign``, each robot added the mean
        force ``added``, the team held the load with the mean torque ``torque`` (N m) beside
        the damping ``−damping ω`` (``damping`` in N m s) and ``d`` was ``drag`` (the first
        call starts)."""
        if self.started:
            self._angle_once += 0.5 * dt * (self._alpha + alpha - 2.0 * self._alpha_first)
            turned = alpha - self._alpha_first
            self.turned = max(self.turned, abs(turned))
            low, high = min(self._range[0], turned), max(self._range[1], turned)
            self._range = (low, high)
            self.swung = max(self.swung, high - low - abs(turned))
        else:
            self._alpha_first = alpha
        self._damping = damping * self.inverse_moment
        self._add_row(alpha, sign, dt, added, drag, torque)

    @staticmethod
    def drag(omega: float, com_velocity: Vec2, radius: float) -> float:
        """``d = ω / √(‖ṗ_C‖² + ω² ρ² + v₀²)`` (see the module docstring)."""
        vx, vy = com_velocity
        return omega / math.sqrt(vx * vx + vy * vy + (omega * radius) ** 2 + SPEED_FLOOR**2)

    def _known_turn(self) -> float:
        """``K[∫∫ τ_h/J]``: the known torque's turn through the drives (:class:`ComFit`'s
        response), its damping ``−D ω`` as ``−(D/J) (∫(α − α₀) − τ_d (α − α₀))`` from the
        angle."""
        turned = self._alpha - self._alpha_first
        return self._torque_twice - self._damping * (self._angle_once - self.lag * turned)

    def _solve(self) -> None:
        information = self._information
        fit = self.fit
        if information is None or fit.rows < self.min_rows:
            self._solution = None
            return
        scale = self._scale_for(fit.rows)
        self._solution = fit.solve_with_prior((2, 3), self.prior, information, scale)

    @property
    def held(self) -> bool:
        """Whether the load has turned at most :data:`HELD_TURN` in the stage so far."""
        return self.turned <= HELD_TURN

    @property
    def estimate(self) -> Vec2 | None:
        """``c₀``, ``z_C`` at the push's first instant in ``W`` then (``None`` if the stage was
        not :attr:`held`: Step 5's estimate stands)."""
        return super().estimate if self.held else None
