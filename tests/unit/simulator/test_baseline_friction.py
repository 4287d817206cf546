"""The centralized reference's friction (simulator/baseline.py): on a load that spins on a
floor with the robots' friction model (a torque ``−τ_c sgn ω``, a drag ``−κ ṗ_C / |ω|``) the fit
finds ``τ_c`` and ``κ`` with ``m``, ``J`` and the arms, each within its own uncertainty; on a
frictionless floor it finds no friction; where the load slides without turning, it finds the
Coulomb friction ``μ m g`` that the spin model cannot describe there."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from simulator.baseline import GRAVITY, fit, regimes, truth_friction

MASS, MOMENT = 5.0, 12.3795
ARMS = np.array([[-2.0, 0.54], [-1.0, -0.86], [1.2, -0.86], [2.0, 0.74]])
"""``p_Ci − p_C`` in the load frame (the paper's load's contacts)."""
PERIOD, SUBSTEPS = 0.01, 10
FRICTION_TORQUE, SPIN_DRAG = 1.2, 0.4
"""N m and N/m: a 5 kg load on supports 1.2 m from its COM at μ = 2 %."""
COULOMB_LIMIT = math.sqrt(2.0 * FRICTION_TORQUE * SPIN_DRAG)
"""N: ``μ m g``, the most the floor's friction can pull (supports at one radius ``c``:
``τ_c = μ m g c`` and ``κ = μ m g / (2c)``)."""


def spinning_run(
    seconds: float,
    friction_torque: float = FRICTION_TORQUE,
    spin_drag: float = SPIN_DRAG,
    velocity_noise: float = 0.0,
    force_noise: float = 0.0,
    slide_s: float = 0.0,
    seed: int = 0,
):
    """Velocities and forces (``(K + 1, n, 2)``, as :func:`~simulator.baseline.fit` takes
    them) of a rigid body on a floor with the friction model, integrated by RK4 with the
    forces held over each period: the team turns it at a wobbling rate about 1 rad/s and
    pushes it by a common force reversed every 2 s (a second, weaker one across every 3 s).
    For the first ``slide_s`` it does not turn: the push slides it, against the Coulomb
    friction ``μ m g`` (and the drag is capped at it wherever ``κ ‖ṗ_C‖ / |ω|`` would exceed
    it, as on a real floor). Noise is white, per axis, on what the robots measure."""
    rng = np.random.default_rng(seed)
    n = len(ARMS)
    centred = ARMS - ARMS.mean(axis=0)
    spread = float(np.sum(centred**2))
    limit = math.sqrt(2.0 * friction_torque * spin_drag)

    def friction(u: np.ndarray, omega: float) -> tuple[np.ndarray, float]:
        speed = float(np.hypot(*u))
        if omega <= 0.0:
            drag = limit / speed if speed > 0.0 else 0.0
            return -drag * u, 0.0
        drag = min(spin_drag / omega, limit / speed if speed > 0.0 else math.inf)
        return -drag * u, -friction_torque

    def derivative(state: np.ndarray, applied: np.ndarray) -> np.ndarray:
        """The state's rate with the robots' world-frame forces ``applied`` held."""
        u, theta, omega = state[2:4], state[4], state[5]
        c, s = math.cos(theta), math.sin(theta)
        arms = ARMS @ np.array([[c, s], [-s, c]])
        torque = float(np.sum(arms[:, 0] * applied[:, 1] - arms[:, 1] * applied[:, 0]))
        drag, resisting = friction(u, omega)
        accel = (applied.sum(axis=0) + drag) / MASS
        if omega <= 0.0 and torque <= friction_torque:  # not turning, and cannot break away
            return np.concatenate((u, accel, (0.0, 0.0)))
        return np.concatenate((u, accel, (omega, (torque + resisting) / MOMENT)))

    state = np.zeros(6)  # p_C, u, θ, ω
    velocities, forces = [], []
    applied = np.zeros((n, 2))
    for k in range(round(seconds / PERIOD) + 1):
        u, theta, omega = state[2:4], state[4], state[5]
        c, s = math.cos(theta), math.sin(theta)
        arms = ARMS @ np.array([[c, s], [-s, c]])  # R(θ) r_i, one per row
        perp = np.stack((-arms[:, 1], arms[:, 0]), axis=1)
        velocities.append(u + omega * perp + rng.normal(0.0, velocity_noise, (n, 2)))
        forces.append(applied + rng.normal(0.0, force_noise, (n, 2)))
        t = k * PERIOD
        push = np.array(
            (2.0 * math.copysign(1.0, math.sin(math.pi * t / 2.0)), math.sin(2 * math.pi * t / 3))
        )
        if t < slide_s:
            torque = 0.0
        else:
            target = 1.0 + 0.3 * math.sin(1.3 * t)
            torque = friction_torque + 8.0 * (target - omega) + 2.0 * math.sin(2.1 * t)
        # f_i = F/n + λ Q R(θ)(r_i − r̄): the common push F and the torque, Σ_i f_i = F
        lever = float(perp.mean(axis=0) @ push)
        spin = np.stack((-centred[:, 1], centred[:, 0]), axis=1) @ np.array([[c, s], [-s, c]])
        applied = push / n + ((torque - lever) / spread) * spin
        h = PERIOD / SUBSTEPS
        for _ in range(SUBSTEPS):
            k1 = derivative(state, applied)
            k2 = derivative(state + 0.5 * h * k1, applied)
            k3 = derivative(state + 0.5 * h * k2, applied)
            k4 = derivative(state + h * k3, applied)
            state = state + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return np.array(velocities), np.array(forces)


def offsets_at(angle: float) -> np.ndarray:
    """``p_C − p_Ci`` in the world frame with the load turned by ``angle``."""
    c, s = math.cos(angle), math.sin(angle)
    return -(ARMS @ np.array([[c, s], [-s, c]]))


def test_noise_free_the_fit_is_the_floor_and_the_load() -> None:
    v, f = spinning_run(12.0)
    result = fit(v, f, PERIOD, 0.0, 0.0)
    assert result.converged and result.turning_intervals == result.ticks - 1
    assert result.sliding_intervals == 0 and result.sliding_friction is None
    assert result.friction_torque == pytest.approx(FRICTION_TORQUE, rel=2e-3)
    assert result.spin_drag == pytest.approx(SPIN_DRAG, rel=2e-3)
    assert result.mass == pytest.approx(MASS, rel=1e-4)
    assert result.moment == pytest.approx(MOMENT, rel=1e-3)
    for fitted, true in zip(result.contact_to_com, offsets_at(result.angle), strict=True):
        assert math.dist(fitted, true) < 1e-3


def test_with_noise_the_friction_is_within_the_fits_own_uncertainty() -> None:
    for seed in range(3):
        v, f = spinning_run(12.0, velocity_noise=0.01, force_noise=0.5, seed=seed)
        result = fit(v, f, PERIOD, 0.01, 0.5)
        assert result.converged
        assert 0 < result.friction_torque_std < 0.1 * FRICTION_TORQUE
        assert 0 < result.spin_drag_std < 0.3 * SPIN_DRAG
        for value, std, true in (
            (result.friction_torque, result.friction_torque_std, FRICTION_TORQUE),
            (result.spin_drag, result.spin_drag_std, SPIN_DRAG),
            (result.mass, result.mass_std, MASS),
            (result.moment, result.moment_std, MOMENT),
        ):
            assert abs(value - true) < 4 * std, (seed, value, std, true)
        # without the friction model, the same data give a load that is not this one
        rigid = fit(v, f, PERIOD, 0.01, 0.5, friction=False)
        assert rigid.friction_torque is None and rigid.spin_drag_std is None
        assert abs(rigid.moment - MOMENT) > 4 * rigid.moment_std


def test_on_a_frictionless_floor_it_finds_no_friction() -> None:
    v, f = spinning_run(12.0, 0.0, 0.0, velocity_noise=0.01, force_noise=0.5)
    result = fit(v, f, PERIOD, 0.01, 0.5)
    rigid = fit(v, f, PERIOD, 0.01, 0.5, friction=False)
    assert abs(result.friction_torque) < 4 * result.friction_torque_std < 0.4
    assert abs(result.spin_drag) < 4 * result.spin_drag_std < 0.4
    # and the load's other constants are as good as without friction in the model
    for found in (result, rigid):
        assert abs(found.mass - MASS) < 4 * found.mass_std
        assert abs(found.moment - MOMENT) < 4 * found.moment_std
    assert result.mass_std < 1.2 * rigid.mass_std and result.moment_std < 1.2 * rigid.moment_std


def test_where_the_load_slides_without_turning_it_meets_coulomb_friction() -> None:
    """For its first 3 s the load does not turn: the push slides it against ``μ m g``, which
    the spin model cannot describe. Those intervals' translation is fitted with ``F_s``, and
    the rest finds the floor; fitted on all of them with the spin model, the drag would not
    be the floor's, and without them the mass would lose the push."""
    v, f = spinning_run(16.0, velocity_noise=0.01, force_noise=0.5, slide_s=3.0)
    result = fit(v, f, PERIOD, 0.01, 0.5)
    assert result.converged
    assert 280 <= result.sliding_intervals <= result.ticks - 1 - result.turning_intervals
    for value, std, true in (
        (result.sliding_friction, result.sliding_friction_std, COULOMB_LIMIT),
        (result.friction_torque, result.friction_torque_std, FRICTION_TORQUE),
        (result.spin_drag, result.spin_drag_std, SPIN_DRAG),
        (result.mass, result.mass_std, MASS),
    ):
        assert abs(value - true) < 4 * std, (value, std, true)
    assert result.sliding_friction_std < 0.1 * COULOMB_LIMIT


def test_the_regimes_are_where_each_model_holds() -> None:
    omega = np.array([0.0, 0.005, -0.05, 0.5, -0.5, 0.5, 0.0, 0.0])
    speed = np.array([0.0, 0.0, 0.01, 0.5, 1.9, 2.1, 0.005, 0.5])
    turning, sliding = regimes(omega, speed, epsilon=0.002, speed_epsilon=0.005, radius=2.0)
    # stuck; below 3ε; turning; turning; within 2ρ|ω|; beyond it; below 3ε_u; beyond it
    assert turning.tolist() == [False, False, True, True, True, False, False, False]
    assert sliding.tolist() == [False, False, False, False, False, True, False, True]


def test_a_load_that_never_turns_is_refused() -> None:
    v, f = spinning_run(3.0, velocity_noise=0.01, force_noise=0.5, slide_s=3.0)
    with pytest.raises(ValueError, match="never turned"):
        fit(v, f, PERIOD, 0.01, 0.5)


def test_the_truths_friction_is_what_the_fit_is_compared_with() -> None:
    none = {"friction_torque": 0.0, "spin_drag": 0.0, "sliding_friction": 0.0}
    assert truth_friction(SimpleNamespace(mass=5.0)) == none  # before the floor: frictionless
    assert truth_friction(SimpleNamespace(mass=5.0, ground_coulomb=0.0)) == none
    weight = 0.02 * GRAVITY * 5.0
    floor = SimpleNamespace(mass=5.0, ground_coulomb=0.02, friction_radius=1.2, friction_torque=-3)
    assert truth_friction(floor) == {  # (its friction_torque: the floor's at that tick)
        "friction_torque": pytest.approx(weight * 1.2),
        "spin_drag": None,
        "sliding_friction": pytest.approx(weight),
    }
    assert truth_friction(SimpleNamespace(**vars(floor), spin_drag=0.4))["spin_drag"] == 0.4
