"""Real sensors are noisy; the paper's estimators are not made for it ("the noisy case will be
the subject of a future work"). This end-to-end run holds the paper's scenario with wheel
odometry noise of 1 cm/s and force noise of 0.5 N to the bounds the noise-robust estimators must
reach: within 1.5 times a centralized batch fit of the same data (m 0.44 %, J 1.2 %,
``contact_to_com`` 12 mm, ``z_ij`` 2.1 mm), with margin, and done within 20 s simulated.

It fails today (no run gets past Step 1), so it is marked ``xfail(strict=True)``: the day the
noise-robust estimators land it passes, the strict marker turns that into a failure, and the
marker must come off."""

from __future__ import annotations

import dataclasses

import pytest

from simulator.inprocess import run_inprocess
from simulator.scenario import load_scenario
from tests.conftest import PAPER, worst_errors

SIGMA_V = 0.01  # m/s per axis
SIGMA_F = 0.5  # N per axis


@pytest.mark.xfail(strict=True, reason="estimators that survive sensor noise are not built yet")
@pytest.mark.parametrize("seed", [1, 2])
def test_the_paper_scenario_with_real_sensor_noise(seed: int) -> None:
    paper = load_scenario(PAPER)
    scenario = dataclasses.replace(
        paper,
        sensors=dataclasses.replace(
            paper.sensors, velocity_noise_std=SIGMA_V, force_noise_std=SIGMA_F
        ),
        run=dataclasses.replace(paper.run, seed=seed, max_time_s=20.0),
    )
    outcome = run_inprocess(scenario, record_every=1000)
    assert outcome.converged, f"not done within {scenario.run.max_time_s:g} s simulated"
    worst = worst_errors(outcome)
    assert worst["mass"] <= 0.01, worst
    assert worst["moment"] <= 0.025, worst
    assert worst["contact_to_com"] <= 0.025, worst
    assert worst["relative"] <= 0.005, worst
