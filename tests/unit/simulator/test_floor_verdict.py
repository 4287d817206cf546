"""A load the team's torque cannot break away gets a verdict, not numbers: on
``pallet.toml`` (a 30 kg pallet on nine blocks, μ_s = 0.35) Step 4's torque of
``inertia_force`` = 25 N a robot does not turn it, every robot says so and stops pushing, and
the run ends with that verdict at once."""

from __future__ import annotations

from pathlib import Path

from simulator.inprocess import run_inprocess
from simulator.lockstep import CANNOT_BREAK_AWAY
from simulator.results import results_dict
from simulator.scenario import PAPER_SCENARIO, load_scenario

PALLET = Path(PAPER_SCENARIO).parent / "pallet.toml"


def test_a_load_the_team_cannot_turn_gets_a_verdict_not_numbers() -> None:
    outcome = run_inprocess(load_scenario(PALLET))
    assert not outcome.converged
    assert outcome.reason == CANNOT_BREAK_AWAY, outcome.reason
    assert "N m left the load where it was" in outcome.detail
    assert outcome.final.time_s < 10.0  # at once, not at max_time_s
    for est in outcome.final.estimates.values():
        assert est.stuck_torque is not None and est.stuck_torque > 0.0
        assert est.moment is None and est.mass is None and est.contact_to_com is None
    truth = outcome.final.truth
    assert truth.omega == 0.0 and truth.com_velocity == (0.0, 0.0)  # held by the floor
    assert results_dict(outcome)["reason"] == CANNOT_BREAK_AWAY
