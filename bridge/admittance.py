"""The admittance loop of a velocity-commanded AGV: from the force its agent commands and the
force its contact's force/torque sensor measures, the velocity its base is told to drive at.

Most real bases take velocity commands, not forces (AgileX's motion command, CiA 402's
velocity modes). Such a robot pushes through a compliant contact (foam, a sprung bumper) with a
force/torque sensor in it, and the bridge closes this loop at the sensor's rate, once a tick
(period ``T``), on world-frame vectors:

.. math::

    e_k &= \\mathrm{dz}\\big(f^{cmd}_k - (f^{raw}_k - \\hat b)\\big)          && (1)\\\\
    M \\dot v^a &= e_k - D\\, v^a \\quad \\text{over } [t_k, t_{k+1}]               && (2)\\\\
    w_{k+1} &= w_k + \\frac{T}{\\tau_i} v^a_{k+1}                            && (3)\\\\
    v^{cmd}_{k+1} &= \\mathrm{sat}\\big(v^a_{k+1} + w_{k+1}\\big)             && (4)

(1) the force error, the sensor's bias ``b̂`` tared away, in a deadzone ``dz`` of
``deadzone_n`` (the error's length is shortened by it, so that sensor noise alone does not
make the base creep); (2) the admittance: a virtual mass ``M`` and damper ``D`` driven by the
error (v̇ = (f_cmd − f_meas − D v) / M), solved exactly over the tick with ``e_k`` held (so
that no ``D T / M`` makes it diverge); (3) an optional integral (``τ_i > 0``) that holds the
base at the speed the load has reached; (4) the velocity command, saturated to
``‖v‖ ≤ max_speed`` and ``‖Δv‖ ≤ max_accel T`` per tick, the saturation taken back into ``w``
(anti-windup).

**Protective stop.** A measured contact force longer than ``max_contact_force`` commands
standstill at once and forgets the loop's state (:attr:`Admittance.overloads` counts it), so
the force stays bounded whatever the gains and the load do: within a few times the limit, as
the contact is compressed while the base brakes within its own limits
(tests/unit/simulator/test_admittance_stability.py: 141 N for a 50 N limit on gains that,
unstopped, reach 2 kN).

**What the gains can and cannot do.** Through a compliant contact the plant seen from the
velocity command is ``m s`` for a free load of mass ``m`` (the force accelerates it) and
``K / s`` for a load held by the others or the floor (the robots squeeze it: ``K`` is the
contact's stiffness). The two differ by ``K / (m ω²)``, a factor of hundreds at the loop's
frequencies, and a team's load is both at once: Step 1's spin-up squeezes it, Step 4 and
Step 7 push it. Fixed gains stable in a squeeze are far too slow on a free load, and gains that
push a free load make a squeeze oscillate:

- the defaults (a plain admittance, ``M = 100 kg``, ``D = 1000 N s/m``, ``τ_i = 0``) are
  stable from soft foam (1000 N/m) to a sprung bumper (10 000 N/m) when four robots squeeze,
  push or turn the paper's load with its sensors' noise, the force within 3 times the 2 N
  commanded (tests/unit/simulator/test_admittance_stability.py); but a plain admittance holds
  a force error ``D v`` on a load moving at ``v``: it does not push a free load with the force
  commanded;
- an integral (``τ_i`` near the base's speed-loop time constant) with a small ``M`` and ``D``
  follows a steady push on a free load, and oscillates as soon as two robots squeeze it.

The agents are given the force the sensor measured, not the one they commanded.

Plain arithmetic on floats, no I/O: the bridge runs it on a robot (:mod:`bridge.bridge`), the
simulator runs the same loop for its velocity-commanded bases in one process.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from agent.platform.config import bounded, check_bounds

Vec2 = tuple[float, float]
_ZERO: Vec2 = (0.0, 0.0)
TRACKING_WINDOW = 100
"""Samples the force-tracking figures are taken over (:meth:`Admittance.tracking`)."""


@dataclass(frozen=True)
class AdmittanceSettings:
    """The admittance loop's gains and limits (``[can.admittance]`` in ``robot.toml``,
    ``[agvs.admittance]`` in a scenario); see the module docstring for the law."""

    mass: float = bounded(100.0, 0.01, 1000.0, "kg")
    """``M``: the virtual mass. Larger is steadier and slower."""
    damping: float = bounded(1000.0, 0.0, 10_000.0, "N s/m")
    """``D``: the virtual damper. It damps the contact's resonance at the cost of a force error:
    ``D v`` on a load moving at ``v`` without the integral, ``D τ_i a`` with it while the load
    accelerates at ``a``."""
    integral_time_s: float = bounded(0.0, 0.0, 10.0, "s")
    """``τ_i``: the integral's time constant, near the base's speed-loop time constant when
    used; 0 (the default): none, a plain admittance."""
    deadzone_n: float = bounded(0.1, 0.0, 50.0, "N")
    """Force errors shorter than this are no error."""
    max_speed: float = bounded(1.5, 0.0, 8.0, "m/s", open_low=True)
    """The fastest velocity commanded (per vector, world frame)."""
    max_accel: float = bounded(2.0, 0.0, 100.0, "m/s²", open_low=True)
    """The largest change of the velocity command per second."""
    max_contact_force: float = bounded(50.0, 1.0, 1000.0, "N")
    """A measured contact force longer than this commands standstill (the protective stop)."""
    tare_samples: int = bounded(20, 1, 10_000)
    """The sensor samples averaged into its bias at start-up."""

    def validate(self, where: str) -> None:
        check_bounds(self, where)


def _norm(v: Vec2) -> float:
    return math.hypot(v[0], v[1])


def _limit(v: Vec2, bound: float) -> Vec2:
    """``v`` shortened to length ``bound`` if it is longer."""
    length = _norm(v)
    if length <= bound:
        return v
    k = bound / length
    return (v[0] * k, v[1] * k)


def deadzone(e: Vec2, width: float) -> Vec2:
    """``e`` shortened by ``width`` (zero if it is shorter): continuous, so the loop has no
    jump at the deadzone's edge."""
    length = _norm(e)
    if length <= width:
        return _ZERO
    k = (length - width) / length
    return (e[0] * k, e[1] * k)


@dataclass(frozen=True)
class Tracking:
    """How well the measured force followed the command over the last samples (N)."""

    samples: int
    rms: float
    p95: float


class Admittance:
    """One robot's admittance loop (see the module docstring), stepped once a ``period_s``."""

    def __init__(self, settings: AdmittanceSettings, period_s: float):
        if not period_s > 0:
            raise ValueError(f"period_s must be positive, got {period_s!r}")
        self.settings = settings
        self.period_s = period_s
        self.bias: Vec2 = _ZERO
        """``b̂``: the sensor's bias, tared (see :attr:`tared`)."""
        self._tare_sum = [0.0, 0.0]
        self._tare_count = 0
        self._measured: Vec2 | None = None
        self._va: Vec2 = _ZERO
        self._w: Vec2 = _ZERO
        self.velocity: Vec2 = _ZERO
        """The velocity command now (what :meth:`step` last returned)."""
        self._errors: deque[float] = deque(maxlen=TRACKING_WINDOW)
        self.overloads = 0
        """Protective stops so far: steps whose measured force was beyond
        ``max_contact_force``."""
        self.overloaded = False
        """Whether the last :meth:`step` was a protective stop."""

    @property
    def tared(self) -> bool:
        """Whether the bias is known (the loop drives only then)."""
        return self._tare_count >= self.settings.tare_samples

    def measure(self, raw: Vec2) -> Vec2:
        """A sensor sample (N, raw); the force the contact carries, ``raw − b̂`` (with the bias
        known so far while taring)."""
        if not self.tared:
            self._tare_sum[0] += raw[0]
            self._tare_sum[1] += raw[1]
            self._tare_count += 1
            self.bias = (
                self._tare_sum[0] / self._tare_count,
                self._tare_sum[1] / self._tare_count,
            )
        force = (raw[0] - self.bias[0], raw[1] - self.bias[1])
        self._measured = force
        return force

    def step(self, commanded: Vec2) -> Vec2:
        """The velocity command for the next period, from the force ``commanded`` for it and
        the last sample (:meth:`measure`); standstill until the bias is tared."""
        measured = self._measured
        self.overloaded = False
        if measured is None or not self.tared:
            return self.stop()
        s, T = self.settings, self.period_s
        if _norm(measured) > s.max_contact_force:
            self.overloaded = True
            self.overloads += 1
            return self.stop()
        error = (commanded[0] - measured[0], commanded[1] - measured[1])
        self._errors.append(_norm(error))
        e = deadzone(error, s.deadzone_n)
        va = self._va
        if s.damping > 0.0:  # (2) solved over the tick with e held: exact, any D T / M
            decay = math.exp(-s.damping * T / s.mass)
            ex, ey = e[0] / s.damping, e[1] / s.damping
            va = (ex + (va[0] - ex) * decay, ey + (va[1] - ey) * decay)
        else:
            va = (va[0] + T * e[0] / s.mass, va[1] + T * e[1] / s.mass)
        w = self._w
        if s.integral_time_s > 0.0:
            k = T / s.integral_time_s
            w = (w[0] + k * va[0], w[1] + k * va[1])
        wanted = (va[0] + w[0], va[1] + w[1])
        last = self.velocity
        step = _limit((wanted[0] - last[0], wanted[1] - last[1]), s.max_accel * T)
        velocity = _limit((last[0] + step[0], last[1] + step[1]), s.max_speed)
        if velocity != wanted and s.integral_time_s > 0.0:  # anti-windup: w takes it back
            w = (velocity[0] - va[0], velocity[1] - va[1])
        self._va, self._w, self.velocity = va, w, velocity
        return velocity

    def stop(self) -> Vec2:
        """Standstill: the loop's state forgotten (the bias is kept); the zero velocity."""
        self._va = self._w = self.velocity = _ZERO
        return _ZERO

    def tracking(self) -> Tracking:
        """The force error ``‖f_cmd − f_meas‖``'s RMS and 95th percentile over the last
        :data:`TRACKING_WINDOW` steps (zeros before the first)."""
        errors = sorted(self._errors)
        if not errors:
            return Tracking(0, 0.0, 0.0)
        rms = math.sqrt(sum(e * e for e in errors) / len(errors))
        p95 = errors[min(len(errors) - 1, math.ceil(0.95 * len(errors)) - 1)]
        return Tracking(len(errors), rms, p95)
