"""What the phase machine and the estimation pipeline read of each other, and nothing more.

Each tick the pipeline brings the robot's estimates up to the estimation instant, then the phase
machine decides with the team when to change the force regime and gives the force
(:mod:`agent.algorithm.agent`). The machine reads the robot's own estimates through
:class:`OwnEstimates`; the pipeline reads what the team applied, and when, through
:class:`Schedule` (and :class:`ProbeSchedule` for the robust family's probes).
"""

from __future__ import annotations

from typing import Protocol

from agent.platform.geometry import Vec2
from agent.platform.protocol import Phase


class OwnEstimates(Protocol):
    """What the phase machine reads of its own robot's estimates (a family's
    :class:`~agent.algorithm.pipeline.EstimationPipeline`)."""

    instant: int
    """The estimation instant."""
    omega: float | None
    """``ω`` at the estimation instant (Step 3)."""
    measured: int | None
    """The last instant whose ``ω`` was measured."""
    zdot: dict[int, Vec2]
    """``ż_ij`` at the estimation instant, by neighbour."""
    velocity: Vec2 | None
    """``ṗ_Ci``, the robot's own velocity, at the estimation instant."""
    com_velocity: Vec2 | None
    """``ṗ_C`` (Step 6)."""
    stuck: bool
    """Whether Step 4's torque left the load where it was (the floor holds it)."""
    changed: bool
    """Whether a probe found the load changed (robust family:
    :mod:`agent.algorithm.robust.load_change`)."""

    @property
    def centroid(self) -> Vec2:
        """``z_i`` at the estimation instant (Step 2)."""
        ...

    @property
    def mean_square_offset(self) -> float:
        """``w / n`` (eq. 16)."""
        ...

    @property
    def mean_spin_torque(self) -> float:
        """The team's mean torque about the centroid in Step 1's spin-up (N m), by consensus."""
        ...

    @property
    def mean_kick_level(self) -> float:
        """The team's mean kick size in Step 1 (N), by consensus (0 for a family that does not
        average it)."""
        ...

    @property
    def drive_share(self) -> float | None:
        """How much of its commanded force this robot's drive applies, from the force its
        sensor measures (``None``: not estimated)."""
        ...

    @property
    def moment(self) -> float | None:
        """``Ĵ`` (Step 4)."""
        ...

    @property
    def friction_torque(self) -> tuple[float, float] | None:
        """``(τ̂_c, σ)``: the floor's friction torque about the COM while the load turns, and
        its standard deviation (N m; ``None``: not estimated)."""
        ...

    @property
    def com_offset_now(self) -> Vec2 | None:
        """``z_C`` (Step 5) at the estimation instant (``None`` before the push)."""
        ...

    def settled(self, phase: Phase) -> bool:
        """Whether the estimates that ``phase`` is for have settled (excite: Steps 1–3 and
        ``w``; inertia: ``Ĵ``; push: ``z_C`` and ``m̂``)."""
        ...


class Schedule(Protocol):
    """What the team applied and when, as one robot's phase machine knows it (a family's
    :class:`~agent.algorithm.phase_machine.PhaseMachine`)."""

    push: Vec2
    """The common force ``f`` of the push phase (eq. 17), before its sign."""
    moment_used: float | None
    """The ``Ĵ`` the push force was sized with."""
    inertia_torque: float
    """Step 4's torque ``sign(ω) k w`` while speeding up (N m)."""
    held: bool
    """Whether the floor holds the load beyond what the team's forces can move (robust)."""
    spin_torque: float
    """This robot's torque ``z_i × f_i`` about the centroid in Step 1's spin-up, filtered
    (N m; robust family, else 0)."""
    kick_level: float
    """N: the size of this robot's Step 1 kick (``kick_force``, grown by the robust family
    while the load is still)."""

    @property
    def phase(self) -> Phase:
        """The team's phase now."""
        ...

    @property
    def load_changes(self) -> int:
        """How many times the team has restarted for a changed load."""
        ...

    def began(self, phase: Phase) -> int | None:
        """The tick at which ``phase`` was entered (``None``: not entered)."""
        ...

    def phase_at(self, tick: int) -> Phase:
        """The phase during tick ``tick``."""
        ...

    def mean_torque(self, first: int, last: int) -> float:
        """The team's mean torque over ticks ``first..last − 1``: Step 4's ``±k w``; in Step 5's
        swing, what a family adds beyond a constant torque (the robust family's brake near
        ``max_turn_rate``)."""
        ...

    def mean_push_sign(self, first: int, last: int) -> float:
        """The mean sign of the common force over ticks ``first..last − 1``."""
        ...

    def swinging(self, first: int, last: int) -> bool:
        """Whether ticks ``first..last − 1`` are in the push's stage for Step 5."""
        ...

    def translating(self, first: int, last: int) -> bool:
        """Whether ticks ``first..last − 1`` are in the push's stage for Step 7."""
        ...

    def mean_push_added(self, first: int, last: int) -> Vec2:
        """The mean force each robot added to the push over ticks ``first..last − 1``."""
        ...


class ProbeSchedule(Schedule, Protocol):
    """A schedule with the probes of a done team (robust family)."""

    probe_ticks: int
    """A probe's length (ticks)."""

    def probe_start(self, tick: int) -> int | None:
        """The first tick of the last probe begun by ``tick`` (``None``: none)."""
        ...

    def probe_sign(self, tick: int) -> float:
        """The common force's sign during tick ``tick`` of a probe (0 between probes)."""
        ...
