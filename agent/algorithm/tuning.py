"""What one agent runs with: who it is (:class:`AgentConfig`) and its gains and limits
(:class:`AgentTuning`), read from TOML by :func:`~agent.platform.config.from_table`."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from agent.algorithm.paper.tuning import PaperTuning
from agent.algorithm.robust.tuning import RobustTuning
from agent.platform.config import (
    ConfigError,
    _number,
    bounded,
    check_bounds,
    check_ticks,
    fields_of,
)


class Estimators(enum.Enum):
    """Which family of estimators an agent runs (``[agent] estimator``), chosen once: each is a
    set of modules behind one interface (:mod:`agent.algorithm.families`)."""

    PAPER = "paper"
    """The paper's (eqs. 10-25, settling judged by drift): exact without noise
    (:mod:`agent.algorithm.paper`)."""
    ROBUST = "robust"
    """For noisy sensors and real drives: fits of the integrated measurements, settling judged
    by each estimate's own uncertainty (:mod:`agent.algorithm.robust`)."""


FAMILY_KEYS = {
    **dict.fromkeys(fields_of(PaperTuning), "paper"),
    **dict.fromkeys(fields_of(RobustTuning), "robust"),
}
"""The keys that live in a family's table: given at the top of the tuning table, they are
refused with a message naming their table."""


@dataclass(frozen=True)
class AgentTuning:
    """The gains and limits an agent runs with; the same for every robot of a team.

    The common ones here, each family's in its own table (:attr:`paper`, :attr:`robust`; only
    the chosen family's is used). The defaults are for real robots: the robust estimators, with
    a Step-1 spin-up and a push sized for noisy sensors and lagging drives. The paper's
    estimators run as in its Sec. VI with the keys of :data:`PAPER_REFERENCE`. Each field
    declares its range (:func:`bounded`), checked by :meth:`validate` before anything starts;
    ``kick_force``, ``inertia_force``, ``paper.push_min_force`` and ``robust.push_force`` are
    also at most ``max_force``. The lower ends counted in ticks are checked by
    :meth:`check_period` where the sensor period is known (the scenario's ``sensors.rate_hz``,
    robot.toml's ``period_s``).
    """

    estimator: Estimators = Estimators.ROBUST
    """``robust`` or ``paper`` (:class:`Estimators`)."""
    max_force: float = bounded(10.0, 0, 1000, "N", open_low=True)
    """N: bound on every commanded force's magnitude (safety)."""
    regression_memory_s: float = bounded(0.0, 0, 3600, "s", off=0.0, min_ticks=10)
    """s: time constant of the least-squares regressions' forgetting: 0 = never forget, else
    at least 10 ticks (a shorter memory forgets every sample at once) and at most an hour."""
    kick_force: float = bounded(2.0, 0, 1000, "N", open_low=True)
    """N: magnitude of the seeded random push that starts Step 1 (at most ``max_force``)."""
    kick_duration_s: float = bounded(0.5, 0, 60, "s", min_ticks=1)
    """s: how long that push lasts (at least a tick: a shorter one would not push at all)."""
    spin_gain: float = bounded(10.0, 0, 1000, "N s/m", open_low=True)
    """N s/m: gain k of the Step-1 spin-up ``f_i = k Σ_j c(‖ż_ij‖) ż_ij`` (stiff enough to hold
    :attr:`spin_speed` against the damping that keeps the floor bounded)."""
    spin_speed: float = bounded(1.0, 0, 10, "m/s", open_low=True)
    """m/s: relative contact speed the Step-1 spin-up settles towards (a fast turn gives the
    arcs and the angle fits more signal against the same noise)."""
    inertia_force: float = bounded(2.0, 0, 1000, "N", open_low=True)
    """N: largest per-robot force of Step 4 (``f_i = k z_i⊥`` with ``k = F/√w``; at most
    ``max_force``)."""
    inertia_min_s: float = bounded(2.0, 0, 600, "s")
    """s: shortest Step 4 (it also spins the load up for Step 5)."""
    push_flip_s: float = bounded(2.0, 0, 60, "s", off=0.0, min_ticks=2)
    """s: the push reverses on the agreed clock so that the load stays on a bounded floor:
    ``+f`` for half of this, then ``−f`` and ``+f`` for this long each, in turn; the COM's
    velocity then swings by ``± n f T / 2m`` about the one it had and its travel by
    ``n f T² / 8m`` (``T`` this: against noise that displacement is the mass's signal). 0
    pushes one way, as the paper does (the load's speed then grows without bound)."""
    brake_gain: float = bounded(2.0, 0, 1000, "N s/m")
    """N s/m: the damping ``f_i = −b ṗ_Ci`` of Remark V.2 that keeps the floor bounded: added
    to the spin-up once the kick is over (it takes out the kick's drift; Steps 1–3 need only
    the turn), and applied alone once the team is done, so that the load comes to rest. 0
    leaves the load to coast, as the paper does."""
    push_direction: tuple[float, float] = (0.0, 1.0)
    """Direction in ``W`` of the common force ``f`` of Steps 5–7: a vector of length in
    [0.001, 1000] (only its direction counts)."""
    observer_gain: float = bounded(2.0, 0, 1000, "1/s", open_low=True)
    """k_e of observer (24)."""
    settle_window_s: float = bounded(1.0, 0, 60, "s", min_ticks=1)
    """s: an estimate has settled when it moved less than the tolerance over this window."""
    settle_tolerance: float = bounded(1e-4, 1e-8, 0.1)
    """Relative change that counts as settled."""
    switch_margin_ticks: int = bounded(10, 0, 1000, "ticks")
    """Ticks added to ``n`` between the team agreeing on a phase switch and making it."""
    paper: PaperTuning = PaperTuning()
    """The paper's estimators' gains (:class:`~agent.algorithm.paper.tuning.PaperTuning`)."""
    robust: RobustTuning = RobustTuning()
    """The robust estimators' gains (:class:`~agent.algorithm.robust.tuning.RobustTuning`)."""

    PUSH_DIRECTION_LENGTH = (0.001, 1000.0)
    """The range of ``push_direction``'s length."""
    MOVED_KEYS = FAMILY_KEYS
    """Keys refused here with the table they live in (:func:`~agent.platform.config.
    from_table`)."""

    def validate(self, where: str) -> None:
        """:class:`ConfigError` naming the key and its range unless every field is in range
        (:func:`bounded`), the forces are at most ``max_force`` and ``push_direction``'s length
        is in [0.001, 1000]."""
        check_bounds(self, where)
        forces = (
            ("kick_force", self.kick_force),
            ("inertia_force", self.inertia_force),
            ("paper.push_min_force", self.paper.push_min_force),
            ("robust.push_force", self.robust.push_force),
        )
        for key, value in forces:
            if value > self.max_force:
                raise ConfigError(
                    f"{where}.{key}: expected at most max_force ({self.max_force!r} N),"
                    f" got {value!r}"
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
        check_ticks(self.paper, f"{where}.paper", period_s, rate)
        check_ticks(self.robust, f"{where}.robust", period_s, rate)


PAPER_REFERENCE = {"estimator": "paper", "spin_gain": 4.0, "spin_speed": 0.5, "push_flip_s": 1.0}
"""The ``[agent]`` keys that run the paper's estimators, the reference, with the gentler Step-1
spin-up and the shorter push reversal they have always been run with: the paper's scenario
(``simulator/scenarios/paper.toml``) spells them out and the generated scenarios
(:mod:`simulator.generate`) carry them, so their results stay those of
``tests/fixtures/paper-results.json``."""


@dataclass(frozen=True)
class AgentConfig:
    """Who one agent is: its id, the team size and its graph neighbours, plus the tuning."""

    robot: int
    n: int
    neighbours: tuple[int, ...]
    period_s: float
    seed: int = 1
    tuning: AgentTuning = AgentTuning()
