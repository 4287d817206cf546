"""One robot's agent: the paper's seven steps, run by each robot on its own data.

An :class:`Agent` knows its id, ``n``, its neighbours' ids and its tuning. Each sensor tick it
is handed its own :class:`~agent.platform.protocol.Measurement` and the
:class:`~agent.platform.protocol.Share` messages its neighbours sent at earlier ticks; it returns
the force to apply until the next tick and the message for its neighbours. It never sees the plant,
global truth, or any other robot's internals, and it does no I/O: transports and processes live
outside it.

It is made of three parts, run in this order each tick ``k``:

- the :class:`~agent.algorithm.inbox.Inbox` takes in the sample and the messages, and says up
  to which *estimation instant* the robot can estimate (``k − 1`` unless messages are late:
  the timing is explained there);
- the :class:`~agent.algorithm.pipeline.EstimationPipeline` runs Steps 1–7 at each instant up to it;
- the :class:`~agent.algorithm.phase_machine.PhaseMachine` agrees with the team on the phase (force
  regime; the phases are explained there) and gives the force for ``[t_k, t_{k+1})``.

A halted team that has every robot back begins again (a new *generation*, see
:mod:`agent.algorithm.coordination`): at the agreed tick ``k_0`` the robot drops its inbox,
estimates and phases and starts them afresh, as if the run began at ``k_0``. Inside, its parts count
ticks from ``k_0`` (:attr:`Agent.origin`); every message in or out carries the run's own
ticks, so that robots that began at different ticks still agree on when things happen.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable

from agent.algorithm.estimation.rotation import wrapped
from agent.algorithm.inbox import HISTORY_TICKS, Inbox
from agent.algorithm.phase_machine import PhaseMachine
from agent.algorithm.pipeline import EstimationPipeline
from agent.algorithm.tuning import AgentConfig
from agent.platform.geometry import Vec2
from agent.platform.protocol import Command, Estimates, Measurement, Phase, Share


class Agent:
    """The estimator and force law of one robot (see the module docstring)."""

    def __init__(self, config: AgentConfig):
        self.config = config
        self.robot = config.robot
        self.n = config.n
        self.neighbours = tuple(sorted(config.neighbours))
        self.origin = 0
        """The run's tick at which this generation began: the parts' tick 0."""
        self.team_back = False
        """Whether every neighbour is alive (the process says): a halted robot is then ready
        to begin again."""
        self._begin(PhaseMachine(config))

    def _begin(self, phase_machine: PhaseMachine) -> None:
        """Fresh parts (the phase machine given, with its barrier's generation)."""
        self.inbox = Inbox(self.neighbours)
        self.pipeline = EstimationPipeline(self.config, self.neighbours)
        self.phase_machine = phase_machine
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
    def generation(self) -> int:
        """How many times the team has begun again after a halt."""
        return self.phase_machine.barrier.generation

    @property
    def instant(self) -> int:
        """The estimation instant of the current estimates, in the run's ticks (``-1`` before
        any)."""
        instant = self.pipeline.instant
        return instant + self.origin if instant >= 0 else instant

    @property
    def rejected(self) -> int:
        """Messages never used (see :class:`~agent.algorithm.inbox.Inbox`)."""
        return self.inbox.rejected

    def step(self, measurement: Measurement, shares: Iterable[Share]) -> tuple[Command, Share]:
        """One sensor tick: returns the force command for this tick and the share to send."""
        generation = self.generation
        mine, others = [], []
        for share in shares:
            share = self._local(share)
            if share is None:
                continue
            (mine if share.generation == generation else others).append(share)
        if self.origin:
            measurement = dataclasses.replace(measurement, tick=measurement.tick - self.origin)
        command, share = self._step(measurement, mine, others)
        if self.generation != generation and self.phase == Phase.EXCITE:
            # The team begins again at this tick (or began a few ticks ago, and this robot
            # catches up): afresh, from the same barrier.
            self.origin += measurement.tick
            self._begin(PhaseMachine(self.config, self.phase_machine.barrier))
            local = dataclasses.replace(measurement, tick=0)
            command, share = self._step(local, [], [])
        elif self.generation != generation and self.phase != Phase.HALTED:
            # A generation already past Step 1–3: this robot has not their estimates. It
            # halts that generation, and the team begins again with it.
            self.phase_machine.halt(measurement.tick)
            barrier = self.phase_machine.barrier
            command = dataclasses.replace(command, force=(0.0, 0.0))
            share = dataclasses.replace(
                share, phase=barrier.phase, ready=barrier.ready, switch_at=barrier.switch_at
            )
        return self._run_command(command), self._run_share(share)

    def _step(
        self, measurement: Measurement, shares: list[Share], others: list[Share]
    ) -> tuple[Command, Share]:
        """:meth:`step` in the parts' ticks; ``others``: shares of other generations, for the
        barrier only."""
        k = measurement.tick
        inbox, pipeline, phases = self.inbox, self.pipeline, self.phase_machine
        if self._commanded is not None:  # the force measured now was applied since the last tick
            pipeline.drive_gain(self._commanded, measurement.force)
        newest = inbox.receive(measurement, shares)
        for e in range(pipeline.instant + 1, newest + 1):
            pipeline.estimate_at(e, inbox, phases)
        phases.team_back = self.team_back
        if phases.step(k, pipeline, [*inbox.latest.values(), *others]):
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
            generation=barrier.generation,
            rotation=wrapped(pipeline.angle),
            rotation_variance=pipeline.rotation.variance,
            mass_information=consensus.mass_information,
            mass_weighted=consensus.mass_weighted,
        )
        before = k - HISTORY_TICKS
        inbox.forget(before)
        pipeline.forget(before)
        phases.forget(before)
        return Command(self.robot, k, force), share

    def halt(self) -> None:
        """Stop the team: from the next tick on this robot applies no force, and every robot
        that hears of it does the same (see :mod:`agent.algorithm.phase_machine`)."""
        self.phase_machine.halt(self.inbox.tick + 1)

    def estimates(self) -> Estimates:
        """The current estimates, at the estimation instant (see :class:`Estimates`), in the
        run's ticks."""
        est = self.pipeline.estimates(self.robot, self.phase_machine)
        o = self.origin
        return dataclasses.replace(
            est,
            tick=est.tick + o if est.tick >= 0 else est.tick,
            phase_since=est.phase_since + o,
            started={step: t + o for step, t in est.started.items()},
            settled={step: t + o for step, t in est.settled.items()},
            generation=self.generation,
        )

    # ---------------------------------------------------------------- the run's ticks
    def _local(self, share: Share) -> Share | None:
        """A neighbour's share in the parts' ticks (``None`` if from before they began)."""
        o = self.origin
        if not o:
            return share
        if share.tick < o:
            return None
        return dataclasses.replace(
            share,
            tick=share.tick - o,
            switch_at=share.switch_at - o if share.switch_at >= o else -1,
            instant=share.instant - o if share.instant >= o else -1,
        )

    def _run_command(self, command: Command) -> Command:
        if not self.origin:
            return command
        return dataclasses.replace(command, tick=command.tick + self.origin)

    def _run_share(self, share: Share) -> Share:
        o = self.origin
        if not o:
            return share
        return dataclasses.replace(
            share,
            tick=share.tick + o,
            switch_at=share.switch_at + o if share.switch_at >= 0 else -1,
            instant=share.instant + o if share.instant >= 0 else -1,
        )
