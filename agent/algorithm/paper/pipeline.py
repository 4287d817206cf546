"""The paper's estimators at each instant (Sec. IV-V): exact without noise.

Step 1 by eqs. (10)–(12) (:class:`~agent.algorithm.paper.relative_position.RelativePosition`),
the load's rotation from the longest edge's own turn, Step 4 by eq. (15) on ``ω``
(:class:`~agent.algorithm.paper.inertia.InertiaEstimator`), Step 5 by the regression of
eq. (18) (:class:`~agent.algorithm.paper.com_regression.ComRegression`), Step 7 by eq. (25) on
eq. (7)'s ``ṗ_C`` (:class:`~agent.algorithm.paper.mass.MassEstimator`): every one the
Appendix's filtered regression. Settling is judged by drift; no uncertainty is published. The
drives are taken for ideal, so the team's gains keep their defaults.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from agent.algorithm.paper.com_regression import ComRegression
from agent.algorithm.paper.inertia import InertiaEstimator
from agent.algorithm.paper.mass import MassEstimator
from agent.algorithm.paper.relative_position import RelativePosition
from agent.algorithm.pipeline import EstimationPipeline
from agent.platform.geometry import Vec2
from agent.platform.protocol import Phase

if TYPE_CHECKING:
    from agent.algorithm.inbox import Inbox
    from agent.algorithm.interfaces import Schedule


class PaperPipeline(EstimationPipeline):
    """One robot's estimates by the paper's estimators."""

    def _new_edge(self) -> RelativePosition:
        return RelativePosition(self.tuning.paper.filter_gain, self.forgetting)

    def _turn(
        self, zdots: dict[int, Vec2], interval: float, inbox: Inbox, ref: int | None
    ) -> float | None:
        """The reference edge's own turn, when it spans the same interval."""
        if ref is not None and abs(self.edges[ref].last_dt - interval) < 1e-9:
            return self.edges[ref].last_turn
        return None

    def _inputs(self, x: Vec2) -> Sequence[float]:
        """``‖x_i‖²`` (→ ``w / n``); ideal drives (gain 1), no mass information, no spin
        torque, no kick size, no ``ẑ_C`` and no turn variance for the team's means (the robust
        family's)."""
        norm2 = x[0] * x[0] + x[1] * x[1]
        return (norm2, 1.0, x[0], x[1], norm2, *(0.0,) * 10)

    def enter(self, phase: Phase, k: int, schedule: Schedule) -> None:
        super().enter(phase, k, schedule)
        if phase == Phase.INERTIA:
            for edge in self.edges.values():
                edge.learning = False  # Step 1 is done: keep the distances, track directions.

    def _new_inertia(self) -> InertiaEstimator:
        return InertiaEstimator(self.tuning.paper.filter_gain, self.forgetting)

    def _update_inertia(self, torque: float, span: float) -> None:
        self.inertia.update(self.omega, torque, span)  # eq. (15) reads ω

    def _new_com(self, schedule: Schedule) -> ComRegression:
        return ComRegression(
            self.tuning.paper.filter_gain,
            self.n,
            schedule.moment_used,
            schedule.push,
            self.forgetting,
        )

    def _update_com(
        self, alpha: float, sign: float, span: float, added: Vec2, torque: float = 0.0
    ) -> None:
        self.com.update(self.omega, alpha, sign, span)  # eq. (18) reads ω

    def _new_mass(self, schedule: Schedule) -> MassEstimator:
        return MassEstimator(self.tuning.paper.filter_gain, self.n, schedule.push, self.forgetting)

    def _update_mass(
        self, velocity: Vec2, offset: Vec2, sign: float, span: float, added: Vec2
    ) -> None:
        self.mass_estimator.update(self.com_velocity, sign, span)  # eq. (25) on eq. (7)'s ṗ_C
