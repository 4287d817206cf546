"""The floor's friction in the plant (``[ground]``, simulator/friction.py) against closed forms.

A sliding load decelerates at ``μ g`` (and viscous drag adds ``b v / m``); a spin about the COM
at ``μ m g c / J``; a wrench within the static limit leaves the load exactly where it is, tick
after tick, and one just beyond breaks it away; the limit itself is the set that a linear
program over the supports' forces finds; the plant reports the friction it applied; and a
plant without a ``[ground]`` table reports none.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from scipy.optimize import linprog

from agent.platform.protocol import GRAVITY, Truth
from simulator.friction import SupportFriction
from simulator.plant import Plant
from simulator.scenario import Scenario, load_scenario, parse_scenario
from tests.helpers.bad_input import paper, with_values
from tests.helpers.paths import PAPER

CASTERS = [[-1.8, -0.8], [1.8, -0.8], [1.8, 0.8], [-1.8, 0.8]]
"""Four casters near the paper plate's corners (paper-floor.toml's)."""
SUPPORTS = {"casters": {"supports": CASTERS}, "area": {}}
"""Given supports, and the default: the load's whole area."""
SQUARE = {
    "body.polygon": [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]],
    "body.com": None,
    "body.moment": None,
    "contacts.points": [[-1.0, -0.5], [-0.5, -1.0], [0.5, -1.0], [1.0, 0.5]],
}
"""A 2 m square of uniform density: a spin about its centre stays a spin."""


def on_ground(ground: dict[str, Any], values: dict[str, Any] | None = None) -> Scenario:
    """The paper's scenario (noise-free, ideal drives) with ``values`` set, on ``ground``."""
    data = with_values(paper(), values or {})
    return parse_scenario({**data, "ground": ground})


def launch(plant: Plant, velocity: tuple[float, float], omega: float = 0.0) -> None:
    """Set the load moving (the COM at ``velocity``, turning at ``omega``)."""
    plant._body.velocity = velocity
    plant._body.angular_velocity = omega


def speed(truth: Truth) -> float:
    return math.hypot(*truth.com_velocity)


# ------------------------------------------------------------------------------ sliding
@pytest.mark.parametrize("supports", SUPPORTS.values(), ids=SUPPORTS.keys())
def test_a_sliding_load_decelerates_at_mu_g(supports) -> None:
    """Every tick takes ``μ g T`` off the speed, the direction and the angle stay, and the
    truth's friction is ``−μ m g`` along the motion with no torque."""
    mu = 0.3
    scenario = on_ground({"coulomb": mu, "static": 0.35, **supports}, {"body.angle": 0.4})
    plant = Plant(scenario)
    launch(plant, (0.6, -0.8))
    period, m = scenario.period_s, scenario.body.mass
    before = plant.truth()
    for _ in range(20):  # 1 m/s takes 0.34 s to stop: stay well clear of it
        plant.advance()
        after = plant.truth()
        assert speed(before) - speed(after) == pytest.approx(mu * GRAVITY * period, rel=1e-9)
        assert after.com_velocity[0] / speed(after) == pytest.approx(0.6, rel=1e-12)
        assert after.omega == pytest.approx(0.0, abs=1e-12)
        assert after.angle == pytest.approx(0.4, abs=1e-12)
        fx, fy = after.friction_force
        assert (fx, fy) == pytest.approx((-0.6 * mu * m * GRAVITY, 0.8 * mu * m * GRAVITY))
        assert after.friction_torque == pytest.approx(0.0, abs=1e-9)
        before = after


def test_viscous_drag_decays_the_motion_exponentially() -> None:
    """With ``b`` alone, ``v(t) = v_0 e^{−b t / m}`` and ``ω(t) = ω_0 e^{−b ρ² t / J}``, at
    every tick (the drag is applied exactly over each physics step)."""
    b = 4.0
    scenario = on_ground({"viscous": b}, SQUARE)
    plant = Plant(scenario)
    launch(plant, (0.5, 0.0), 1.2)
    m, j = scenario.body.mass, scenario.body.moment
    rho2 = plant.truth().viscous_radius2
    for _ in range(50):
        plant.advance()
    truth = plant.truth()
    t = truth.time_s
    assert truth.com_velocity[0] == pytest.approx(0.5 * math.exp(-b * t / m), rel=1e-9)
    assert truth.omega == pytest.approx(1.2 * math.exp(-b * rho2 * t / j), rel=1e-9)
    # a 2 m square: (a² + a²) / 12 = 2/3, less each cell's own h²/6 (7 × 7 cells)
    assert rho2 == pytest.approx(2.0 / 3.0 - (2.0 / 7.0) ** 2 / 6.0, rel=1e-9)


def test_viscous_drag_adds_b_v_over_m_to_the_coulomb_deceleration() -> None:
    """``m v̇ = −μ m g − b v``: ``v(t) = (v_0 + μ m g / b) e^{−b t / m} − μ m g / b``, to the
    physics step's first order (the Coulomb force is held over each 1 ms step while the drag
    decays the speed within it: ``μ g b dt² / 2m`` a step, 2e-4 of the speed here)."""
    mu, b = 0.1, 6.0
    scenario = on_ground({"coulomb": mu, "viscous": b})
    plant = Plant(scenario)
    launch(plant, (0.0, 1.0))
    m = scenario.body.mass
    for _ in range(30):
        plant.advance()
    truth = plant.truth()
    limit = mu * m * GRAVITY / b
    expected = (1.0 + limit) * math.exp(-b * truth.time_s / m) - limit
    assert truth.com_velocity[1] == pytest.approx(expected, rel=1e-3)
    assert 1.0 - expected > mu * GRAVITY * truth.time_s * 1.5  # the drag's share shows


# ------------------------------------------------------------------------------ spinning
def test_a_spin_about_the_com_decelerates_at_mu_m_g_c_over_j() -> None:
    """A square turning about its centre stays a turn (its supports are symmetric), losing
    ``μ m g c T / J`` of ``ω`` every tick, with ``c`` within 1 % of the continuous figure,
    ``a (√2 + ln(1 + √2)) / 6`` for a square of side ``a``."""
    mu = 0.2
    scenario = on_ground({"coulomb": mu}, SQUARE)
    plant = Plant(scenario)
    launch(plant, (0.0, 0.0), 2.0)
    m, j, period = scenario.body.mass, scenario.body.moment, scenario.period_s
    c = plant.truth().friction_radius
    assert c == pytest.approx(2.0 * (math.sqrt(2.0) + math.asinh(1.0)) / 6.0, rel=0.01)
    before = plant.truth()
    for _ in range(20):
        plant.advance()
        after = plant.truth()
        assert before.omega - after.omega == pytest.approx(mu * m * GRAVITY * c * period / j)
        assert speed(after) == pytest.approx(0.0, abs=1e-12)
        assert after.friction_torque == pytest.approx(-mu * m * GRAVITY * c, rel=1e-9)
        before = after


def test_a_spin_on_casters_meets_the_friction_radius_torque() -> None:
    """On the paper plate's four casters the first tick of a spin loses
    ``μ m g c T / J`` to first order (the casters' forces also push the COM a little)."""
    mu = 0.02
    scenario = on_ground({"coulomb": mu, "static": 0.03, "supports": CASTERS})
    plant = Plant(scenario)
    launch(plant, (0.0, 0.0), 1.0)
    c = plant.truth().friction_radius
    loads = scenario.ground.loads(scenario.body.mass, scenario.body.com)
    assert c == loads.friction_radius
    plant.advance()
    expected = mu * scenario.body.mass * GRAVITY * c * scenario.period_s / scenario.body.moment
    assert 1.0 - plant.truth().omega == pytest.approx(expected, rel=1e-3)


def test_a_load_that_stops_stays_stopped() -> None:
    """A sliding load stops when ``μ g`` has taken its speed (within a tick) and then stays
    exactly where it stopped: no creep, no chatter."""
    mu = 0.3
    plant = Plant(on_ground({"coulomb": mu, "static": 0.35}))
    launch(plant, (0.5, 0.0))
    stop_s = 0.5 / (mu * GRAVITY)
    while plant.time_s < stop_s + 0.02:
        plant.advance()
    rest = plant.truth()
    assert rest.com_velocity == (0.0, 0.0) and rest.omega == 0.0
    travel = rest.largest_travel
    assert travel == pytest.approx(0.5**2 / (2 * mu * GRAVITY), rel=0.02)
    for _ in range(300):
        plant.advance()
        truth = plant.truth()
        assert truth.com_position == rest.com_position and truth.angle == rest.angle
    assert truth.largest_travel == travel


# ------------------------------------------------------------------------------ sticking
def _through_the_com(scenario: Scenario, force: float) -> dict[int, tuple[float, float]]:
    """Robots 2 and 3 (on the plate's lower edge) pushing along y with ``force`` in all and no
    torque about the COM."""
    cx = scenario.body.com[0]
    a, b = scenario.contacts[1][0] - cx, scenario.contacts[2][0] - cx
    f3 = -a * force / (b - a)
    return {2: (0.0, force - f3), 3: (0.0, f3)}


def _about_the_com(scenario: Scenario, torque: float) -> dict[int, tuple[float, float]]:
    """Robots 2 and 3 pushing along y in opposite senses: a pure ``torque``."""
    f = torque / (scenario.contacts[2][0] - scenario.contacts[1][0])
    return {2: (0.0, -f), 3: (0.0, f)}


def _held(scenario: Scenario, commands: dict[int, tuple[float, float]], ticks: int) -> Truth:
    plant = Plant(scenario)
    for _ in range(ticks):
        for robot, force in commands.items():
            plant.command(robot, force)
        plant.advance()
    return plant.truth()


WRENCHES = {"force": _through_the_com, "torque": _about_the_com}


@pytest.mark.parametrize("wrench", WRENCHES.values(), ids=WRENCHES.keys())
@pytest.mark.parametrize("supports", SUPPORTS.values(), ids=SUPPORTS.keys())
def test_a_wrench_within_the_static_limit_leaves_the_load_exactly_still(wrench, supports) -> None:
    """99 % of ``μ_s m g`` through the COM, or of ``μ_s m g c`` about it, for 5 s: the load
    never moves at all, and the floor's force and torque are the robots' reversed. 101 %
    breaks it away."""
    mu_s = 0.35
    scenario = on_ground({"coulomb": 0.3, "static": mu_s, **supports})
    weight = scenario.body.mass * GRAVITY
    c = scenario.ground.loads(scenario.body.mass, scenario.body.com).friction_radius
    limit = mu_s * weight * (1.0 if wrench is _through_the_com else c)
    still = _held(scenario, wrench(scenario, 0.99 * limit), 500)
    assert (still.largest_travel, still.largest_speed, still.largest_omega) == (0.0, 0.0, 0.0)
    if wrench is _through_the_com:
        assert still.friction_force == pytest.approx((0.0, -0.99 * limit), abs=1e-9)
        assert still.friction_torque == pytest.approx(0.0, abs=1e-9)
    else:
        assert still.friction_force == pytest.approx((0.0, 0.0), abs=1e-9)
        assert still.friction_torque == pytest.approx(-0.99 * limit, rel=1e-9)
    moving = _held(scenario, wrench(scenario, 1.01 * limit), 100)
    assert moving.largest_speed > 0.1 or moving.largest_omega > 0.1


def test_a_held_load_stays_still_through_the_drives_lag() -> None:
    """With drives that lag (the robots' wrench changing at every physics step) a wrench
    that stays within the limit still moves nothing."""
    scenario = on_ground(
        {"coulomb": 0.02, "static": 0.03, "supports": CASTERS},
        {"actuators.time_constant_s": 0.05, "actuators.gain_error_std": 0.02},
    )
    limit = 0.03 * scenario.body.mass * GRAVITY
    still = _held(scenario, _through_the_com(scenario, 0.9 * limit), 300)
    assert (still.largest_travel, still.largest_speed, still.largest_omega) == (0.0, 0.0, 0.0)


def _limit_scale(
    arms: np.ndarray, limits: np.ndarray, direction: np.ndarray, sides: int, inscribed: bool
) -> float:
    """The largest ``λ`` with ``λ direction`` in the limit set, each support's disc replaced by
    a regular ``sides``-gon inside it (``inscribed``) or around it: a linear program over the
    supports' forces ``q_k``."""
    count = len(arms)
    angles = 2 * np.pi * np.arange(sides) / sides
    radius = math.cos(math.pi / sides) if inscribed else 1.0
    rows = np.zeros((count * sides, 2 * count + 1))
    for k in range(count):
        rows[k * sides : (k + 1) * sides, 2 * k] = np.cos(angles)
        rows[k * sides : (k + 1) * sides, 2 * k + 1] = np.sin(angles)
    bounds_ = np.repeat(radius * limits, sides)
    equal = np.zeros((3, 2 * count + 1))
    equal[0, 0:-1:2] = 1.0
    equal[1, 1:-1:2] = 1.0
    equal[2, 0:-1:2], equal[2, 1:-1:2] = -arms[:, 1], arms[:, 0]
    equal[:, -1] = -direction
    cost = np.zeros(2 * count + 1)
    cost[-1] = -1.0
    free = [(None, None)] * (2 * count) + [(0.0, None)]
    found = linprog(cost, A_ub=rows, b_ub=bounds_, A_eq=equal, b_eq=np.zeros(3), bounds=free)
    assert found.status == 0
    return float(found.x[-1])


@pytest.mark.parametrize("supports", SUPPORTS.values(), ids=SUPPORTS.keys())
def test_the_static_limit_is_the_supports_limit_set(supports) -> None:
    """For wrenches of 12 random directions (forces, torques and both), the supports hold one
    just within the set of ``(Σ q_k, Σ r_k × q_k)``, ``‖q_k‖ ≤ μ_s N_k``, and not one just
    beyond it (the set bracketed by linear programs over 64-gons inside and around the
    supports' discs)."""
    scenario = on_ground({"coulomb": 0.3, "static": 0.35, **supports})
    ground, com = scenario.ground, scenario.body.com
    normal = ground.loads(scenario.body.mass, com).normal
    arms = np.array(ground.supports) - com
    limits = 0.35 * np.array(normal)
    friction = SupportFriction(arms, limits)
    rng = np.random.default_rng(7)
    for _ in range(12):
        direction = rng.normal(size=3) * (1.0, 1.0, friction.torque_limit / friction.force_limit)
        inner = _limit_scale(arms, limits, direction, 64, inscribed=True)
        outer = _limit_scale(arms, limits, direction, 64, inscribed=False)
        assert friction.holds(*(0.995 * inner * direction))
        assert not friction.holds(*(1.005 * outer * direction))


# ------------------------------------------------------------------------------ the truth
def test_the_truth_carries_the_ground() -> None:
    scenario = load_scenario(PAPER.parent / "paper-floor.toml")
    truth = Plant(scenario).truth()
    loads = scenario.ground.loads(scenario.body.mass, scenario.body.com)
    assert (truth.ground_coulomb, truth.ground_static, truth.ground_viscous) == (0.02, 0.03, 0.0)
    assert truth.friction_radius == loads.friction_radius
    assert truth.viscous_radius2 == loads.viscous_radius2
    assert truth.friction_force == (0.0, 0.0) and truth.friction_torque == 0.0  # tick 0


def test_a_frictionless_plant_reports_no_friction() -> None:
    plant = Plant(load_scenario(PAPER))
    plant.command(1, (3.0, 1.0))
    for _ in range(10):
        plant.advance()
    truth = plant.truth()
    assert speed(truth) > 0.0
    ground = (truth.ground_coulomb, truth.ground_static, truth.ground_viscous)
    assert ground == (0.0, 0.0, 0.0)
    assert (truth.friction_radius, truth.viscous_radius2, truth.friction_torque) == (0, 0, 0)
    assert truth.friction_force == (0.0, 0.0)


def test_a_load_change_moves_the_normal_loads() -> None:
    """A change of mass and COM (``[[events]]``) gives the supports the loads of the new
    load's statics, and the truth the new friction radius."""
    data = with_values(paper(), {"run.max_time_s": 5.0})
    data["ground"] = {"coulomb": 0.02, "static": 0.03, "supports": CASTERS}
    data["events"] = [{"at_s": 0.1, "mass": 6.0, "com": [0.5, 0.2]}]
    scenario = parse_scenario(data)
    plant = Plant(scenario)
    before = plant.truth().friction_radius
    while plant.time_s < 0.2:
        plant.advance()
    after = plant.truth()
    loads = scenario.ground.loads(6.0, (0.5, 0.2))
    assert after.friction_radius == loads.friction_radius != before
    assert after.viscous_radius2 == loads.viscous_radius2
    assert sum(loads.normal) == pytest.approx(6.0 * GRAVITY)


def test_a_support_at_rest_in_a_turn_gets_a_finite_force() -> None:
    """The load turning about one support: that support's ``‖u_k‖²``, summed from its four
    terms, rounds below 0 here (its square root was NaN, and so was the wrench the plant then
    applied: a generated load that the kick could have moved was found held)."""
    arm = (-0.9433050469559874, 0.6715302078397394)
    w = -0.40339759256967955
    supports = SupportFriction([arm, (0.5, 0.5), (-0.5, 0.2)], [1.0, 1.0, 1.0], creep=1e-6)
    wrench = supports.coulomb(w * arm[1], -w * arm[0], w)
    assert all(math.isfinite(c) for c in wrench)
    assert supports.coulomb(0.0, 0.0, 0.0) == (0.0, 0.0, 0.0)
