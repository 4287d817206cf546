"""The uncertainties the robust estimators publish (``Estimates``' standard deviations and
covariances), and the factors they are calibrated by.

``Cov(p_C − p_Ci) = Cov(z_i) + Cov(z_C)``, taking the two as independent: ``Cov(z_i)`` as the
mean of the robot's own edges' (the consensus averages edges like them), and ``Cov(z_C)`` as the
push fit's turned with the load, plus ``c cᵀ (σ_J/J)²`` for the ``Ĵ`` it was computed with
(``c ∝ J``), plus that of the gains' correction ``h``; then scaled as calibrated
(:data:`PUBLISHED_VARIANCE`); :meth:`agent.algorithm.robust.pipeline.RobustPipeline._reported`
computes them. The gains' corrections take every robot's gain as uncertain as
this one's, ``σ_g``: ``ḡ`` and ``q / (w/n)`` then have about ``σ_g / √n`` relative, and
``h = Σ g_i z_i / n`` has ``σ_g² w / (2 n²)`` per axis.
"""

from __future__ import annotations

from dataclasses import dataclass

PUBLISHED_VARIANCE = {
    "relative": 1.14,
    "contact_to_com": 1.28,
    "moment": 1.41,
    "friction_torque": 2.33,
    "coulomb": 574.0,
}
"""Factors on the variances the robust estimators publish for ``z_ij``, ``contact_to_com``,
``Ĵ`` and the floor's friction torque ``τ̂_c`` and coefficient ``μ̂`` (not on those they settle
by): the drives' gains, the reversing push and the floor's friction add errors their fits do
not model, and the direction filters of the ``z_ij`` take the team's turn for twice as
uncertain as independent robots' turns (:mod:`agent.algorithm.robust.rotation`). ``μ̂``'s fit
counts each row of Step 7's displacement as independent, where its errors are the velocity
noise's random walk and the friction's column is smooth: its variance is 574 times too small
(a correlation time for that column would be the principled repair). Measured over 40 runs of
the noise benchmark on a real floor (the paper's load on ``paper-floor.toml``'s four casters at
1 cm/s with lagging drives of 2 % gain error, each seed's ``μ`` drawn in [0.5 %, 3 %],
``μ_s`` = 1.5 ``μ``), seeds 20–59: 95 % of the errors fall within 1.96 published standard
deviations (2.45 for the planar ones: the 95 % ellipse, each ``z_ij`` on its own) with the
variances scaled by these factors; the team's ``m̂``, published unscaled, held the truth 97.9 %
of the time. The benchmark's seeds, 0–19, were not used.

``heft bench calibrate published-variance --first-seed 20 --seeds 40 --coulomb-range 0.005
0.03`` prints each factor, the share inside with it, and the factor for 95 % inside. On
2026-11-27, with the factors of the frictionless calibration before (0.79, 1.57, 1.52 and 1
for both of the floor's), it printed 1.14 for ``relative`` (88.6 % inside), 1.28 for
``contact_to_com`` (98.6 %), 1.41 for ``moment`` (95.0 %), 2.33 for ``friction_torque``
(80.7 %) and 574 for ``coulomb`` (10.0 %), 35 of the 40 runs done."""


@dataclass(frozen=True)
class FitShares:
    """The shares of one robot's uncertainties that its fits' row counts give, which their
    correlation times scale (:attr:`~agent.algorithm.robust.least_squares.RunFit.
    correlation_time`): what their calibration reads besides the estimates (``None``: not
    fitted yet)."""

    moment: float | None = None
    """kg m²: the inertia fit's own share of the published ``moment_std`` before its factor
    in :data:`PUBLISHED_VARIANCE` (the fit's standard deviation, scaled as ``Ĵ`` is by
    ``q / (w/n)``)."""
    own_mass: tuple[float, float, float] | None = None
    """``(m̂_i, σ, σ_fit)`` (kg): this robot's own mass (before the team's consensus on it), its
    standard deviation, and the mass fit's own share of it (scaled as ``m̂_i`` is by ``ḡ``)."""


def packed(cov) -> tuple[float, float, float]:
    """A planar covariance ``((xx, xy), (xy, yy))`` as ``(xx, xy, yy)``."""
    (a, b), (_, d) = cov
    return (a, b, d)
