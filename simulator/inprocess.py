"""The in-process run: one plant, ``n`` agents and the in-memory transport, stepped in lockstep
as fast as the machine allows.

The tick and the run's end are :mod:`simulator.lockstep`'s, as over processes. Each tick ``k``:
the plant is sampled, every agent steps on its own measurement and on the messages delivered to
it so far (it uses those stamped before ``k``), their messages go through the transport, the
agents' forces go to the plant, and the plant advances one sensor period. The run is over once
the team is done (and the scenario's :attr:`~simulator.scenario.Scenario.end_s` has passed: its
load changes and its hold), halted, or at the scenario's ``max_time_s``. Ground truth is
recorded beside the agents' estimates of the same instant, every ``record_every`` ticks and
from the tick the run is over at, for evaluation only (an agent that lost a message may lag a
tick: such instants are not recorded). Each agent's step calls are timed, so that the time each
robot's estimators take can be told apart from the plant's (:attr:`RunOutcome.step_s`).

``link="can"`` is the reference of a run over the AGVs' CAN buses (``heft run --can``): every
measurement and every command is clamped and quantised as it is when it crosses the bus
(:class:`~simulator.can_drivers.CanQuantiser`, of the robots' profile), so that a lockstep run
over CAN gives the same estimates. Velocity-commanded bases (``[agvs] profile = "velocity"``)
run their admittance loops here, as their AGV bridges do over CAN
(:class:`~simulator.lockstep.AdmittanceDrive`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

from agent.algorithm.agent import Agent
from agent.algorithm.tuning import AgentConfig
from agent.platform.protocol import Estimates, Measurement, Truth
from agent.platform.transport import InMemoryTransport, Transport
from simulator.history import History
from simulator.lockstep import (
    ALIGN_TICKS,
    INTERRUPTED,
    PlantTicks,
    RunEnd,
    Verdict,
    mass_verdict,
)
from simulator.scenario import Scenario

Progress = Callable[[int, float, list[Agent]], None]
LINKS = ("memory", "can")
"""How the robots' measurements and commands reach the agents in :func:`run_inprocess`: as
they are, or quantised as on the AGVs' CAN buses."""


@dataclass
class Sample:
    """One recorded instant: the truth then and every robot's estimates of that instant."""

    time_s: float
    truth: Truth
    estimates: dict[int, Estimates]


@dataclass
class RunOutcome:
    """What a run produced: final estimates, truth at the same instant, and the history."""

    scenario: Scenario
    converged: bool
    ticks: int
    wall_s: float
    final: Sample
    history: list[Sample] = field(default_factory=list)
    phase_ticks: dict[str, int] = field(default_factory=dict)
    step_s: dict[int, float] = field(default_factory=dict)
    """Seconds each robot's agent spent in its step calls, by robot (in-process runs: each call
    timed on the wall clock; the agents take turns on one thread)."""
    transport: dict = field(default_factory=dict)
    """What the transport reported (the Zenoh run: the plant's counters and latencies)."""
    reason: str = ""
    """Why the run did not converge (``""`` when it did), short and machine-readable: out of
    simulated time, a robot lost, a process lost, interrupted (see docs/cli.md: Exit status)."""
    detail: str = ""
    """The same for people: one sentence (``""`` when it converged)."""

    @property
    def sim_time_s(self) -> float:
        return self.ticks * self.scenario.period_s


def make_agents(scenario: Scenario) -> list[Agent]:
    """One agent per robot, each told only its id, ``n``, its neighbours and the tuning."""
    return [
        Agent(
            AgentConfig(
                robot=i,
                n=scenario.n,
                neighbours=scenario.neighbours(i),
                period_s=scenario.period_s,
                seed=scenario.run.seed,
                tuning=scenario.agent,
            )
        )
        for i in range(1, scenario.n + 1)
    ]


def run_inprocess(
    scenario: Scenario,
    *,
    transport: Transport | None = None,
    record_every: int = 5,
    progress: Progress | None = None,
    progress_every: int = 100,
    link: str = "memory",
    on_measure: Callable[[list[Measurement]], None] | None = None,
    on_sample: Callable[[Sample, list[Agent]], None] | None = None,
) -> RunOutcome:
    """Run ``scenario`` to convergence (or its time limit) in this process; ``link`` is one
    of :data:`LINKS` (see the module docstring). ``on_measure`` (if given) sees every tick's
    measurements, robot 1 first, as the agents get them (the centralized baseline fits
    them); ``on_sample`` (if given) sees each recorded sample with the agents whose estimates
    it holds, in the state they were then (the last call: the final sample)."""
    if link not in LINKS:
        raise ValueError(f"link must be one of {LINKS}, got {link!r}")
    quantiser = None
    if link == "can":
        from bridge.codec import AgvCodec
        from simulator.can_drivers import CanQuantiser

        quantiser = CanQuantiser(scenario.period_s, AgvCodec(scenario.agvs.profile))
    plant = PlantTicks(scenario, quantiser)
    end = RunEnd.of(scenario)
    agents = make_agents(scenario)
    transport = transport or InMemoryTransport(scenario.n, scenario.edges)
    history: History[Sample] = History()
    phase_ticks: dict[str, int] = {}
    step_s = {agent.robot: 0.0 for agent in agents}
    started = time.perf_counter()
    verdict: Verdict | None = None
    over_at = -1  # the tick the run is over at (-1: not yet)
    pending: Truth | None = None  # truth at the instant the next step's estimates refer to
    final: Sample | None = None
    k = 0
    try:
        while verdict is None or k <= over_at + ALIGN_TICKS:
            measurements = plant.measure()
            if on_measure is not None:
                on_measure(measurements)
            forces, shares = [], []
            for agent, measurement in zip(agents, measurements):
                received = transport.receive(agent.robot)
                began = time.perf_counter()
                command, share = agent.step(measurement, received)
                step_s[agent.robot] += time.perf_counter() - began
                forces.append(command.force)
                shares.append(share)
            for share in shares:
                transport.send(share)
            # Estimates of tick k - 1, unless an agent lags behind a late or lost message.
            if pending is not None and all(a.instant == k - 1 for a in agents):
                final = _sample(k - 1, scenario, pending, agents)
                history.append(final)
                if on_sample is not None:
                    on_sample(final, agents)
                if verdict is not None:
                    break
            team_phase = min(a.phase for a in agents)
            phase_ticks.setdefault(team_phase.label, k)
            if progress is not None and k % progress_every == 0:
                progress(k, k * scenario.period_s, agents)
            if verdict is None:
                verdict, over_at = end.over(k, agents), k
            # The plant has not moved since it was sampled: its truth is that of tick k.
            pending = plant.apply(forces, truth=k % record_every == 0 or verdict is not None)
            k += 1
    except KeyboardInterrupt:  # Ctrl-C, or SIGTERM/SIGHUP turned into it: keep what was done
        if final is None:
            raise
        verdict = Verdict(INTERRUPTED, "asked to stop")
    assert final is not None and verdict is not None
    verdict = mass_verdict(verdict, final.estimates, final.time_s)
    return RunOutcome(
        scenario=scenario,
        converged=not verdict.reason,
        reason=verdict.reason,
        detail=verdict.detail,
        ticks=final.truth.tick,
        wall_s=time.perf_counter() - started,
        final=final,
        history=_with_final(history, final),
        phase_ticks=phase_ticks,
        step_s=step_s,
    )


def _sample(instant: int, scenario: Scenario, truth: Truth, agents: list[Agent]) -> Sample:
    return Sample(
        time_s=instant * scenario.period_s,
        truth=truth,
        estimates={a.robot: a.estimates() for a in agents},
    )


def _with_final(history: History[Sample], final: Sample) -> list[Sample]:
    """The recorded samples, ending with the final one (a long run records only some)."""
    samples = list(history)
    if not samples or samples[-1] is not final:
        samples.append(final)
    return samples
