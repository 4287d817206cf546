"""The lockstep tick and the run's end (simulator/lockstep.py), which the in-process run and
the processes share: the truth of a tick is read before the plant moves, forces cross the link
as measurements do, and a run is over on the team's state: done past the scenario's end, halted,
or out of simulated time."""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

from agent.platform.evaluation import final_instant
from agent.platform.protocol import Phase
from bridge.admittance import Admittance
from bridge.codec import AgvCodec, clamp_force
from simulator.can_drivers import CanQuantiser
from simulator.inprocess import run_inprocess
from simulator.lockstep import PlantTicks, RunEnd, Verdict
from simulator.plant import Plant
from simulator.scenario import Scenario, load_scenario
from tests.helpers.paths import PAPER

END = RunEnd(end_tick=100, last_tick=1000, period_s=0.01, max_time_s=10.0)


def _team(*robots: tuple[Phase, int]) -> list[SimpleNamespace]:
    return [SimpleNamespace(phase=phase, phase_since=since) for phase, since in robots]


def test_a_run_is_over_once_the_team_is_done_and_the_scenario_has_ended() -> None:
    done = _team((Phase.DONE, 60), (Phase.DONE, 80))
    assert END.over(99, done) is None  # the load changes and the hold are not over
    assert END.over(100, done) == Verdict()
    late = _team((Phase.DONE, 60), (Phase.DONE, 140))
    assert END.over(140, late) == Verdict()
    assert END.over(500, _team((Phase.DONE, 60), (Phase.PUSH, 80))) is None


def test_a_halted_team_or_one_out_of_time_is_over_and_not_converged() -> None:
    verdict = END.over(300, _team((Phase.HALTED, 290), (Phase.HALTED, 291)))
    assert verdict == Verdict("team halted", "the team halted at t = 3.00 s simulated")
    pushing = _team((Phase.PUSH, 60), (Phase.PUSH, 60))
    assert END.over(999, pushing) is None
    out = END.over(1000, pushing)
    assert out is not None and out.reason == "out of simulated time (run.max_time_s = 10 s)"
    # Done at the last tick, but before the scenario's end: out of time all the same.
    early = dataclasses.replace(END, end_tick=1200)
    assert early.over(1000, _team((Phase.DONE, 60), (Phase.DONE, 80))) == out


def test_the_inprocess_run_is_judged_at_the_final_instant_of_its_estimates() -> None:
    """Held past the team's end (6.99 s) to 10 s: the run ends at the scenario's end, the
    instant the launcher takes as final from the same estimates."""
    paper = load_scenario(PAPER)
    held = dataclasses.replace(paper, run=dataclasses.replace(paper.run, hold_s=10.0))
    outcome = run_inprocess(held)
    assert outcome.converged and outcome.ticks == held.end_tick == 1000
    assert final_instant(list(outcome.final.estimates.values()), held.end_tick) == 1000
    assert outcome.final.truth.tick == 1000


def test_a_tick_reads_the_truth_before_the_plant_moves_and_forces_cross_the_link() -> None:
    paper = load_scenario(PAPER)
    link = CanQuantiser(paper.period_s)
    ticks = PlantTicks(paper, link)
    force = (12.3456789, -0.0123456)
    ticks.measure()
    truth = ticks.apply([force] * paper.n)
    assert truth is not None and truth.tick == 0 and truth.com_velocity == (0.0, 0.0)
    assert ticks.tick == 1
    assert ticks.apply([force] * paper.n, truth=False) is None
    measured = ticks.measure()
    assert [m.force for m in measured] == [link.force(force)] * paper.n
    assert link.force(force) != force  # (quantised: the test would see a force not carried)


def _velocity_scenario(seconds: float) -> Scenario:
    scenario = load_scenario(PAPER.with_name("paper-velocity.toml"))
    return dataclasses.replace(scenario, run=dataclasses.replace(scenario.run, max_time_s=seconds))


def test_a_velocity_bases_tick_crosses_the_link_through_its_admittance_loop() -> None:
    """Over CAN: the base's velocity and the sensor's raw force as the velocity profile's codec
    quantises them, the force tared by the loop; the loop's velocity, quantised as a
    MotionCommand, is what the base drives at. A twin plant driven by the same velocities and
    a second set of loops give the same values."""
    scenario = _velocity_scenario(1.0)
    codec = AgvCodec("velocity")
    ticks = PlantTicks(scenario, CanQuantiser(scenario.period_s, codec))
    twin = Plant(scenario)
    loops = [Admittance(scenario.agvs.admittance, scenario.period_s) for _ in range(scenario.n)]
    quantised = moving = 0
    for k in range(60):
        measured, raw = ticks.measure(), twin.measure()
        for m, r, loop in zip(measured, raw, loops):
            assert m.velocity == codec.quantize_velocity(r.velocity)
            assert m.force == loop.measure(codec.quantize_force(r.force))
            quantised += m.velocity != r.velocity
        forces = [(2.0 * math.cos(k / 7 + i), 1.0) for i in range(scenario.n)]
        forces[0] = (600.0, -0.5) if k == 45 else forces[0]  # beyond the protocol's ±500 N
        ticks.apply(forces, truth=False)
        bases = ticks.plant.bases
        assert bases is not None
        for robot, (loop, force) in enumerate(zip(loops, forces), start=1):
            velocity = codec.quantize_command_velocity(loop.step(clamp_force(force)[0]))
            assert bases.commanded[robot - 1] == velocity
            twin.command_velocity(robot, velocity)
            moving += velocity != (0.0, 0.0)
        twin.advance()
    assert quantised > 0 and moving > 100  # (the loops tare for 20 ticks, then drive)


def test_an_inprocess_can_run_on_velocity_bases_is_deterministic() -> None:
    scenario = _velocity_scenario(3.0)
    first = run_inprocess(scenario, link="can", record_every=1)
    again = run_inprocess(scenario, link="can", record_every=1)
    assert first.history == again.history and len(first.history) > 250
    memory = run_inprocess(scenario, record_every=1)
    assert memory.history != first.history  # the link's quantisation is in the run
