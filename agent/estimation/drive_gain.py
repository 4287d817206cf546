"""The drive's gain: how much of its command a robot's drive applies, from the force it measures.

The paper takes every robot for an ideal force source. A real drive with gain ``g`` and a
first-order lag ``τ_d`` applies ``f`` with ``τ_d ḟ = g u − f``. Over a tick of length ``Δt``
with the command ``u`` held, a unit-gain drive's force goes from ``y₀`` to
``y₁ = u + (y₀ − u) a``, ``a = e^{−Δt/τ_d}``, and averages

    ȳ = u + (y₀ − u) (τ_d/Δt)(1 − a);

the robot measures ``f̄ = g ȳ`` plus white noise, at the end of the tick. The commands change
every tick (the spin-up's feed back the noisy velocities), so no first-order (derivative)
model of the lag will do. For each lag of a grid (:data:`LAGS`) the unit-gain response ``ȳ``
is run alongside; least squares gives ``ĝ = Σ f̄ ȳ / Σ ȳ²`` for each, and the lag whose
residual is least is taken. Its variance is ``σ̂² / Σ ȳ²`` (the noise is white).

The team's mean gain ``ḡ`` (by consensus, :mod:`agent.estimation.centroid`) scales the force
the robust Step 7 assumed: the team pushed with ``n ḡ f``, not ``n f``, so ``m`` is ``ḡ`` times
its fit's.
"""

from __future__ import annotations

import math

from agent.estimation.geometry import Vec2

LAGS = tuple(0.005 * i for i in range(21))
"""s: the drive lags tried (0 to 0.1 s by 5 ms)."""
MIN_ROWS = 50
"""Rows (two a tick) before the gain is taken from the fit rather than assumed 1."""


class DriveGain:
    """``g`` of this robot's drive, from its commands and the forces it measured."""

    def __init__(self, lags: tuple[float, ...] = LAGS) -> None:
        self.lags = lags
        self._decay: list[tuple[float, float]] | None = None
        """Per lag: ``a`` and ``(τ_d/Δt)(1 − a)`` (for the first ``Δt``)."""
        self._dt = 0.0
        self._state = [(0.0, 0.0)] * len(lags)
        """Per lag: the unit-gain drive's force at the end of the last tick."""
        self._fy = [0.0] * len(lags)
        """Per lag: ``Σ f̄ ȳ``."""
        self._yy = [0.0] * len(lags)
        """Per lag: ``Σ ȳ²``."""
        self._ff = 0.0
        """``Σ f̄²``."""
        self.rows = 0

    def _coefficients(self, dt: float) -> list[tuple[float, float]]:
        if self._decay is None or dt != self._dt:
            self._dt = dt
            self._decay = [
                (math.exp(-dt / lag), lag / dt * (1.0 - math.exp(-dt / lag))) if lag else (0, 0)
                for lag in self.lags
            ]
        return self._decay

    def update(self, command: Vec2, measured: Vec2, dt: float) -> None:
        """The force ``measured`` at the end of a tick of length ``dt`` over which the drive
        was commanded ``command``."""
        ux, uy = command
        fx, fy = measured
        for i, (a, c) in enumerate(self._coefficients(dt)):
            x0, y0 = self._state[i]
            mx, my = ux + (x0 - ux) * c, uy + (y0 - uy) * c
            self._state[i] = (ux + (x0 - ux) * a, uy + (y0 - uy) * a)
            self._fy[i] += fx * mx + fy * my
            self._yy[i] += mx * mx + my * my
        self._ff += fx * fx + fy * fy
        self.rows += 2

    def _best(self) -> tuple[float, float] | None:
        """``(ĝ, residual sum of squares)`` for the lag whose residual is least."""
        best = None
        for fy, yy in zip(self._fy, self._yy):
            if yy <= 0.0:
                continue
            gain = fy / yy
            rss = max(self._ff - gain * fy, 0.0)
            if best is None or rss < best[1]:
                best = (gain, rss, yy)
        if best is None or best[0] <= 0.0:
            return None
        return best[0], best[1] / (self.rows - 2) / best[2]

    @property
    def estimate(self) -> float:
        """``ĝ``: 1 (an ideal drive) until the fit has one."""
        if self.rows < MIN_ROWS:
            return 1.0
        best = self._best()
        return 1.0 if best is None else best[0]

    @property
    def std(self) -> float | None:
        """The standard deviation of :attr:`estimate` (``None`` until the fit has one)."""
        if self.rows < MIN_ROWS:
            return None
        best = self._best()
        return None if best is None else math.sqrt(best[1])

    @property
    def covariance(self) -> tuple[tuple[float]] | None:
        """``((std²,),)``."""
        std = self.std
        return None if std is None else ((std * std,),)
