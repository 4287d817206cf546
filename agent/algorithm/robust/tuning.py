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
    inertia_brake_level: float = bounded(0.5, 0, 1)
    """Step 4 brakes with this fraction of the torque it speeds up with: on a real floor,
    whose friction torque brakes the turn all the while, equal levels would stop the load
    within a few flips; below 1 the turn keeps up (a frictionless load's turn grows by
    ``(1 − this) k w T / 2J`` a flip). 1: the paper's symmetric torque."""
    max_turn_rate: float = bounded(1.8, 0, 100, "rad/s", open_low=True)
    """rad/s: Step 4's torque fades (linearly, over the last :data:`~agent.algorithm.robust.
    phases.TURN_RATE_TAPER` of it) as the load's turn ``|ω̂|`` nears this, either way: a light
    load under the team's torque would otherwise turn faster every flip (a generated load of
    J = 2.9 kg m² under 8.7 N m turned at 3.3 rad/s), beyond what its floor allows."""
    breakaway_speed: float = bounded(0.05, 0, 10, "m/s", open_low=True)
    """m/s: Step 1's kick grows (doubling every ``kick_duration_s``, up to ``max_force``) until
    the robot's contact, or its speed relative to a neighbour's, filtered over
    :data:`~agent.algorithm.robust.phases.MOVING_TIME_CONSTANT_S`, is faster than this: the
    load has broken away from its floor, and the spin-up's gain is ``spin_gain`` times the
    kick's growth."""
    breakaway_s: float = bounded(3.0, 0, 600, "s", min_ticks=1)
    """s: a load that ``max_force``'s kick has not moved after this long is held by its floor:
    the robots stop pushing, with the verdict "cannot break the load away"."""
    push_force: float = bounded(2.0, 0, 1000, "N", open_low=True)
    """N: every robot pushes with exactly this (at most ``max_force``): the robots' Ĵ differ by
    their noise, and eq. (17)'s ``f̄_y Ĵ/n`` would make their forces differ too, where Steps 5
    and 7 need one common force."""
    spin_up_s: float = bounded(1.5, 0, 60, "s")
    """s: the push begins by turning the load up to ``pendulum_spin`` for this long (each robot
    adds the torque ``τ̂_c + Ĵ (ω* − ω̂) / spin_up_s``, no net force), so that the swing of
    Step 5's stage is small against the supports' speed about the COM."""
    pendulum_spin: float = bounded(1.2, 0, 10, "rad/s", open_low=True)
    """rad/s: ``ω*``, the turn the load is brought up to for Step 5's stage (within the floor's
    ``|ω|``)."""
    pendulum_s: float = bounded(6.0, 0, 600, "s", min_ticks=10)
    """s: the push's first stage, Step 5's, in which the load swings about its COM as it turns
    (the torque ``s_ω τ̂_c`` keeps it turning against the floor's friction)."""
    pendulum_flip_s: float = bounded(1.0, 0, 60, "s", min_ticks=2)
    """s: the push's reversal period ``T`` in Step 5's stage (``push_flip_s`` is Step 7's):
    shorter than Step 7's, so that the COM's speed (``n f T / 2m``) stays small against the
    supports' speed about it, ``|ω| r``, where the floor's friction is a torque alone."""
    translate_brake_s: float = bounded(1.5, 0, 60, "s", min_ticks=1)
    """s: then every robot brakes its contact (``−b ṗ_Ci``, ``brake_gain``) for this long: the
    load stops turning before it is pushed in translation (Step 7's stage)."""
    turn_damping: float = bounded(4.0, 0, 1000, "N s/m")
    """N s/m: in Step 7's stage each robot adds ``−b ω̂ z_i⊥`` (torque ``−b ω̂ w``, no net
    force) beside the torque that moves the common force's line of action from the contacts'
    centroid to the COM that Step 5 found: the load then translates, so that every support
    moves with the COM and friction's force is ``−μ m g v̂_C`` exactly."""
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
