"""Step 1's spin-up is a torque with no net force on every generated load: generated load 54
on the noise benchmark's floor (47 kg under 4 robots, μ = 0.55 %) grew its kicks to
``max_force``, and its robots' spin-up terms, each ``spin_gain`` times its own kick's size and
cut by its own saturation, no longer cancelled: a net force of 9 N, and the load travelled
3.7 m in Step 1, off its floor. With the team's mean kick size as every robot's gain and each
edge's term bounded alike at both its ends, it stays within 0.5 m."""

from __future__ import annotations

import math

from agent.platform.protocol import Phase
from simulator.inprocess import run_inprocess
from tests.helpers.floor import generated_on_floor

SEED = 54


def test_step_1_does_not_push_a_heavy_load_off_its_floor() -> None:
    scenario, _, _ = generated_on_floor(SEED, max_time_s=20.0)
    start = []
    travel = []
    gains = []

    def on_sample(sample, agents) -> None:
        if sample.estimates[1].phase != Phase.EXCITE:
            return
        com = sample.truth.com_position
        if not start:
            start.append(com)
        travel.append(math.dist(com, start[0]))
        gains.append([a.pipeline.mean_kick_level for a in agents])

    outcome = run_inprocess(scenario, on_sample=on_sample, record_every=1)
    assert outcome.final.estimates[1].phase != Phase.EXCITE, "Step 1 never ended"
    assert max(travel) < 0.5, max(travel)
    # The kicks grew (the floor held the load at first), and the robots' gains agree.
    last = gains[-1]
    assert min(last) > 1.5 * scenario.agent.kick_force
    assert max(last) - min(last) < 1e-3 * max(last)
