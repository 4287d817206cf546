"""The drive's gain: how much of its command a robot's drive applies, from the force it measures.

The paper takes every robot for an ideal force source. A real drive with gain ``g`` and a
first-order lag ``τ_d`` applies ``f`` with ``τ_d ḟ = g u − f``. Over a tick of length ``Δt``
with the command ``u`` held, a unit-gain drive's force goes from ``y₀`` to
``y₁ = u + (y₀ − u) a``, ``a = e^{−Δt/τ_d}``, and averages

    ȳ = u + (y₀ − u) (τ_d/Δt)(1 − a);

the robot measures ``f̄ = g ȳ`` plus white noise, at the end of the tick. The commands change
every tick (the spin-up feeds the noisy velocities back), and a first-order (derivative) model
of the lag biased ``ĝ`` by −1.2 % and −1.3 % (the team's mean, seeds 1 and 2 of
``paper-noisy.toml``). So for each lag of a grid (:data:`LAGS`) the unit-gain response ``ȳ``
is run alongside; least squares gives ``ĝ = Σ f̄ ȳ / Σ ȳ²`` for each, and the lag whose
residual is least is taken. Its variance is ``σ̂² / Σ ȳ²`` (the noise is white).

The team's mean gain ``ḡ`` (by consensus, :mod:`agent.algorithm.robust.team_mass`) scales the
force the robust Step 7 assumed: the team pushed with ``n ḡ f``, not ``n f``, so ``m`` is ``ḡ``
times its fit's.
"""

from __future__ import annotations

import math

from agent.platform.geometry import Vec2

LAGS = tuple(0.005 * i for i in range(21))
"""s: the drive lags tried (0 to 0.1 s by 5 ms)."""
MIN_ROWS = 50
"""Rows (two a tick) before the gain is taken from the fit rather than assumed 1."""


class DriveGain:
    """``g`` of this robot's drive, from its commands and the forces it measured."""

    def __init__(self) -> None:
        self._decay: list[tuple[float, float]] = []
        """Per lag of :data:`LAGS`: ``a`` and ``(τ_d/Δt)(1 − a)``, for :attr:`_dt`."""
        self._dt = 0.0
        self._state = [(0.0, 0.0)] * len(LAGS)
        """Per lag: the unit-gain drive's force at the end of the last tick."""
        self._fy = [0.0] * len(LAGS)
        """Per lag: ``Σ f̄ ȳ``."""
        self._yy = [0.0] * len(LAGS)
        """Per lag: ``Σ ȳ²``."""
        self._ff = 0.0
        """``Σ f̄²``."""
        self.rows = 0
        self._fit: tuple[float, float] | None = None
        """``(ĝ, its variance)`` for the lag whose residual is least (``None``: no fit yet)."""

    def update(self, command: Vec2, measured: Vec2, dt: float) -> None:
        """The force ``measured`` at the end of a tick of length ``dt`` over which the drive
        was commanded ``command``."""
        if dt != self._dt:
            self._dt = dt
            self._decay = [
                (math.exp(-dt / lag), lag / dt * (1.0 - math.exp(-dt / lag))) if lag else (0, 0)
                for lag in LAGS
            ]
        ux, uy = command
        fx, fy = measured
        self._ff += fx * fx + fy * fy
        self.rows += 2
        fitting, ff = self.rows >= MIN_ROWS, self._ff
        # Each lag's unit-gain response over the tick, its sums, and (once there are enough
        # rows) its fit, in one pass: the lag whose residual is least gives ĝ.
        best: tuple[float, float] | None = None  # (ĝ, Σ ȳ²) of the best lag so far
        least = 0.0  # its residual sum of squares
        state, sums_fy, sums_yy = self._state, self._fy, self._yy
        for i, (a, c) in enumerate(self._decay):
            x0, y0 = state[i]
            dx, dy = x0 - ux, y0 - uy
            mx, my = ux + dx * c, uy + dy * c
            state[i] = (ux + dx * a, uy + dy * a)
            s_fy = sums_fy[i] = sums_fy[i] + (fx * mx + fy * my)
            s_yy = sums_yy[i] = sums_yy[i] + (mx * mx + my * my)
            if not fitting or s_yy <= 0.0:
                continue
            gain = s_fy / s_yy
            rss = ff - gain * s_fy
            if rss < 0.0:
                rss = 0.0
            if best is None or rss < least:
                best, least = (gain, s_yy), rss
        if best is None or best[0] <= 0.0:
            self._fit = None
        else:
            gain, yy = best
            self._fit = (gain, least / (self.rows - 2) / yy)

    @property
    def estimate(self) -> float:
        """``ĝ``: 1 (an ideal drive) until the fit has one."""
        return 1.0 if self._fit is None else self._fit[0]

    @property
    def std(self) -> float | None:
        """The standard deviation of :attr:`estimate` (``None`` until the fit has one)."""
        return None if self._fit is None else math.sqrt(self._fit[1])

    @property
    def covariance(self) -> tuple[tuple[float]] | None:
        """``((std²,),)``."""
        std = self.std
        return None if std is None else ((std * std,),)
