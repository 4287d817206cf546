"""A heavy load on a sticky floor is broken away and estimated: seed 2 of the generated loads
on the noise benchmark's floor (46 kg under 8 robots, μ = 2.6 %, μ_s = 3.9 %: 18 N to break it
away) did not move under Step 1's first kick of 2 N a robot; the kick grows until it moves,
and Step 4's torque and the push are sized against the friction torque the spin-up met."""

from __future__ import annotations

import dataclasses
import math

from agent.algorithm.tuning import Estimators
from simulator.bench.floor import FloorSettings, on_floor
from simulator.bench.noise import (
    GENERATED_INERTIA_BRAKE_S,
    GENERATED_PUSH_DAMPING,
    NoiseSettings,
    noisy,
)
from simulator.generate import generate_scenario
from simulator.inprocess import run_inprocess

SEED = 2


def test_a_heavy_load_the_first_kick_cannot_move_is_estimated() -> None:
    settings = dataclasses.replace(
        NoiseSettings(),
        push_damping=GENERATED_PUSH_DAMPING,
        inertia_brake_s=GENERATED_INERTIA_BRAKE_S,
        max_time_s=30.0,
    )
    scenario = noisy(generate_scenario(SEED), settings, SEED, Estimators.ROBUST)
    mu, mu_s = FloorSettings((0.005, 0.03)).draw(SEED)
    scenario, _ = on_floor(scenario, mu, mu_s)
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
