"""Simulated arcs: the arc fit (:mod:`agent.algorithm.robust.arc_fit`) on one edge's samples
of ``ż_ij``, against its truth, for the calibration of its uncertainty
(``heft bench calibrate arc-correlation``, :mod:`simulator.bench.calibrate`).

Two contacts :data:`RADIUS` apart on a load turning at ``ω(t) = 0.3 + 0.2 sin t`` rad/s
(:func:`turn`), from a random direction, sampled every :data:`PERIOD_S`; each robot's velocity
has white noise ``σ`` per axis, so ``ż_ij`` has ``√2 σ``. One arc per noise level
(:data:`NOISES`) and seed is fitted for the longest of :data:`LENGTHS_S`, and read at each
length: the fitted radius ``‖z_ij‖`` and centre ``c = −z_ij(t₀)`` with their published
variance and covariance, against the truth.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agent.algorithm.robust.arc_fit import ArcRelativePosition

RADIUS = 1.5
"""m: ``‖z_ij‖``."""
PERIOD_S = 0.01
"""s: the samples' period (100 Hz)."""
NOISES = (0.001, 0.003, 0.01, 0.03)
"""m/s: the velocity noise ``σ`` per axis and robot, 1 mm/s to 3 cm/s."""
LENGTHS_S = (3.0, 5.0, 10.0, 20.0)
"""s: the arc's lengths at which the fit is read."""


def turn(t: float) -> tuple[float, float]:
    """``(ω(t), θ(t))``: the load's angular velocity, 0.3 ± 0.2 rad/s, and its rotation
    since ``t = 0``."""
    return 0.3 + 0.2 * math.sin(t), 0.3 * t - 0.2 * math.cos(t) + 0.2


@dataclass(frozen=True)
class ArcReading:
    """The fit of one arc after ``seconds``: the radius' error (m) and variance (m²), the
    centre's error (m) and covariance ``(xx, xy, yy)`` (m²)."""

    noise: float
    seconds: float
    seed: int
    radius_error: float
    radius_variance: float
    centre_error: tuple[float, float]
    centre_covariance: tuple[float, float, float]


def fit_arc(noise: float, seed: int, lengths: Sequence[float] = LENGTHS_S) -> list[ArcReading]:
    """One arc with velocity noise ``noise`` (m/s per axis and robot), fitted for the longest
    of ``lengths`` (s) and read at each (none at a length whose circle is not known yet)."""
    rng = np.random.default_rng((seed, round(noise * 1e6)))
    phase = rng.uniform(0.0, math.tau)
    start = (-RADIUS * math.cos(phase), -RADIUS * math.sin(phase))  # c = −z_ij(t₀)
    edge = ArcRelativePosition()
    readings = []
    ends = {round(s / PERIOD_S): s for s in lengths}
    for k in range(1, max(ends) + 1):
        omega, angle = turn((k - 1) * PERIOD_S)
        z = (RADIUS * math.cos(phase + angle), RADIUS * math.sin(phase + angle))
        dx, dy = math.sqrt(2.0) * noise * rng.normal(size=2)
        edge.update((-omega * z[1] + dx, omega * z[0] + dy), PERIOD_S)
        if k in ends and edge.centre is not None and edge.distance_std is not None:
            (xx, xy), (_, yy) = edge.centre_covariance
            centre = edge.centre
            readings.append(
                ArcReading(
                    noise=noise,
                    seconds=ends[k],
                    seed=seed,
                    radius_error=edge.distance - RADIUS,
                    radius_variance=edge.distance_std**2,
                    centre_error=(centre[0] - start[0], centre[1] - start[1]),
                    centre_covariance=(xx, xy, yy),
                )
            )
    return readings


def fit_arcs(seeds: int, noises: Sequence[float] = NOISES) -> list[ArcReading]:
    """:func:`fit_arc` for seeds ``0 .. seeds − 1`` at each noise level."""
    return [
        reading for noise in noises for seed in range(seeds) for reading in fit_arc(noise, seed)
    ]
