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
above, and at the agreed tick every robot begins a new *epoch* in the ``inertia`` phase (Steps
4–7 again; the contacts' geometry, Steps 1–3, holds for the changed load). Phases compare by
epoch first: a robot that hears a neighbour in a later epoch catches up with it.
"""

from __future__ import annotations

from collections.abc import Iterable

from agent.protocol import Phase, Share


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
        self.epoch = 0
        """How many times the team has restarted for a changed load."""

    def _enter(self, phase: int, epoch: int) -> None:
        self.phase = Phase(phase)
        self.epoch = epoch
        self.ready = 0
        self.switch_at = -1

    def halt(self) -> None:
        """Jump to ``halted`` at once; neighbours catch up with it."""
        self._enter(Phase.HALTED, self.epoch)

    def _order(self, phase: Phase, epoch: int) -> tuple[bool, int, int]:
        """Which of two team states is later: ``halted`` last, then by epoch, then phase."""
        return (phase == Phase.HALTED, epoch, phase)

    def step(self, tick: int, own_ready: bool, shares: Iterable[Share]) -> bool:
        """Merge the neighbours' views and our readiness; returns ``True`` if the phase
        changed at this tick (the new phase applies from ``tick`` on)."""
        shares = list(shares)
        start = (self.phase, self.epoch)
        order = self._order
        latest = max(shares, key=lambda s: order(s.phase, s.epoch), default=None)
        if latest is not None and order(latest.phase, latest.epoch) > order(*start):
            self._enter(latest.phase, latest.epoch)
        latest_proposal = tick + self.n + self.margin  # no robot can have proposed later
        for s in shares:
            if s.phase == self.phase and s.epoch == self.epoch:
                self.ready |= s.ready & self.all_ready  # bits of robots not in the team: none
                if 0 <= s.switch_at <= latest_proposal and (
                    self.switch_at < 0 or s.switch_at < self.switch_at
                ):
                    self.switch_at = s.switch_at
        if own_ready and (self.phase, self.epoch) == start:
            self.ready |= 1 << (self.robot - 1)
        # Leaving a phase takes every robot; restarting for a changed load, any one.
        enough = self.ready != 0 if self.phase == Phase.DONE else self.ready == self.all_ready
        if enough and self.switch_at < 0:
            self.switch_at = tick + self.n + self.margin
        if 0 <= self.switch_at <= tick:
            if self.phase == Phase.DONE:
                self._enter(Phase.INERTIA, self.epoch + 1)
            else:
                self._enter(self.phase + 1, self.epoch)
        return (self.phase, self.epoch) != start
