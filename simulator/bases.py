"""Velocity-commanded bases holding the load through compliant contacts (``[agvs] profile =
"velocity"``): what the plant's robots are when they take velocity commands.

Robot ``i`` is a base at ``x_i`` with velocity ``v_i`` (world frame ``W``), starting at its
contact point's world position ``p_Ci(0)`` at rest. Its speed loop follows the commanded
``v_cmd,i`` (held over a tick) with a first-order lag ``τ``, within the base's acceleration
and speed limits:

.. math::

    \\dot v_i = \\mathrm{clamp}\\big((v_{cmd,i} - v_i) / τ,\\ a_{max}\\big),
    \\qquad \\|v_i\\| \\le v_{max}, \\qquad \\dot x_i = v_i

(``clamp`` shortens a vector to the given length). Per physics step ``Δt`` the lag is taken
exactly, ``Δv = (v_cmd − v)(1 − e^{−Δt/τ})``, then shortened to ``a_max Δt`` and the speed to
``v_max``; the position follows with the new velocity (semi-implicit Euler).

The contact is a spring and damper between the base and the load's contact point ``C_i``:

.. math::

    f_i = K (x_i - p_{Ci}) + C (v_i - \\dot p_{Ci})

applied to the load at ``C_i``, in both directions (the robots hold the load, as in the
paper's: they can pull). The reaction on the base is its speed loop's to reject (not modelled:
the base is far heavier than the contact is stiff).

What the robot's sensors give at tick ``k`` (:meth:`Bases.velocities`, the plant's
:meth:`~simulator.plant.Plant.measure`): its base's velocity ``v_i(t_k)``, and its contact's
force ``f_i`` averaged over the tick's physics steps plus the force/torque sensor's bias
``b_i`` (drawn once per run from the seed, :data:`SENSOR_BIAS_STREAM`) and the sensor's noise.

Plain floats per physics step (no numpy): the plant steps these ``n`` bases and contacts
``physics_hz`` times per simulated second.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from agent.platform.geometry import Vec2

SENSOR_BIAS_STREAM = 2
"""The force/torque sensors' biases are ``default_rng((seed, SENSOR_BIAS_STREAM))``'s: a
stream of their own, so the sensors' noise draws are those of the force drives."""


def sensor_biases(seed: int, n: int, std: float) -> tuple[Vec2, ...]:
    """Each robot's force/torque sensor bias ``b_i ~ N(0, std²)`` per axis (N), robot 1 first,
    from the run's ``seed``."""
    if std <= 0.0:
        return ((0.0, 0.0),) * n
    draws = np.random.default_rng((seed, SENSOR_BIAS_STREAM)).normal(0.0, std, size=(n, 2))
    return tuple((float(x), float(y)) for x, y in draws)


def _shorten(x: float, y: float, bound: float) -> Vec2:
    """``(x, y)`` shortened to length ``bound`` if it is longer."""
    length = math.hypot(x, y)
    if length <= bound:
        return x, y
    k = bound / length
    return x * k, y * k


class Bases:
    """``n`` velocity-commanded bases and their contacts (see the module docstring), stepped
    by the plant once per physics step."""

    def __init__(
        self,
        start: Sequence[Vec2],
        time_constant_s: float,
        max_accel: float,
        max_speed: float,
        stiffness: float,
        damping: float,
        dt: float,
    ):
        self.position: list[Vec2] = [(float(x), float(y)) for x, y in start]
        """``x_i`` (m, ``W``)."""
        self.velocity: list[Vec2] = [(0.0, 0.0)] * len(self.position)
        """``v_i`` (m/s, ``W``)."""
        self.commanded: list[Vec2] = [(0.0, 0.0)] * len(self.position)
        """``v_cmd,i`` (m/s, ``W``), held until the next command."""
        self.stiffness = float(stiffness)
        self.damping = float(damping)
        self._follow = 1.0 - math.exp(-dt / time_constant_s)
        self._max_step = max_accel * dt
        self._max_speed = float(max_speed)
        self._dt = dt

    def command(self, robot_index: int, velocity: Vec2) -> None:
        """Base ``robot_index`` (0-based) drives at ``velocity`` from the next step on."""
        self.commanded[robot_index] = velocity

    def forces(self, contacts: Sequence[Vec2], contact_velocities: Sequence[Vec2]) -> list[Vec2]:
        """``f_i = K (x_i − p_Ci) + C (v_i − ṗ_Ci)`` for the contact points ``p_Ci`` moving at
        ``ṗ_Ci`` (``W``), robot 1 first."""
        k, c = self.stiffness, self.damping
        return [
            (k * (x[0] - p[0]) + c * (v[0] - q[0]), k * (x[1] - p[1]) + c * (v[1] - q[1]))
            for x, v, p, q in zip(self.position, self.velocity, contacts, contact_velocities)
        ]

    def step(self) -> None:
        """One physics step of every base's speed loop and position."""
        follow, max_step, max_speed, dt = self._follow, self._max_step, self._max_speed, self._dt
        positions, velocities = self.position, self.velocity
        for i, (v, u) in enumerate(zip(velocities, self.commanded)):
            dvx, dvy = _shorten((u[0] - v[0]) * follow, (u[1] - v[1]) * follow, max_step)
            vx, vy = _shorten(v[0] + dvx, v[1] + dvy, max_speed)
            x = positions[i]
            velocities[i] = (vx, vy)
            positions[i] = (x[0] + vx * dt, x[1] + vy * dt)
