"""A heavy load on a sticky floor is broken away and estimated: seed 2 of the generated loads
on the noise benchmark's floor (46 kg under 8 robots, μ = 2.6 %, μ_s = 3.9 %: 18 N to break it
away) did not move under Step 1's first kick of 2 N a robot; the kick grows until it moves,
and Step 4's torque and the push are sized against the friction torque the spin-up met."""

from __future__ import annotations

import math

from simulator.inprocess import run_inprocess
from tests.helpers.floor import generated_on_floor

SEED = 2


def test_a_heavy_load_the_first_kick_cannot_move_is_estimated() -> None:
    scenario, mu, mu_s = generated_on_floor(SEED)
    truth = scenario.body
    assert mu_s * truth.mass * 9.81 > scenario.n * scenario.agent.kick_force  # held at first
    outcome = run_inprocess(scenario)
    assert outcome.converged, outcome.detail
    final = outcome.final
    for robot, est in final.estimates.items():
        assert abs(est.mass / final.truth.mass - 1.0) < 0.03
        assert abs(est.moment / final.truth.moment - 1.0) < 0.03
        assert math.dist(est.contact_to_com, final.truth.contact_to_com[robot - 1]) < 0.02
        assert abs(est.coulomb - mu) < 0.005
