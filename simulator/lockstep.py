"""The lockstep tick and the run's end, defined once for the run in one process
(:func:`~simulator.inprocess.run_inprocess`) and for the run over processes (the plant process,
:class:`~simulator.node.PlantNode`; the launcher, :mod:`simulator.launcher`; ``heft watch``):
a lockstep run over Zenoh is the in-process run, estimate for estimate and instant for instant.

Tick ``k`` (:class:`PlantTicks`):

1. the plant is sampled at ``t_k``: every robot's measurement (:meth:`PlantTicks.measure`);
2. every robot's agent steps on its measurement and its neighbours' shares of tick ``k − 1``
   (:meth:`~agent.algorithm.agent.Agent.step`) and answers with its force for
   ``[t_k, t_{k+1})``: in one process at once; over processes the plant waits until every
   live robot's command of tick ``k`` is in;
3. the forces are held (:meth:`PlantTicks.apply`; a robot without one, lost or silent, gets
   zero), the truth of ``t_k`` is read when it is wanted (the plant has not moved since it was
   sampled), and the plant advances one sensor period.

On the AGVs' CAN buses the link clamps and quantises every measurement and command it carries:
the plant process has the buses themselves (:class:`~simulator.can_drivers.CanDriversPort`),
the run in one process their stand-in as the ``link`` of :class:`PlantTicks`
(:class:`~simulator.can_drivers.CanQuantiser`).

Each robot's part of steps 1 and 3 is its :class:`Drive`'s. A force drive (the paper's robot)
passes the sample and the force across the link. A velocity-commanded base (``[agvs] profile
= "velocity"``) is behind an admittance loop (:mod:`bridge.admittance`), which its AGV bridge
runs over CAN and :class:`AdmittanceDrive` in one process, in the same order:

1. the base's velocity and the sensor's raw force of ``t_k`` cross the link; the loop tares
   the force (``f_k = adm.measure(raw_k)``), and the agent gets the velocity and ``f_k``;
2. the agent answers with its force ``u_k``;
3. the loop turns it into the base's velocity ``v_k = adm.step(u_k)``, which crosses the link
   (a ``MotionCommand``) to the base for ``[t_k, t_{k+1})``.

So a lockstep run in one process with the CAN link equals the run over the buses.

The run's end (:class:`RunEnd`), decided on the team's state, never on message timing:

- *done*: every robot is done, and the scenario's ``end_tick`` (its load changes and hold) has
  come: the final instant is ``t_f = max(end_tick, max_i phase_since_i)``
  (:func:`~agent.platform.evaluation.final_instant`), and the run is over at tick ``t_f``,
  converged, unless some robot's estimates then publish no mass (:func:`mass_verdict`:
  "mass not determined", which both runs apply to their final instant);
- *halted*: every robot halted (one robot's halt reaches the whole team: it is the highest
  phase): over, not converged;
- *out of simulated time*: tick ``k`` is the scenario's last (``run.max_time_s``), the team
  not done: over, not converged.

The run is judged at the first instant, from the one it is over at, whose estimates every robot
has given: in one process within :data:`ALIGN_TICKS` more ticks (an agent may lag behind a
late or lost message); over processes the launcher waits for it a grace of wall time
(:data:`~simulator.launcher.FINAL_GRACE_S`). The plant process stops after the last tick, so
a run over processes out of simulated time is judged at the newest such instant before it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from agent.algorithm.robust.pipeline import PUBLISHED_FROM
from agent.platform.evaluation import InPhase, final_instant
from agent.platform.geometry import Vec2
from agent.platform.protocol import Estimates, Measurement, Phase, Truth

if TYPE_CHECKING:
    from bridge.admittance import Admittance
    from simulator.plant import Plant
    from simulator.scenario import Scenario

ALIGN_TICKS = 64
"""Ticks a run in one process steps on, past the tick it is over at, for every agent's
estimates to refer to the same instant."""
INTERRUPTED = "interrupted"
TEAM_HALTED = "team halted"


class Link(Protocol):
    """What the robots' link does to the values it carries (the CAN buses' clamps and
    quantisation: :class:`~simulator.can_drivers.CanQuantiser`)."""

    def measurement(self, m: Measurement) -> Measurement:
        """``m`` as the robot's agent (or its AGV bridge) gets it."""
        ...

    def force(self, force: Vec2) -> Vec2:
        """A commanded force as the robot's drive gets it."""
        ...

    def loop_force(self, force: Vec2) -> Vec2:
        """An agent's force as the admittance loop on its AGV bridge takes it (velocity
        profile)."""
        ...

    def velocity(self, velocity: Vec2) -> Vec2:
        """A commanded velocity as the robot's base gets it (velocity profile)."""
        ...


@dataclass(frozen=True, slots=True)
class VelocityCommand:
    """The velocity (m/s, ``W``) robot ``robot``'s base drives at from ``tick`` until the next:
    what an AGV bridge's ``MotionCommand`` tells the plant (velocity profile over CAN)."""

    robot: int
    tick: int
    velocity: Vec2


class Drive(Protocol):
    """One robot's side of the tick: what its agent gets of its sample, and what the plant
    gets of its command (see the module docstring)."""

    def measurement(self, m: Measurement) -> Measurement:
        """Step 1: the plant's sample ``m`` as the robot's agent gets it."""
        ...

    def command(self, value: Vec2) -> None:
        """Step 3: the command the robot answered with, given to the plant for the period."""
        ...


class ForceDrive:
    """A force drive (``[actuators]``, the paper's robots): the agent's force goes to the
    plant as the link carries it."""

    def __init__(self, plant: Plant, robot: int, link: Link | None):
        self.plant, self.robot, self.link = plant, robot, link

    def measurement(self, m: Measurement) -> Measurement:
        return m if self.link is None else self.link.measurement(m)

    def command(self, value: Vec2) -> None:
        self.plant.command(self.robot, value if self.link is None else self.link.force(value))


class AdmittanceDrive:
    """A velocity-commanded base with its admittance loop (:mod:`bridge.admittance`), as its
    AGV bridge runs it: the sensor's raw force, as the link carries it, is tared into the force
    the agent gets (:meth:`~bridge.admittance.Admittance.measure`), and the agent's force (as
    the bridge takes it) becomes the base's velocity
    (:meth:`~bridge.admittance.Admittance.step`), as the link carries it."""

    def __init__(self, plant: Plant, robot: int, admittance: Admittance, link: Link | None):
        self.plant, self.robot, self.link = plant, robot, link
        self.admittance = admittance

    def measurement(self, m: Measurement) -> Measurement:
        if self.link is not None:
            m = self.link.measurement(m)
        return dataclasses.replace(m, force=self.admittance.measure(m.force))

    def command(self, value: Vec2) -> None:
        link = self.link
        if link is None:
            self.plant.command_velocity(self.robot, self.admittance.step(value))
            return
        velocity = self.admittance.step(link.loop_force(value))
        self.plant.command_velocity(self.robot, link.velocity(velocity))


class BaseDrive:
    """A velocity-commanded base whose admittance loop runs on its AGV bridge (over CAN): the
    plant's raw sample goes out as it is (the buses quantise it), and the command is the
    bridge's velocity."""

    def __init__(self, plant: Plant, robot: int):
        self.plant, self.robot = plant, robot

    def measurement(self, m: Measurement) -> Measurement:
        return m

    def command(self, value: Vec2) -> None:
        self.plant.command_velocity(self.robot, value)


def drives(scenario: Scenario, plant: Plant, link: Link | None, bridged: bool) -> list[Drive]:
    """Each robot's :class:`Drive`, robot 1 first: force drives, or velocity-commanded bases
    (``scenario.agvs``) whose admittance loops run here unless ``bridged`` (on the AGV
    bridges)."""
    robots = range(1, scenario.n + 1)
    agvs = scenario.agvs
    if not agvs.velocity:
        return [ForceDrive(plant, robot, link) for robot in robots]
    if bridged:
        return [BaseDrive(plant, robot) for robot in robots]
    from bridge.admittance import Admittance

    return [
        AdmittanceDrive(plant, robot, Admittance(agvs.admittance, scenario.period_s), link)
        for robot in robots
    ]


class PlantTicks:
    """The plant of ``scenario``, tick by tick (see the module docstring); ``link`` (if given)
    stands for what carries the values between the robots and their agents; ``bridged``: the
    robots' AGV bridges run the velocity-commanded bases' admittance loops (a run over CAN),
    the plant takes their velocities (:class:`VelocityCommand`)."""

    def __init__(self, scenario: Scenario, link: Link | None = None, bridged: bool = False):
        from simulator.plant import Plant  # pymunk: not for the commands' parsers

        self.plant = Plant(scenario)
        self.link = link
        self.drives = drives(scenario, self.plant, link, bridged)

    @property
    def tick(self) -> int:
        """``k``: the tick the plant is at."""
        return self.plant.tick

    @property
    def time_s(self) -> float:
        """``t_k``."""
        return self.plant.time_s

    def measure(self) -> list[Measurement]:
        """Step 1: every robot's measurement of tick ``k``, robot 1 first, as its agent gets
        it."""
        return [d.measurement(m) for d, m in zip(self.drives, self.plant.measure())]

    def apply(self, commands: Sequence[Vec2], truth: bool = True) -> Truth | None:
        """Step 3: robot ``i``'s command ``commands[i − 1]`` (its force; a bridged base's
        velocity) goes to the plant through its :class:`Drive` for ``[t_k, t_{k+1})``; the
        plant advances to ``t_{k+1}``. Returns the truth of ``t_k`` (``None`` unless
        ``truth``)."""
        for drive, command in zip(self.drives, commands):
            drive.command(command)
        now = self.plant.truth() if truth else None
        self.plant.advance()
        return now


CANNOT_BREAK_AWAY = "cannot break the load away"
"""The verdict of a team whose every robot found the load held by the floor."""
MASS_NOT_DETERMINED = "mass not determined"
"""The verdict of a team done without a mass it could publish: its ``m̂`` stopped getting
surer short of :data:`~agent.algorithm.robust.pipeline.PUBLISHED_FROM` of itself, or the load
swung under Step 7's push (:data:`~agent.algorithm.robust.pipeline.SWUNG_TURN`: then no COM is
published either)."""


@dataclass(frozen=True)
class Verdict:
    """Why a run ended: ``reason`` is short and machine-readable (``""``: converged), ``detail``
    a sentence for people."""

    reason: str = ""
    detail: str = ""


def halted(lost: Iterable[int], detail: str) -> Verdict:
    """The verdict of a team that halted: the robots ``lost`` named (``n`` is fixed: estimates
    without one of them would be wrong), or only that it halted."""
    robots = sorted(lost)
    return Verdict(f"robot(s) {robots} lost" if robots else TEAM_HALTED, detail)


def mass_verdict(verdict: Verdict, estimates: Mapping[int, Estimates], t_s: float) -> Verdict:
    """``verdict``, or :data:`MASS_NOT_DETERMINED` if it says the team converged while some
    robot's final ``estimates`` (at ``t_s``) publish no mass."""
    unknown = [robot for robot, est in sorted(estimates.items()) if est.mass is None]
    if verdict.reason or not unknown:
        return verdict
    swung = [robot for robot in unknown if estimates[robot].contact_to_com is None]
    com = (
        f"; nor is the COM by robot(s) {swung}: the load turned under the push, so their COM was"
        " off"
        if swung
        else ""
    )
    return Verdict(
        MASS_NOT_DETERMINED,
        f"the team was done at t = {t_s:.2f} s simulated, but robot(s) {unknown} know the mass"
        f" only to worse than {100 * PUBLISHED_FROM:g} %, or measured it while the load turned"
        f" under the push (a COM known too roughly): no mass is published{com}",
    )


@dataclass(frozen=True)
class RunEnd:
    """When a run of a scenario is over (see the module docstring)."""

    end_tick: int
    """The earliest final instant: :attr:`~simulator.scenario.Scenario.end_tick`."""
    last_tick: int
    """The scenario's last tick, ``run.max_time_s / period_s``: the plant process stops after
    it."""
    period_s: float
    max_time_s: float

    @classmethod
    def of(cls, scenario: Scenario) -> RunEnd:
        period_s, max_time_s = scenario.period_s, scenario.run.max_time_s
        return cls(scenario.end_tick, round(max_time_s / period_s), period_s, max_time_s)

    def out_of_time(self, tick: int) -> bool:
        """Whether a team not done at ``tick`` is out of simulated time."""
        return tick >= self.last_tick

    def out_of_time_verdict(self) -> Verdict:
        return Verdict(
            f"out of simulated time (run.max_time_s = {self.max_time_s:g} s)",
            f"the team was not done after the scenario's {self.max_time_s:g} s",
        )

    def over(self, tick: int, team: Sequence[InPhase]) -> Verdict | None:
        """The verdict if the run is over at ``tick``, the robots of ``team`` stepped (their
        phases); ``None`` while it goes on."""
        phase = min(robot.phase for robot in team)
        if all(getattr(robot, "stuck", False) for robot in team):
            torque = max(getattr(robot, "stuck_torque", 0.0) for robot in team)
            because = next((b for robot in team if (b := getattr(robot, "held_because", ""))), "")
            if because:
                return Verdict(
                    CANNOT_BREAK_AWAY,
                    f"{because} (t = {tick * self.period_s:.2f} s simulated)",
                )
            return Verdict(
                CANNOT_BREAK_AWAY,
                f"Step 4's torque of {torque:.3g} N m left the load where it was at"
                f" t = {tick * self.period_s:.2f} s simulated: the floor holds it (the torque"
                " is inertia_force a robot, at most max_force)",
            )
        if phase == Phase.HALTED:
            return halted((), f"the team halted at t = {tick * self.period_s:.2f} s simulated")
        if phase == Phase.DONE:
            done = final_instant(team, self.end_tick)
            if done is not None and tick >= done:
                return Verdict()
        if self.out_of_time(tick):
            return self.out_of_time_verdict()
        return None
