"""The floor's friction on the plant's load (``[ground]``, :class:`~simulator.scenario.Ground`).

The model. The load rests on supports ``s_k`` carrying the normal loads ``N_k``
(:meth:`Ground.loads`: ``Σ N_k = m g``, ``Σ N_k r_k = 0`` with ``r_k`` the support's arm from
the COM). Support ``k`` moves at ``u_k = ṗ_C + ω r_k⊥``. While it slides, the floor pushes it
back with ``−μ N_k u_k / ‖u_k‖``; while the load sticks, with whatever holds it still, up to
``μ_s N_k`` at each support. The load feels the sum of these forces and their torque about the
COM, coupled as on a real floor: a load that turns as it slides meets less resistance to either
than to each alone, and a wrench the supports can hold leaves it where it is. Viscous drag at
each support, ``−b (N_k / m g) u_k``, sums to ``−b ṗ_C`` and ``−b ρ² ω`` exactly
(``ρ² = Σ N_k ‖r_k‖² / m g``, and ``Σ N_k r_k = 0``), so it is applied as that force and torque.

Three regimes, by the load's kinetic energy ``E = ½ m ‖ṗ_C‖² + ½ J ω² = ½ σ²`` (one number to
read per physics step; :meth:`GroundContact.set_loads` sets the bounds). In one physics step of
``dt`` friction changes ``σ`` by at most ``δσ(μ) = μ g dt (√m + m c / √J)``: its force is at
most ``μ m g``, its torque ``μ m g c``.

- *sliding* (``σ ≥ 2 δσ(μ)``): each support's Coulomb force is computed for its velocity at the
  start of each physics step and applied with the robots' forces (:meth:`SupportFriction.coulomb`):
  friction cannot turn the load back within a step. A support slower than what its own friction
  changes its speed by in a step (near the centre of a turn) is pushed back in proportion to its
  speed, so that it comes to rest instead of its force flipping from step to step;
- *slow* (below): Chipmunk's velocity-level friction, one ``PivotJoint`` per support between the
  static body and the load with ``max_bias = 0`` (it restores no position, only the support's
  velocity) and ``max_force = μ N_k``. At each step its solver looks for impulses
  ``‖p_k‖ ≤ μ N_k dt`` that bring the supports to rest: the load stops without overshooting.
  (The solver clamps each support's impulse to its disc in the plain norm, not in that of the
  support's effective mass, so a slow support's friction is off its exact direction by up to
  that mass's anisotropy, ``1 + m ‖r_k‖² / J``: a few per cent of a slow load's deceleration.
  Only the last mm/s to cm/s of a stop are slow, about a tick.);
- *stuck*: once ``σ`` is below ``√m`` :data:`STICK_SPEED` (or ``2 δσ(μ_s − μ)`` if more: what
  a stop with the kinetic limit can leave while the robots push on within the static one) and
  the supports can hold the robots' wrench (:meth:`SupportFriction.holds`, with ``μ_s``), the
  load is at rest: its velocity is set to zero and the floor balances the robots exactly at
  every step, for as long as their wrench stays within the static limit (no chatter, no drift).
  A wrench beyond it breaks the load away: it is slow again, with ``μ``.

The slow regime is left for sliding at four times the energy it is entered below (hysteresis: a
load that hovers at the bound does not switch at every step).

Viscous drag over a physics step decays the velocity as the linear law does,
``ṗ_C ← ṗ_C e^{−b dt/m}`` when nothing else acts: the force applied through the step is
``−m (1 − e^{−b dt/m}) / dt · ṗ_C``, and likewise ``−J (1 − e^{−b ρ² dt/J}) / dt · ω``, stable
for any ``b``.

What the floor did: Chipmunk integrates the velocities as ``ṗ_C ← ṗ_C + (f / m) dt`` and then
adds the joints' impulses ``/ m``; so over a tick, the floor's mean force is
``(m Δṗ_C − Σ f dt) / T`` and its mean torque about the COM ``(J Δω − Σ τ dt) / T``, with
``f`` and ``τ`` the robots' force and torque at each step (:attr:`GroundContact.force`,
:attr:`GroundContact.torque`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import pymunk
from pymunk import Vec2d

from agent.platform.geometry import Vec2
from agent.platform.protocol import GRAVITY

if TYPE_CHECKING:
    from simulator.integrator import PoseCorrection
    from simulator.scenario import Ground, SupportLoads

STICK_SPEED = 1e-4
"""m/s: a load slower than this (as kinetic energy, ``½ m STICK_SPEED²``) may stick: a deadband
as in Karnopp's stick-slip model, far below the speeds the agents drive the load at (cm/s and
more)."""
HYSTERESIS = 4.0
"""The slow regime is entered below an energy and left at this many times it."""
HOLD_TOLERANCE = 1e-9
"""A wrench within this fraction of the static limit's figures beyond it is held (rounding)."""
MAX_NEWTON_STEPS = 50
"""Newton steps of :meth:`SupportFriction.holds` at the most (it takes a handful)."""
SLIDING, SLOW, STUCK = "sliding", "slow", "stuck"


class SupportFriction:
    """Coulomb friction of supports at load-frame arms ``r_k`` (from the COM) with limits
    ``C_k`` (N): the wrench on a sliding load, and whether the supports hold a wrench."""

    def __init__(self, arms: Sequence[Vec2], limits: Sequence[float], creep: float = 0.0) -> None:
        self._arms = np.array(arms, dtype=float).reshape(-1, 2)
        self.creep = max(creep, 1e-300)
        """m/s: ``u_s``, the speed below which a support's force is ``C_k u_k / u_s``
        (:meth:`coulomb`)."""
        self._limits = np.array(limits, dtype=float)
        self._moments = np.column_stack(
            (np.ones(len(self._arms)), self._arms, (self._arms**2).sum(axis=1))
        )
        """Per support: ``1, r_x, r_y, ‖r‖²``."""
        self.force_limit = float(self._limits.sum())
        """``Σ C_k``: the largest force (a pure translation's friction)."""
        self.torque_limit = float(self._limits.dot(np.sqrt(self._moments[:, 3])))
        """``Σ C_k ‖r_k‖``: the largest torque about the COM (a pure spin's friction)."""
        self._length = self.torque_limit / self.force_limit if self.force_limit > 0 else 1.0
        """m: ``L``, the unit of :meth:`_least_power`'s arms."""
        self._scaled_arms = self._arms / self._length
        count = len(self._arms)
        self._jacobians = np.stack(
            (
                np.column_stack((np.ones(count), np.zeros(count), -self._scaled_arms[:, 1])),
                np.column_stack((np.zeros(count), np.ones(count), self._scaled_arms[:, 0])),
            ),
            axis=1,
        )
        """``J_k`` (K × 2 × 3): ``u_k = J_k V``, scaled units."""
        self._best: np.ndarray | None = None
        """The last minimiser :meth:`holds` found (a twist, scaled units)."""

    def coulomb(self, vx: float, vy: float, w: float) -> tuple[float, float, float]:
        """The force (load frame) and torque about the COM of the supports sliding with the
        COM's velocity ``(vx, vy)`` (load frame) and the angular velocity ``w``:
        ``F = −Σ C_k u_k / ‖u_k‖``, ``τ = −Σ C_k r_k × u_k / ‖u_k‖``.

        With ``s_k = C_k / ‖u_k‖``, ``S_0 = Σ s_k``, ``S_1 = Σ s_k r_k`` and
        ``S_2 = Σ s_k ‖r_k‖²``: ``F = −(S_0 v + ω S_1⊥)``, ``τ = −(S_1 × v + ω S_2)``, and
        ``‖u_k‖² = ‖v‖² + 2ω (v_y r_x − v_x r_y) + ω² ‖r_k‖²``.

        A support slower than :attr:`creep`, ``u_s``, is pushed back by ``C_k u_k / u_s``
        instead (``s_k = C_k / max(‖u_k‖, u_s)``): one near the centre of a turn would have its
        full force flip from step to step as it passes through rest; ``u_s`` is the most its own
        friction changes its speed in a step, so it comes to rest without overshooting."""
        moments = self._moments
        s = moments.dot((vx * vx + vy * vy, 2.0 * w * vy, -2.0 * w * vx, w * w))
        np.maximum(s, 0.0, out=s)  # ‖u_k‖² of a support at rest may round below 0
        np.sqrt(s, out=s)
        np.maximum(s, self.creep, out=s)
        np.divide(self._limits, s, out=s)
        s0, s1x, s1y, s2 = s.dot(moments).tolist()
        return -(s0 * vx - w * s1y), -(s0 * vy + w * s1x), -(s1x * vy - s1y * vx + w * s2)

    def holds(self, fx: float, fy: float, tau: float) -> bool:
        """Whether the supports hold the load still against the force ``(fx, fy)`` (load frame)
        and the torque ``tau`` about the COM.

        They do iff the wrench ``w = (F, τ)`` lies in the limit set
        ``S = {(Σ q_k, Σ r_k × q_k) : ‖q_k‖ ≤ C_k}``, whose support function is the
        friction's power ``Φ(V) = Σ C_k ‖u_k‖`` for the twist ``V = (v, ω)``: iff no motion
        takes more power from the wrench than friction takes, ``wᵀV ≤ Φ(V)``. Both sides are
        homogeneous, so: iff ``min Φ(V) ≥ 1`` over the plane ``wᵀV = 1`` (convex, and finite
        as the supports are not on one line). Wrenches within the diamond of the force and
        torque limits, ``‖F‖ / Σ C_k + |τ| / Σ C_k ‖r_k‖ ≤ 1``, are held at once (``S`` is
        convex and holds its corners); wrenches beyond either limit are not. The others
        minimise over the plane: first at the kinks of ``Φ``, the twists that turn the load
        about one support (often the minimum with few supports), then by Newton's method from
        the lowest of them or from the last minimiser (smoothing ``‖u‖`` by 1e-6 of the
        supports' reach)."""
        force = math.hypot(fx, fy)
        torque_limit, force_limit = self.torque_limit, self.force_limit
        slack = 1.0 + HOLD_TOLERANCE
        if force > force_limit * slack or abs(tau) > torque_limit * slack:
            return False
        if force * torque_limit + abs(tau) * force_limit <= force_limit * torque_limit:
            return True
        return self._least_power(fx, fy, tau) >= 1.0 - HOLD_TOLERANCE

    def _least_power(self, fx: float, fy: float, tau: float) -> float:
        """``min Φ(V)`` over ``wᵀV = 1`` (see :meth:`holds`), in units where the torque is
        divided by the length ``L = Σ C_k ‖r_k‖ / Σ C_k`` (and ``ω`` multiplied by it)."""
        arms, limits = self._scaled_arms, self._limits
        w = np.array((fx, fy, tau / self._length))
        # The plane: V = w / ‖w‖² + B z, with B's columns orthonormal and orthogonal to w.
        origin = w / w.dot(w)
        wx, wy, wt = w
        first = (0.0, wt, -wy) if abs(wx) < abs(wy) else (-wt, 0.0, wx)  # w × a unit axis
        second = (
            wy * first[2] - wt * first[1],
            wt * first[0] - wx * first[2],
            wx * first[1] - wy * first[0],
        )
        basis = np.column_stack((first, second))
        basis /= np.sqrt((basis**2).sum(axis=0))
        # Φ's kinks: the load turning about support j, V ∝ (−r_j⊥, 1) = (r_jy, −r_jx, 1).
        about = np.column_stack((arms[:, 1], -arms[:, 0], np.ones(len(arms))))
        reach = about.dot(w)
        kinks = about[np.abs(reach) > 1e-12] / reach[np.abs(reach) > 1e-12, None]
        starts = [] if self._best is None else [(self._best - origin).dot(basis)]
        if len(kinks):
            powers = self._powers(kinks)
            best = int(np.argmin(powers))
            if powers[best] < 1.0 - HOLD_TOLERANCE:
                return float(powers[best])
            starts.append((kinks[best] - origin).dot(basis))
        along = self._jacobians.dot(basis)  # u_k = along_k z + offset_k
        offset = self._jacobians.dot(origin)
        products = np.einsum("kij,kil->kjl", along, along).reshape(-1, 4)  # along_kᵀ along_k
        eps2 = 1e-12 * float((arms**2).sum(axis=1).max())

        def power(z: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
            u = offset + along.dot(z)
            n = np.sqrt((u**2).sum(axis=1) + eps2)
            return float(limits.dot(n)), u, n

        z = min(starts, key=lambda s: power(s)[0]) if starts else np.zeros(2)
        value, u, n = power(z)
        for _ in range(MAX_NEWTON_STEPS):
            if value < 1.0 - HOLD_TOLERANCE:
                break
            slopes = (along * (u / n[:, None])[:, :, None]).sum(axis=1)  # ∂‖u_k‖/∂z
            gradient = limits.dot(slopes)
            weights = limits / n
            (hxx, hxy, _, hyy), (sxx, sxy), (_, syy) = (
                weights.dot(products).tolist(),
                *(slopes.T * weights).dot(slopes).tolist(),
            )
            hxx, hxy, hyy = hxx - sxx, hxy - sxy, hyy - syy
            hxx, hyy = hxx + 1e-12 * (hxx + hyy), hyy + 1e-12 * (hxx + hyy)
            gx, gy = gradient.tolist()
            det = hxx * hyy - hxy * hxy
            step = np.array(((hyy * gx - hxy * gy) / det, (hxx * gy - hxy * gx) / det))
            decrement = float(gradient.dot(step))
            if decrement < 1e-14:
                break
            t = 1.0
            candidate, cu, cn = power(z - step)
            while candidate > value - 0.25 * t * decrement and t > 1e-8:
                t *= 0.5
                candidate, cu, cn = power(z - t * step)
            if candidate >= value:
                break
            z, value, u, n = z - t * step, candidate, cu, cn
        self._best = origin + basis.dot(z)
        return value

    def _powers(self, twists: np.ndarray) -> np.ndarray:
        """``Φ`` of each row of ``twists`` (scaled units, see :meth:`_least_power`)."""
        arms = self._scaled_arms
        ux = twists[:, None, 0] - twists[:, None, 2] * arms[None, :, 1]
        uy = twists[:, None, 1] + twists[:, None, 2] * arms[None, :, 0]
        return np.hypot(ux, uy).dot(self._limits)


class GroundContact:
    """The floor under a pymunk body: :meth:`step` is one physics step with the floor's
    friction; :meth:`start_tick` and :meth:`end_tick` bracket a sensor period to measure what
    the floor did over it (see the module docstring)."""

    def __init__(
        self,
        space: pymunk.Space,
        body: pymunk.Body,
        ground: Ground,
        dt: float,
        pose: PoseCorrection,
    ) -> None:
        self._space, self._body, self._dt = space, body, dt
        self._pose = pose
        """Where the force and torque of each step the load moves freely are summed for the
        pose's second-order term (:mod:`simulator.integrator`)."""
        self.ground = ground
        self.loads: SupportLoads
        """The normal loads and friction figures now (:meth:`set_loads`)."""
        self._joints: list[pymunk.PivotJoint] = []
        if ground.static > 0.0:
            for s in ground.supports:
                joint = pymunk.PivotJoint(space.static_body, body, body.local_to_world(s), s)
                joint.max_bias = 0.0  # no position to restore: only the support's velocity
                self._joints.append(joint)
        self.regime = SLIDING
        """``sliding``, ``slow`` or ``stuck`` (see the module docstring)."""
        self._coulomb = ground.coulomb > 0.0
        self._kinetic = self._static = SupportFriction((), ())
        self._slow_energy = self._stick_energy = self._damp_v = self._damp_w = 0.0
        self._held: tuple[float, float, float] | None = None
        """The robots' force and torque (``W``) the floor last held the load against."""
        self.force: Vec2 = (0.0, 0.0)
        """The floor's force on the load averaged over the last tick (N, ``W``)."""
        self.torque: float = 0.0
        """Its torque about the COM, averaged likewise (N m)."""
        self._start = (0.0, 0.0, 0.0)
        """The load's ``ṗ_C`` and ``ω`` as the tick began."""
        self._fx = self._fy = self._tau = 0.0
        """The robots' force and torque summed over the tick's steps."""
        self.set_loads()

    def set_loads(self) -> None:
        """Take the body's mass, moment and COM as they are now: the normal loads, the
        supports' arms and limits, the regimes' energies and the drag's factors (at the start,
        and after every load change)."""
        body, ground, dt = self._body, self.ground, self._dt
        m, j = body.mass, body.moment
        com = body.center_of_gravity
        self.loads = loads = ground.loads(m, (com.x, com.y))
        arms = [(x - com.x, y - com.y) for x, y in ground.supports]
        reach2 = max(x * x + y * y for x, y in arms)
        # the most one support's friction changes its speed in a step, C_k dt (1/m + R²/J)
        creep = ground.coulomb * max(loads.normal) * dt * (1.0 / m + reach2 / j)
        self._kinetic = SupportFriction(arms, [ground.coulomb * n for n in loads.normal], creep)
        self._static = SupportFriction(arms, [ground.static * n for n in loads.normal])
        reach = GRAVITY * dt * (math.sqrt(m) + m * loads.friction_radius / math.sqrt(j))
        """``δσ(μ) / μ``."""
        stick = max(STICK_SPEED * math.sqrt(m), 2.0 * (ground.static - ground.coulomb) * reach)
        self._stick_energy = 0.5 * stick**2 if self._joints else 0.0
        slow = 0.5 * (2.0 * ground.coulomb * reach) ** 2
        self._slow_energy = max(slow, self._stick_energy) if self._joints else 0.0
        b, rho2 = ground.viscous, loads.viscous_radius2
        self._damp_v = m * -math.expm1(-b * dt / m) / dt
        self._damp_w = j * -math.expm1(-b * rho2 * dt / j) / dt
        self._held = None  # the limits changed: hold again only what the new ones hold
        if self.regime == SLOW:
            self._limit_joints()
        elif self.regime == SLIDING and body.kinetic_energy < self._slow_energy:
            self._enter(SLOW)

    def _enter(self, regime: str) -> None:
        """Switch to ``regime``: the joints in the space with the kinetic limits when slow,
        out of it otherwise; at rest when stuck."""
        space, joints, was = self._space, self._joints, self.regime
        if regime == SLOW and was != SLOW:
            space.add(*joints)
            self._limit_joints()
        elif was == SLOW and regime != SLOW:
            space.remove(*joints)
        if regime == STUCK:
            self._body.velocity = (0.0, 0.0)
            self._body.angular_velocity = 0.0
        self.regime = regime

    def _limit_joints(self) -> None:
        for joint, normal in zip(self._joints, self.loads.normal):
            joint.max_force = self.ground.coulomb * normal

    def _holds(self, force: Vec2d, torque: float, c: float, s: float) -> bool:
        """Whether the supports hold the load still against the robots' ``force`` (``W``) and
        ``torque``, the load at the angle of cosine ``c`` and sine ``s``: at once if they held
        these last; else by :meth:`SupportFriction.holds`."""
        wrench = (force.x, force.y, torque)
        if wrench == self._held:
            return True
        if self._static.holds(c * force.x + s * force.y, c * force.y - s * force.x, torque):
            self._held = wrench
            return True
        return False

    def start_tick(self) -> None:
        """Begin a sensor period: remember the load's velocity."""
        body = self._body
        v = body.velocity
        self._start = (v.x, v.y, body.angular_velocity)
        self._fx = self._fy = self._tau = 0.0

    def step(self, force: Vec2d, torque: float, cos: float, sin: float) -> None:
        """One physics step of ``dt`` with the robots' ``force`` (at the COM, ``W``) and
        ``torque`` (about the COM), and the floor's friction; ``cos`` and ``sin`` are the load's
        angle's."""
        body = self._body
        self._fx += force.x
        self._fy += force.y
        self._tau += torque
        regime = self.regime
        energy = body.kinetic_energy
        if regime == STUCK:
            if energy == 0.0 and self._holds(force, torque, cos, sin):
                self._space.step(self._dt)  # at rest, the floor balancing the robots
                return
            regime = SLOW  # broken away (or set moving from outside)
        if regime == SLIDING:
            if energy < self._slow_energy:
                regime = SLOW
        elif energy >= HYSTERESIS * self._slow_energy and self._slow_energy > 0.0:
            regime = SLIDING
        if regime == SLOW and energy < self._stick_energy and self._holds(force, torque, cos, sin):
            regime = STUCK
        if regime != self.regime:
            self._enter(regime)
            if regime == STUCK:
                self._space.step(self._dt)
                return
        if regime == SLIDING and self._coulomb:
            v, w, c, s = body.velocity, body.angular_velocity, cos, sin
            fx, fy, tau = self._kinetic.coulomb(c * v.x + s * v.y, c * v.y - s * v.x, w)
            felt = Vec2d(
                force.x + c * fx - s * fy - self._damp_v * v.x,
                force.y + s * fx + c * fy - self._damp_v * v.y,
            )
            felt_torque = torque + tau - self._damp_w * w
        elif self._damp_v:
            felt = force - body.velocity * self._damp_v
            felt_torque = torque - body.angular_velocity * self._damp_w
        else:
            felt, felt_torque = force, torque
        body.force = felt
        body.torque = felt_torque
        if regime != SLOW:
            # (slow: the joints' impulses act too; a stop's last mm/s, left to Chipmunk alone)
            self._pose.add(felt.x, felt.y, felt_torque)
        self._space.step(self._dt)

    def end_tick(self, period: float) -> None:
        """End a sensor period of ``period`` s: :attr:`force` and :attr:`torque` over it."""
        body, dt = self._body, self._dt
        vx, vy, w = self._start
        v = body.velocity
        self.force = (
            (body.mass * (v.x - vx) - self._fx * dt) / period,
            (body.mass * (v.y - vy) - self._fy * dt) / period,
        )
        self.torque = (body.moment * (body.angular_velocity - w) - self._tau * dt) / period
