"""The robust estimators' own gains (``[agent.robust]`` in a scenario, ``[tuning.robust]`` in
robot.toml)."""

from __future__ import annotations

from dataclasses import dataclass

from agent.platform.config import bounded, check_bounds


@dataclass(frozen=True)
class RobustTuning:
    """The gains of the noise-tolerant estimators and of their force laws."""

    settle_uncertainty: float = bounded(0.01, 1e-6, 0.5)
    """The relative standard deviation below which an estimate may count as settled (and
    changes within three of its standard deviations count as still)."""
    inertia_flip_s: float = bounded(1.0, 0, 60, "s", min_ticks=1)
    """s: Step 4 speeds up for this long, then brakes for as long, in turn (at most
    ``inertia_flip_s`` × the load's angular acceleration above the turn it had)."""
    inertia_brake_s: float = bounded(0.5, 0, 60, "s")
    """s: Step 4 first brakes for this long. Half of ``inertia_flip_s`` makes ω swing about the
    turn the load had, by half as much as speeding up first: for compact, light loads, whose
    turn would leave the floor; a slower turn gives Step 1's direction filters less signal.
    0: speed up first."""
    push_force: float = bounded(2.0, 0, 1000, "N", open_low=True)
    """N: every robot pushes with exactly this (at most ``max_force``): the robots' Ĵ differ by
    their noise, and eq. (17)'s ``f̄_y Ĵ/n`` would make their forces differ too, where Steps 5
    and 7 need one common force."""
    push_damping: float = bounded(2.0, 0, 1000, "N s/m")
    """N s/m: each robot adds ``−b ṗ̂_G`` to the push (the centroid's velocity, which every
    robot estimates alike from Step 2): the COM's speed then stays within about ``f / b`` and a
    drift dies out, whatever the load's mass; Steps 5 and 7 take the force as commanded. 0: the
    push alone."""
    change_threshold: float = bounded(6.0, 0.1, 1000, off=0.0)
    """Once done, the team probes the load, and a robot whose probe finds the mass or the COM
    off its estimates by more than this many standard deviations (its score,
    :mod:`agent.algorithm.robust.load_change`) calls the load changed: the team estimates it
    again. 0: no probes; the load comes to rest."""
    monitor_gap_s: float = bounded(1.0, 0, 60, "s", min_ticks=1)
    """s: before each probe, the team damps the COM's velocity for this long."""
    probe_s: float = bounded(2.0, 0, 60, "s", min_ticks=4)
    """s: a probe's length ``T`` (rounded to 4 ticks): ``+f``, ``−f``, ``+f`` for ``T/4``,
    ``T/2``, ``T/4``; the COM swings by ``n f T² / 16m``."""

    def validate(self, where: str) -> None:
        """:class:`~agent.platform.config.ConfigError` naming the key and its range unless every
        field is in range."""
        check_bounds(self, where)
