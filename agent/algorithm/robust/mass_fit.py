"""Step 7 under noise: ``m`` from the COM's displacement, not from its velocity.

Under the team's common force ``s(t) f`` (the sign ``s = ±1`` reverses on the agreed clock to
keep the floor bounded, :meth:`~agent.algorithm.phase_machine.PhaseMachine.push_sign`) the COM
accelerates at ``n s f / m`` (Step 7), so from the mass fit's first instant ``t₀``

    p_C(t) − p_C(t₀) = v₀ (t − t₀) + (n f / m) (S(t) − τ_d Σ(t) + τ_d² s(t)),
    Σ(t) = ∫_{t₀}^{t} s dt,   S(t) = ∫_{t₀}^{t} Σ dt,

linear in ``(v₀ₓ, v₀ᵧ, 1/m)`` with one row per axis (a force ``a(t)`` that every robot adds
to the push, ``push_damping``'s, adds ``n ∫∫a`` to the last regressor, lagged alike);
``τ_d`` is the drives' lag, which Step 4's fit found
(:attr:`~agent.algorithm.robust.inertia_fit.InertiaFit.lag`): a drive with a first-order lag
applies ``s/(1 + τ_d p)`` (``p`` = d/dt), whose double integral is
``S − τ_d Σ + τ_d² s/(1 + τ_d p)``; the last term's lag is left out (it only matters for a
tick after each reversal). A robot measures the displacement without
differentiating anything: ``p_C = p_Ci − o`` with ``o = p_Ci − p_C = z_i + z_C`` (Steps 2 and
5), a vector of the load that turns with it, so

    p_C(t) − p_C(t₀) = ∫_{t₀}^{t} ṗ_Ci dt − (I − R(θ(t₀) − θ(t))) o(t),

the integral of its own velocity (trapezoid) and the current estimate of ``o`` turned back by
the load's rotation since ``t₀``. Where eq. (7)'s ``ṗ_C = ṗ_Ci − ω o⊥`` carries ω's noise
times the offset (centimetres per second), the displacement's error is the velocity noise's
random walk.

On a real floor the COM also feels friction's force. While the load turns fast compared with
its COM's speed (``‖ṗ_C‖ ≪ |ω| r`` at the supports, as this experiment keeps it), Coulomb
friction at supports ``r_k`` under normal loads ``N_k`` pulls the COM back with
``μ Σ N_k r̂_k r̂_kᵀ ṗ_C / (|ω| ‖r_k‖)`` to first order, whose mean over the load's turns is
``κ ṗ_C / |ω|`` with ``κ = μ Σ N_k / (2‖r_k‖)`` (N/m, the *spin drag*): a fourth column
``−D``, ``D(t) = ∫∫ ṗ_C / |ω| = ∫ (∫ dp_C / |ω|) dt`` (the displacement's increments over
each interval divided by that interval's ``|ω|``, from the load's rotation), with the
unknown ``κ / m``, takes it up; ``κ̂`` is published (0 on a frictionless floor, within its
uncertainty). A viscous drag ``−b ṗ_C`` adds ``b |ω|`` to ``κ`` while ``ω`` is steady.

Uncertainty: the fit's ``σ̂² M⁻¹`` as it is, every row counted (over 40 runs of the paper's
scenario at 1 cm/s, seeds 0–39, the rows counted one per 0.2 s gave standard deviations eight
times the errors'); ``std(m̂) = std(1/m) m̂²``. ``heft bench calibrate correlation-time``
measures the factor on this variance again, for each robot's own ``m̂`` (the noise
benchmark's runs of seeds 0–39, before the team's consensus; a factor ``k`` is a correlation
time of ``k Δt / 2``, two rows a tick): on 2026-11-27 it printed 2.53 for 95 % of them within
1.96 standard deviations (92.5 % with every row counted), 3.14 with ``--ideal-drives``
(91.9 %). The team's ``m̂``, which is published, needs no factor
(:data:`~agent.algorithm.robust.uncertainty.PUBLISHED_VARIANCE`). The fit takes the
commanded force for the applied one; the pipeline scales its ``m`` by the drives' mean gain
(:mod:`agent.algorithm.robust.drive_gain`).
"""

from __future__ import annotations

import math

from agent.algorithm.robust.least_squares import ReciprocalFit
from agent.platform.geometry import Vec2, rotate


MIN_SPIN = 0.05
"""rad/s: the ``|ω|`` below which the spin drag's column takes this instead (a load barely
turning is outside the friction model's range; the floor keeps it from dividing by 0)."""


class MassFit(ReciprocalFit):
    """``m`` from the COM's displacement while the team pushes with ``f`` each."""

    min_rows = 20  # two rows a sample
    correlation_time = 0.0  # each row counts: measured (below)

    def __init__(self, n: int, force: Vec2, forgetting: float = 1.0, lag: float = 0.0):
        # rows [t, 0, n f_x (S − τ_d Σ), −D_x], [0, t, n f_y (…), −D_y] (v₀ₓ, v₀ᵧ, 1/m, κ/m)
        super().__init__(4, forgetting)
        self.n = n
        self.total_force = (n * force[0], n * force[1])
        self._added_once: Vec2 = (0.0, 0.0)
        self._added_twice: Vec2 = (0.0, 0.0)
        """``∫a dt`` and ``∫∫a`` of the force ``a`` each robot added to the push."""
        self.lag = lag
        self.started = False
        self._once = 0.0
        """``Σ = ∫s dt`` since the first sample."""
        self._twice = 0.0
        """``S = ∫∫s`` since the first sample."""
        self._velocity: Vec2 = (0.0, 0.0)
        self._travel: Vec2 = (0.0, 0.0)
        """``∫ṗ_Ci dt`` since the first sample."""
        self._angle0 = 0.0
        self._angle = 0.0
        self._displacement: Vec2 = (0.0, 0.0)
        self._drag_once: Vec2 = (0.0, 0.0)
        """``∫ dp_C / |ω|`` since the first sample."""
        self._drag_twice: Vec2 = (0.0, 0.0)
        """``D = ∫∫ ṗ_C / |ω|`` since the first sample."""

    def update(
        self,
        velocity: Vec2,
        offset: Vec2,
        angle: float,
        sign: float,
        dt: float,
        *,
        added: Vec2 = (0.0, 0.0),
    ) -> None:
        """Feed the robot's contact velocity ``ṗ_Ci``, the offset ``o = p_Ci − p_C`` and the
        load's rotation ``angle`` at the end of an interval ``dt`` of pushing with the mean
        sign ``sign`` and the mean force ``added`` each robot added to it (the first call
        starts)."""
        if not self.started:
            self.started = True
            self._velocity, self._angle0 = velocity, angle
            self._angle = angle
            return
        v0 = self._velocity
        travel = self._travel
        self._travel = (
            travel[0] + 0.5 * dt * (v0[0] + velocity[0]),
            travel[1] + 0.5 * dt * (v0[1] + velocity[1]),
        )
        self._velocity = velocity
        self.t += dt
        self._twice += dt * self._once + 0.5 * sign * dt * dt
        self._once += sign * dt
        (ox, oy), (tx, ty) = self._added_once, self._added_twice
        self._added_twice = (
            tx + dt * ox + 0.5 * added[0] * dt * dt,
            ty + dt * oy + 0.5 * added[1] * dt * dt,
        )
        self._added_once = (ox + added[0] * dt, oy + added[1] * dt)
        back = rotate(offset, self._angle0 - angle)
        dx = self._travel[0] - (offset[0] - back[0])
        dy = self._travel[1] - (offset[1] - back[1])
        t, (fx, fy), lag = self.t, self.total_force, self.lag
        pushed = self._twice - lag * self._once + lag * lag * sign
        (ox, oy), (tx, ty) = self._added_once, self._added_twice
        ax = self.n * (tx - lag * ox + lag * lag * added[0])
        ay = self.n * (ty - lag * oy + lag * lag * added[1])
        # Friction's spin drag: the displacement's increment over |ω| (ω from the rotation).
        spin = max(abs(angle - self._angle) / dt, MIN_SPIN)
        self._angle = angle
        (px, py), (qx, qy) = self._displacement, self._drag_once
        once = (qx + (dx - px) / spin, qy + (dy - py) / spin)
        self._displacement, self._drag_once = (dx, dy), once
        twice = self._drag_twice
        self._drag_twice = (
            twice[0] + 0.5 * dt * (qx + once[0]),
            twice[1] + 0.5 * dt * (qy + once[1]),
        )
        (drag_x, drag_y) = self._drag_twice
        self.fit.add((t, 0.0, pushed * fx + ax, -drag_x), dx)
        self.fit.add((0.0, t, pushed * fy + ay, -drag_y), dy)
        self._solve()

    def spin_drag(self, gain: float = 1.0) -> tuple[float, float] | None:
        """``(κ̂, σ)`` (N/m): the floor's spin drag ``κ = p₄/p₃`` times the drives' mean
        ``gain`` (which scales ``m̂`` alike), and its standard deviation (first order)."""
        fit = self._solution
        if fit is None:
            return None
        p3, p4 = fit.estimate[2], fit.estimate[3]
        gradient = (0.0, 0.0, -p4 / (p3 * p3), 1.0 / p3)
        return gain * p4 / p3, gain * math.sqrt(fit.variance_of(gradient, self._scale))
