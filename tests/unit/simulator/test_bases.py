"""Velocity-commanded bases (simulator/bases.py) and the plant on them: the speed loop's lag and
limits against their closed forms, a static contact's force, the load's momentum against the
contacts' impulse, and each sensor's bias drawn from the seed on a stream of its own."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest

from simulator.bases import Bases, sensor_biases
from simulator.plant import Plant
from simulator.scenario import Sensors, load_scenario, parse_scenario
from tests.helpers.paths import PAPER

DT = 1e-3


def _base(tau: float = 0.05, accel: float = 3.0, speed: float = 4.0) -> Bases:
    return Bases([(0.0, 0.0)], tau, accel, speed, 3000.0, 20.0, DT)


def _run(bases: Bases, steps: int) -> None:
    for _ in range(steps):
        bases.step()


def test_a_base_reaches_its_command_with_its_time_constant() -> None:
    """Below the acceleration limit: ``v(t) = u (1 − e^{−t/τ})``, exactly per step."""
    bases = _base(tau=0.05)
    bases.command(0, (0.06, -0.08))  # 0.1 m/s: at most 2 m/s², below the 3 m/s² limit
    _run(bases, 50)  # t = τ
    vx, vy = bases.velocity[0]
    assert vx == pytest.approx(0.06 * (1 - math.exp(-1)), rel=1e-12)
    assert vy == pytest.approx(-0.08 * (1 - math.exp(-1)), rel=1e-12)
    _run(bases, 450)  # 10 τ
    assert bases.velocity[0] == pytest.approx((0.06, -0.08), rel=1e-4)
    x, y = bases.position[0]
    assert math.hypot(x, y) == pytest.approx(0.1 * (0.5 - 0.05 * (1 - math.exp(-10))), rel=2e-3)


def test_a_base_accelerates_within_its_limit_and_keeps_its_top_speed() -> None:
    """A step to 2 m/s would ask 40 m/s²: the base ramps at 3 m/s² (0.3 m/s after 0.1 s, along
    the command) until the lag asks less; a command beyond the top speed gets the top speed."""
    bases = _base(tau=0.05, accel=3.0, speed=4.0)
    bases.command(0, (1.2, 1.6))
    _run(bases, 100)
    assert bases.velocity[0] == pytest.approx((0.18, 0.24), rel=1e-9)
    bases.command(0, (30.0, 40.0))
    _run(bases, 3000)
    assert math.hypot(*bases.velocity[0]) == pytest.approx(4.0, rel=1e-12)
    assert bases.velocity[0] == pytest.approx((2.4, 3.2), rel=1e-9)


def test_the_contact_force_is_the_spring_and_damper_between_base_and_load() -> None:
    bases = Bases([(1.0, 2.0)], 0.05, 3.0, 4.0, 3000.0, 20.0, DT)
    bases.velocity[0] = (0.5, 0.0)
    (force,) = bases.forces([(0.99, 2.002)], [(0.1, 0.2)])
    assert force == pytest.approx((3000 * 0.01 + 20 * 0.4, 3000 * -0.002 + 20 * -0.2))


def _pair(**agvs: Any) -> dict[str, Any]:
    """Two robots on opposite sides of a 2 m square of 4 kg, no noise, no bias."""
    return {
        "name": "pair",
        "body": {"polygon": [[-1, -1], [1, -1], [1, 1], [-1, 1]], "mass": 4.0},
        "contacts": {"points": [[-1, 0], [1, 0]]},
        "graph": {"edges": [[1, 2]]},
        "agvs": {"profile": "velocity", "sensor_bias_std": 0.0, **agvs},
    }


def test_a_static_contact_pushes_with_stiffness_times_compression() -> None:
    """Both bases drive 1 cm into the load and stop: the load, squeezed from both sides, stays;
    each contact then carries ``K δ``, δ its base's travel."""
    plant = Plant(parse_scenario(_pair(contact_stiffness=5000.0)))
    for tick in range(300):
        inwards = 0.01 if tick < 100 else 0.0
        plant.command_velocity(1, (inwards, 0.0))
        plant.command_velocity(2, (-inwards, 0.0))
        plant.advance()
    bases, truth = plant.bases, plant.truth()
    assert bases is not None
    compression = bases.position[0][0] - truth.contacts[0][0]
    assert compression == pytest.approx(0.01, rel=0.01)  # the lag's 0.5 mm less is caught up
    first, second = (m.force for m in plant.measure())
    assert first == pytest.approx((5000.0 * compression, 0.0), abs=1e-6)
    assert second == pytest.approx((-5000.0 * compression, 0.0), abs=1e-6)
    assert truth.com_position == pytest.approx((0.0, 0.0), abs=1e-9)
    for m in plant.measure():
        assert m.velocity == pytest.approx((0.0, 0.0), abs=1e-15)


def test_the_loads_momentum_changes_by_the_contacts_impulse() -> None:
    """``m Δṗ_C`` over each tick is the period times the forces' mean over it (what the
    sensors report, without bias and noise), whatever the bases do."""
    scenario = load_scenario(PAPER.with_name("paper-velocity.toml"))
    plant = Plant(dataclasses.replace(scenario, sensors=Sensors()))
    rng = np.random.default_rng(5)
    mass, period = scenario.body.mass, scenario.period_s
    moved = 0.0
    for _ in range(200):
        for robot in range(1, plant.n + 1):
            plant.command_velocity(robot, tuple(rng.normal(0.0, 0.05, 2)))
        before = plant.truth().com_velocity
        plant.advance()
        after = plant.truth().com_velocity
        forces = [
            (m.force[0] - b[0], m.force[1] - b[1]) for m, b in zip(plant.measure(), plant.biases)
        ]
        impulse = [period * sum(f[axis] for f in forces) for axis in (0, 1)]
        change = [mass * (after[axis] - before[axis]) for axis in (0, 1)]
        assert change == pytest.approx(impulse, rel=1e-9, abs=1e-12)
        moved = max(moved, math.hypot(*after))
    assert moved > 0.01  # the load was pushed about


def test_each_sensors_bias_is_drawn_from_the_seed_on_a_stream_of_its_own() -> None:
    velocity = load_scenario(PAPER.with_name("paper-velocity.toml"))
    noisy = load_scenario(PAPER.with_name("paper-noisy.toml"))
    plant = Plant(velocity)
    biases = plant.biases
    assert biases == sensor_biases(velocity.run.seed, velocity.n, 0.3)
    assert biases == Plant(velocity).biases  # reproducible
    assert len(set(biases)) == velocity.n and all(0 < math.hypot(*b) < 2.0 for b in biases)
    assert sensor_biases(velocity.run.seed + 1, velocity.n, 0.3) != biases
    assert sensor_biases(1, 3, 0.0) == ((0.0, 0.0),) * 3
    # At tick 0 nothing moves and nothing pushes: the raw force is the bias plus the noise,
    # and the noise is the force drives' own draw.
    for raw, drive, bias in zip(plant.measure(), Plant(noisy).measure(), biases):
        assert raw.velocity == drive.velocity
        assert raw.force == (drive.force[0] + bias[0], drive.force[1] + bias[1])


def test_commands_of_the_other_kind_are_refused() -> None:
    plant = Plant(parse_scenario(_pair()))
    with pytest.raises(ValueError, match="command_velocity"):
        plant.command(1, (1.0, 0.0))
    with pytest.raises(ValueError, match="finite"):
        plant.command_velocity(1, (math.nan, 0.0))
    with pytest.raises(ValueError, match=r"1\.\.2"):
        plant.command_velocity(3, (0.0, 0.0))
    with pytest.raises(ValueError, match="use command$"):
        Plant(load_scenario(PAPER)).command_velocity(1, (0.0, 0.0))
