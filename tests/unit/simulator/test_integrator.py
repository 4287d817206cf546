"""The plant's step against the exact motion under a held force and torque
(:mod:`simulator.integrator`): poses and velocities of one motion at one instant."""

from __future__ import annotations

import pymunk
import pytest

from simulator.integrator import PoseCorrection

DT = 1e-3
STEPS = 250
COG = (0.3, -0.1)
V0, W0 = (0.4, -0.2), 0.7
FORCE, TORQUE = (1.5, -0.5), 0.8
MASS, MOMENT = 2.0, 0.5


def _run(correct: bool) -> tuple[pymunk.Body, tuple[float, float]]:
    """The body after :data:`STEPS` steps, and where its COM started."""
    space = pymunk.Space()
    body = pymunk.Body(MASS, MOMENT)
    body.center_of_gravity = COG
    body.position = (0.0, 0.0)  # (places the origin: the COM at COG, as the plant does)
    space.add(body)
    start = body.local_to_world(COG)
    body.velocity, body.angular_velocity = V0, W0
    pose = PoseCorrection(body, DT)
    for k in range(STEPS):
        body.force, body.torque = FORCE, TORQUE
        pose.add(*FORCE, TORQUE)
        space.step(DT)
        if correct and k % 10 == 9:  # at every tick of 10 steps, as the plant does
            pose.apply()
    return body, (start.x, start.y)


def test_a_held_wrench_gives_the_exact_pose_and_velocity_at_every_tick() -> None:
    t = STEPS * DT
    a = (FORCE[0] / MASS, FORCE[1] / MASS)
    alpha = TORQUE / MOMENT
    body, start = _run(correct=True)
    com = body.local_to_world(COG)
    assert (com.x, com.y) == pytest.approx(
        tuple(s + v * t + 0.5 * x * t * t for s, v, x in zip(start, V0, a)), abs=1e-12
    )
    assert body.angle == pytest.approx(W0 * t + 0.5 * alpha * t * t, abs=1e-12)
    assert tuple(body.velocity) == pytest.approx((V0[0] + a[0] * t, V0[1] + a[1] * t), abs=1e-12)
    assert body.angular_velocity == pytest.approx(W0 + alpha * t, abs=1e-12)


def test_chipmunk_alone_leaves_the_pose_half_a_step_behind() -> None:
    """Without the correction the angle lacks ``Σ (h²/2) α`` = ``(h/2) α t``: what a contact's
    velocity read with the body's angle would turn ahead of the pose."""
    t = STEPS * DT
    alpha = TORQUE / MOMENT
    body, _ = _run(correct=False)
    exact = W0 * t + 0.5 * alpha * t * t
    assert exact - body.angle == pytest.approx(0.5 * DT * alpha * t, rel=1e-9)
