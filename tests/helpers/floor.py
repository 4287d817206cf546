"""A plant's truth on a floor with friction, for tests that judge the friction estimates, and
the generated loads on the noise benchmark's floors."""

from __future__ import annotations

import dataclasses

from agent.algorithm.tuning import Estimators
from agent.platform.protocol import Truth
from simulator.bench.floor import FloorSettings, on_floor
from simulator.bench.noise import NoiseSettings, for_generated, noisy
from simulator.generate import generate_scenario

FLOOR = Truth(
    10,
    0.1,
    (1.0, 0.0),
    0.0,
    (0.0, 0.0),
    0.0,
    ((0.0, 0.0), (2.0, 0.0)),
    ((0.0, 0.0),) * 2,
    ((1.0, 0.0), (-1.0, 0.0)),
    5.0,
    2.0,
    ground_coulomb=0.02,
    ground_static=0.03,
    friction_radius=1.5,
    viscous_radius2=2.5,
)
"""Two robots on a 5 kg load at rest, at tick 10 (0.1 s), on a floor of μ = 2 % whose supports
are 1.5 m from the COM on average: a spin meets ``μ m g c`` = 1.4715 N m."""


def generated_on_floor(seed: int, max_time_s: float = 30.0):
    """``(scenario, μ, μ_s)``: generated load ``seed`` as the noise benchmark runs it on floors
    (``heft bench noise --generated N --coulomb-range 0.005 0.03``): its sensors' noise, its
    drives, the robust estimators with the generated loads' settings, its seed's floor."""
    settings = for_generated(dataclasses.replace(NoiseSettings(), max_time_s=max_time_s))
    scenario = noisy(generate_scenario(seed), settings, seed, Estimators.ROBUST)
    mu, mu_s = FloorSettings((0.005, 0.03)).draw(seed)
    scenario, _ = on_floor(scenario, mu, mu_s)
    return scenario, mu, mu_s
