"""The admittance loop's default gains on the paper's load behind velocity-commanded bases
(``paper-velocity.toml``'s plant, four robots): stable from soft foam to a sprung bumper when
the robots squeeze, push or turn the load, and the protective stop bounding the contact force
under gains that are not.

The agents' forces are replaced by fixed patterns held 1 s each way, so that the loop alone is
judged. The sensor's noise is off (its draws would be the largest part of a peak of the
measured force); the odometry keeps its noise, and the contact force read is the true one."""

from __future__ import annotations

import dataclasses
import math

import pytest

from bridge.admittance import Admittance, AdmittanceSettings
from simulator.plant import Plant
from simulator.scenario import load_scenario
from tests.helpers.paths import PAPER

COMMAND_N = 2.0
SECONDS = 4.0
PATTERNS = {
    "squeeze": ((COMMAND_N, 0.0), (0.0, 0.0), (0.0, 0.0), (-COMMAND_N, 0.0)),
    "push": ((COMMAND_N, 0.0),) * 4,
    "turn": ((0.0, -COMMAND_N), (COMMAND_N, 0.0), (-COMMAND_N, 0.0), (0.0, COMMAND_N)),
}
"""Each robot's force; the push and the turn change sign every second, the squeeze holds."""
STIFFNESSES = (1000.0, 3000.0, 10000.0)
"""N/m: the documented range of contact stiffness, its ends and the scenario's."""


def play(pattern: str, stiffness: float, settings: AdmittanceSettings) -> tuple[float, int]:
    """The largest contact force (N) over the run, and the loops' protective stops."""
    base = load_scenario(PAPER.with_name("paper-velocity.toml"))
    scenario = dataclasses.replace(
        base,
        sensors=dataclasses.replace(base.sensors, force_noise_std=0.0),
        agvs=dataclasses.replace(base.agvs, contact_stiffness=stiffness, admittance=settings),
    )
    plant = Plant(scenario)
    loops = [Admittance(settings, scenario.period_s) for _ in range(scenario.n)]
    forces = PATTERNS[pattern]
    largest = 0.0
    for tick in range(round(SECONDS / scenario.period_s)):
        sign = 1.0 if pattern == "squeeze" or int(tick * scenario.period_s) % 2 == 0 else -1.0
        for robot, (measurement, loop, force) in enumerate(
            zip(plant.measure(), loops, forces), start=1
        ):
            measured = loop.measure(measurement.force)
            largest = max(largest, math.hypot(*measured))
            command = (sign * force[0], sign * force[1])
            plant.command_velocity(robot, loop.step(command))
        plant.advance()
    return largest, sum(loop.overloads for loop in loops)


@pytest.mark.parametrize("stiffness", STIFFNESSES)
@pytest.mark.parametrize("pattern", sorted(PATTERNS))
def test_the_default_gains_keep_the_contact_force_bounded(pattern: str, stiffness: float) -> None:
    largest, overloads = play(pattern, stiffness, AdmittanceSettings())
    assert largest <= 3 * COMMAND_N, f"{pattern} at {stiffness:g} N/m: {largest:.1f} N"
    assert overloads == 0


def test_the_protective_stop_bounds_the_force_of_gains_that_oscillate() -> None:
    """An integral with a small virtual mass pushes a free load well and oscillates in a
    squeeze: without the stop its contact force grows to kilonewtons; with it, the force stays
    within a few times ``max_contact_force`` (the base brakes within its own limits, and the
    contact is compressed while it does: 141 N for a 50 N limit here)."""
    oscillating = AdmittanceSettings(mass=3.0, damping=10.0, integral_time_s=0.05)
    unbounded = dataclasses.replace(oscillating, max_contact_force=1000.0)
    runaway, _ = play("squeeze", 3000.0, unbounded)
    assert runaway > 1000.0
    largest, overloads = play("squeeze", 3000.0, oscillating)
    assert overloads > 0
    assert largest <= 4 * oscillating.max_contact_force
