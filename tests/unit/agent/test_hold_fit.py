"""Step 7's refinement of ``z_C``: the turn of a load the team holds while it pushes it
(:mod:`agent.algorithm.robust.hold_fit`), and the least squares with a prior under it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.algorithm.robust.hold_fit import HELD_TURN, HoldFit
from agent.algorithm.robust.least_squares import LeastSquares
from agent.algorithm.robust.pipeline import SWUNG_TURN
from agent.algorithm.robust.uncertainty import STEP5_COM_VARIANCE
from agent.platform.geometry import rotate

DT = 0.01


def cross(a, b) -> float:
    return a[0] * b[1] - a[1] * b[0]


def _flip(k: int, period: int) -> float:
    """``+`` for ``period/2`` ticks, then ``−`` and ``+`` for ``period`` each."""
    if k < period // 2:
        return 1.0
    return -1.0 if (k - period // 2) // period % 2 == 0 else 1.0


def _held_push(
    c0,
    prior,
    *,
    across: bool = True,
    lag: float = 0.0,
    drag: float = 0.0,
    noise: float = 0.0,
    seconds: float = 3.0,
    seed: int = 4,
):
    """A load of ``J`` = 12 kg m² under ``n`` = 4 robots, turned by ``α₀`` = 0.7 rad since
    the push began (``z_C = R(α) c₀``), pushed with ``s(t) f`` (and ``s'(t) Q f`` with
    ``across``) and held by ``τ_h = −n ẑ_C × c − b ω̃ w`` with Step 5's ``ẑ_C = R(α) prior``
    and ``ω̃`` the turn rate with white noise (each robot's ``ω̂``); the drives apply the
    forces through a first-order ``lag``, the floor a torque ``−β d`` (``drag`` = β, with
    the COM translating at ``‖ṗ_C‖``). Returns the fit fed as the pipeline feeds it, with
    the angle measured with a random walk of ``noise`` rad/√s."""
    rng = np.random.default_rng(seed)
    n, moment, force, b, w, rho = 4, 12.0, (0.0, 3.0), 4.0, 8.0, math.sqrt(2.0)
    alpha0, fine = 0.7, 50
    period = round(2.0 / DT)
    fit = HoldFit(n, moment, force, lag, prior, ((0.03**2, 0.0), (0.0, 0.03**2)))
    theta, omega, walk = alpha0, 0.0, 0.0
    applied_force, applied_torque = (0.0, 0.0), 0.0
    speed = 0.2  # ‖ṗ_C‖, as Step 6 measures it
    fit.update(theta, 1.0, DT)
    for k in range(round(seconds / DT)):
        sign = _flip(k, period)
        cross_sign = _flip(k, period // 2) if across else 0.0
        common = (sign * force[0] - cross_sign * force[1], sign * force[1] + cross_sign * force[0])
        added = (common[0] - sign * force[0], common[1] - sign * force[1])
        z_hat = rotate(prior, theta)
        feedforward = -n * cross(z_hat, common)
        measured_omega = omega + rng.normal(0.0, 0.005) if noise else omega
        held = feedforward - b * measured_omega * w
        for _ in range(fine):
            h = DT / fine
            if lag:
                a = h / lag
                applied_force = tuple(f + a * (c - f) for f, c in zip(applied_force, common))
                applied_torque += a * (held - applied_torque)
            else:
                applied_force, applied_torque = common, held
            z_c = rotate(c0, theta)
            d = omega / math.sqrt(speed**2 + (omega * rho) ** 2 + 1e-6)
            torque = n * cross(z_c, applied_force) + applied_torque - drag * d
            omega += torque / moment * h
            theta += omega * h
        walk += noise * math.sqrt(DT) * rng.normal()
        fit.update(
            theta + walk,
            sign,
            DT,
            added=added,
            drag=HoldFit.drag(measured_omega, (speed, 0.0), rho),
            torque=feedforward,
            damping=b * w,
        )
    return fit


def test_the_held_turn_finds_the_com_that_step_5_missed() -> None:
    """Step 5 left ``ẑ_C`` 2 cm off across and along the push: the turn the team holds
    against, with the push in two directions, finds both components without noise."""
    c0 = (0.25, -0.4)
    prior = (c0[0] + 0.02, c0[1] - 0.015)
    fit = _held_push(c0, prior)
    # (within a millimetre: the damping is applied held over each tick, not as the fit models
    # it, continuous)
    assert math.dist(fit.estimate, c0) < 1e-3
    assert fit.std < 2e-3
    assert math.dist(fit.com_offset(0.3), rotate(fit.estimate, 0.3)) < 1e-12


def test_a_push_in_one_direction_sees_only_the_com_across_it() -> None:
    """With noise, along one direction ``f`` alone the turn measures the component of ``c₀``
    across the push, ``(n/J) R(−α) Qᵀ f``'s; along it the estimate stays about Step 5's, as
    uncertain as the prior says."""
    c0 = (0.25, -0.4)
    prior = (c0[0] + 0.02, c0[1] - 0.015)
    fit = _held_push(c0, prior, across=False, noise=1e-4)
    seen = rotate((3.0, 0.0), -0.7)  # R(−α) Qᵀ f, f = (0, 3), up to its size
    seen = (seen[0] / 3.0, seen[1] / 3.0)
    unseen = (-seen[1], seen[0])
    error = (fit.estimate[0] - c0[0], fit.estimate[1] - c0[1])
    prior_error = (prior[0] - c0[0], prior[1] - c0[1])
    assert abs(error[0] * seen[0] + error[1] * seen[1]) < 5e-3
    unseen_error = error[0] * unseen[0] + error[1] * unseen[1]
    assert unseen_error == pytest.approx(
        prior_error[0] * unseen[0] + prior_error[1] * unseen[1], abs=3e-3
    )
    assert fit.std == pytest.approx(0.03, rel=0.1)  # the prior's, along the push


def test_the_held_turn_takes_the_drives_lag_and_the_floors_drag() -> None:
    """Drives 20 ms late and a floor that drags the turn: the push and the holding torque both
    lagged, and the drag column, keep the estimate within a millimetre."""
    c0 = (0.25, -0.4)
    prior = (c0[0] + 0.02, c0[1] - 0.015)
    fit = _held_push(c0, prior, lag=0.02, drag=0.8)
    assert math.dist(fit.estimate, c0) < 1e-3


def test_the_held_turn_with_noise_holds_the_truth_within_its_interval() -> None:
    """The team's ``ω̂`` noisy (5 mm/s: the damping it commands is a real disturbance; the fit
    takes the damping from the angle) and the angle walking: the estimate is better than Step
    5's 2.5 cm, and within three of its standard deviations of the truth."""
    c0 = (0.25, -0.4)
    prior = (c0[0] + 0.02, c0[1] - 0.015)
    fit = _held_push(c0, prior, noise=1e-4, drag=0.8, lag=0.02)
    error = math.dist(fit.estimate, c0)
    assert error < 0.5 * math.dist(prior, c0)
    assert fit.std < 0.5 * 0.03  # it knows more than its prior
    # one robot's fit, its rows' covariance scaled as Step 5's (which understates its error by
    # STEP5_COM_VARIANCE; the team publishes the robots' mean, with a factor of its own)
    assert error < 3.0 * math.sqrt(STEP5_COM_VARIANCE) * fit.std


# ------------------------------------------------------------------------------ the solver
def test_least_squares_with_a_prior_is_the_posterior() -> None:
    """Rows that see ``p₁ + p₂`` only, and a prior on ``(p₁, p₂)``: the estimate and its
    covariance are the Gaussian posterior's, computed densely."""
    rng = np.random.default_rng(7)
    truth = np.array([0.5, 1.0, -2.0])
    fit = LeastSquares(3)
    rows = []
    for _ in range(200):
        a = np.array([1.0, rng.normal(), 0.0])
        a[2] = a[1]  # p₁ and p₂ enter together: the rows alone are singular
        b = a @ truth + rng.normal(0.0, 0.1)
        fit.add(tuple(a), b)
        rows.append((a, b))
    mean, cov = np.array([0.9, -1.9]), np.array([[0.04, 0.01], [0.01, 0.09]])
    information = np.linalg.inv(cov)
    scale = 2.0
    solution = fit.solve_with_prior((1, 2), tuple(mean), tuple(information.ravel()), scale)
    assert fit.solve() is None  # singular without the prior
    a = np.array([r for r, _ in rows])
    y = np.array([t for _, t in rows])
    sigma2 = solution.variance
    h = a.T @ a / (scale * sigma2)
    h[1:, 1:] += information
    g = a.T @ y / (scale * sigma2)
    g[1:] += information @ mean
    posterior = np.linalg.solve(h, g)
    assert np.allclose(solution.estimate, posterior, atol=1e-9)
    assert np.allclose(solution.covariance(scale), np.linalg.inv(h), rtol=1e-6, atol=1e-12)
    residual = y - a @ posterior
    assert sigma2 == pytest.approx(residual @ residual / (200 - 3), rel=1e-3)  # its fixed point
    # what the rows see is theirs; what they do not, the prior's
    assert posterior[1] + posterior[2] == pytest.approx(truth[1] + truth[2], abs=0.02)
    assert posterior[1] - posterior[2] == pytest.approx(mean[0] - mean[1], abs=0.05)


def test_a_stage_that_did_not_hold_the_turn_gives_no_estimate() -> None:
    """A load that swings more than ``HELD_TURN`` under the push (Step 5's ``ẑ_C`` too far off
    for the push to act through the COM) is outside the fit's model: Step 5's estimate stands."""
    fit = HoldFit(4, 12.0, (0.0, 3.0), 0.0, (0.1, 0.2), ((1e-4, 0.0), (0.0, 1e-4)))
    for k in range(200):
        turn = 0.5 * HELD_TURN * math.sin(0.05 * k)  # within it: held
        fit.update(1.0 + turn, 1.0, DT, drag=0.1 * math.cos(0.05 * k), damping=32.0)
    assert fit.held and fit.estimate is not None
    fit.update(1.0 + 1.5 * HELD_TURN, 1.0, DT, drag=0.0, damping=32.0)
    assert not fit.held and fit.estimate is None


def test_a_turn_left_from_step_5_is_no_swing() -> None:
    """A load that began the stage turning at 0.1 rad/s, its turn dying out, has turned, not
    swung (:data:`~agent.algorithm.robust.pipeline.SWUNG_TURN`); one that swings back and
    forth about where it began has."""
    drifting = HoldFit(4, 12.0, (0.0, 3.0), 0.0, (0.1, 0.2), ((1e-4, 0.0), (0.0, 1e-4)))
    swinging = HoldFit(4, 12.0, (0.0, 3.0), 0.0, (0.1, 0.2), ((1e-4, 0.0), (0.0, 1e-4)))
    drifting.update(1.0, 1.0, DT)
    swinging.update(1.0, 1.0, DT)
    for k in range(1, 300):
        turned = 0.3 * (1.0 - math.exp(-k * DT))
        drifting.update(1.0 + turned, 1.0, DT, drag=0.1, damping=32.0)
        swinging.update(1.0 + 0.2 * math.sin(2.0 * k * DT), 1.0, DT, drag=0.1, damping=32.0)
    assert drifting.turned > 0.25 and drifting.swung < 1e-9
    assert not drifting.held  # turned: the fit's model no longer holds
    assert swinging.swung > SWUNG_TURN
