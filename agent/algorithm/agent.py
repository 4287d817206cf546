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
- the :class:`~agent.algorithm.pipeline.EstimationPipeline` runs Steps 1–7 at each instant up
  to it;
- the :class:`~agent.algorithm.phase_machine.PhaseMachine` agrees with the team on the phase
  (force regime; the phases are explained there) and gives the force for ``[t_k, t_{k+1})``.

The pipeline and the phase machine are those of the family of estimators the tuning names
(:mod:`agent.algorithm.families`), chosen once, here.

A halted team that has every robot back begins again (a *rejoin*, see
:mod:`agent.algorithm.coordination`): at the agreed tick ``k_0`` the robot drops its inbox,
estimates and phases and starts them afresh, as if the run began at ``k_0``. Inside, its parts count
ticks from ``k_0`` (:attr:`Agent.origin`); every message in or out carries the run's own
ticks, so that robots that began at different ticks still agree on when things happen.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable

from agent.algorithm.families import FAMILIES
from agent.algorithm.inbox import HISTORY_TICKS, Inbox
from agent.algorithm.phase_machine import PhaseMachine
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
        self.family = FAMILIES[config.tuning.estimator]
        """The family of estimators this agent runs."""
        self.origin = 0
        """The run's tick at which the team last began (its last rejoin): the parts' tick 0."""
        self.team_back = False
        """Whether every neighbour is alive (the process says): a halted robot is then ready
        to begin again."""
        self._begin(self.family.phases(config))

    def _begin(self, phase_machine: PhaseMachine) -> None:
        """Fresh parts (the phase machine given, with its barrier's rejoins)."""
        self.inbox = Inbox(self.neighbours)
        self.pipeline = self.family.pipeline(self.config, self.neighbours)
        self.phase_machine = phase_machine
        self._commanded: Vec2 | None = None
        """The force commanded at the last tick."""

    @property
    def phase(self) -> Phase:
        return self.phase_machine.barrier.phase

    @property
    def stuck(self) -> bool:
        """Whether this robot found the load held by the floor (Step 1's kick at ``max_force``
        did not move it, or Step 4's torque did not turn it)."""
        return self.pipeline.stuck or self.phase_machine.held

    @property
    def held_because(self) -> str:
        """Why the floor holds the load beyond the team's forces ("" unless it does)."""
        return self.phase_machine.held_because

    @property
    def stuck_torque(self) -> float:
        """Step 4's torque ``|k w|`` (N m): what did not turn a stuck load."""
        return abs(self.phase_machine.inertia_torque)

    @property
    def phase_since(self) -> int:
        """The tick at which this robot entered its phase, in the run's ticks (as its
        :meth:`estimates` say)."""
        return self.phase_machine.since + self.origin

    @property
    def load_changes(self) -> int:
        """How many times the team has restarted for a changed load."""
        return self.phase_machine.barrier.load_changes

    @property
    def rejoins(self) -> int:
        """How many times the team has begun again after a halt."""
        return self.phase_machine.barrier.rejoins

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
        rejoins = self.rejoins
        mine, others = [], []
        for share in shares:
            share = self._local(share)
            if share is None:
                continue
            (mine if share.barrier.rejoins == rejoins else others).append(share)
        if self.origin:
            measurement = dataclasses.replace(measurement, tick=measurement.tick - self.origin)
        command, share = self._step(measurement, mine, others)
        if self.rejoins != rejoins and self.phase == Phase.EXCITE:
            # The team begins again at this tick (or began a few ticks ago, and this robot
            # catches up): afresh, from the same barrier.
            self.origin += measurement.tick
            self._begin(self.family.phases(self.config, self.phase_machine.barrier))
            local = dataclasses.replace(measurement, tick=0)
            command, share = self._step(local, [], [])
        elif self.rejoins != rejoins and self.phase != Phase.HALTED:
            # A rejoined team already past Steps 1–3: this robot has not their estimates. It
            # halts the team, and the team begins again with it.
            self.phase_machine.halt(measurement.tick)
            command = dataclasses.replace(command, force=(0.0, 0.0))
            share = dataclasses.replace(share, barrier=self.phase_machine.barrier.state)
        return self._run_command(command), self._run_share(share)

    def _step(
        self, measurement: Measurement, shares: list[Share], others: list[Share]
    ) -> tuple[Command, Share]:
        """:meth:`step` in the parts' ticks; ``others``: shares of other rejoins, for the
        barrier only."""
        k = measurement.tick
        inbox, pipeline, phases = self.inbox, self.pipeline, self.phase_machine
        if self._commanded is not None:  # the force measured now was applied since the last tick
            pipeline.applied(self._commanded, measurement.force)
        newest = inbox.receive(measurement, shares)
        for e in range(pipeline.instant + 1, newest + 1):
            pipeline.estimate_at(e, inbox, phases)
        phases.team_back = self.team_back
        phases.degrees = {j: s.degree for j, s in inbox.latest.items()}
        views = [s.barrier for s in inbox.latest.values()] + [s.barrier for s in others]
        if phases.step(k, pipeline, views):
            pipeline.enter(phases.phase, k, phases)
        force = phases.force(k, pipeline, measurement.velocity)
        self._commanded = force
        consensus = pipeline.consensus
        share = Share(
            sender=self.robot,
            tick=k,
            velocity=measurement.velocity,
            degree=consensus.degree,
            instant=pipeline.instant,
            barrier=phases.barrier.state,
            consensus=pipeline.consensus_state(),
            flows=consensus.shared_flows(),
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
            rejoins=self.rejoins,
        )

    # ---------------------------------------------------------------- the run's ticks
    def _local(self, share: Share) -> Share | None:
        """A neighbour's share in the parts' ticks (``None`` if from before they began)."""
        o = self.origin
        if not o:
            return share
        if share.tick < o:
            return None
        switch_at = share.barrier.switch_at
        return dataclasses.replace(
            share,
            tick=share.tick - o,
            barrier=dataclasses.replace(
                share.barrier, switch_at=switch_at - o if switch_at >= o else -1
            ),
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
        switch_at = share.barrier.switch_at
        return dataclasses.replace(
            share,
            tick=share.tick + o,
            barrier=dataclasses.replace(
                share.barrier, switch_at=switch_at + o if switch_at >= 0 else -1
            ),
            instant=share.instant + o if share.instant >= 0 else -1,
        )
