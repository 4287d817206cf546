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

Once the fit has :data:`NARROW_ROWS` rows, only the lags within :data:`NARROW_LAGS` steps of
the grid of the best so far run on (a lag dropped then cannot be taken up again: its response
needs every tick's command since the start), which halves the drive's time in each tick. By
then the lags farther out no longer compete: over seeds 0–19 of ``paper-noisy.toml`` and of
``paper-floor.toml`` and generated loads 0–11 (20 ms drives), and 8 seeds with 50 ms drives, the
best lag of the whole grid never left the window afterwards, so ``ĝ`` was the whole grid's to
the bit; with 90 ms drives (next to the grid's end) it did in 0.08 % of the ticks, where ``ĝ``
was then up to 0.54 of its standard deviation off the whole grid's.

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
NARROW_ROWS = 400
"""Rows (2 s of ticks at 100 Hz) after which only the lags near the best so far run on."""
NARROW_LAGS = 4
"""How many lags either side of the best so far run on after :data:`NARROW_ROWS`."""


class DriveGain:
    """``g`` of this robot's drive, from its commands and the forces it measured."""

    def __init__(self) -> None:
        self._lags = list(LAGS)
        """The lags tried: :data:`LAGS`, then those near the best (:data:`NARROW_ROWS`)."""
        self._narrowed = False
        self._decay: list[tuple[float, float]] = []
        """Per lag of :attr:`_lags`: ``a`` and ``(τ_d/Δt)(1 − a)``, for :attr:`_dt`."""
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
        self.estimate = 1.0
        """``ĝ``: 1 (an ideal drive) until the fit has one."""
        self.fitted: float | None = None
        """The best lag's gain as fitted, at least 0 (a drive that applies nothing of its
        command), ``None`` until there is a fit: what the drive does, where :attr:`estimate`
        keeps 1 for a fit that is not positive."""

    def update(self, command: Vec2, measured: Vec2, dt: float) -> None:
        """The force ``measured`` at the end of a tick of length ``dt`` over which the drive
        was commanded ``command``."""
        if dt != self._dt:
            self._dt = dt
            self._decay = [
                (math.exp(-dt / lag), lag / dt * (1.0 - math.exp(-dt / lag))) if lag else (0, 0)
                for lag in self._lags
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
        where = 0  # its place in the lags
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
                best, least, where = (gain, s_yy), rss, i
        self.fitted = None if best is None else max(best[0], 0.0)
        if best is None or best[0] <= 0.0:
            self._fit, self.estimate = None, 1.0
        else:
            gain, yy = best
            self._fit, self.estimate = (gain, least / (self.rows - 2) / yy), gain
        if self.rows >= NARROW_ROWS and not self._narrowed and best is not None:
            self._narrow(where)

    def _narrow(self, best: int) -> None:
        """Keep the lags within :data:`NARROW_LAGS` of the one at ``best``, dropping the rest."""
        kept = slice(max(0, best - NARROW_LAGS), best + NARROW_LAGS + 1)
        self._lags, self._decay = self._lags[kept], self._decay[kept]
        self._state, self._fy, self._yy = self._state[kept], self._fy[kept], self._yy[kept]
        self._narrowed = True

    @property
    def std(self) -> float | None:
        """The standard deviation of :attr:`estimate` (``None`` until the fit has one)."""
        return None if self._fit is None else math.sqrt(self._fit[1])

    @property
    def covariance(self) -> tuple[tuple[float]] | None:
        """``((std²,),)``."""
        std = self.std
        return None if std is None else ((std * std,),)
