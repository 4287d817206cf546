"""The load's floor, checked over every tick wherever a run is followed from.

The plant tracks the load's excursion (largest travel from the start, largest speed, largest
``|ω|``) at every tick and its truth carries it: a run's floor figures are then the same in
one process and over Zenoh, where the launcher hears only some instants of the team.
"""

from __future__ import annotations

import dataclasses
import io
import math

import pytest

from simulator.inprocess import run_inprocess
from simulator.launcher import run_zenoh
from simulator.plant import Plant
from simulator.results import floor_check, format_table
from simulator.scenario import load_scenario
from tests.helpers.accuracy import assert_same_estimates
from tests.helpers.paths import PAPER, paper_at_half_pace


@pytest.fixture(scope="module")
def paper_run():
    return run_inprocess(load_scenario(PAPER))


def test_the_truth_carries_the_excursion_over_every_tick() -> None:
    """Pushed one way, then back, then to rest: each tick's truth holds the largest travel,
    speed and ``|ω|`` of every tick so far (computed here from each tick's own truth), which
    by the end are well above the load's travel, speed and ``|ω|`` then."""
    scenario = load_scenario(PAPER)
    plant = Plant(scenario)
    start = plant.truth().com_position
    travel = speed = omega = 0.0
    pushes = [(3.0, 1.0)] * 100 + [(-3.0, -1.0)] * 200 + [(3.0, 1.0)] * 100
    for force in pushes:
        truth = plant.truth()
        travel = max(travel, math.dist(truth.com_position, start))
        speed = max(speed, math.hypot(*truth.com_velocity))
        omega = max(omega, abs(truth.omega))
        excursion = (truth.largest_travel, truth.largest_speed, truth.largest_omega)
        assert excursion == pytest.approx((travel, speed, omega), rel=1e-12, abs=1e-15)
        for robot in range(1, scenario.n + 1):
            plant.command(robot, force)
        plant.advance()
    last = plant.truth()
    assert last.largest_travel > math.dist(last.com_position, start) + 0.1
    assert last.largest_speed > math.hypot(*last.com_velocity) + 0.1
    assert last.largest_omega > abs(last.omega) + 0.01


def test_the_floor_does_not_depend_on_the_samples_recorded(paper_run) -> None:
    """A run that recorded its final instant only has the same floor figures."""
    bare = dataclasses.replace(paper_run, history=[paper_run.final])
    assert floor_check(bare) == floor_check(paper_run)
    floor = floor_check(paper_run)
    assert 0.3 < floor["travel_m"] < 1.0 and 1.0 < floor["speed"] < 1.5, floor


@pytest.mark.slow
@pytest.mark.parametrize("clock", ["lockstep", "realtime"])
def test_the_floor_over_zenoh_is_the_in_process_runs(paper_run, clock: str) -> None:
    """Over Zenoh the launcher hears the team's estimates every fifth tick: the floor figures
    are the plant's, over every tick, not the largest of the instants heard; they equal the
    in-process run's (in lockstep exactly; in real time to 1 cm, 0.01 m/s and 0.01 rad/s when
    every robot began each step as many ticks after it did there: the real-time run starts a
    tick or so late, and one in which a late command moved one step's start against the others
    is its own); and the recorded samples (the plots' points) span the run. In real time at
    half pace (:func:`~tests.helpers.paths.paper_at_half_pace`)."""
    scenario = paper_at_half_pace() if clock == "realtime" else load_scenario(PAPER)
    there = run_zenoh(scenario, clock=clock, log_stream=io.StringIO())
    assert there.converged
    here, floor = floor_check(paper_run), floor_check(there)
    heard = [sample.truth for sample in there.history]
    assert floor["speed"] >= max(math.hypot(*truth.com_velocity) for truth in heard)
    assert floor["omega"] >= max(abs(truth.omega) for truth in heard)
    steps = {r: e.started for r, e in there.final.estimates.items()}
    lags = {
        steps[r].get(step, -1) - began
        for r, e in paper_run.final.estimates.items()
        for step, began in e.started.items()
        if step > 1  # Step 1 begins at tick 0
    }
    same_path = len(lags) == 1  # every later step, each robot's, as many ticks late
    if clock == "lockstep":
        assert lags == {0} and floor == here
    if same_path:
        assert floor["travel_m"] == pytest.approx(here["travel_m"], abs=0.01), floor
        assert floor["speed"] == pytest.approx(here["speed"], abs=0.01), floor
        assert floor["omega"] == pytest.approx(here["omega"], abs=0.01), floor
    else:
        print(f"\n{clock}: the steps began at other ticks ({steps}): floor {floor}")
    assert floor["within"]
    assert f"from t = 0 to {there.final.time_s:.2f} s" in format_table(there)
    ticks = [sample.truth.tick for sample in there.history]
    assert ticks[0] < 10 and ticks[-1] == there.final.truth.tick and len(ticks) > 100, ticks


@pytest.mark.slow
def test_the_ground_over_zenoh_is_the_in_process_runs() -> None:
    """On a floor with friction (paper-floor.toml's casters), lockstep over Zenoh ends at the
    in-process run's instant with the same truth, the ground's figures and the friction the
    plant applied included, and the same estimates."""
    scenario = load_scenario(PAPER.parent / "paper-floor.toml")
    here = run_inprocess(scenario)
    there = run_zenoh(scenario, log_stream=io.StringIO())
    assert there.final.truth == here.final.truth
    truth = there.final.truth
    assert (truth.ground_coulomb, truth.ground_static) == (0.02, 0.03)
    assert truth.friction_radius > 0.0 and truth.friction_force != (0.0, 0.0)
    assert_same_estimates(here, there)
