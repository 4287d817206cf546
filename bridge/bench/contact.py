"""A velocity-commanded base pushing a load through a compliant contact, with a force/torque
sensor in it: what ``heft bench can --profile velocity`` plays on the bus against a bridge.

One robot's share of a load, as a point mass ``m`` in the plane (world frame, every vector 2-D),
and its base:

.. math::

    \\dot v &= \\mathrm{clamp}\\big((v_{cmd} - v)/\\tau,\\ a_{max}\\big),
        \\quad \\lVert v \\rVert \\le v_{max}                                   && (1)\\\\
    f &= K (x - p) + C (v - \\dot p)                                            && (2)\\\\
    m \\ddot p &= f - b \\dot p                                                && (3)

(1) the base's speed loop, first order with time constant ``τ`` and its own acceleration and
speed limits (a vector clamp); (2) the contact, a spring ``K`` and damper ``C`` between the
base at ``x`` and the load's contact point at ``p`` (the base holds the load: it can pull);
(3) the load share, with a viscous drag ``b`` (casters rolling on a floor), so that a steady
push has a steady speed. Integrated with semi-implicit Euler over
:data:`SUBSTEPS` substeps a tick. The sensor reports ``f`` averaged over the tick, plus its
bias and Gaussian noise; the base reports ``v``. Both start at rest, the contact unloaded, so
the bridge tares the sensor on its first samples.

The simulator's plant models the same base and contact on the whole load
(:mod:`simulator`); this one is small enough to run in the benchmark's own loop.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

Vec2 = tuple[float, float]
SUBSTEPS = 20
"""Integration substeps a tick (0.5 ms each at a 10 ms tick)."""


@dataclass(frozen=True)
class ContactSettings:
    """The base, contact, load share and sensor of :class:`ContactModel`."""

    load_mass: float = 1.25
    """``m``, kg: one robot's share of the load (the paper's 5 kg load, four robots)."""
    drag: float = 5.0
    """``b``, N s/m: the load share's viscous drag."""
    time_constant_s: float = 0.05
    """``τ``: the base's speed loop."""
    max_accel: float = 3.0
    """m/s², the base's own acceleration limit."""
    max_speed: float = 4.0
    """m/s, the base's own speed limit."""
    stiffness: float = 3000.0
    """``K``, N/m: 1000 (soft foam) to 10 000 (a sprung bumper)."""
    damping: float = 20.0
    """``C``, N s/m."""
    noise_std: float = 0.05
    """N, the sensor's noise per axis."""
    bias: Vec2 = (0.3, -0.2)
    """N, the sensor's bias (the bridge tares it)."""


def _limit(v: Vec2, bound: float) -> Vec2:
    length = math.hypot(v[0], v[1])
    if length <= bound:
        return v
    return (v[0] * bound / length, v[1] * bound / length)


class ContactModel:
    """The model of the module docstring, advanced a tick (``period_s``) at a time."""

    def __init__(self, settings: ContactSettings, period_s: float, seed: int = 0):
        self.settings = settings
        self.period_s = period_s
        self.rng = random.Random(seed)
        self.x: Vec2 = (0.0, 0.0)
        self.v: Vec2 = (0.0, 0.0)
        self.p: Vec2 = (0.0, 0.0)
        self.pd: Vec2 = (0.0, 0.0)
        self.force: Vec2 = (0.0, 0.0)
        """The contact force averaged over the last tick (N)."""

    def advance(self, command: Vec2) -> None:
        """One tick with the base told to drive at ``command`` (m/s)."""
        s = self.settings
        dt = self.period_s / SUBSTEPS
        (x0, x1), (v0, v1), (p0, p1), (q0, q1) = self.x, self.v, self.p, self.pd
        total0 = total1 = 0.0
        for _ in range(SUBSTEPS):
            a0, a1 = _limit(
                ((command[0] - v0) / s.time_constant_s, (command[1] - v1) / s.time_constant_s),
                s.max_accel,
            )
            v0, v1 = _limit((v0 + a0 * dt, v1 + a1 * dt), s.max_speed)
            x0, x1 = x0 + v0 * dt, x1 + v1 * dt
            f0 = s.stiffness * (x0 - p0) + s.damping * (v0 - q0)
            f1 = s.stiffness * (x1 - p1) + s.damping * (v1 - q1)
            q0 += (f0 - s.drag * q0) / s.load_mass * dt
            q1 += (f1 - s.drag * q1) / s.load_mass * dt
            p0, p1 = p0 + q0 * dt, p1 + q1 * dt
            total0, total1 = total0 + f0, total1 + f1
        self.x, self.v, self.p, self.pd = (x0, x1), (v0, v1), (p0, p1), (q0, q1)
        self.force = (total0 / SUBSTEPS, total1 / SUBSTEPS)

    def sensed(self) -> Vec2:
        """The sensor's raw reading of the last tick: force, bias and noise (N)."""
        s = self.settings
        return (
            self.force[0] + s.bias[0] + self.rng.gauss(0.0, s.noise_std),
            self.force[1] + s.bias[1] + self.rng.gauss(0.0, s.noise_std),
        )
