"""The plant: a pymunk rigid body standing in for the real load and the robots' drivers.

The agents never see this module's state directly. Each sensor tick they get one
:class:`~agent.platform.protocol.Measurement` per robot from :meth:`Plant.measure` (the velocity of
the robot's contact point and the force it applied, both with optional Gaussian noise), and they
answer with :meth:`Plant.command` (the force to apply until the next tick).
:meth:`Plant.advance` then integrates one sensor period. :meth:`Plant.truth` exposes the ground
truth for evaluation only, with the load's excursion over every tick so far (its largest travel
from the start, speed and ``|ω|``: what the scenario's floor is checked against).

Conventions (those of the paper, Sec. II):

- Frames: the world frame ``W`` and the load frame, whose origin sits at
  ``scenario.body.position`` and whose angle in ``W`` is ``scenario.body.angle`` at ``t = 0``.
  The polygon, the COM and the contact points of the scenario are given in the load frame.
- ``Q = [[0, -1], [1, 0]]``, ``v⊥ = Q v``; the torque of ``f_i`` applied at ``C_i`` is
  ``τ_i = (p_Ci − p_C)⊥ᵀ f_i``; a rigid body obeys ``ṗ_Ci = ṗ_C + ω (p_Ci − p_C)⊥``.
- ``p_G`` is the centroid of the contact points, ``z_i = p_Ci − p_G``, ``z_C = p_G − p_C``.
- Robot ids are ``1..n``; robot ``i`` pushes at ``scenario.contacts[i - 1]``.
- Tick ``k`` is the instant ``t_k = k / rate_hz``. A force commanded after sample ``k`` is held
  constant (in ``W``) during ``[t_k, t_{k+1}]`` and reported by the measurement of tick ``k + 1``.

Actuators (``scenario.actuators``, ideal by default as in the paper): robot ``i`` commanded
``u_i`` applies ``f_i`` with ``τ ḟ_i = g_i u_i + w_i − f_i``, integrated exactly per physics
substep for the target held over the tick (``f ← t + (f − t) e^{−Δt/τ}``); its measurement
reports ``f_i`` averaged over the tick's substeps (what the load felt), plus the sensor's noise.
The gains and the actuator noise come from a random stream of their own (:data:`ACTUATOR_STREAM`),
so a run's sensor noise is the same with actuators ideal or not.

Velocity-commanded bases (``scenario.agvs``, ``profile = "velocity"``): each robot is a base
with a speed loop holding the load through a spring and damper (:mod:`simulator.bases`, whose
docstring has the model's equations), integrated per physics substep with the load. The robots
then take velocity commands (:meth:`Plant.command_velocity`) and measure their base's velocity
and the raw force of the force/torque sensor in their contact: the contact's force averaged
over the tick, plus the sensor's bias (:attr:`Plant.biases`, from a random stream of its own,
:data:`simulator.bases.SENSOR_BIAS_STREAM`) and noise. The admittance loop that turns the
agents' forces into those velocities is the AGV's (:mod:`bridge.admittance`; in one process
:class:`simulator.lockstep.PlantTicks` runs it).

Load changes (``scenario.events``): at the first tick at or after a change's ``at_s`` the body
takes its new mass, moment and COM before the period is integrated (:meth:`Plant.change_load`).
The load frame stays where it is, and so do the contacts and their velocities; only the COM
moves within the load.

The floor (``scenario.ground``): without it the load slides on nothing, as in the paper; with
it every physics substep is :meth:`simulator.friction.GroundContact.step`, which adds the
floor's friction at the load's supports, and the truth carries the friction applied
(:mod:`simulator.friction`).

Implementation notes (pymunk 7): Chipmunk's step leaves out the second-order term of the
motion, ``(h²/2) f / m``: its velocities would be half a step ahead of its poses. The plant adds
that term to the pose at each tick's end (:mod:`simulator.integrator`), so the velocities the
robots measure and the poses of the truth are one motion's at one instant. The body carries
the scenario's mass and moment and has no shapes (a shape with a density would override them);
space gravity is zero and damping is off;
``body.force``/``body.torque`` are cleared by every step, so the held forces are re-applied at
the contacts' *current* world points before every physics substep. The per-substep path uses
plain floats and pymunk calls only (no numpy but the floor's one product over its supports) to
keep the plant far faster than real time.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import pymunk
from pymunk import Vec2d

from agent.platform.geometry import Vec2
from agent.platform.protocol import Measurement, Truth
from simulator.bases import Bases, sensor_biases
from simulator.friction import GroundContact
from simulator.integrator import PoseCorrection

if TYPE_CHECKING:
    from simulator.scenario import Scenario

_ZERO: Vec2 = (0.0, 0.0)
ACTUATOR_STREAM = 1
"""The actuators' random draws are ``default_rng((seed, ACTUATOR_STREAM))``'s."""


class Plant:
    """The simulated load pushed by ``scenario.n`` robots (see the module docstring)."""

    def __init__(self, scenario: Scenario) -> None:
        spec = scenario.body
        if scenario.substeps < 1:
            raise ValueError("physics_hz must be at least the sensor rate")
        self._n: int = scenario.n
        self._period: float = scenario.period_s
        self._substeps: int = scenario.substeps
        self._dt: float = 1.0 / scenario.run.physics_hz
        self._velocity_noise: float = float(scenario.sensors.velocity_noise_std)
        self._force_noise: float = float(scenario.sensors.force_noise_std)
        self._rng = np.random.default_rng(scenario.run.seed)

        self._space = pymunk.Space()
        self._space.gravity = (0.0, 0.0)
        self._space.damping = 1.0  # 1.0 = no damping
        body = pymunk.Body(float(spec.mass), float(spec.moment), body_type=pymunk.Body.DYNAMIC)
        body.center_of_gravity = (float(spec.com[0]), float(spec.com[1]))
        # The angle first: setting it keeps the COM fixed in W and moves the load-frame origin,
        # while setting the position places the origin. Done in this order, both are as given.
        body.angle = float(spec.angle)
        body.position = (float(spec.position[0]), float(spec.position[1]))
        self._space.add(body)  # no shapes: they would override mass and moment
        self._body, space = body, self._space
        self._pose = PoseCorrection(body, self._dt)
        """The second-order term of every physics step, added at each tick's end
        (:mod:`simulator.integrator`)."""
        ground = scenario.ground
        self._ground = (
            None if ground is None else GroundContact(space, body, ground, self._dt, self._pose)
        )
        """The floor's friction (:mod:`simulator.friction`); None: frictionless."""
        self._substep = self._free_step if self._ground is None else self._ground.step
        """One physics step with the robots' force and torque: ``(force, torque, cos θ, sin θ)``."""
        self._cog = Vec2d(float(spec.com[0]), float(spec.com[1]))
        self._local: tuple[Vec2d, ...] = tuple(
            Vec2d(float(x), float(y)) for x, y in scenario.contacts
        )
        self._arms: tuple[Vec2, ...] = tuple(
            (p.x - self._cog.x, p.y - self._cog.y) for p in self._local
        )

        self._commanded: list[Vec2] = [_ZERO] * self._n
        self._applied: tuple[Vec2, ...] = (_ZERO,) * self._n
        self.tick: int = 0

        actuators = scenario.actuators
        self._ideal = actuators.ideal
        drives = np.random.default_rng((scenario.run.seed, ACTUATOR_STREAM))
        if actuators.gains:
            gains = actuators.gains
        elif actuators.gain_error_std > 0.0:
            errors = drives.normal(0.0, actuators.gain_error_std, size=self._n)
            gains = tuple(np.clip(1.0 + errors, 0.5, 1.5))
        else:
            gains = (1.0,) * self._n
        self.gains: tuple[float, ...] = tuple(float(g) for g in gains)
        """Each robot's actuator gain ``g_i`` (robot 1 first)."""
        self._drives = drives
        self._actuator_noise = float(actuators.force_noise_std)
        tau = float(actuators.time_constant_s)
        self._follow = 1.0 - math.exp(-self._dt / tau) if tau > 0.0 else 1.0
        """How far a drive's force goes towards its target in one substep."""
        self._drive_force: list[Vec2] = [_ZERO] * self._n
        """Each drive's force now (with a lag it carries over from one tick to the next)."""
        agvs = scenario.agvs
        self._bases: Bases | None = None
        """The velocity-commanded bases (:mod:`simulator.bases`); None: force drives."""
        self.biases: tuple[Vec2, ...] = ((0.0, 0.0),) * self._n
        """Each robot's force/torque sensor bias (N; zero with force drives)."""
        if agvs.velocity:
            contacts = [body.local_to_world(p) for p in self._local]
            self._bases = Bases(
                [(p.x, p.y) for p in contacts],
                agvs.speed_time_constant_s,
                agvs.max_accel,
                agvs.max_speed,
                agvs.contact_stiffness,
                agvs.contact_damping,
                self._dt,
            )
            self.biases = sensor_biases(scenario.run.seed, self._n, agvs.sensor_bias_std)
        self._events = list(scenario.events)
        """The load changes still to come, first first."""
        self._start: Vec2 = self._com_position()
        """``p_C(t_0)``, where the load's travel is measured from."""
        self.largest_travel = self.largest_speed = self.largest_omega = 0.0
        """The load's excursion over every tick so far (see :meth:`_track`)."""
        self._track()

    @property
    def n(self) -> int:
        """Number of robots."""
        return self._n

    @property
    def bases(self) -> Bases | None:
        """The velocity-commanded bases (:mod:`simulator.bases`); None with force drives."""
        return self._bases

    @property
    def time_s(self) -> float:
        """Time of the current tick, ``tick * period``."""
        return self.tick * self._period

    def measure(self) -> list[Measurement]:
        """Every robot's sample at the current tick (index ``robot - 1``).

        ``velocity`` is the contact point's velocity, ``force`` the force applied during the
        last period (zero at tick 0), each plus ``N(0, σ²)`` noise per axis when σ > 0. With
        velocity-commanded bases (:mod:`simulator.bases`): the base's velocity and the raw
        force of the sensor in its contact, its bias included (the admittance loop tares it).
        """
        forces = self._applied
        if self._bases is None:
            body = self._body
            to_world = body.local_to_world
            velocity_at = body.velocity_at_world_point
            velocities = [velocity_at(to_world(p)) for p in self._local]
        else:
            velocities = list(self._bases.velocity)
            forces = tuple((f[0] + b[0], f[1] + b[1]) for f, b in zip(forces, self.biases))
        tick, time_s, n = self.tick, self.time_s, self._n
        if self._velocity_noise > 0.0:
            dv = self._rng.normal(0.0, self._velocity_noise, size=(n, 2)).tolist()
        else:
            dv = [_ZERO] * n
        if self._force_noise > 0.0:
            df = self._rng.normal(0.0, self._force_noise, size=(n, 2)).tolist()
        else:
            df = [_ZERO] * n
        return [
            Measurement(
                robot=i + 1,
                tick=tick,
                time_s=time_s,
                velocity=(v[0] + dv[i][0], v[1] + dv[i][1]),
                force=(forces[i][0] + df[i][0], forces[i][1] + df[i][1]),
            )
            for i, v in enumerate(velocities)
        ]

    def command(self, robot: int, force: Sequence[float]) -> None:
        """Hold ``force`` (in ``W``) at robot ``robot``'s contact from the next :meth:`advance`
        (force drives).

        Raises :class:`ValueError` if ``robot`` is not in ``1..n``, ``force`` is not two
        finite numbers, or the robots are velocity-commanded bases.
        """
        if self._bases is not None:
            raise ValueError("the robots are velocity-commanded bases: use command_velocity")
        self._commanded[robot - 1] = self._vector(robot, force, "force")

    def command_velocity(self, robot: int, velocity: Sequence[float]) -> None:
        """Robot ``robot``'s base drives at ``velocity`` (m/s, in ``W``) from the next
        :meth:`advance` (``[agvs] profile = "velocity"``, :mod:`simulator.bases`).

        Raises :class:`ValueError` if ``robot`` is not in ``1..n``, ``velocity`` is not two
        finite numbers, or the robots are force drives.
        """
        if self._bases is None:
            raise ValueError("the robots are force drives: use command")
        self._bases.command(robot - 1, self._vector(robot, velocity, "velocity"))

    def _vector(self, robot: int, value: Sequence[float], name: str) -> Vec2:
        """``value`` for robot ``robot`` as two floats; :class:`ValueError` unless the robot is
        in ``1..n`` and they are two finite numbers."""
        if isinstance(robot, bool) or not isinstance(robot, int) or not 1 <= robot <= self._n:
            raise ValueError(f"robot must be an integer in 1..{self._n}, got {robot!r}")
        if len(value) != 2:
            raise ValueError(f"{name} must have two components, got {value!r}")
        x, y = float(value[0]), float(value[1])
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ValueError(f"{name} must be finite, got {value!r}")
        return (x, y)

    def advance(self) -> None:
        """Integrate one sensor period: ``substeps`` steps of ``1 / physics_hz``, the held
        forces applied at the contacts' current world points before every step.

        The forces are fixed in ``W`` over the period, so their sum is too; only their torque
        about the COM changes as the load turns. With ``a_i`` a contact's arm from the COM in
        the load frame and ``θ`` the load's angle, ``τ = Σ (R(θ) a_i) × f_i = cos θ A − sin θ B``
        with ``A = Σ a_i × f_i`` and ``B = Σ a_i · f_i``: the same as applying each force at its
        contact's world point, at two numbers per substep.
        """
        while self._events and self.time_s >= self._events[0].at_s - 1e-9:
            event = self._events.pop(0)
            self.change_load(event.mass, event.moment, event.com)
        ground = self._ground
        if ground is not None:
            ground.start_tick()
        if self._bases is not None:
            self._advance_bases()
        elif self._ideal:
            self._advance_ideal()
        else:
            self._advance_through_drives()
        self._pose.apply()
        if ground is not None:
            ground.end_tick(self._period)
        self.tick += 1
        self._track()

    def _advance_ideal(self) -> None:
        """:meth:`advance` with ideal drives: the commanded forces, held over the period."""
        applied = tuple(self._commanded)
        fx = sum(f[0] for f in applied)
        fy = sum(f[1] for f in applied)
        cross_sum = sum(a[0] * f[1] - a[1] * f[0] for a, f in zip(self._arms, applied))
        dot_sum = sum(a[0] * f[0] + a[1] * f[1] for a, f in zip(self._arms, applied))
        body, substep = self._body, self._substep
        force = Vec2d(fx, fy)
        for _ in range(self._substeps):
            angle = body.angle
            c, s = math.cos(angle), math.sin(angle)
            substep(force, c * cross_sum - s * dot_sum, c, s)
        self._applied = applied

    def _advance_bases(self) -> None:
        """:meth:`advance` with velocity-commanded bases (:mod:`simulator.bases`): per physics
        step, each contact's force from its base and the load's contact point (``p_Ci = p_C +
        r_i``, ``ṗ_Ci = ṗ_C + ω r_i⊥``, ``r_i = R(θ) a_i``), their sum and torque ``Σ r_i × f_i``
        on the load, then the bases' step. The forces' mean over the period is what the
        sensors report."""
        n, bases, arms, cog = self._n, self._bases, self._arms, self._cog
        assert bases is not None
        total = [[0.0, 0.0] for _ in range(n)]
        body, substep = self._body, self._substep
        for _ in range(self._substeps):
            angle = body.angle
            c, s = math.cos(angle), math.sin(angle)
            com, velocity, omega = body.local_to_world(cog), body.velocity, body.angular_velocity
            arms_w = [(c * a[0] - s * a[1], s * a[0] + c * a[1]) for a in arms]
            points = [(com.x + r[0], com.y + r[1]) for r in arms_w]
            moving = [(velocity.x - omega * r[1], velocity.y + omega * r[0]) for r in arms_w]
            fx = fy = torque = 0.0
            for r, f, acc in zip(arms_w, bases.forces(points, moving), total):
                fx += f[0]
                fy += f[1]
                torque += r[0] * f[1] - r[1] * f[0]
                acc[0] += f[0]
                acc[1] += f[1]
            substep(Vec2d(fx, fy), torque, c, s)
            bases.step()
        m = self._substeps
        self._applied = tuple((acc[0] / m, acc[1] / m) for acc in total)

    def _free_step(self, force: Vec2d, torque: float, cos: float, sin: float) -> None:
        """One physics step of the frictionless plant: ``force`` at the COM, ``torque`` about
        it (the load's angle's ``cos`` and ``sin``: the floor's, :meth:`GroundContact.step`)."""
        body = self._body
        body.force = force
        body.torque = torque
        self._pose.add(force.x, force.y, torque)
        self._space.step(self._dt)

    def _advance_through_drives(self) -> None:
        """:meth:`advance` with the actuators' lag, gains and noise (see the module docstring):
        the forces change from substep to substep, so do their sum and torque."""
        n = self._n
        if self._actuator_noise > 0.0:
            noise = self._drives.normal(0.0, self._actuator_noise, size=(n, 2)).tolist()
        else:
            noise = [_ZERO] * n
        targets = [
            (g * u[0] + w[0], g * u[1] + w[1])
            for g, u, w in zip(self.gains, self._commanded, noise)
        ]
        follow, arms = self._follow, self._arms
        forces = self._drive_force
        total = [[0.0, 0.0] for _ in range(n)]
        body, substep = self._body, self._substep
        for _ in range(self._substeps):
            forces = [
                (f[0] + (t[0] - f[0]) * follow, f[1] + (t[1] - f[1]) * follow)
                for f, t in zip(forces, targets)
            ]
            fx = fy = cross_sum = dot_sum = 0.0
            for a, f, acc in zip(arms, forces, total):
                fx += f[0]
                fy += f[1]
                cross_sum += a[0] * f[1] - a[1] * f[0]
                dot_sum += a[0] * f[0] + a[1] * f[1]
                acc[0] += f[0]
                acc[1] += f[1]
            angle = body.angle
            c, s = math.cos(angle), math.sin(angle)
            substep(Vec2d(fx, fy), c * cross_sum - s * dot_sum, c, s)
        self._drive_force = forces
        m = self._substeps
        self._applied = tuple((acc[0] / m, acc[1] / m) for acc in total)

    def change_load(
        self, mass: float | None = None, moment: float | None = None, com: Vec2 | None = None
    ) -> None:
        """Give the load a new mass (kg), moment of inertia about its new COM (kg m²) and COM
        (load frame, m), each when given. The load frame keeps its pose and every point of the
        load its velocity: the COM's velocity becomes that of the new COM's point."""
        body = self._body
        if com is not None:
            cog = Vec2d(float(com[0]), float(com[1]))
            origin = body.position
            velocity = body.velocity_at_world_point(body.local_to_world(cog))
            body.center_of_gravity = cog
            body.position = origin  # (pymunk keeps the COM's world point, not the origin's)
            body.velocity = velocity
            self._cog = cog
            self._arms = tuple((p.x - cog.x, p.y - cog.y) for p in self._local)
        if mass is not None:
            body.mass = float(mass)
        if moment is not None:
            body.moment = float(moment)
        self._pose.reload()
        if self._ground is not None:
            self._ground.set_loads()  # the weight and its centre moved: the normal loads too

    def _com_position(self) -> Vec2:
        """``p_C`` now."""
        com = self._body.local_to_world(self._cog)
        return (com.x, com.y)

    def _track(self) -> None:
        """Take the current tick ``k`` into the load's excursion (called at every tick, the
        first included): ``largest_travel = max_k ‖p_C(t_k) − p_C(t_0)‖``, ``largest_speed =
        max_k ‖ṗ_C(t_k)‖``, ``largest_omega = max_k |ω(t_k)|``; :meth:`truth` reports them,
        so the floor is checked over every tick wherever the truth is read."""
        body = self._body
        velocity = body.velocity
        travel = math.dist(self._com_position(), self._start)
        self.largest_travel = max(self.largest_travel, travel)
        self.largest_speed = max(self.largest_speed, math.hypot(velocity.x, velocity.y))
        self.largest_omega = max(self.largest_omega, abs(body.angular_velocity))

    def truth(self) -> Truth:
        """The ground truth at the current tick."""
        body = self._body
        to_world = body.local_to_world
        velocity_at = body.velocity_at_world_point
        com = to_world(self._cog)
        contacts = [to_world(p) for p in self._local]
        return Truth(
            tick=self.tick,
            time_s=self.time_s,
            com_position=(com.x, com.y),
            angle=body.angle,
            com_velocity=(body.velocity.x, body.velocity.y),
            omega=body.angular_velocity,
            contacts=tuple((p.x, p.y) for p in contacts),
            contact_velocities=tuple((v.x, v.y) for v in map(velocity_at, contacts)),
            contact_to_com=tuple((com.x - p.x, com.y - p.y) for p in contacts),
            mass=body.mass,
            moment=body.moment,
            largest_travel=self.largest_travel,
            largest_speed=self.largest_speed,
            largest_omega=self.largest_omega,
            **self._ground_truth(),
        )

    def _ground_truth(self) -> dict[str, Any]:
        """The floor's fields of :class:`Truth` (none without friction: their zeros)."""
        contact = self._ground
        if contact is None:
            return {}
        ground, loads = contact.ground, contact.loads
        return {
            "ground_coulomb": ground.coulomb,
            "ground_static": ground.static,
            "ground_viscous": ground.viscous,
            "friction_radius": loads.friction_radius,
            "viscous_radius2": loads.viscous_radius2,
            "friction_force": contact.force,
            "friction_torque": contact.torque,
        }
