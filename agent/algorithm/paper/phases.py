"""The paper's force laws where the families differ (Sec. V and VI).

- *inertia*: the torque ``±k w`` speeds the turn the load already has up until ``|ω|`` reaches
  ``inertia_max_omega``, then brakes it down to half of that, and so on. ``ω`` at the tick is
  predicted from its last measurement, the torque applied since and ``Ĵ`` (eq. 15): without
  noise every robot predicts the same value, so they all reverse at the same tick;
- *push*: ``f = max(f̄_y Ĵ/n, push_min_force)`` (eq. 17 and Sec. VI, ``f_y = J/n`` for
  ``f̄_y = 1``);
- *done*: the damping alone brings the load to rest.
"""

from __future__ import annotations

from agent.algorithm.interfaces import OwnEstimates
from agent.algorithm.phase_machine import PhaseMachine


class PaperPhases(PhaseMachine):
    """The phase machine of the paper's estimators."""

    def _inertia_direction(self, k: int, own: OwnEstimates) -> float:
        """Speed the turn up until ``|ω|`` reaches the limit, then brake down to half of it."""
        speed = abs(self.omega_at(k, own))
        limit = self.tuning.paper.inertia_max_omega
        if speed >= limit:
            return -1.0
        if speed <= 0.5 * limit:
            return 1.0
        return self.direction

    def _push_magnitude(self, moment: float) -> float:
        paper = self.tuning.paper
        return max(paper.push_fbar * moment / self.n, paper.push_min_force)

    def omega_at(self, tick: int, own: OwnEstimates) -> float:
        """ω at ``t_tick``, predicted from the last instant it was measured with the torque the
        team applied since (eq. 15) and ``Ĵ``: every robot, whichever messages it has received,
        predicts the same value, so they all take the same decisions."""
        omega = own.omega or 0.0
        moment = own.moment
        if own.measured is None or moment is None:
            return omega
        impulse = sum(self._torque.get(t, 0.0) for t in range(own.measured, tick))
        return omega + impulse * self.dt / moment
