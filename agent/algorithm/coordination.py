"""How the team agrees on when to change what it applies (the paper's instants t_1..t_4).

No robot decides for the team and none looks at global truth: each robot decides only whether
*it* is ready to leave the current phase (its own estimates have settled). A phase barrier
then makes the switch simultaneous:

- every robot floods the set of robots it knows to be ready (a bitmask, merged by union with
  the neighbours in the same phase);
- a robot that sees all ``n`` robots ready proposes to switch at ``tick + n + margin``; proposals
  are merged by min-consensus. The first proposal reaches every robot within ``n − 1`` ticks
  (the graph's diameter is below ``n``), before it falls due, so every robot switches at the
  same tick;
- a robot that hears a neighbour already in a later phase (it missed messages) catches up at
  once. ``halted``, the highest phase, spreads the same way.

Once the team is ``done`` it watches the load (robust estimators): a robot whose probes say the
load has changed is ready to *restart*, and one robot is enough — it proposes the restart as
above, and at the agreed tick every robot counts one more *load change* and begins the
``inertia`` phase again (Steps 4–7; the contacts' geometry, Steps 1–3, holds for the changed
load). Phases compare by load changes first: a robot that hears a neighbour after more load
changes catches up with it.

A halted team begins again once every robot is back (:mod:`agent.node` says when a robot's
neighbours are all alive again): in ``halted`` a robot is ready when it has every neighbour,
all ``n`` must be, and at the agreed tick every robot counts one more *rejoin* and begins again
from Step 1 (``excite``, no load change), with everything it had estimated dropped
(:class:`agent.algorithm.agent.Agent` starts afresh). Rejoins come before everything else: a
robot that hears of more rejoins catches up with them, as with a later phase (it missed the
agreed tick: in real time a proposal crosses the graph more slowly than one hop a tick; or it is
a new process of a robot that was lost, joining the halted team); a neighbour's message of fewer
rejoins is ignored.

A family may size the forces of Steps 4 to 7 on what Step 1 measured (the robust estimators:
on the floor's friction torque, :mod:`agent.algorithm.robust.phases`), in discrete *levels*.
Every robot's value of what it measured differs from the others' by a little, and a little
is enough to round to another level at a boundary: a robot that pushed one level harder than
the others assume would bias every fit of the team. So the barrier agrees on them: a robot
that becomes ready to leave Step 1 asks for its levels, the team keeps the largest asked for
(merged like the ready robots, with the neighbours of the same rejoins), and since every robot
must be ready before any proposes the switch, every robot has the same levels at the agreed
tick. They hold for the rest of the run (a load change keeps the floor) and begin again at 0
after a halt.
"""

from __future__ import annotations

from collections.abc import Iterable

from agent.platform.protocol import Barrier, Phase


class PhaseBarrier:
    """One robot's view of the team's phase."""

    def __init__(self, robot: int, n: int, margin: int):
        self.robot = robot
        self.n = n
        self.margin = margin
        self.all_ready = (1 << n) - 1
        self.phase = Phase.EXCITE
        self.ready = 0
        """Bitmask of the robots known to be ready to leave ``phase`` (robot ``i`` is bit
        ``i − 1``)."""
        self.switch_at = -1
        """The agreed tick of the switch to the next phase (``-1`` while none is agreed)."""
        self.load_changes = 0
        """How many times the team has restarted for a changed load."""
        self.rejoins = 0
        """How many times the team has begun again after a halt."""
        self.levels = (0, 0)
        """The largest levels asked for by the robots ready to leave Step 1 (see the module
        docstring)."""

    @property
    def state(self) -> Barrier:
        """This view, as shared."""
        return Barrier(
            self.phase, self.ready, self.switch_at, self.load_changes, self.rejoins, self.levels
        )

    def _enter(self, phase: int, load_changes: int) -> None:
        self.phase = Phase(phase)
        self.load_changes = load_changes
        self.ready = 0
        self.switch_at = -1

    def halt(self) -> None:
        """Jump to ``halted`` at once; neighbours catch up with it."""
        self._enter(Phase.HALTED, self.load_changes)

    @staticmethod
    def _order(rejoins: int, phase: Phase, load_changes: int) -> tuple[int, bool, int, int]:
        """Which of two team states is later: by rejoins, then ``halted`` last, then by load
        changes, then phase."""
        return (rejoins, phase == Phase.HALTED, load_changes, phase)

    def step(
        self,
        tick: int,
        own_ready: bool,
        barriers: Iterable[Barrier],
        levels: tuple[int, int] = (0, 0),
    ) -> bool:
        """Merge the neighbours' views and our readiness (with the ``levels`` this robot asks
        for once ready to leave Step 1); returns ``True`` if the phase (or the load changes,
        or the rejoins) changed at this tick (the new one applies from ``tick`` on)."""
        start = (self.phase, self.load_changes, self.rejoins)
        order = self._order
        views = [b for b in barriers if b.rejoins >= self.rejoins]
        latest = max(views, key=lambda b: order(b.rejoins, b.phase, b.load_changes), default=None)
        if latest is not None and order(latest.rejoins, latest.phase, latest.load_changes) > order(
            self.rejoins, self.phase, self.load_changes
        ):
            if latest.rejoins > self.rejoins:
                self.levels = (0, 0)
            self.rejoins = latest.rejoins
            self._enter(latest.phase, latest.load_changes)
        for b in views:
            if b.rejoins == self.rejoins:
                self.levels = _larger(self.levels, b.levels)
        latest_proposal = tick + self.n + self.margin  # no robot can have proposed later
        for b in views:
            if (b.phase, b.load_changes, b.rejoins) == (
                self.phase,
                self.load_changes,
                self.rejoins,
            ):
                self.ready |= b.ready & self.all_ready  # bits of robots not in the team: none
                if 0 <= b.switch_at <= latest_proposal and (
                    self.switch_at < 0 or b.switch_at < self.switch_at
                ):
                    self.switch_at = b.switch_at
        if own_ready and (self.phase, self.load_changes, self.rejoins) == start:
            own = 1 << (self.robot - 1)
            if self.phase == Phase.EXCITE and not self.ready & own:
                self.levels = _larger(self.levels, levels)
            self.ready |= own
        # Leaving a phase takes every robot; restarting for a changed load, any one.
        enough = self.ready != 0 if self.phase == Phase.DONE else self.ready == self.all_ready
        if enough and self.switch_at < 0:
            self.switch_at = tick + self.n + self.margin
        if 0 <= self.switch_at <= tick:
            if self.phase == Phase.DONE:
                self._enter(Phase.INERTIA, self.load_changes + 1)
            elif self.phase == Phase.HALTED:
                self.rejoins += 1
                self.levels = (0, 0)
                self._enter(Phase.EXCITE, 0)
            else:
                self._enter(self.phase + 1, self.load_changes)
        return (self.phase, self.load_changes, self.rejoins) != start


def _larger(a: tuple[int, int], b: tuple[int, int]) -> tuple[int, int]:
    """Each level the larger of the two."""
    return (max(a[0], b[0]), max(a[1], b[1]))
