"""Step 7 ends once the team knows its mass, the ``m̂`` it publishes: generated load 94 on its
floor (49 kg under three robots, μ = 0.96 %) has one robot whose own fit is four times less
sure than the others' (0.87 % against 0.21 and 0.24 % when Step 7 ends), and the team waited
6.9 s for it when every robot judged its own; judged by the team's, Step 7 lasts 2.5 s."""

from __future__ import annotations

from simulator.inprocess import run_inprocess
from simulator.results import step_times
from tests.helpers.floor import generated_on_floor

SEED = 94


def test_step_7_ends_once_the_teams_mass_is_known() -> None:
    scenario, _, _ = generated_on_floor(SEED, max_time_s=40.0)
    outcome = run_inprocess(scenario, record_every=1000)
    assert outcome.converged, outcome.detail
    step7 = next(s for s in step_times(outcome) if s["step"] == 7)
    assert step7["end_s"] - step7["start_s"] < 4.0, step7
    truth = outcome.final.truth
    for found in outcome.final.estimates.values():
        assert found.mass is not None and found.mass_std is not None
        assert abs(found.mass - truth.mass) < 1.96 * found.mass_std
