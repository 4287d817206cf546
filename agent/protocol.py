"""The contract between a robot's agent and everything around it.

Every message that crosses a process or a machine is defined here, and nowhere else:

- :class:`Measurement` — what a robot senses at one sensor tick (plant or AGV → agent),
- :class:`Command` — the force the agent asks its robot to apply until the next tick
  (agent → plant or AGV),
- :class:`Share` — what an agent tells its graph neighbours each tick (agent → neighbours),
- :class:`Estimates` — the agent's current estimates, for logs, results and displays.

All vectors are planar, ``(x, y)`` tuples in SI units, in the common world frame ``W`` of the
paper (Sec. II). Robot ids are ``1..n``. A *tick* is the index of a sensor sample; every robot's
sample ``k`` is taken at the same instant ``t_k`` (the robots' clocks are synchronised), and a
message stamped ``k`` was produced after sample ``k`` and before sample ``k + 1``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

Vec2 = tuple[float, float]


@dataclass(frozen=True, slots=True)
class Measurement:
    """Robot ``robot``'s sample at ``tick``: its contact point's velocity ``ṗ_Ci`` and the
    force it measures itself applying (both in ``W``)."""

    robot: int
    tick: int
    time_s: float
    velocity: Vec2
    force: Vec2


@dataclass(frozen=True, slots=True)
class Command:
    """The force robot ``robot`` applies at its contact point from ``tick`` until the next."""

    robot: int
    tick: int
    force: Vec2


@dataclass(frozen=True, slots=True)
class Share:
    """What agent ``sender`` sends its neighbours after its step at ``tick``.

    ``velocity`` is the sender's sample of ``tick``. The consensus states refer to the
    sender's *estimation instant* ``tick - 1`` (the newest instant for which it had its
    neighbours' velocities); vectors are in ``W`` at that instant.

    - ``degree``: the sender's number of neighbours (Metropolis consensus weights).
    - ``centroid``: the sender's centroid iterate ``x_i`` (Aragues et al. [10]) or ``None``.
    - ``spread``: the sender's average-consensus state ``ξ_i`` for ``w = Σ‖z_i‖²`` (eq. 16).
    - ``phase``, ``ready``, ``switch_at``: the team's phase barrier (see
      :mod:`agent.coordination`): the sender's phase, the bitmask of robots known to be ready
      to leave it, and the agreed tick of the switch (``-1`` while none is agreed).
    """

    sender: int
    tick: int
    velocity: Vec2
    degree: int
    centroid: Vec2 | None = None
    spread: float = 0.0
    phase: int = 0
    ready: int = 0
    switch_at: int = -1


@dataclass(frozen=True, slots=True)
class Estimates:
    """An agent's estimates at its estimation instant ``tick`` (vectors in ``W`` then).

    ``None`` marks a quantity not estimated yet. ``relative_positions[j]`` is
    ``z_ij = p_Ci - p_Cj``; ``centroid_offset`` is ``z_i = p_Ci - p_G``; ``com_offset`` is
    ``z_C = p_G - p_C``; ``contact_to_com`` is ``p_C - p_Ci = -(z_i + z_C)``.
    ``spread`` is ``w = Σ_i ‖z_i‖²`` as the robot knows it by consensus (eq. 16).
    ``com_observer`` is observer (24)'s ``ẑ_C`` (run beside the team's estimate).
    ``started`` maps a paper step (1..7) to the tick at which the robot began it, ``settled`` to
    the tick at which its estimate first settled.
    """

    robot: int
    tick: int
    phase: str
    omega: float | None = None
    relative_positions: dict[int, Vec2] = field(default_factory=dict)
    centroid_offset: Vec2 | None = None
    spread: float | None = None
    moment: float | None = None
    com_offset: Vec2 | None = None
    com_observer: Vec2 | None = None
    com_velocity: Vec2 | None = None
    mass: float | None = None
    contact_to_com: Vec2 | None = None
    started: dict[int, int] = field(default_factory=dict)
    settled: dict[int, int] = field(default_factory=dict)
