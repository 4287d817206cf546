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

    def _enter(self, phase: int) -> None:
        self.phase = Phase(phase)
        self.ready = 0
        self.switch_at = -1

    def halt(self) -> None:
        """Jump to ``halted`` at once; neighbours catch up with it."""
        self._enter(Phase.HALTED)

    def step(self, tick: int, own_ready: bool, shares: Iterable[Share]) -> bool:
        """Merge the neighbours' views and our readiness; returns ``True`` if the phase
        changed at this tick (the new phase applies from ``tick`` on)."""
        shares = list(shares)
        start = self.phase
        latest = max((s.phase for s in shares), default=self.phase)
        if latest > self.phase:
            self._enter(latest)
        latest_proposal = tick + self.n + self.margin  # no robot can have proposed later
        for s in shares:
            if s.phase == self.phase:
                self.ready |= s.ready & self.all_ready  # bits of robots not in the team: none
                if 0 <= s.switch_at <= latest_proposal and (
                    self.switch_at < 0 or s.switch_at < self.switch_at
                ):
                    self.switch_at = s.switch_at
        if own_ready and self.phase == start:
            self.ready |= 1 << (self.robot - 1)
        if self.ready == self.all_ready and self.switch_at < 0:
            self.switch_at = tick + self.n + self.margin
        if 0 <= self.switch_at <= tick:
            self._enter(self.phase + 1)
        return self.phase != start
