"""A load the team's forces cannot move gets a verdict, not numbers: on ``pallet.toml`` (a 30 kg
pallet on nine blocks, μ = 0.3, μ_s = 0.35) the floor's friction torque that Step 1's spin-up
meets asks more of Step 4 than ``max_force`` = 60 N a robot gives; with ``max_force`` = 20 N a
robot (80 N in all, under the 103 N that breaks it away) Step 1's kick never moves it. Either
way every robot says so and stops pushing, and the run ends with that verdict at once. A team
whose drives do not pass their force on (velocity-commanded bases behind gains that do not push)
is told so, not that the floor holds the load."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from simulator.inprocess import run_inprocess
from simulator.lockstep import CANNOT_BREAK_AWAY
from simulator.results import results_dict
from simulator.scenario import PAPER_SCENARIO, load_scenario

PALLET = Path(PAPER_SCENARIO).parent / "pallet.toml"


def _held(outcome, detail: str) -> None:
    assert not outcome.converged
    assert outcome.reason == CANNOT_BREAK_AWAY, outcome.reason
    assert detail in outcome.detail, outcome.detail
    assert outcome.final.time_s < 10.0  # at once, not at max_time_s
    for est in outcome.final.estimates.values():
        assert est.stuck_torque is not None
        assert est.moment is None and est.mass is None and est.contact_to_com is None
    assert results_dict(outcome)["reason"] == CANNOT_BREAK_AWAY


def test_a_load_the_team_cannot_turn_steadily_gets_a_verdict_not_numbers() -> None:
    outcome = run_inprocess(load_scenario(PALLET))
    _held(outcome, "asks more of Step 4 than max_force = 60 N")
    # the friction torque the spin-up met, against the truth's μ m g c (41 N m)
    found = float(outcome.detail.split("met in Step 1, ")[1].split(" N m")[0])
    truth = outcome.final.truth
    assert abs(found / truth.coulomb_torque - 1.0) < 0.15
    for est in outcome.final.estimates.values():
        assert est.stuck_torque > 0.0  # the most max_force gives


def test_a_load_the_kick_cannot_move_gets_a_verdict_not_numbers() -> None:
    scenario = load_scenario(PALLET)
    agent = dataclasses.replace(
        scenario.agent, max_force=20.0, kick_force=5.0, inertia_force=10.0, spin_gain=100.0
    )
    agent = dataclasses.replace(agent, robust=dataclasses.replace(agent.robust, push_force=10.0))
    outcome = run_inprocess(dataclasses.replace(scenario, agent=agent))
    _held(outcome, "Step 1's kick, grown to max_force = 20 N a robot, did not move the load")
    assert outcome.detail.split(" (t = ")[0].endswith(": the floor holds it"), outcome.detail
    assert {est.stuck_torque for est in outcome.final.estimates.values()} == {0.0}
    truth = outcome.final.truth
    assert truth.largest_travel < 1e-6 and truth.largest_omega < 1e-6


def test_a_kick_the_drives_do_not_pass_on_is_not_blamed_on_the_floor() -> None:
    """``paper-velocity.toml``'s bases behind the admittance loop's default gains, on a
    frictionless floor: the kick does not move the load because the drives apply little of
    it, and the verdict says that."""
    outcome = run_inprocess(load_scenario(PALLET.with_name("paper-velocity.toml")))
    assert outcome.reason == CANNOT_BREAK_AWAY
    assert "'s drive applied only " in outcome.detail, outcome.detail
    assert "the force did not reach the load" in outcome.detail
    assert "floor" not in outcome.detail
    share = float(outcome.detail.split("applied only ")[1].split(" %")[0])
    assert share < 50.0
    assert outcome.final.truth.ground_coulomb == 0.0
