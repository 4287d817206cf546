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
random walk. The fit's rows are the model's *steps* from one sample to the next (each row and
its target minus the previous sample's): a random walk's steps are independent where its values
are not (the least-squares fit of a random walk's steps is its generalized least squares), so
the fit's ``σ̂² M⁻¹`` means what it says. Fitted on the displacements themselves, each
robot's ``m̂`` on generated load 14 (32.9 kg under three robots, μ = 2.2 %, nine runs of the
noise benchmark's noise with other seeds) was 1.5 % off (root mean square) where the fit gave
0.1 %; on its steps, 0.9 % off where it gives 0.4 % (the trapezoid's neighbouring steps share a
sample, and the fit takes the direction ``v̂_C`` and the gains as known: what the rest is was not
measured).

On a real floor the load slides or rolls against Coulomb friction at its supports. The team
measures the mass while the load translates without turning (the push's *translation* stage,
:mod:`agent.algorithm.robust.phases`): every support then moves with the COM, so friction's
force is exactly ``−μ m g v̂_C`` (``v̂_C`` the COM's direction of motion, whatever the supports'
layout) and its torque about the COM is zero. A fourth column ``−C(t)``,
``C = ∫∫ v̂_C``, with the unknown ``μ g`` takes it up (the COM's velocity ``ṗ_C`` is Step 6's,
taken to change linearly over each interval, so that a reversal within one turns ``v̂_C``
where the velocity passes closest to zero: :func:`_directions`): ``μ̂`` is published (0 on a
frictionless floor, within its uncertainty).

Uncertainty: the fit's ``σ̂² M⁻¹`` as it is, every row counted; ``std(m̂) = std(1/m) m̂²``.
``heft bench calibrate correlation-time --generated --coulomb-range 0.005 0.03 --first-seed 80
--seeds 120`` measures the factor on the fit's share of each robot's own ``m̂``'s variance (the
noise benchmark's runs of the generated loads on floors, before the team's consensus; a factor
``k`` is a correlation time of ``k Δt / 2``, two rows a tick): on 2026-11-29, fitted on the
steps, it printed 3.8 for 95 % of them within 1.96 standard deviations (84.2 % with every row
counted; the fit's share is 64 % of the variance, the offset's and the gains' the rest). Each
row stays counted: the team's ``m̂``, which Step 7 settles by and the team publishes, weighs
the robots' fits by this variance, and has its own factor
(:data:`~agent.algorithm.robust.uncertainty.PUBLISHED_VARIANCE`). The fit takes the
commanded force for the applied one; the pipeline scales its ``m`` by the drives' mean gain
(:mod:`agent.algorithm.robust.drive_gain`).

The offset ``o`` is known only as well as Steps 2 and 5 made it: off by ``δ``, it moves every
target by ``(R(α) − I) δ₀`` (``δ₀`` at the fit's first instant, ``α`` the turn since), nothing
while the load translates without turning, but a push through a COM far from the true one
turns it. The estimates are linear in the targets, ``p̂ = M⁻¹ Σ a_k y_k``, so that error moves
them by ``M⁻¹ Σ a_k g_kᵀ δ₀`` (``g_k`` how row ``k``'s target moves per unit ``δ₀``: a step's
by ``(R(α_k) − R(α_{k−1})) δ₀``), and with
``δ₀`` of the offset's published standard deviation ``σ_o`` per axis (the pipeline gives Step 5's,
:attr:`offset_std`) ``m̂``'s and ``μ̂``'s variances carry ``σ_o² ‖(M⁻¹ Σ a_k g_kᵀ)_j‖²`` beside
the fit's own. Generated load 47 (10.5 kg, its COM 1.3 m from its three contacts' centroid,
on μ = 1.65 %) left Step 5 with ``ẑ_C`` 30 cm off, its standard deviation 28 cm; its push
turned it, and its ``m̂`` was 37 % off behind a published ±9.5 %. Now its robots' ``m̂`` are
known to no better than 18 %: the team publishes no mass, and a simulated run ends with the
verdict "mass not determined".
"""

from __future__ import annotations

import math

from agent.algorithm.robust.least_squares import ReciprocalFit
from agent.platform.geometry import Vec2, rotate
from agent.platform.protocol import GRAVITY

TURNING = 0.9
"""``v̂₀ · v̂₁`` below which an interval's direction of motion is integrated over
:data:`PIECES` pieces of it (the velocity passed near zero, or turned fast), not as a
trapezoid."""
PIECES = 8


class MassFit(ReciprocalFit):
    """``m`` from the COM's displacement while the team pushes with ``f`` each."""

    min_rows = 20  # two rows a sample
    correlation_time = 0.0  # each row counts: measured (below)

    def __init__(
        self,
        n: int,
        force: Vec2,
        forgetting: float = 1.0,
        lag: float = 0.0,
        offset_std: float = 0.0,
    ):
        # rows: the steps of [t, 0, n f_x (S − τ_d Σ), −C_x], [0, t, n f_y (…), −C_y]
        # (v₀ₓ, v₀ᵧ, 1/m, μ g) from one sample to the next
        super().__init__(4, forgetting)
        self.offset_std = offset_std
        """m: the standard deviation of the offset ``o`` the fit is given (per axis)."""
        self._offset_rows = [0.0] * (2 * self.fit.params)
        """``Σ a_k g_kᵀ`` (params × 2, row-major): each row ``a_k`` times how an error ``δ`` of
        the offset moves its target, ``g_k = ((R(α) − I) δ)``'s coefficients (see
        :meth:`_offset_variance`)."""
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
        self._direction: Vec2 = (0.0, 0.0)
        self._sliding_once: Vec2 = (0.0, 0.0)
        self._sliding_twice: Vec2 = (0.0, 0.0)
        """``C = ∫∫ v̂_C`` since the first sample."""
        zero = (0.0, 0.0, 0.0, 0.0)
        self._previous = ((zero, 0.0), (zero, 0.0), (0.0, 0.0))
        """The last sample's rows and targets, and its ``(cos α − 1, sin α)``: the steps' start."""

    def update(
        self,
        velocity: Vec2,
        offset: Vec2,
        angle: float,
        sign: float,
        dt: float,
        *,
        added: Vec2 = (0.0, 0.0),
        com_velocity: Vec2 | None = None,
    ) -> None:
        """Feed the robot's contact velocity ``ṗ_Ci``, the offset ``o = p_Ci − p_C``, the
        load's rotation ``angle`` and the COM's velocity ``com_velocity`` (Step 6) at the end
        of an interval ``dt`` of pushing with the mean sign ``sign`` and the mean force
        ``added`` each robot added to it (the first call starts)."""
        moving = com_velocity or (0.0, 0.0)
        if not self.started:
            self.started = True
            self._velocity, self._angle0 = velocity, angle
            self._direction = moving
            return
        once, twice = _directions(self._direction, moving, dt)
        (cx, cy), (qx, qy) = self._sliding_once, self._sliding_twice
        self._sliding_twice = (qx + dt * cx + twice[0], qy + dt * cy + twice[1])
        self._sliding_once = (cx + once[0], cy + once[1])
        self._direction = moving
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
        slid_x, slid_y = self._sliding_twice
        row_x, row_y = (t, 0.0, pushed * fx + ax, -slid_x), (0.0, t, pushed * fy + ay, -slid_y)
        (px, pdx), (py, pdy), (pc1, ps1) = self._previous
        step_x = tuple(a - b for a, b in zip(row_x, px))
        step_y = tuple(a - b for a, b in zip(row_y, py))
        self.fit.add(step_x, dx - pdx)
        self.fit.add(step_y, dy - pdy)
        turned = angle - self._angle0
        c1, s1 = math.cos(turned) - 1.0, math.sin(turned)
        self._previous = ((row_x, dx), (row_y, dy), (c1, s1))
        g1, h1 = c1 - pc1, s1 - ps1
        cross, lam = self._offset_rows, self.fit.forgetting
        for i in range(self.fit.params):  # the steps move by (g δx − h δy, h δx + g δy)
            ax_, ay_ = step_x[i], step_y[i]
            cross[2 * i] = lam * cross[2 * i] + ax_ * g1 + ay_ * h1
            cross[2 * i + 1] = lam * cross[2 * i + 1] - ax_ * h1 + ay_ * g1
        self._solve()

    def _offset_variance(self, index: int) -> float:
        """``Var(p̂_index)`` from the offset's uncertainty: the fit's targets move by
        ``(R(α) − I) δ₀`` for an offset off by ``δ`` (``δ₀`` at the fit's first instant, ``α``
        the load's turn since), so ``∂p̂/∂δ₀ = M⁻¹ Σ a_k g_kᵀ``, and with ``δ₀`` of
        :attr:`offset_std` per axis its variance is ``σ_o² ‖(M⁻¹ Σ a_k g_kᵀ)_index‖²``. Zero
        while the load does not turn; it grows with the turn that Step 7's push off an
        uncertain COM gives the load (generated load 47, 10.5 kg on a floor of μ = 1.65 %:
        ``ẑ_C`` off by 30 cm, ``m̂`` 37 % off behind a published standard deviation of 4.9 %)."""
        fit = self._solution
        if fit is None or self.offset_std <= 0.0:
            return 0.0
        inverse, cross, p = fit.inverse, self._offset_rows, self.fit.params
        gx = sum(inverse[index * p + j] * cross[2 * j] for j in range(p))
        gy = sum(inverse[index * p + j] * cross[2 * j + 1] for j in range(p))
        return self.offset_std**2 * (gx * gx + gy * gy)

    def _solve(self) -> None:
        super()._solve()
        fit = self._solution
        if fit is not None and self._std is not None:
            p = fit.estimate[self.index]
            self._std = math.hypot(
                self._std, math.sqrt(self._offset_variance(self.index)) / (p * p)
            )

    @property
    def coulomb(self) -> tuple[float, float] | None:
        """``(μ̂, σ)``: the floor's kinetic friction coefficient ``p₄ / g`` and its standard
        deviation (``None`` before the fit)."""
        fit = self._solution
        if fit is None:
            return None
        gradient = (0.0, 0.0, 0.0, 1.0)
        std = math.sqrt(fit.variance_of(gradient, self._scale) + self._offset_variance(3))
        return fit.estimate[3] / GRAVITY, std / GRAVITY


def _unit(v: Vec2) -> Vec2:
    """``v / ‖v‖`` (``(0, 0)`` for ``v = 0``)."""
    speed = math.hypot(v[0], v[1])
    return (0.0, 0.0) if speed == 0.0 else (v[0] / speed, v[1] / speed)


def _directions(before: Vec2, after: Vec2, dt: float) -> tuple[Vec2, Vec2]:
    """``(∫ v̂ ds, ∫ (dt − s) v̂ ds)`` over an interval ``dt`` in which the velocity goes
    linearly from ``before`` to ``after``: the trapezoid's while ``v̂`` barely turns, else the
    midpoints of :data:`PIECES` pieces."""
    u0, u1 = _unit(before), _unit(after)
    if u0[0] * u1[0] + u0[1] * u1[1] >= TURNING:
        return (
            (0.5 * dt * (u0[0] + u1[0]), 0.5 * dt * (u0[1] + u1[1])),
            (dt * dt * (u0[0] / 3.0 + u1[0] / 6.0), dt * dt * (u0[1] / 3.0 + u1[1] / 6.0)),
        )
    h = dt / PIECES
    ox = oy = tx = ty = 0.0
    for j in range(PIECES):
        s = (j + 0.5) / PIECES
        ux, uy = _unit(
            (before[0] + s * (after[0] - before[0]), before[1] + s * (after[1] - before[1]))
        )
        ox += h * ux
        oy += h * uy
        tx += h * (dt - s * dt) * ux
        ty += h * (dt - s * dt) * uy
    return (ox, oy), (tx, ty)
