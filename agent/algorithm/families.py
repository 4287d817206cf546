"""The families of estimators, each a set of modules behind one interface, chosen once.

A family is an :class:`~agent.algorithm.pipeline.EstimationPipeline` (its estimators of the
seven steps) and a :class:`~agent.algorithm.phase_machine.PhaseMachine` (its force laws where
the families differ), with its own tuning table (``[agent.paper]``, ``[agent.robust]``). The
agent picks one by ``estimator`` when it is made (:class:`~agent.algorithm.agent.Agent`);
nothing else asks which it runs.
"""

from __future__ import annotations

from dataclasses import dataclass

from agent.algorithm.paper.phases import PaperPhases
from agent.algorithm.paper.pipeline import PaperPipeline
from agent.algorithm.phase_machine import PhaseMachine
from agent.algorithm.pipeline import EstimationPipeline
from agent.algorithm.robust.phases import RobustPhases
from agent.algorithm.robust.pipeline import RobustPipeline
from agent.algorithm.tuning import Estimators


@dataclass(frozen=True)
class Family:
    """One family of estimators: its pipeline and its phase machine."""

    pipeline: type[EstimationPipeline]
    phases: type[PhaseMachine]


FAMILIES: dict[Estimators, Family] = {
    Estimators.PAPER: Family(PaperPipeline, PaperPhases),
    Estimators.ROBUST: Family(RobustPipeline, RobustPhases),
}
"""Each :class:`~agent.algorithm.tuning.Estimators` value's family."""
