"""The pymunk plant against closed forms: the rigid-body physics the estimators rely on.

Conventions as in the paper notes: ``Q = [[0, -1], [1, 0]]``, ``v⊥ = Q v``,
``τ_i = (p_Ci − p_C)⊥ᵀ f_i``, ``z_i = p_Ci − p_G``, ``z_C = p_G − p_C``.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from agent.platform.geometry import Vec2
from agent.platform.protocol import Truth
from simulator.plant import Plant
from simulator.scenario import Actuators, Scenario, Sensors, load_scenario
from tests.helpers.paths import PAPER


def perp(v: Vec2) -> Vec2:
    """``Q v``."""
    return (-v[1], v[0])


def dot(a: Vec2, b: Vec2) -> float:
    return a[0] * b[0] + a[1] * b[1]


def sub(a: Vec2, b: Vec2) -> Vec2:
    return (a[0] - b[0], a[1] - b[1])


@pytest.fixture(scope="module")
def paper() -> Scenario:
    return load_scenario(PAPER)


@pytest.fixture
def moving(paper: Scenario) -> Scenario:
    """The paper load, displaced and turned, so that no frame coincides with ``W``."""
    body = replace(paper.body, position=(1.5, -0.7), angle=0.4)
    return replace(paper, body=body, sensors=Sensors(rate_hz=paper.sensors.rate_hz))


def ticks_per_second(scenario: Scenario) -> int:
    return round(1.0 / scenario.period_s)


# --- 6. mass and moment -------------------------------------------------------------------------


def test_mass_and_moment_are_the_scenarios_exactly(paper: Scenario) -> None:
    plant = Plant(paper)
    truth = plant.truth()
    assert truth.mass == paper.body.mass
    assert truth.moment == paper.body.moment
    assert plant._body.mass == paper.body.mass  # the pymunk body itself
    assert plant._body.moment == paper.body.moment
    assert list(plant._space.shapes) == []  # nothing that could override them
    plant.command(1, (3.0, 1.0))
    for _ in range(10):
        plant.advance()
    assert plant.truth().mass == paper.body.mass
    assert plant.truth().moment == paper.body.moment


def test_initial_pose_places_load_frame(moving: Scenario) -> None:
    """The load frame's origin sits at ``body.position``, turned by ``body.angle``."""
    plant = Plant(moving)
    truth = plant.truth()
    (x0, y0), a = moving.body.position, moving.body.angle
    c, s = math.cos(a), math.sin(a)

    def world(p: Vec2) -> Vec2:
        return (x0 + c * p[0] - s * p[1], y0 + s * p[0] + c * p[1])

    assert truth.tick == 0 and truth.time_s == 0.0
    assert truth.angle == pytest.approx(a, abs=1e-15)
    assert truth.com_position == pytest.approx(world(moving.body.com), abs=1e-12)
    for got, local in zip(truth.contacts, moving.contacts, strict=True):
        assert got == pytest.approx(world(local), abs=1e-12)
    assert truth.com_velocity == (0.0, 0.0) and truth.omega == 0.0


# --- 1. rigid-body kinematics -------------------------------------------------------------------


def check_rigid(truth: Truth) -> None:
    pc, vc, w = truth.com_position, truth.com_velocity, truth.omega
    for p, v in zip(truth.contacts, truth.contact_velocities, strict=True):
        r = perp(sub(p, pc))
        assert v == pytest.approx((vc[0] + w * r[0], vc[1] + w * r[1]), abs=1e-12, rel=0)
    n = len(truth.contacts)
    for i in range(n):
        for j in range(i + 1, n):
            z = sub(truth.contacts[i], truth.contacts[j])
            dz = sub(truth.contact_velocities[i], truth.contact_velocities[j])
            assert abs(dot(dz, z)) <= 1e-12 * (1.0 + math.hypot(*dz) * math.hypot(*z))
            # ż_ij = ω z_ij⊥
            assert dz == pytest.approx((w * -z[1], w * z[0]), abs=1e-12, rel=0)


def test_contact_velocities_are_rigid(moving: Scenario) -> None:
    plant = Plant(moving)
    plant.command(1, (1.0, 4.0))  # one robot: the load both translates and spins
    for _ in range(60):
        plant.advance()
    plant.command(3, (-1.0, 2.0))
    for _ in range(40):
        plant.advance()
        truth = plant.truth()
        check_rigid(truth)
        assert abs(truth.omega) > 0.1 and math.hypot(*truth.com_velocity) > 0.1
        # zero noise: the measurements are the truth exactly
        for m, v in zip(plant.measure(), truth.contact_velocities, strict=True):
            assert m.velocity == v
        assert truth.contact_to_com == tuple(sub(truth.com_position, p) for p in truth.contacts)


def test_truth_offsets(moving: Scenario) -> None:
    plant = Plant(moving)
    plant.command(2, (1.0, -2.0))
    for _ in range(30):
        plant.advance()
    truth = plant.truth()
    g = truth.centroid
    zs = truth.centroid_offsets
    assert sum(z[0] for z in zs) == pytest.approx(0.0, abs=1e-12)
    assert sum(z[1] for z in zs) == pytest.approx(0.0, abs=1e-12)
    for z, p, r in zip(zs, truth.contacts, truth.contact_to_com, strict=True):
        assert z == pytest.approx(sub(p, g), abs=1e-15)
        # p_C − p_Ci = −(z_i + z_C)
        zc = truth.com_offset
        assert r == pytest.approx((-(z[0] + zc[0]), -(z[1] + zc[1])), abs=1e-12)
    assert truth.com_offset == pytest.approx(sub(g, truth.com_position), abs=1e-15)


# --- 2. pure torque -----------------------------------------------------------------------------


def test_pure_torque_spins_up_at_constant_rate(paper: Scenario) -> None:
    plant = Plant(paper)
    start = plant.truth()
    k = 1.0
    w = sum(dot(z, z) for z in start.centroid_offsets)
    alpha = k * w / paper.body.moment
    ticks = ticks_per_second(paper)
    for tick in range(ticks):
        for i, z in enumerate(plant.truth().centroid_offsets, start=1):
            plant.command(i, (k * -z[1], k * z[0]))  # k z_i⊥, recomputed as the load turns
        plant.advance()
        if tick == ticks // 2 - 1:
            half = plant.truth()
            assert half.omega == pytest.approx(alpha * half.time_s, rel=1e-3)
    end = plant.truth()
    assert end.time_s == pytest.approx(1.0)
    assert math.hypot(*end.com_velocity) < 1e-9
    assert end.com_position == pytest.approx(start.com_position, abs=1e-9)
    assert end.omega == pytest.approx(alpha * end.time_s, rel=1e-3)
    assert end.omega > 0.1  # the test is not vacuous
    assert end.angle - start.angle == pytest.approx(0.5 * alpha * end.time_s**2, rel=2e-2)


# --- 3. common force ----------------------------------------------------------------------------


def test_common_force_accelerates_com_at_n_f_over_m(paper: Scenario) -> None:
    # shift the COM so that z_C ≠ 0 whatever the paper's contacts are
    com = (paper.body.com[0] + 0.3, paper.body.com[1] - 0.2)
    scenario = replace(paper, body=replace(paper.body, com=com))
    plant = Plant(scenario)
    start = plant.truth()
    zc = start.com_offset
    assert math.hypot(*zc) > 0.1
    f = (0.8, -0.5)
    n, m, J = scenario.n, scenario.body.mass, scenario.body.moment
    for i in range(1, n + 1):
        plant.command(i, f)

    plant.advance()  # ω̇ = (n/J) z_C⊥ᵀ f at the start
    omega_dot = plant.truth().omega / plant.truth().time_s
    assert omega_dot == pytest.approx(n / J * dot(perp(zc), f), rel=1e-3)

    ticks = ticks_per_second(scenario)
    for _ in range(ticks - 1):
        plant.advance()
    end = plant.truth()
    a = (n * f[0] / m, n * f[1] / m)
    assert end.com_velocity == pytest.approx((a[0] * end.time_s, a[1] * end.time_s), rel=1e-9)
    # The pose at the same instant as the velocity (simulator.integrator): x = a t² / 2, where
    # Chipmunk's own step leaves it half a step behind, a dt² N (N − 1) / 2 after N steps of dt
    shift = 0.5 * end.time_s**2
    moved = sub(end.com_position, start.com_position)
    assert moved == pytest.approx((a[0] * shift, a[1] * shift), rel=1e-9)
    assert abs(end.omega) > 0.0  # the load swings like a pendulum meanwhile


# --- 4. noise -----------------------------------------------------------------------------------


def noisy_errors(scenario: Scenario, samples_per_axis: int) -> tuple[np.ndarray, np.ndarray]:
    plant = Plant(scenario)
    f = (0.5, 0.25)
    plant.command(1, f)
    dv: list[Vec2] = []
    df: list[Vec2] = []
    while len(dv) < samples_per_axis:
        plant.advance()
        truth = plant.truth()
        for meas, v in zip(plant.measure(), truth.contact_velocities, strict=True):
            dv.append(sub(meas.velocity, v))
            df.append(sub(meas.force, f if meas.robot == 1 else (0.0, 0.0)))
    return np.array(dv), np.array(df)


def test_velocity_and_force_noise(moving: Scenario) -> None:
    sensors = Sensors(rate_hz=moving.sensors.rate_hz, velocity_noise_std=0.01, force_noise_std=0.2)
    scenario = replace(moving, sensors=sensors)
    dv, df = noisy_errors(scenario, 2000)
    for errors, std in ((dv, 0.01), (df, 0.2)):
        assert errors.shape[0] >= 2000
        for axis in (0, 1):
            assert errors[:, axis].std() == pytest.approx(std, rel=0.1)
            assert abs(errors[:, axis].mean()) < 4 * std / math.sqrt(errors.shape[0])

    again_v, again_f = noisy_errors(scenario, 2000)
    assert np.array_equal(dv, again_v) and np.array_equal(df, again_f)
    other = replace(scenario, run=replace(scenario.run, seed=scenario.run.seed + 1))
    other_v, _ = noisy_errors(other, 2000)
    assert not np.array_equal(dv, other_v)


def test_zero_noise_is_exact(moving: Scenario) -> None:
    dv, df = noisy_errors(moving, 200)
    assert not dv.any() and not df.any()


# --- 5. commands --------------------------------------------------------------------------------


def test_command_rejects_bad_robot_and_force(paper: Scenario) -> None:
    plant = Plant(paper)
    n = paper.n
    for robot in (0, n + 1, -1):
        with pytest.raises(ValueError):
            plant.command(robot, (1.0, 0.0))
    for force in ((math.nan, 0.0), (0.0, math.inf), (1.0,), (1.0, 2.0, 3.0)):
        with pytest.raises(ValueError):
            plant.command(1, force)
    plant.command(n, (1.0, 2.0))  # the last robot is valid


def test_measured_force_is_the_one_applied_last_period(paper: Scenario) -> None:
    plant = Plant(paper)
    n = paper.n
    meas = plant.measure()
    assert [m.robot for m in meas] == list(range(1, n + 1))
    assert all(m.force == (0.0, 0.0) and m.tick == 0 and m.time_s == 0.0 for m in meas)

    plant.command(2, (1.0, -2.0))
    assert plant.measure()[1].force == (0.0, 0.0)  # not applied yet
    plant.advance()
    meas = plant.measure()
    assert meas[1].force == (1.0, -2.0) and meas[1].tick == 1
    assert meas[1].time_s == pytest.approx(paper.period_s)
    assert all(m.force == (0.0, 0.0) for i, m in enumerate(meas) if i != 1)

    plant.command(2, (0.0, 0.0))
    assert plant.measure()[1].force == (1.0, -2.0)  # still the last period's force
    plant.advance()
    assert all(m.force == (0.0, 0.0) for m in plant.measure())
    # with no force, the load keeps its momentum
    before = plant.truth()
    plant.advance()
    after = plant.truth()
    assert after.com_velocity == pytest.approx(before.com_velocity, abs=1e-15)
    assert after.omega == pytest.approx(before.omega, abs=1e-15)


# --- 7. actuators -------------------------------------------------------------------------------


def with_actuators(scenario: Scenario, **settings) -> Scenario:
    return replace(scenario, actuators=Actuators(**settings))


def test_a_lagging_drive_follows_its_command_exponentially(paper: Scenario) -> None:
    tau = 0.02
    plant = Plant(with_actuators(paper, time_constant_s=tau))
    u = (4.0, -2.0)
    plant.command(1, u)
    period, substeps = paper.period_s, paper.substeps
    dt = period / substeps
    for k in range(1, 11):
        before = plant.truth()
        plant.advance()
        after = plant.truth()
        measured = plant.measure()[0].force
        # The drive's force at substep j of the run is u (1 − e^{−j Δt/τ}); the measurement
        # is its mean over the tick's substeps.
        steps = range((k - 1) * substeps + 1, k * substeps + 1)
        share = sum(1.0 - math.exp(-j * dt / tau) for j in steps) / substeps
        assert measured == pytest.approx((u[0] * share, u[1] * share), rel=1e-12)
        # ... and what the load felt: its momentum grew by the measured force times the tick.
        gained = sub(after.com_velocity, before.com_velocity)
        impulse = (measured[0] * period / paper.body.mass, measured[1] * period / paper.body.mass)
        assert gained == pytest.approx(impulse, rel=1e-9)
    assert measured[0] < u[0]  # after 5 time constants, still short of the command
    assert measured[0] > 0.99 * u[0]


def test_gains_scale_what_a_robot_applies(paper: Scenario) -> None:
    gains = (0.9, 1.1, 1.0, 1.25)
    plant = Plant(with_actuators(paper, gains=gains))
    assert plant.gains == gains
    for robot in range(1, 5):
        plant.command(robot, (1.0, 2.0))
    plant.advance()
    for meas, g in zip(plant.measure(), gains, strict=True):
        assert meas.force == pytest.approx((g, 2 * g), rel=1e-12)
    # Drawn from the seed when not given: within [0.5, 1.5], the same for the same seed.
    drawn = Plant(with_actuators(paper, gain_error_std=0.02)).gains
    assert drawn == Plant(with_actuators(paper, gain_error_std=0.02)).gains
    assert len(set(drawn)) == 4 and all(0.9 < g < 1.1 for g in drawn)


def test_actuator_noise_is_on_the_applied_force_and_leaves_the_sensor_noise_alone(
    moving: Scenario,
) -> None:
    sensors = Sensors(rate_hz=moving.sensors.rate_hz, velocity_noise_std=0.01)
    scenario = replace(moving, sensors=sensors)
    noisy = with_actuators(scenario, force_noise_std=0.3)
    plants = Plant(scenario), Plant(noisy)
    forces, velocity_noise = [], ([], [])
    for _ in range(2000):
        for plant in plants:
            plant.command(1, (0.5, 0.25))
            plant.advance()
        for k, plant in enumerate(plants):
            measured = plant.measure()[0]  # once a tick: each call draws the sensors' noise
            velocity_noise[k].append(sub(measured.velocity, plant.truth().contact_velocities[0]))
        forces.append(sub(measured.force, (0.5, 0.25)))
    errors = np.array(forces)
    for axis in (0, 1):
        assert errors[:, axis].std() == pytest.approx(0.3, rel=0.1)
    # The sensors' noise is drawn from its own stream: the same with the drives noisy or not.
    assert np.allclose(velocity_noise[0], velocity_noise[1], rtol=0, atol=1e-12)


def test_ideal_actuators_are_the_papers(paper: Scenario) -> None:
    assert paper.actuators.ideal and Actuators(gains=(1.0,) * 4).ideal
    assert not Actuators(time_constant_s=0.01).ideal
    plant = Plant(paper)
    assert plant.gains == (1.0,) * paper.n
