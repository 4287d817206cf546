"""Step 4 under noise: ``J`` from the load's rotation angle, not from its angular velocity.

While the team applies eq. (14) the load obeys ``J θ̈ = τ`` (eq. 15) with the team's torque
``τ(t) = ±k w`` known to every robot. Integrating twice from the phase's first instant ``t₀``,

    θ(t) = θ₀ + ω₀ (t − t₀) + Φ(t) / J,      Φ(t) = ∫_{t₀}^{t} ∫_{t₀}^{s} τ dr ds,

linear in ``(θ₀, ω₀, 1/J)``: least squares on the rows ``[1, t − t₀, Φ(t)] · p = θ(t)`` gives
``Ĵ = 1/p₃``. On a real floor the load also feels a friction torque about its COM,
``−τ_c sgn ω`` while it turns (Coulomb friction at its supports, exact for a spin about the
COM; the experiment keeps the load turning one way, so ``sgn ω`` is the turn's sign ``s_ω``):
a fifth column ``Σ_ω(t) = ∫∫ s_ω = s_ω (t − t₀)²/2`` with the unknown ``−τ_c / J`` takes it up,
and ``τ̂_c = −p₅/p₃`` is published (0 on a frictionless floor, within its uncertainty).
A drive applies its command through a lag (``actuators.time_constant_s``): to
first order the torque then acts ``τ_d`` late, ``Φ(t − τ_d) ≈ Φ(t) − τ_d Ω(t)`` with
``Ω = ∫τ``, so a fourth column ``Ω`` with the unknown ``−τ_d / J`` takes it up (zero for ideal
drives). The angle ``θ`` is the rotation the team tracks from its arc fits (Step 1, the
sum of each instant's turn of the ``z_ij``, averaged over the team by
:mod:`agent.algorithm.robust.rotation`), whose error is millimetres over metres, where
eq. (5)'s instantaneous ``ω = (z_ij⊥)ᵀ ż_ij / ‖z_ij‖²`` carries the velocity noise of every
sample. Between two instants ``h`` apart with a constant torque ``τ``, ``Φ`` grows by
``Ω h + τ h²/2`` and ``Ω = ∫τ`` by ``τ h``: exact for the piecewise-constant torque the team
applies.

Uncertainty: ``σ̂² (AᵀA)⁻¹`` of the fit assumes independent residuals; the angle's errors (the
arc fits' walk) are correlated, so the rows count as one per
:data:`~agent.algorithm.robust.least_squares.CORRELATION_TIME`: the variance is scaled by
``CORRELATION_TIME / Δt``. Then
``std(Ĵ) = std(p₃) / p₃²``, combined with the relative uncertainty of the torque's scale (``w``,
from Step 2: ``Ĵ ∝ w``) given at the start.
"""

from __future__ import annotations

import math

from agent.algorithm.robust.least_squares import ReciprocalFit, Solution


class InertiaFit(ReciprocalFit):
    """``J`` from the rotation angle while the team applies eq. (14) with torque ``±k w``."""

    def __init__(self, forgetting: float = 1.0, torque_scale_std: float = 0.0):
        # rows [1, t − t₀, Φ, Ω, Σ_ω] (θ₀, ω₀, 1/J, −τ_d/J, −τ_c/J) = θ
        super().__init__(5, forgetting)
        self.torque_scale_std = torque_scale_std
        """The relative standard deviation of the torque's scale (``w``)."""
        self.started = False
        self.impulse = 0.0
        """``Ω = ∫τ dt`` since the first sample."""
        self.phi = 0.0
        """``Φ = ∫∫τ`` since the first sample."""
        self.spin_twice = 0.0
        """``Σ_ω = ∫∫ sgn ω`` since the first sample."""
        self._spin_once = 0.0

    def update(self, angle: float, torque: float, dt: float, *, spin: float = 1.0) -> None:
        """Feed the rotation ``angle`` (rad) at the end of an interval ``dt`` during which the
        team's torque was ``torque`` and the load turned the way ``spin`` (``±1``); the first
        call only marks the start."""
        if self.started:
            self.phi += self.impulse * dt + 0.5 * torque * dt * dt
            self.impulse += torque * dt
            self.spin_twice += self._spin_once * dt + 0.5 * spin * dt * dt
            self._spin_once += spin * dt
            self.t += dt
        self.started = True
        self.fit.add((1.0, self.t, self.phi, self.impulse, self.spin_twice), angle)
        self._solve()

    @property
    def fit_std(self) -> float | None:
        """The fit's own share of :attr:`std` (kg m²): the share that
        :attr:`~agent.algorithm.robust.least_squares.RunFit.correlation_time` scales."""
        return super().std

    @property
    def std(self) -> float | None:
        """The standard deviation of :attr:`estimate` (kg m²): the fit's and the torque
        scale's (``Ĵ ∝ w``)."""
        from_fit = self.fit_std
        if from_fit is None:
            return None
        return math.hypot(from_fit, self.torque_scale_std * self.estimate)

    @property
    def friction_torque(self) -> tuple[float, float] | None:
        """``(τ̂_c, σ)`` (N m, in the commanded torque's scale): the floor's friction torque
        about the COM, ``−p₅/p₃``, and its standard deviation (the fit's, first order)."""
        fit = self._solution
        if fit is None:
            return None
        return self._of_solution("friction_torque", self._friction_of)

    def _friction_of(self, fit: Solution) -> tuple[float, float]:
        p3, p5 = fit.estimate[2], fit.estimate[4]
        gradient = (0.0, 0.0, p5 / (p3 * p3), 0.0, -1.0 / p3)
        return -p5 / p3, math.sqrt(fit.variance_of(gradient, self._scale))

    @property
    def lag(self) -> float:
        """``τ_d`` (s): the drives' lag the fit found (``−p₄ / p₃``), 0 until it has one or if it
        comes out negative (Steps 5 and 7 take it up from here)."""
        fit = self._solution
        return 0.0 if fit is None else max(0.0, -fit.estimate[3] / fit.estimate[2])
