"""The admittance loop of a velocity-commanded AGV: from the force its agent commands and the
force its contact's force/torque sensor measures, the velocity its base is told to drive at.

Most real bases take velocity commands, not forces (AgileX's motion command, CiA 402's
velocity modes). Such a robot pushes through a compliant contact (foam, a sprung bumper) with a
force/torque sensor in it, and the bridge closes this loop at the sensor's rate, once a tick
(period ``T``), on world-frame vectors:

.. math::

    e_k &= \\mathrm{dz}\\big(f^{cmd}_k - (f^{raw}_k - \\hat b)\\big)          && (1)\\\\
    M \\frac{v^a_{k+1} - v^a_k}{T} &= e_k - D\\, v^a_k                       && (2)\\\\
    w_{k+1} &= w_k + \\frac{T}{\\tau_i} v^a_{k+1}                            && (3)\\\\
    v^{cmd}_{k+1} &= \\mathrm{sat}\\big(v^a_{k+1} + w_{k+1}\\big)             && (4)

(1) the force error, the sensor's bias ``b̂`` tared away, in a deadzone ``dz`` of
``deadzone_n`` (the error's length is shortened by it, so that sensor noise alone does not
make the base creep); (2) the admittance: a virtual mass ``M`` and damper ``D`` driven by the
error (v̇ = (f_cmd − f_meas − D v) / M); (3) an integral that holds the base at the speed the
load has reached; (4) the velocity command, saturated to ``‖v‖ ≤ max_speed`` and
``‖Δv‖ ≤ max_accel T`` per tick. The saturation is taken back into ``w`` (anti-windup).

Why (3): pushing a load of mass ``m`` needs the base to *accelerate* with it, and a base's
speed loop (time constant ``τ``) follows ``v_cmd`` with a lag. With ``τ_i = τ`` the base's
acceleration is ``v^a/τ``: a steady push needs a steady ``v^a = τ a``, which (2) holds with
``e = D τ a``, and with ``e = 0`` when ``D = 0``. Without (3) a steady push would need an error
growing with the load's speed. The loop's gain is ``m / (τ_i M)`` at low frequency (the force
is ``m`` times the acceleration): a larger ``M`` is slower and steadier, and ``M`` must keep
that gain below the contact's resonance ``√(K/m)`` (``K`` its stiffness). How to choose the
gains on a real robot: ``deploy/README.md``.

The bias is tared from the first ``tare_samples`` samples, while the base stands still and the
contact is not loaded (the robot placed against the load, not pushing it); the base is held at
standstill until then. :meth:`Admittance.stop` (a stale sensor or agent) commands standstill
and forgets the loop's state.

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

    mass: float = bounded(10.0, 0.01, 1000.0, "kg")
    """``M``: the virtual mass. Larger is steadier and slower."""
    damping: float = bounded(0.0, 0.0, 10_000.0, "N s/m")
    """``D``: the virtual damper. It damps the contact's resonance at the cost of a force error
    ``D τ a`` while the load accelerates at ``a``."""
    integral_time_s: float = bounded(0.05, 0.0, 10.0, "s")
    """``τ_i``: the base's speed-loop time constant (0: no integral, a plain admittance)."""
    deadzone_n: float = bounded(0.1, 0.0, 50.0, "N")
    """Force errors shorter than this are no error."""
    max_speed: float = bounded(1.5, 0.0, 8.0, "m/s", open_low=True)
    """The fastest velocity commanded (per vector, world frame)."""
    max_accel: float = bounded(2.0, 0.0, 100.0, "m/s²", open_low=True)
    """The largest change of the velocity command per second."""
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
        if measured is None or not self.tared:
            return self.stop()
        s, T = self.settings, self.period_s
        error = (commanded[0] - measured[0], commanded[1] - measured[1])
        self._errors.append(_norm(error))
        e = deadzone(error, s.deadzone_n)
        va = self._va
        va = (va[0] + T * (e[0] - s.damping * va[0]) / s.mass,
              va[1] + T * (e[1] - s.damping * va[1]) / s.mass)  # fmt: skip
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
