"""The second-order term of the load's motion over each physics step, which Chipmunk leaves out.

pymunk (Chipmunk) moves a body with the velocity it has before a step and then changes that
velocity by the step's force, ``x_{k+1} = x_k + h v_k``, ``v_{k+1} = v_k + h f_k / m`` (and
``θ``, ``ω`` with ``τ_k / J``). Its velocities are then the mean velocities of the next step,
half a step ahead of its poses: a contact's velocity read with the body's angle turns
``(h/2) ω`` ahead of the pose, and the trapezoid of the sampled ``ω`` runs ahead of the angle
by ``(h/2)(ω(t) − ω(0))``. At 1 kHz and 1 rad/s that is 0.5 mrad, about 1 mm across a load a
couple of metres long: an error of the plant, the same in every run, that no real load makes.

For a force and torque held over a step the exact motion is

    x_{k+1} = x_k + h v_k + (h²/2) f_k / m,    θ_{k+1} = θ_k + h ω_k + (h²/2) τ_k / J,

and the velocities change by ``h f_k / m`` and ``h τ_k / J`` as in Chipmunk. So Chipmunk's
velocities are the exact ones, and its poses lack ``Σ_k (h²/2) f_k / m`` and
``Σ_k (h²/2) τ_k / J``. :class:`PoseCorrection` sums that term over a sensor period's physics
steps (:meth:`~PoseCorrection.add`, floats only) and adds it to the pose at the period's end
(:meth:`~PoseCorrection.apply`): what the robots measure and the truth then refer to one
motion at one instant, and what the forces impart over a tick is unchanged. The angle is
added about the COM, the translation to it. Within the period the pose lags by at most the
period's sum (``T² f / 2m`` for a force held over the period ``T``, 0.05 mm for 1 m/s² at
100 Hz), which the robots' torques read through their arms: an error of second order in the
step, as is holding a torque that turns with the load at its value at the start of a step.
"""

from __future__ import annotations

import pymunk


class PoseCorrection:
    """The pose term ``(h²/2) (f / m, τ / J)`` of a sensor period's physics steps of ``dt``
    (see the module docstring)."""

    def __init__(self, body: pymunk.Body, dt: float) -> None:
        self._body = body
        self._half_h2 = 0.5 * dt * dt
        self._dx = self._dy = self._dangle = 0.0
        self._per_force = self._per_torque = 0.0
        self.reload()

    def reload(self) -> None:
        """Take the body's mass and moment again (after a load change)."""
        self._per_force = self._half_h2 / self._body.mass
        self._per_torque = self._half_h2 / self._body.moment

    def add(self, fx: float, fy: float, torque: float) -> None:
        """One physics step with the force ``(fx, fy)`` (N, at the COM, ``W``) and the torque
        (N m, about the COM) that the body felt over it."""
        k = self._per_force
        self._dx += fx * k
        self._dy += fy * k
        self._dangle += torque * self._per_torque

    def apply(self) -> None:
        """Add the steps' term since the last call to the body's pose: the angle about the COM
        (as pymunk sets it), then the COM's translation."""
        if self._dangle:
            body = self._body
            body.angle = body.angle + self._dangle
        if self._dx or self._dy:
            body = self._body
            p = body.position
            body.position = (p.x + self._dx, p.y + self._dy)
        self._dx = self._dy = self._dangle = 0.0
