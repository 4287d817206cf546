"""What one agent runs with: who it is (:class:`AgentConfig`) and its gains and limits
(:class:`AgentTuning`), read from TOML by :func:`~agent.platform.config.from_table`."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from agent.platform.config import ConfigError, _number, bounded, check_bounds, check_ticks


class Estimators(enum.Enum):
    """Which estimators an agent runs (``[agent] estimator``)."""

    PAPER = "paper"
    """The paper's (eqs. 10-25, settling judged by drift): exact without noise."""
    ROBUST = "robust"
    """For noisy sensors: Step 1 by the arc fit (:mod:`agent.algorithm.estimation.arc_fit`),
    settling
    judged by each estimate's own uncertainty."""


@dataclass(frozen=True)
class AgentTuning:
    """The gains and limits an agent runs with; the same for every robot of a team.

    The defaults are those of the paper's scenario (Sec. VI) and work for the generated ones.
    Each field declares its range (:func:`bounded`), checked by :meth:`validate` before anything
    starts; ``kick_force``, ``inertia_force`` and ``push_min_force`` are also at most
    ``max_force``. The lower ends counted in ticks (``kick_duration_s``, ``settle_window_s``,
    ``regression_memory_s``) are checked by :meth:`check_period` where the sensor period is
    known (the scenario's ``sensors.rate_hz``, robot.toml's ``period_s``).
    """

    estimator: Estimators = Estimators.PAPER
    """``paper`` or ``robust`` (:class:`Estimators`)."""
    max_force: float = bounded(10.0, 0, 1000, "N", open_low=True)
    """N: bound on every commanded force's magnitude (safety)."""
    filter_gain: float = bounded(5.0, 0, 1000, "1/s", open_low=True)
    """k_f (1/s), the low-pass filters of the Appendix."""
    regression_memory_s: float = bounded(0.0, 0, 3600, "s", off=0.0, min_ticks=10)
    """s: time constant of the least-squares regressions' forgetting: 0 = never forget, else
    at least 10 ticks (a shorter memory forgets every sample at once) and at most an hour."""
    kick_force: float = bounded(2.0, 0, 1000, "N", open_low=True)
    """N: magnitude of the seeded random push that starts Step 1 (at most ``max_force``)."""
    kick_duration_s: float = bounded(0.5, 0, 60, "s", min_ticks=1)
    """s: how long that push lasts (at least a tick: a shorter one would not push at all)."""
    spin_gain: float = bounded(4.0, 0, 1000, "N s/m", open_low=True)
    """N s/m: gain k of the Step-1 spin-up ``f_i = k Σ_j c(‖ż_ij‖) ż_ij``."""
    spin_speed: float = bounded(0.5, 0, 10, "m/s", open_low=True)
    """m/s: relative contact speed the Step-1 spin-up settles towards."""
    inertia_force: float = bounded(2.0, 0, 1000, "N", open_low=True)
    """N: largest per-robot force of Step 4 (``f_i = k z_i⊥`` with ``k = F/√w``; at most
    ``max_force``)."""
    inertia_min_s: float = bounded(2.0, 0, 600, "s")
    """s: shortest Step 4 (it also spins the load up for Step 5)."""
    inertia_max_omega: float = bounded(1.0, 0, 10, "rad/s", open_low=True)
    """rad/s: Step 4 brakes when |ω| reaches this and speeds up again below half of it."""
    inertia_flip_s: float = bounded(1.0, 0, 60, "s", min_ticks=1)
    """s: with ``estimator = "robust"``, Step 4 speeds up for this long, then brakes for as
    long, in turn (at most ``inertia_flip_s`` × the load's angular acceleration above the
    turn it had: keep it below ``inertia_max_omega``)."""
    inertia_brake_s: float = bounded(0.0, 0, 60, "s")
    """s: with ``estimator = "robust"``, Step 4 first brakes for this long. Half of
    ``inertia_flip_s`` makes ω swing about the turn the load had, by half as much as speeding
    up first: for compact, light loads, whose turn would leave the floor; a slower turn gives
    Step 1's direction filters less signal. 0: speed up first."""
    push_fbar: float = bounded(1.0, 0, 1000, "rad/s² per m", open_low=True)
    """f̄_y (rad/s² per m) of Steps 5–7: each robot pushes with ``f = f̄_y Ĵ / n`` (Sec. VI) ..."""
    push_min_force: float = bounded(1.0, 0, 1000, "N", open_low=True)
    """N: ... but at least this much (a compact load's COM would barely accelerate for Step 7),
    and at most ``max_force``."""
    push_force: float = bounded(3.0, 0, 1000, "N", open_low=True)
    """N: with ``estimator = "robust"``, every robot pushes with exactly this (at most
    ``max_force``): the robots' Ĵ differ by their noise, and eq. (17)'s ``f̄_y Ĵ/n`` would
    make their forces differ too, where Steps 5 and 7 need one common force."""
    push_flip_s: float = bounded(1.0, 0, 60, "s", off=0.0, min_ticks=2)
    """s: the push reverses on the agreed clock so that the load stays on a bounded floor:
    ``+f`` for half of this, then ``−f`` and ``+f`` for this long each, in turn; the COM's
    velocity then swings by ``± n f T / 2m`` about the one it had and its travel by
    ``n f T² / 8m`` (``T`` this). 0 pushes one way, as the paper does (the load's speed then
    grows without bound)."""
    brake_gain: float = bounded(2.0, 0, 1000, "N s/m")
    """N s/m: the damping ``f_i = −b ṗ_Ci`` of Remark V.2 that keeps the floor bounded: added
    to the spin-up once the kick is over (it takes out the kick's drift; Steps 1–3 need only
    the turn), and applied alone once the team is done, so that the load comes to rest. 0
    leaves the load to coast, as the paper does."""
    push_damping: float = bounded(0.0, 0, 1000, "N s/m")
    """N s/m: with ``estimator = "robust"``, each robot adds ``−b ṗ̂_G`` to the push (the
    centroid's velocity, which every robot estimates alike from Step 2): the COM's speed then
    stays within about ``f / b`` and a drift dies out, whatever the load's mass; Steps 5 and 7
    take the force as commanded. 0: the push alone."""
    change_threshold: float = bounded(6.0, 0.1, 1000, off=0.0)
    """With ``estimator = "robust"``: once done, the team probes the load, and a robot whose
    probe finds the mass or the COM off its estimates by more than this many standard
    deviations (its score, :mod:`agent.algorithm.estimation.load_change`) calls the load
    changed: the team estimates it again. 0: no probes; the load comes to rest."""
    monitor_gap_s: float = bounded(1.0, 0, 60, "s", min_ticks=1)
    """s: before each probe, the team damps the COM's velocity for this long."""
    probe_s: float = bounded(2.0, 0, 60, "s", min_ticks=4)
    """s: a probe's length ``T`` (rounded to 4 ticks): ``+f``, ``−f``, ``+f`` for ``T/4``,
    ``T/2``, ``T/4``; the COM swings by ``n f T² / 16m``."""
    push_direction: tuple[float, float] = (0.0, 1.0)
    """Direction in ``W`` of the common force ``f`` of Steps 5–7: a vector of length in
    [0.001, 1000] (only its direction counts)."""
    observer_gain: float = bounded(2.0, 0, 1000, "1/s", open_low=True)
    """k_e of observer (24)."""
    settle_window_s: float = bounded(1.0, 0, 60, "s", min_ticks=1)
    """s: an estimate has settled when it moved less than the tolerance over this window."""
    settle_tolerance: float = bounded(1e-4, 1e-8, 0.1)
    """Relative change that counts as settled."""
    settle_uncertainty: float = bounded(0.01, 1e-6, 0.5)
    """With ``estimator = "robust"``: the relative standard deviation below which an estimate
    may count as settled (and changes within three of its standard deviations count as
    still)."""
    switch_margin_ticks: int = bounded(10, 0, 1000, "ticks")
    """Ticks added to ``n`` between the team agreeing on a phase switch and making it."""

    PUSH_DIRECTION_LENGTH = (0.001, 1000.0)
    """The range of ``push_direction``'s length."""

    def validate(self, where: str) -> None:
        """:class:`ConfigError` naming the key and its range unless every field is in range
        (:func:`bounded`), the forces are at most ``max_force`` and ``push_direction``'s length
        is in [0.001, 1000]."""
        check_bounds(self, where)
        for key in ("kick_force", "inertia_force", "push_min_force", "push_force"):
            if getattr(self, key) > self.max_force:
                raise ConfigError(
                    f"{where}.{key}: expected at most max_force ({self.max_force!r} N),"
                    f" got {getattr(self, key)!r}"
                )
        low, high = self.PUSH_DIRECTION_LENGTH
        if not low <= math.hypot(*self.push_direction) <= high:
            raise ConfigError(
                f"{where}.push_direction: expected a vector of length in [{_number(low)},"
                f" {_number(high)}], got {list(self.push_direction)!r}"
            )

    def check_period(self, where: str, period_s: float, rate: str) -> None:
        """:class:`ConfigError` unless the durations counted in ticks are long enough for a
        sensor period of ``period_s`` s (``rate`` names where it comes from, for the message)."""
        check_ticks(self, where, period_s, rate)


@dataclass(frozen=True)
class AgentConfig:
    """Who one agent is: its id, the team size and its graph neighbours, plus the tuning."""

    robot: int
    n: int
    neighbours: tuple[int, ...]
    period_s: float
    seed: int = 1
    tuning: AgentTuning = AgentTuning()
