"""Step 1 under noise: ``z_ij`` from the arc that the integrated relative velocity traces.

The rigid body keeps ``‖z_ij‖`` constant while ``z_ij`` turns with the load (``ż_ij =
ω z_ij⊥``), so the integral of the measured relative velocity from the first sample ``t₀``,

    s(t) = ∫_{t₀}^{t} ż_ij dt = z_ij(t) − z_ij(t₀),

lies on a circle of radius ``r = ‖z_ij‖`` centred at ``c = −z_ij(t₀)`` (the notes, "Noise"),
whatever ω does meanwhile, in every phase (the fit learns all along). The circle is fitted by
least squares on the algebraic residual ``‖s − c‖² − r²`` (Kåsa's fit), linear in
``p = (c_x, c_y, d)`` with ``d = r² − ‖c‖²``:

    [2 s_x, 2 s_y, 1] p = s_x² + s_y²,

and then ``z_ij(t) = s(t) − c``, ``‖z_ij‖ = √(d + ‖c‖²)``. Integration averages the velocity
noise out: the integral's error is a random walk of ``σ √(2 Δt t)`` (``σ`` per axis and robot,
samples ``Δt`` apart), millimetres where eq. (12)'s instantaneous ratio errs by tens of per cent
(the notes' table). No filter transient, no ratio of small numbers, no sign to follow: ``s``
is the same whichever way the load turns.

Uncertainty. The fit's least-squares covariance ``σ̂² (AᵀA)⁻¹`` of ``p`` (``σ̂²`` the
residuals' mean square) assumes independent residuals; those of one random walk are correlated
along all of it, as if there were a handful of independent samples, not ``N``. Scaled by
``N`` and :data:`CORRELATION`, it gives the covariance of the centre ``c`` (hence of
``s − c``, which starts the direction filter below) and, through ``∂r/∂p = (c_x/r, c_y/r,
1/(2r))``, of the radius ``‖z_ij‖``.

Direction. ``s(t) − c`` carries the walk, which grows as ``√t``; the radius does not. So the
direction ``ψ`` of ``z_ij`` is filtered on its own (a scalar Kalman filter): it turns by the
arc's increment between samples (its process noise is the walk's step, ``σ_e Δt / (r √2)`` of
angle: the trapezoid averages two samples), or by the team's turn, which averages every edge's
increments (:meth:`follow`, :mod:`agent.algorithm.robust.rotation`: its process noise is then a
share of that step's), and each sample measures it without any walk:
``z_ij = −ż_ij⊥ / ω`` (eq. 10, the notes' correction) points along ``∓ż_ij⊥``, the sign that
of the filter's prediction, with an angular noise of ``σ_e / ‖ż_ij‖`` (``σ_e²`` the
relative velocity's noise variance per axis, measured from the samples' second differences:
``Var(ż_{k+1} − 2ż_k + ż_{k−1}) = 6 σ_e²`` for white noise, the motion's own share
``ω² ‖ż‖ Δt²`` being negligible). Then
``z_ij = r̂ (cos ψ̂, sin ψ̂)``, its covariance ``r̂² P`` across and ``Var(r̂)`` along.

The circle is determined once the arc is long enough: :attr:`estimate` is ``None`` until the
fitted radius is known to within half of itself. Sums are kept with an optional exponential
forgetting, O(1) per sample (:class:`~agent.algorithm.robust.least_squares.LeastSquares`).
Every sample adds its row; once the circle is determined it is solved again every
:data:`SOLVE_EVERY` samples (a 3 × 3 inverse and the radius' variance), the last solve's
centre and radius standing in between.
"""

from __future__ import annotations

import math

from agent.algorithm.estimation.estimator import Covariance
from agent.algorithm.robust.least_squares import LeastSquares, Solution
from agent.algorithm.robust.uncertainty import packed
from agent.platform.geometry import Vec2, angle_between, largest_std

DIRECTION_VARIANCE = 1.5
"""Factor on the direction filter's variance ``P`` when published: the filter takes the
increments' and the measurements' noise as independent, and they share each sample's. Set
over 40 runs of the paper's scenario at 1 cm/s (seeds 0–39), where 95 % of the robots' ``z_ij``
fell within the 95 % ellipse with ``P`` scaled by 1.4 to 1.5.

Measured again by ``heft bench calibrate direction-variance`` (the noise benchmark's runs of
seeds 0–39; each edge's 95 % ellipse without ``PUBLISHED_VARIANCE``, the factor on ``r² P``
alone). On 2026-11-27 it printed 1.19 for 95 % of the edges inside (1.27 for 95 % of the
robots with all their edges inside; with 1.5, 97.5 % and 96.2 %); with ``--ideal-drives``,
1.13 and 1.25."""
SOLVE_EVERY = 4
"""Samples between two solves of a determined circle. A turn between two samples is measured
about one centre at both ends, so a centre held for a few samples loses no turn and counts none
twice; and a few more rows move the fit by little: on ``paper-noisy.toml`` (seeds 0–2) the
centre moved over 4 samples by a median 0.5 % of its standard deviation (99 % of the times
under 12 %; about one standard deviation at most, on the circle's first samples)."""
CORRELATION = 2.5
"""Factor on ``N σ̂² (AᵀA)⁻¹``, the covariance of the centre and of the radius. Set on
simulated arcs (‖z‖ = 1.5 m, ω = 0.3 ± 0.2 rad/s, 100 Hz, σ from 1 mm/s to 3 cm/s, 40 seeds,
3 s to 20 s of arc), where the mean squared error of ``z_ij`` per axis was 0.6 to 1.4 times
the variance this gives.

Measured again by ``heft bench calibrate arc-correlation`` (those arcs, each read at 3, 5, 10
and 20 s). On 2026-11-27 it printed 2.52 for 95 % of the centres inside their 95 % ellipse
(94.7 % with 2.5) and 1.2 for 95 % of the radii within 1.96 standard deviations (99.8 % with
2.5); the centre's mean squared error per axis was 0.27 to 0.97 times its variance."""


class ArcRelativePosition:
    """Estimates one edge's ``z_ij`` from the samples of ``ż_ij = ṗ_Ci − ṗ_Cj`` by fitting
    the circle of ``∫ż_ij dt`` (see the module docstring)."""

    def __init__(self, forgetting: float = 1.0, min_speed: float = 1e-6):
        self.min_speed = min_speed
        """m/s: a sample with ``‖ż_ij‖`` at most this leaves the arc where it is."""
        self.moving = False
        """Whether the last sample was used (``‖ż_ij‖ > min_speed``)."""
        self.zdot: Vec2 | None = None
        """``ż_ij`` at the last sample used."""
        self.s: Vec2 = (0.0, 0.0)
        """``∫ż_ij dt`` since the first sample used."""
        self.last_turn = 0.0
        """The load's rotation (rad) between the last two samples used."""
        self.last_dt = 0.0
        """s: the interval between the last two samples used."""
        self.step: Vec2 = (0.0, 0.0)
        """``∫ż_ij dt`` between the last two samples used (the trapezoid)."""
        self.arc: Vec2 = (0.0, 0.0)
        """``s − c``: ``z_ij`` on the arc at the last sample used once the circle is known."""
        self.fit = LeastSquares(3, forgetting)
        """Kåsa's rows ``[2 s_x, 2 s_y, 1] (c_x, c_y, d) = ‖s‖²``."""
        self.direction: float | None = None
        """``ψ̂`` (rad): the filtered direction of ``z_ij``."""
        self.direction_var = 0.0
        """``P``: its variance (rad²)."""
        self._before: Vec2 | None = None
        """``ż_ij`` at the sample before the last one used."""
        self._second = [0.0, 0.0]
        """The (forgotten) sum of the squared second differences of ``ż_ij``, and its count."""
        self.noise = 0.0
        """``σ_e²``: the relative velocity's noise variance per axis (m²/s²), measured (0 until
        a second difference is)."""
        self._solution: Solution | None = None
        """The fit at its last solve, once it determines the circle."""
        self._unsolved = 0
        """Samples added since that solve."""
        self.distance: float | None = None
        """``‖z_ij‖ = √(d + ‖c‖²)``, the fitted radius (``None`` until the circle is
        determined)."""
        self.distance_std: float | None = None
        """The standard deviation (m) of :attr:`distance`: the fit's, through
        ``∂r/∂p = (c_x/r, c_y/r, 1/(2r))``, scaled by ``N`` and :data:`CORRELATION`."""
        self._last_estimate: tuple = (None, None, None)
        """``(r̂, ψ̂, z_ij)`` of the last :attr:`estimate` made."""

    def update(self, zdot: Vec2, dt: float, *, follow: bool = True) -> None:
        """Feed ``ż_ij`` sampled ``dt`` after the last sample used."""
        zx, zy = zdot
        if math.hypot(zx, zy) <= self.min_speed:
            self.moving = False
            return
        self.moving = True
        last = self.zdot
        if last is None:
            self.zdot = zdot
            self._add(self.s)
            return
        bx, by = self.s
        h = 0.5 * dt
        sx = bx + h * (last[0] + zx)
        sy = by + h * (last[1] + zy)
        prior = self._before
        if prior is not None:  # the noise, from the second difference of ż_ij
            ex = zx - 2.0 * last[0] + prior[0]
            ey = zy - 2.0 * last[1] + prior[1]
            lam, second = self.fit.forgetting, self._second
            second[0] = lam * second[0] + ex * ex + ey * ey
            second[1] = lam * second[1] + 1.0
            self.noise = second[0] / (12.0 * second[1])
        self.s = s = (sx, sy)
        self.step = (sx - bx, sy - by)
        self._before, self.zdot = last, zdot
        self.last_dt = dt
        self._add(s)
        fit = self._solution
        if fit is not None:  # both ends about the same centre: its own refits are no turn
            cx, cy, _ = fit.estimate
            self.arc = arc = (sx - cx, sy - cy)
            self.last_turn = angle_between((bx - cx, by - cy), arc)
            if follow:
                self.follow(self.last_turn)
        else:
            self.last_turn = angle_between(last, zdot)  # ż_ij turns with z_ij
            self.direction = None

    def follow(self, turn: float, variance: float | None = None) -> None:
        """One step of the direction filter (see the module docstring) at the last sample
        used: the direction turns by ``turn`` (rad) of variance ``variance`` (rad²; ``None``:
        that of the arc's own increment, :attr:`last_turn`), then the sample measures it.
        :meth:`update` calls it with the arc's own increment unless told not to
        (``follow=False``: the caller then follows the team's turn)."""
        fit = self._solution
        if fit is None or not self.moving:
            return
        zdot, dt = self.zdot, self.last_dt
        r = self.distance
        if self.direction is None:  # start from the arc, with its uncertainty
            c = fit.estimate
            self.direction = math.atan2(self.s[1] - c[1], self.s[0] - c[0])
            self.direction_var = (self._arc_std / r) ** 2
            return
        noise = self.noise
        self.direction += turn
        own = 0.5 * noise * dt * dt / (r * r)
        self.direction_var += own if variance is None else variance
        speed2 = zdot[0] * zdot[0] + zdot[1] * zdot[1]
        if noise <= 0.0 or speed2 <= 0.0:
            return
        # z_ij along ∓ż_ij⊥ = ∓(−ż_y, ż_x): the sign nearer the prediction.
        psi = self.direction
        measured = math.atan2(zdot[0], -zdot[1])
        if math.cos(measured - psi) < 0.0:
            measured += math.pi
        innovation = math.remainder(measured - psi, math.tau)
        variance = noise / speed2
        gain = self.direction_var / (self.direction_var + variance)
        self.direction = psi + gain * innovation
        self.direction_var *= 1.0 - gain

    def _add(self, s: Vec2) -> None:
        x, y = s
        fit = self.fit
        fit.add((2.0 * x, 2.0 * y, 1.0), x * x + y * y)
        if self._solution is not None:
            self._unsolved += 1
            if self._unsolved < SOLVE_EVERY:
                return
        self._unsolved = 0
        solution = fit.solve() if fit.rows >= 10 else None
        self._solution = self.distance = self.distance_std = None
        if solution is None:
            return
        cx, cy, d = solution.estimate
        r2 = d + cx * cx + cy * cy
        if not r2 > 0.0:
            return
        r = math.sqrt(r2)
        scale = CORRELATION * solution.rows
        std = math.sqrt(solution.variance_of((cx / r, cy / r, 0.5 / r), scale))
        if std > 0.5 * r:  # the circle not yet determined
            return
        self._solution, self.distance, self.distance_std = solution, r, std

    @property
    def speed2(self) -> float:
        """``‖ż_ij‖²`` at the last sample used (0 before any)."""
        zdot = self.zdot
        return 0.0 if zdot is None else zdot[0] * zdot[0] + zdot[1] * zdot[1]

    @property
    def _scale(self) -> float:
        return CORRELATION * self._solution.rows

    @property
    def centre(self) -> Vec2 | None:
        """``c = −z_ij(t₀)``."""
        fit = self._solution
        return None if fit is None else (fit.estimate[0], fit.estimate[1])

    @property
    def estimate(self) -> Vec2 | None:
        """``z_ij = r̂ (cos ψ̂, sin ψ̂)`` at the last sample used, in ``W`` then."""
        r, psi = self.distance, self.direction
        if r is None or psi is None:
            return None
        last_r, last_psi, z = self._last_estimate
        if r is not last_r or psi is not last_psi:  # read several times a sample: made once
            z = (r * math.cos(psi), r * math.sin(psi))
            self._last_estimate = (r, psi, z)
        return z

    @property
    def covariance(self) -> Covariance | None:
        """The covariance (m²) of :attr:`estimate`: ``Var(r̂)`` along it, ``r̂² P`` across."""
        z, radial = self.estimate, self.distance_std
        if z is None or radial is None:
            return None
        r = self.distance
        u = (z[0] / r, z[1] / r)
        along, across = radial * radial, DIRECTION_VARIANCE * r * r * self.direction_var
        return (
            (along * u[0] * u[0] + across * u[1] * u[1], (along - across) * u[0] * u[1]),
            ((along - across) * u[0] * u[1], along * u[1] * u[1] + across * u[0] * u[0]),
        )

    @property
    def std(self) -> float | None:
        """The standard deviation (m) of :attr:`estimate` along its least certain axis."""
        radial, r = self.distance_std, self.distance
        if radial is None or self.direction is None:
            return self._arc_std
        return max(radial, r * math.sqrt(DIRECTION_VARIANCE * self.direction_var))

    @property
    def centre_covariance(self) -> Covariance | None:
        """The covariance (m²) of :attr:`centre`: the fit's, scaled by ``N`` and
        :data:`CORRELATION`."""
        fit = self._solution
        if fit is None:
            return None
        (a, b, _), (_, d, _), _ = fit.covariance(self._scale)
        return ((a, b), (b, d))

    @property
    def _arc_std(self) -> float | None:
        """The centre's standard deviation along its least certain axis (m)."""
        cov = self.centre_covariance
        return None if cov is None else largest_std(*packed(cov))
