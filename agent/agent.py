"""One robot's agent: the paper's seven steps, run by each robot on its own data.

An :class:`Agent` knows its id, ``n``, its neighbours' ids and its tuning. Each sensor tick it
is handed its own :class:`~agent.protocol.Measurement` and the :class:`~agent.protocol.Share`
messages its neighbours sent at earlier ticks; it returns the force to apply until the next
tick and the message for its neighbours. It never sees the plant, global truth, or any other
robot's internals, and it does no I/O: transports and processes live outside it.

It is made of three parts, run in this order each tick ``k``:

- the :class:`~agent.inbox.Inbox` takes in the sample and the messages, and says up to which
  *estimation instant* the robot can estimate (``k − 1`` unless messages are late: the timing is
  explained there);
- the :class:`~agent.pipeline.EstimationPipeline` runs Steps 1–7 at each instant up to it;
- the :class:`~agent.phase_machine.PhaseMachine` agrees with the team on the phase (force
  regime; the phases are explained there) and gives the force for ``[t_k, t_{k+1})``.
"""

from __future__ import annotations

from collections.abc import Iterable

from agent.config import AgentConfig
from agent.estimation.geometry import Vec2
from agent.inbox import HISTORY_TICKS, Inbox
from agent.phase_machine import PhaseMachine
from agent.pipeline import EstimationPipeline
from agent.protocol import Command, Estimates, Measurement, Phase, Share


class Agent:
    """The estimator and force law of one robot (see the module docstring)."""

    def __init__(self, config: AgentConfig):
        self.robot = config.robot
        self.n = config.n
        self.neighbours = tuple(sorted(config.neighbours))
        self.inbox = Inbox(self.neighbours)
        self.pipeline = EstimationPipeline(config, self.neighbours)
        self.phase_machine = PhaseMachine(config)
        self._commanded: Vec2 | None = None
        """The force commanded at the last tick."""

    @property
    def phase(self) -> Phase:
        return self.phase_machine.barrier.phase

    @property
    def epoch(self) -> int:
        """How many times the team has restarted for a changed load."""
        return self.phase_machine.barrier.epoch

    @property
    def instant(self) -> int:
        """The estimation instant of the current estimates (``-1`` before any)."""
        return self.pipeline.instant

    @property
    def rejected(self) -> int:
        """Messages never used (see :class:`~agent.inbox.Inbox`)."""
        return self.inbox.rejected

    def step(self, measurement: Measurement, shares: Iterable[Share]) -> tuple[Command, Share]:
        """One sensor tick: returns the force command for this tick and the share to send."""
        k = measurement.tick
        inbox, pipeline, phases = self.inbox, self.pipeline, self.phase_machine
        if self._commanded is not None:  # the force measured now was applied since the last tick
            pipeline.drive_gain(self._commanded, measurement.force)
        newest = inbox.receive(measurement, shares)
        for e in range(pipeline.instant + 1, newest + 1):
            pipeline.estimate_at(e, inbox, phases)
        if phases.step(k, pipeline, inbox.latest.values()):
            pipeline.enter(phases.phase, k, phases)
        force = phases.force(k, pipeline, measurement.velocity)
        self._commanded = force
        consensus = pipeline.consensus
        barrier = phases.barrier
        share = Share(
            sender=self.robot,
            tick=k,
            velocity=measurement.velocity,
            degree=consensus.degree,
            centroid=consensus.centroid,
            spread=consensus.spread,
            phase=barrier.phase,
            ready=barrier.ready,
            switch_at=barrier.switch_at,
            flows=consensus.shared_flows(),
            instant=pipeline.instant,
            gain=consensus.gain,
            gain_centroid=consensus.gain_centroid,
            gain_spread=consensus.gain_spread,
            epoch=barrier.epoch,
        )
        before = k - HISTORY_TICKS
        inbox.forget(before)
        pipeline.forget(before)
        phases.forget(before)
        return Command(self.robot, k, force), share

    def halt(self) -> None:
        """Stop the team: from the next tick on this robot applies no force, and every robot
        that hears of it does the same (see :mod:`agent.phase_machine`)."""
        self.phase_machine.halt(self.inbox.tick + 1)

    def estimates(self) -> Estimates:
        """The current estimates, at the estimation instant (see :class:`Estimates`)."""
        return self.pipeline.estimates(self.robot, self.phase_machine)
