"""The estimators of ``agent.algorithm.estimation`` (and ``agent.algorithm.safety``) against closed
forms.

Every expected value is computed here, independently of the code under test: rotation matrices
and ``Q = [[0, -1], [1, 0]]`` in numpy, analytic trajectories (``y = θ sin t``, uniformly or
uniformly accelerated rotating bodies, constant-acceleration translation), analytic first-order
filters (complex exponentials), or a fine Runge-Kutta integration of the paper's dynamics.
Conventions (paper notes): ``v⊥ = Q v``, ``a × b = (a⊥)ᵀ b``, ``ż_ij = ω z_ij⊥``.
"""

from __future__ import annotations

import cmath
import inspect
import math
import random
from itertools import pairwise

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.algorithm.estimation.angular_velocity import angular_velocity
from agent.algorithm.estimation.com_observer import ComObserver
from agent.algorithm.estimation.com_velocity import com_velocity
from agent.algorithm.estimation.consensus import metropolis_weight
from agent.algorithm.estimation.estimator import Estimator
from agent.algorithm.estimation.excitation import capped_spin_up_force, kick_force, spin_up_force
from agent.algorithm.estimation.inertia import inertia_force
from agent.algorithm.estimation.settling import SettleDetector, SettleDetectors
from agent.algorithm.estimation.team_consensus import TeamConsensus
from agent.algorithm.paper.com_regression import ComRegression
from agent.algorithm.paper.filtered_regression import FilteredRegression
from agent.algorithm.paper.inertia import InertiaEstimator
from agent.algorithm.paper.mass import MassEstimator
from agent.algorithm.paper.relative_position import RelativePosition
from agent.algorithm.robust.team_mass import (
    MAX_MASS_INFORMATION,
    disagreement,
    inputs,
    mass_input,
    team_mass,
)
from agent.algorithm.safety import saturate
from agent.platform.geometry import angle_between, arc_factor, cross, rotate
from agent.platform.protocol import Share
from agent.platform.team import ConsensusState, flow_width

Q = np.array([[0.0, -1.0], [1.0, 0.0]])
FAST = settings(max_examples=50, deadline=None)

angles = st.floats(-math.pi, math.pi, allow_nan=False)
lengths = st.floats(0.05, 5.0, allow_nan=False)
coords = st.floats(-10.0, 10.0, allow_nan=False)


def rot(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def polar(r: float, a: float) -> np.ndarray:
    return np.array([r * math.cos(a), r * math.sin(a)])


def sample_times(rng: np.random.Generator | None, duration: float, dt: float = 0.01) -> list:
    """``0, dt, 2 dt, …`` (regular) or random intervals in ``[dt/5, 2 dt]`` (irregular)."""
    if rng is None:
        return [k * dt for k in range(round(duration / dt) + 1)]
    steps = rng.uniform(0.2 * dt, 2.0 * dt, size=round(2 * duration / dt))
    times = np.concatenate([[0.0], np.cumsum(steps)])
    return [float(t) for t in times[times <= duration]]


# --------------------------------------------------------------------------------------------
# geometry
# --------------------------------------------------------------------------------------------


@FAST
@given(coords, coords, coords, coords)
def test_cross_is_perp_transpose_times_b(ax, ay, bx, by):
    a, b = np.array([ax, ay]), np.array([bx, by])
    expected = float((Q @ a) @ b)
    assert cross((ax, ay), (bx, by)) == pytest.approx(expected, abs=1e-12)
    assert cross((ax, ay), (bx, by)) == pytest.approx(-cross((bx, by), (ax, ay)), abs=1e-12)


def test_cross_orientation():
    assert cross((1.0, 0.0), (0.0, 1.0)) == 1.0
    assert cross((0.0, 1.0), (1.0, 0.0)) == -1.0
    assert cross((2.0, 3.0), (4.0, 6.0)) == 0.0


@FAST
@given(coords, coords, angles)
def test_rotate_is_rotation_matrix(x, y, angle):
    expected = rot(angle) @ np.array([x, y])
    assert rotate((x, y), angle) == pytest.approx(tuple(expected), abs=1e-12)


def test_rotate_quarter_turn_is_counter_clockwise():
    assert rotate((1.0, 0.0), math.pi / 2) == pytest.approx((0.0, 1.0), abs=1e-15)
    assert rotate((0.0, 1.0), -math.pi / 2) == pytest.approx((1.0, 0.0), abs=1e-15)


@FAST
@given(lengths, angles, st.floats(-math.pi + 1e-6, math.pi - 1e-6), lengths)
def test_angle_between_recovers_signed_angle(r, a, phi, scale):
    v = polar(r, a)
    w = scale * (rot(phi) @ v)
    assert angle_between(tuple(v), tuple(w)) == pytest.approx(phi, abs=1e-9)


@pytest.mark.parametrize(
    "a, b",
    [((1.0, 0.0), (-1.0, 0.0)), ((0.0, 1.0), (0.0, -1.0)), ((-1.0, 0.0), (1.0, 0.0))],
)
def test_angle_between_antiparallel_is_plus_pi(a, b):
    # The docstring promises a result in (-π, π]: opposite directions must give +π.
    assert angle_between(a, b) == math.pi


@pytest.mark.parametrize("turn", [-2.5, -1.0, -0.3, -1e-5, 0.0, 3e-5, 2e-4, 0.01, 0.3, 1.0, 2.5])
@pytest.mark.parametrize("dt", [0.01, 0.7])
def test_arc_factor_makes_trapezoid_exact_for_uniform_rotation(turn, dt):
    v0 = np.array([0.8, -1.3])
    omega = turn / dt
    v1 = rot(turn) @ v0
    if turn == 0.0:
        exact = dt * v0
    else:
        # ∫₀^dt R(ωt) v0 dt = (1/ω) Q⁻¹ (R(ω dt) − I) v0, since d/dt R(ωt) = ω Q R(ωt);
        # R(φ) − I written with cos φ − 1 = −2 sin²(φ/2) to avoid cancellation.
        c1, s1 = -2.0 * math.sin(0.5 * turn) ** 2, math.sin(turn)
        exact = (Q.T @ np.array([[c1, -s1], [s1, c1]]) @ v0) / omega
    trapezoid = 0.5 * dt * (v0 + v1)
    got = trapezoid * arc_factor(turn)
    assert tuple(got) == pytest.approx(tuple(exact), rel=1e-12, abs=1e-15)
    if abs(turn) >= 0.3:  # the plain trapezoid is visibly wrong at such turns
        assert np.linalg.norm(trapezoid - exact) > 1e-3 * np.linalg.norm(exact)


# --------------------------------------------------------------------------------------------
# filtered regression (Appendix, eq. 26)
# --------------------------------------------------------------------------------------------


def run_scalar(theta, times, kf=5.0, forgetting=1.0, y0=0.3):
    """ẏ = θ u with u = cos t, y = y0 + θ sin t."""
    est = FilteredRegression(kf, outputs=1, params=1, forgetting=forgetting)
    est.start((y0 + theta * math.sin(times[0]),))
    for t0, t1 in pairwise(times):
        est.update((y0 + theta * math.sin(t1),), ((math.sin(t1) - math.sin(t0),),), t1 - t0)
    return est


@pytest.mark.parametrize("irregular", [False, True])
@pytest.mark.parametrize("theta", [2.5, -0.37, 1e-3])
def test_filtered_regression_scalar_exact(theta, irregular):
    rng = np.random.default_rng(11) if irregular else None
    est = run_scalar(theta, sample_times(rng, 10.0))
    assert est.estimate[0] == pytest.approx(theta, abs=1e-9)


@pytest.mark.parametrize("irregular", [False, True])
def test_filtered_regression_two_parameters_exact(irregular):
    """ẏ = φ(t)ᵀ c with φ = (cos t, sin t): y = c1 sin t − c2 cos t."""
    c = (0.7, -1.9)
    rng = np.random.default_rng(12) if irregular else None
    times = sample_times(rng, 10.0)

    def y(t):
        return c[0] * math.sin(t) - c[1] * math.cos(t) + 4.0

    est = FilteredRegression(3.0, outputs=1, params=2)
    est.start((y(times[0]),))
    for t0, t1 in pairwise(times):
        integral = (math.sin(t1) - math.sin(t0), math.cos(t0) - math.cos(t1))
        est.update((y(t1),), (integral,), t1 - t0)
    assert est.estimate == pytest.approx(c, abs=1e-9)


def test_filtered_regression_two_outputs_exact():
    """y ∈ R²: ẏ = θ (cos t, 2 cos 2t), y = θ (sin t, sin 2t)."""
    theta = -0.8
    times = sample_times(np.random.default_rng(13), 6.0)
    est = FilteredRegression(5.0, outputs=2, params=1)
    est.start((0.0, 0.0))
    for t0, t1 in pairwise(times):
        y = (theta * math.sin(t1), theta * math.sin(2 * t1))
        integral = ((math.sin(t1) - math.sin(t0),), (math.sin(2 * t1) - math.sin(2 * t0),))
        est.update(y, integral, t1 - t0)
    assert est.estimate[0] == pytest.approx(theta, abs=1e-9)


def test_filtered_regression_none_before_excitation():
    est = FilteredRegression(5.0, outputs=1, params=1)
    assert est.estimate is None
    est.start((1.0,))
    assert est.estimate is None
    for _ in range(50):  # u = 0: y stays put, nothing to learn from
        est.update((1.0,), ((0.0,),), 0.01)
    assert est.estimate is None
    est.update((1.0 + 2.0 * 0.01,), ((0.01,),), 0.01)  # u = 1 for one interval, θ = 2
    assert est.estimate[0] == pytest.approx(2.0, abs=1e-12)

    two = FilteredRegression(5.0, outputs=1, params=2)
    two.start((0.0,))
    for k in range(100):  # φ = (1, 0) for ever: the second parameter is not determined
        two.update(((k + 1) * 0.01 * 0.5,), ((0.01, 0.0),), 0.01)
    assert two.estimate is None


def test_filtered_regression_rejects_bad_arguments():
    with pytest.raises(ValueError):
        FilteredRegression(5.0, outputs=1, params=3)
    with pytest.raises(ValueError):
        FilteredRegression(5.0, outputs=1, params=1, forgetting=0.0)
    with pytest.raises(ValueError):
        FilteredRegression(5.0, outputs=1, params=1, forgetting=1.5)


def _jump_run(forgetting):
    """θ = 2 on [0, 5], θ = −1 on [5, 10]; y continuous, sampled at 100 Hz."""
    est = FilteredRegression(5.0, outputs=1, params=1, forgetting=forgetting)

    def y(k):
        t = k * 0.01
        if k <= 500:
            return 2.0 * math.sin(t)
        return 2.0 * math.sin(5.0) - (math.sin(t) - math.sin(5.0))

    est.start((y(0),))
    for k in range(1, 1001):
        integral = math.sin(k * 0.01) - math.sin((k - 1) * 0.01)
        est.update((y(k),), ((integral,),), 0.01)
        if k == 500:
            before = est.estimate[0]
    return before, est.estimate[0]


def test_filtered_regression_forgetting_tracks_a_jump():
    before, after = _jump_run(0.95)
    assert before == pytest.approx(2.0, abs=1e-9)
    assert after == pytest.approx(-1.0, abs=1e-6)
    _, stuck = _jump_run(1.0)  # without forgetting the old data dominate
    assert abs(stuck + 1.0) > 0.1


# --------------------------------------------------------------------------------------------
# relative position (Prop. IV.1, eqs. 10-12 corrected)
# --------------------------------------------------------------------------------------------


class Body:
    """Two points ``r_i``, ``r_j`` (body frame) of a rigid body at rotation ``alpha(t)`` and an
    arbitrary translation: exact contact velocities."""

    def __init__(self, ri, rj, omega, alpha):
        self.ri, self.rj = np.asarray(ri), np.asarray(rj)
        self.omega, self.alpha = omega, alpha

    def translation_velocity(self, t):
        return np.array([0.3 * math.cos(t) - 1.0, 2.0 - t])

    def velocity(self, r, t):
        return self.translation_velocity(t) + self.omega(t) * (Q @ rot(self.alpha(t)) @ r)

    def zdot(self, t):
        return self.velocity(self.ri, t) - self.velocity(self.rj, t)

    def z(self, t):
        return rot(self.alpha(t)) @ (self.ri - self.rj)


def feed(rp: RelativePosition, zdot, t: float, last: list) -> None:
    """Feed ``ż_ij`` sampled at ``t``: ``dt`` runs from the last sample used (``last[0]``)."""
    rp.update(tuple(zdot), t - (t if last[0] is None else last[0]))
    if rp.moving:
        last[0] = t


def omega_sign(rp: RelativePosition, zdot) -> float:
    """``sign(ω)`` from the estimate by eq. (5), as Step 3 gets it."""
    return math.copysign(1.0, angular_velocity(rp.estimate, tuple(zdot)))


@pytest.mark.parametrize("omega", [0.7, -0.7, 3.0, -2.2, 0.05, -0.05])
def test_relative_position_constant_omega(omega):
    rng = np.random.default_rng(round(1000 * abs(omega)) + (omega < 0))
    ri, rj, a0 = rng.uniform(-2, 2, 2), rng.uniform(-2, 2, 2), rng.uniform(-3, 3)
    body = Body(ri, rj, lambda t: omega, lambda t: a0 + omega * t)
    rp = RelativePosition(5.0)
    assert rp.estimate is None and rp.distance is None and rp.covariance is None
    times = sample_times(None, 5.0)
    last = [None]
    for t in times:
        feed(rp, body.zdot(t), t, last)
    z = body.z(times[-1])
    assert rp.distance == pytest.approx(np.linalg.norm(z), rel=1e-6)
    assert np.linalg.norm(np.array(rp.estimate) - z) < 1e-6
    assert omega_sign(rp, body.zdot(times[-1])) == math.copysign(1.0, omega)


def test_relative_position_interval_runs_from_the_last_sample_used():
    """A sample of an edge at rest is not used; the next interval spans the one it missed."""
    omega, a0 = 1.5, 0.3
    body = Body((0.9, -0.4), (-0.6, 0.8), lambda t: omega, lambda t: a0 + omega * t)
    rp = RelativePosition(5.0)
    last = [None]
    for k in range(301):
        t = 0.01 * k
        if k == 150:
            rp.update((0.0, 0.0), 0.01)
            assert not rp.moving and last[0] == pytest.approx(1.49)
            continue
        feed(rp, body.zdot(t), t, last)
        assert rp.moving
        if k == 151:
            assert rp.last_dt == pytest.approx(0.02)  # from t = 1.49 s
    # Fed 0.01 s there instead, the estimate would be off by 7 mm.
    assert np.linalg.norm(np.array(rp.estimate) - body.z(3.0)) < 1e-9


def _sign_change_body():
    # ω(t) = 0.5 − 0.2 t: zero at t = 2.5 s; α(t) = 0.4 + 0.5 t − 0.1 t².
    return Body(
        (0.7, -0.2), (-0.5, 0.9), lambda t: 0.5 - 0.2 * t, lambda t: 0.4 + 0.5 * t - 0.1 * t * t
    )


def test_relative_position_tracks_through_a_sign_change_after_learning():
    body = _sign_change_body()
    rp = RelativePosition(5.0)
    last = [None]
    for t in sample_times(None, 5.0):
        if t >= 2.0:
            rp.learning = False
        feed(rp, body.zdot(t), t, last)
        if t > 1.0 and abs(t - 2.5) > 1e-9:  # (at t = 2.5 s ż = 0: no sample)
            z = body.z(t)
            assert np.linalg.norm(np.array(rp.estimate) - z) < 1e-6, t
            assert omega_sign(rp, body.zdot(t)) == math.copysign(1.0, body.omega(t)), t
    assert rp.sigma == -1.0  # y_ij reversed once
    assert rp.distance == pytest.approx(np.linalg.norm(body.z(0.0)), rel=1e-6)


def test_relative_position_learning_through_a_sign_change():
    body = _sign_change_body()
    rp = RelativePosition(5.0)
    last = [None]
    for t in sample_times(None, 5.0):
        feed(rp, body.zdot(t), t, last)
    assert np.linalg.norm(np.array(rp.estimate) - body.z(5.0)) < 1e-6
    assert omega_sign(rp, body.zdot(5.0)) == -1.0


def test_relative_position_ignores_a_load_at_rest():
    rp = RelativePosition(5.0)
    for _ in range(20):
        rp.update((0.0, 0.0), 0.01)
        assert not rp.moving
    assert rp.estimate is None and rp.direction is None and not rp.regression.started


@pytest.mark.parametrize("omega", [0.8, -0.8, 2.0, -0.3])
def test_eq12_corrected_sign_rule_and_distance(omega):
    """Eq. (12) as corrected, on the exact (continuous) filtered signals.

    Complex numbers stand for planar vectors (``v⊥ = i v``). With ``z(t) = z0 e^{iωt}``:
    ``ż = iω z``, ``y = ż⊥/‖ż‖``. A first-order filter ``ẋ^f = k(x − x^f)`` of ``A e^{iωt}``
    from ``x^f(0)`` is ``k/(k+iω) A e^{iωt} + (x^f(0) − k/(k+iω) A) e^{−kt}``; the Appendix
    starts ``y^f(0) = y(0)`` and ``ż^f(0) = 0``.
    """
    kf, t = 5.0, 3.0
    z0 = complex(1.2, -0.5)
    dist = abs(z0)
    gain = kf / (kf + 1j * omega)
    z = z0 * cmath.exp(1j * omega * t)
    zdot = 1j * omega * z
    y = 1j * zdot / abs(zdot)
    a_y = 1j * (1j * omega * z0) / abs(omega * z0)  # y = a_y e^{iωt}
    yf = gain * a_y * cmath.exp(1j * omega * t) + (a_y - gain * a_y) * math.exp(-kf * t)
    zdotf = gain * (1j * omega * z0) * (cmath.exp(1j * omega * t) - math.exp(-kf * t))

    def dot(a, b):
        return (a.conjugate() * b).real

    # Corrected eq. (10): z = −sign(ω) ‖z‖ y (the printed "+sign(ω)" gives −z).
    assert abs(-math.copysign(dist, omega) * y - z) < 1e-12
    assert abs(math.copysign(dist, omega) * y + z) < 1e-12
    # Corrected eq. (12) and the sign rule after it.
    assert abs(zdotf) / (kf * abs(y - yf)) == pytest.approx(dist, rel=1e-12)
    sign_rule = -math.copysign(1.0, dot(zdotf, y - yf))
    assert sign_rule == math.copysign(1.0, omega)

    # The estimator agrees with the closed form.
    body = Body((z0.real, z0.imag), (0.0, 0.0), lambda s: omega, lambda s: omega * s)
    rp = RelativePosition(kf)
    last = [None]
    for s in sample_times(None, t):
        feed(rp, body.zdot(s), s, last)
    assert omega_sign(rp, body.zdot(t)) == sign_rule
    assert rp.distance == pytest.approx(abs(zdotf) / (kf * abs(y - yf)), rel=1e-6)
    assert rp.estimate == pytest.approx((z.real, z.imag), abs=1e-6)


# --------------------------------------------------------------------------------------------
# angular velocity (eq. 5 corrected), COM velocity (eq. 7)
# --------------------------------------------------------------------------------------------


@FAST
@given(lengths, angles, st.floats(-5.0, 5.0, allow_nan=False))
def test_angular_velocity_eq5(r, a, omega):
    z = polar(r, a)
    zdot = omega * (Q @ z)
    assert angular_velocity(tuple(z), tuple(zdot)) == pytest.approx(omega, abs=1e-12)


@FAST
@given(lengths, angles, st.floats(-3.0, 3.0), st.floats(0.0, 10.0), coords, coords)
def test_com_velocity_eq7_on_a_rigid_body(r, a0, omega, t, vx, vy):
    # p_C(t) = p0 + v t + ½ a t², α(t) = a0 + ω t; contact at body offset r_b.
    acc = np.array([0.2, -0.1])
    body_offset = polar(r, 0.7)
    v_c = np.array([vx, vy]) + acc * t
    offset = rot(a0 + omega * t) @ body_offset  # p_Ci − p_C
    v_contact = v_c + omega * (Q @ offset)  # d/dt [p_C + R(α) r_b]
    got = com_velocity(tuple(v_contact), omega, tuple(offset))
    assert got == pytest.approx(tuple(v_c), abs=1e-9)


# --------------------------------------------------------------------------------------------
# centroid (Aragues et al.) and average consensus (eq. 16)
# --------------------------------------------------------------------------------------------


def graph(kind: str, n: int) -> list[tuple[int, int]]:
    if kind == "path":
        return [(i, i + 1) for i in range(n - 1)]
    if kind == "ring":
        return [(i, (i + 1) % n) for i in range(n)]
    if kind == "star":
        return [(0, i) for i in range(1, n)]
    raise ValueError(kind)


def neighbours_of(n, edges):
    nb = {i: [] for i in range(n)}
    for i, j in edges:
        nb[i].append(j)
        nb[j].append(i)
    return nb


def test_metropolis_weight_values():
    assert metropolis_weight(1, 1) == 0.5
    assert metropolis_weight(1, 2) == pytest.approx(1 / 3)
    assert metropolis_weight(2, 1) == pytest.approx(1 / 3)
    assert metropolis_weight(3, 5) == pytest.approx(1 / 6)
    assert metropolis_weight(5, 3) == pytest.approx(1 / 6)
    # Row sums below 1 on a star: the hub's Σ_j a_ij = d/(1+d).
    assert 5 * metropolis_weight(5, 1) == pytest.approx(5 / 6)


class TurningLoad:
    """Robot ``i``'s view of contacts ``p`` (at instant 0) on a load that turns by ``turn`` per
    instant: exact ``z_ij`` in ``W`` and rotations since earlier instants."""

    def __init__(self, p, i, turn):
        self.p, self.i, self.turn = p, i, turn
        self.instant = 0

    def turned_since(self, instant):
        return self.turn * (self.instant - instant)

    def relative_position(self, j):
        z = rot(self.turn * self.instant) @ (self.p[self.i] - self.p[j])
        return (float(z[0]), float(z[1]))


class Member(TeamConsensus):
    """One robot's team consensus with the robust family's inputs, settable: its drive's gain
    and its mass input; its states by their symbols."""

    def __init__(self, robot: int, neighbours):
        self.gain_input, self.mass_input = 1.0, (0.0, 0.0, 0.0, 0.0)
        super().__init__(
            robot,
            neighbours,
            lambda x: inputs(x, self.gain_input, self.mass_input, 0.0, 0.0, None, 0.0),
        )

    xi = property(lambda self: self["mean_square_offset"])
    gain = property(lambda self: self["mean_gain"])
    h = property(lambda self: self["mean_gain_offset"])
    q = property(lambda self: self["mean_gain_square_offset"])

    def team_mass(self, own: float):
        return team_mass(self["mean_mass_information"], self["mean_weighted_mass"], own)

    def disagreement(self, n: int) -> float:
        return disagreement(
            self["mean_mass_information"],
            self["mean_weighted_log_mass"],
            self["mean_weighted_square_log_mass"],
            n,
        )


def message(i: int, t: int, c: Member) -> Share:
    return Share(
        sender=i,
        tick=t,
        velocity=(0.0, 0.0),
        degree=c.degree,
        instant=t,
        consensus=c.state,
        flows=c.shared_flows(),
    )


def run_consensus(p, edges, rounds, turn=0.0, lost=frozenset(), gains=None, masses=None):
    """The team's iterations: at instant ``t`` each robot hears its neighbours' messages of
    ``t − 1``, except ``(t, sender, receiver)`` in ``lost`` (it keeps the older one it has).
    Yields the team after each instant."""
    n = len(p)
    nb = neighbours_of(n, edges)
    team = {i: Member(i, sorted(nb[i])) for i in range(n)}
    for i, c in team.items():
        c.gain_input = 1.0 if gains is None else gains[i]
        if masses is not None:
            c.mass_input = mass_input(*masses[i])
    frames = {i: TurningLoad(p, i, turn) for i in range(n)}
    heard = {i: {} for i in range(n)}
    sent = {}
    for t in range(rounds):
        for i in range(n):
            for j in nb[i]:
                if j in sent and (t, j, i) not in lost:
                    heard[i][j] = sent[j]
        for i, c in team.items():
            frames[i].instant = t
            c.update(turn, heard[i], frames[i])
        sent = {i: message(i, t, c) for i, c in team.items()}
        yield team


def offsets(p, turn, t):
    """``z_i = p_Ci − p_G`` at instant ``t``."""
    return (p - p.mean(axis=0)) @ rot(turn * t).T


@pytest.mark.parametrize("turn", [0.0, 0.01])
@pytest.mark.parametrize("kind", ["path", "ring", "star"])
def test_centroid_consensus_converges_to_offsets_and_w(kind, turn):
    n = 6
    p = np.random.default_rng(21).uniform(-3, 3, size=(n, 2))
    for team in run_consensus(p, graph(kind, n), 3000, turn):
        x = np.array([c.centroid for c in team.values()])
        xi = [c.xi for c in team.values()]
        assert np.abs(x.sum(axis=0)).max() < 1e-12  # Σ x_i = 0
        assert sum(xi) == pytest.approx(float((x**2).sum()), abs=1e-9)  # Σ ξ_i = Σ ‖x_i‖²
    truth = offsets(p, turn, 2999)
    assert np.abs(x - truth).max() < 1e-9
    w = float((truth**2).sum())
    for c in team.values():
        assert c.xi == pytest.approx(w / n, abs=1e-9)


@pytest.mark.parametrize("lossy", [False, True])
def test_the_drives_gains_averages(lossy):
    """Beside ``z_i`` and ``w``: the mean gain ``ḡ``, ``h = Σ g_i z_i / n`` (turning with the
    load) and ``q = Σ g_i ‖z_i‖² / n``, whatever messages are lost."""
    n, turn, rounds = 6, 0.01, 3000
    p = np.random.default_rng(5).uniform(-3, 3, size=(n, 2))
    gains = np.random.default_rng(6).normal(1.0, 0.05, size=n)
    edges = graph("ring", n)
    lost = _lossy(n, edges, rounds, 0.2, 7) if lossy else frozenset()
    for team in run_consensus(p, edges, rounds, turn, lost, gains):
        gamma = [c.gain for c in team.values()]
        assert sum(gamma) == pytest.approx(float(gains.sum()), abs=1e-9) or lossy
    z = offsets(p, turn, rounds - 1)
    h = (gains[:, None] * z).sum(axis=0) / n
    q = float((gains * (z**2).sum(axis=1)).sum()) / n
    for c in team.values():
        assert c.gain == pytest.approx(float(gains.mean()), abs=1e-9)
        assert c.h == pytest.approx(tuple(h), abs=1e-9)
        assert c.q == pytest.approx(q, abs=1e-9)
    assert np.linalg.norm(h) > 0.01  # not the unweighted centroid's zero


@pytest.mark.parametrize("lossy", [False, True])
def test_the_team_mass_is_the_information_weighted_mean(lossy):
    """Step 7's consensus on information: each robot's fit weighs by its inverse variance, and
    the team's relative standard deviation is that of a robot of mean information."""
    n, rounds = 5, 2000
    p = np.random.default_rng(8).uniform(-3, 3, size=(n, 2))
    fits = [(5.0, 0.05), (5.2, 0.1), (4.9, 0.025), (5.1, 0.05), (5.0, None)]  # kg, kg
    edges = graph("path", n)
    lost = _lossy(n, edges, rounds, 0.2, 9) if lossy else frozenset()
    *_, team = run_consensus(p, edges, rounds, 0.0, lost, masses=fits)
    info = [(0.01 * m / s) ** 2 if s else 0.0 for m, s in fits]
    mean = sum(w * m for w, (m, _) in zip(info, fits)) / sum(info)
    assert mean == pytest.approx(4.9633, abs=1e-4)  # nearest the surest fit, 4.9 ± 0.025
    for c in team.values():
        mass, rho = c.team_mass(5.0)
        assert mass == pytest.approx(mean, abs=1e-9)
        assert rho == pytest.approx(0.01 / math.sqrt(sum(info) / n), rel=1e-9)
    # A state that is no weighted mean of the fits yet is not used.
    assert team[0].team_mass(20.0) is None and team[0].team_mass(-1.0) is None
    # The fits are further apart than their standard deviations say: chi-square about their
    # weighted mean, over n − 1, and the team's interval widened by its square root.
    chi2 = sum(
        w * math.log(m / math.exp(_log_mean(info, fits))) ** 2 for w, (m, _) in zip(info, fits)
    )
    scale = math.sqrt(chi2 / 1e-4 / (n - 1))
    assert scale > 1.5
    for c in team.values():
        assert c.disagreement(n) == pytest.approx(scale, rel=1e-6)


def _log_mean(info, fits):
    return sum(w * math.log(m) for w, (m, _) in zip(info, fits)) / sum(info)


def test_fits_that_agree_leave_the_team_mass_interval_as_it_is() -> None:
    log = math.log(5.0)
    agreeing = (2.0, 2.0 * log, 2.0 * log * log)
    assert disagreement(*agreeing, 4) == 1.0
    assert disagreement(0.0, 0.0, 0.0, 4) == 1.0  # no fit yet
    assert disagreement(1.0, log, log * log + 1e-4, 1) == 1.0  # a lone robot
    # two robots 2 % apart with 1 % each: chi-square 2, S = sqrt(2)
    a, b = math.log(4.95), math.log(5.05)
    assert disagreement(1.0, (a + b) / 2, (a * a + b * b) / 2, 2) == pytest.approx(
        math.sqrt(2.0) * (b - a) / 0.02, rel=1e-9
    )


def test_a_mass_fits_information_is_bounded() -> None:
    assert mass_input(None, 0.1) == (0.0,) * 4 and mass_input(5.0, None) == (0.0,) * 4
    log = math.log(5.0)
    assert mass_input(5.0, 0.05) == pytest.approx((1.0, 5.0, log, log * log))  # 1 %: one unit
    assert mass_input(5.0, 0.0)[:2] == (MAX_MASS_INFORMATION, 5.0 * MAX_MASS_INFORMATION)
    assert mass_input(5.0, 1e-6)[0] == MAX_MASS_INFORMATION


def _lossy(n, edges, rounds, probability, seed):
    rng = random.Random(seed)
    directed = [(j, i) for i, j in edges] + list(edges)
    return frozenset(
        (t, j, i) for t in range(rounds) for j, i in directed if rng.random() < probability
    )


def _plain_centroid(p, edges, rounds, lost):
    """The iteration without flows, each robot using the last ``x_j`` it heard."""
    n = len(p)
    nb = neighbours_of(n, edges)
    deg = {i: len(nb[i]) for i in nb}
    x = np.zeros((n, 2))
    heard = {}
    sent = None
    for t in range(rounds):
        for i in range(n):
            for j in nb[i]:
                if sent is not None and (t, j, i) not in lost:
                    heard[i, j] = sent[j]
        new = x.copy()
        for i in range(n):
            for j in nb[i]:
                if (i, j) in heard:
                    a = metropolis_weight(deg[i], deg[j])
                    new[i] += a * (heard[i, j] - x[i] + p[i] - p[j])
        x, sent = new, new.copy()
    return x


@pytest.mark.parametrize("kind", ["path", "ring"])
def test_centroid_consensus_keeps_its_sums_under_message_loss(kind):
    """A fifth of the messages lost, all the time: ``Σ x_i`` departs from 0 while an edge's two
    ends disagree, comes back to it as soon as they hear each other, and every robot still
    reaches ``z_i`` and ``w / n`` exactly; the plain iteration keeps the drift for good."""
    n, rounds, turn = 6, 3000, 0.01
    p = np.random.default_rng(22).uniform(-3, 3, size=(n, 2))
    edges = graph(kind, n)
    lost = _lossy(n, edges, rounds, 0.2, seed=5)
    worst = 0.0
    for team in run_consensus(p, edges, rounds, turn, lost):
        x = np.array([c.centroid for c in team.values()])
        worst = max(worst, np.abs(x.sum(axis=0)).max())
    assert worst > 1e-2  # the losses did break the sum, for a while
    assert np.abs(x.sum(axis=0)).max() < 1e-12
    truth = offsets(p, turn, rounds - 1)
    assert np.abs(x - truth).max() < 1e-9
    w = float((truth**2).sum())
    assert all(c.xi == pytest.approx(w / n, abs=1e-9) for c in team.values())
    plain = _plain_centroid(p, edges, rounds, _lossy(n, edges, rounds, 0.2, seed=5))
    assert np.abs(plain.sum(axis=0)).max() > 1e-3


def test_centroid_consensus_one_update_by_hand():
    """``x_i⁺ = Σ_j a_ij (x_j − x_i + z_ij)`` from ``x_i = 0``, each ``x_j`` turned from the
    instant it refers to; ``ξ_i⁺ = Σ_j a_ij ξ_j + ‖x_i⁺‖²`` (input ``‖x_i‖²``, from 0)."""
    phi, t = 0.2, 5
    p = np.array([[0.0, 0.0], [1.0, 2.0], [-3.0, 0.5]])
    frame = TurningLoad(p, 0, phi)
    frame.instant = t
    c = Member(0, (1, 2))
    x1, x2 = (0.4, -0.3), (-1.1, 0.7)
    team1 = ConsensusState(centroid_offset=x1, mean_square_offset=0.8)
    team2 = ConsensusState(centroid_offset=x2, mean_square_offset=-0.2)
    shares = {
        1: Share(sender=1, tick=t - 1, velocity=(0, 0), degree=2, instant=t - 1, consensus=team1),
        2: Share(sender=2, tick=t - 1, velocity=(0, 0), degree=3, instant=t - 3, consensus=team2),
    }
    c.update(phi, shares, frame)
    a1, a2 = 1 / 3, 1 / 4
    expected = a1 * (rot(phi) @ x1 + frame.relative_position(1)) + a2 * (
        rot(3 * phi) @ x2 + frame.relative_position(2)
    )
    assert c.centroid == pytest.approx(tuple(expected), abs=1e-12)
    assert c.xi == pytest.approx(a1 * 0.8 + a2 * -0.2 + expected @ expected, abs=1e-12)


def test_centroid_consensus_adopts_each_neighbour_flow_once():
    """Hearing ``F_ji`` sets ``F_ij = −F_ji`` (turned to now): ``x_i = −Σ_j F_ij``,
    ``ξ_i = ‖x_i‖² − Σ_j F^s_ij``. The same message heard again changes nothing."""
    phi, t = 0.3, 7
    frame = TurningLoad(np.zeros((2, 2)), 0, phi)
    frame.instant = t
    c = Member(0, (1,))
    theirs = Share(
        sender=1,
        tick=t - 2,
        velocity=(0, 0),
        degree=1,
        # x_j where this robot's x_i will be: the iteration's own term is nil.
        consensus=ConsensusState(centroid_offset=(0.5, -1.0), mean_square_offset=2.0),
        flows=((0, 0.5, -1.0, 0.25, *[0.0] * (flow_width() - 3)),),
        instant=t - 2,
    )
    c.update(phi, {1: theirs}, frame)
    x = rot(2 * phi) @ np.array([0.5, -1.0])
    xi = x @ x + 0.25
    ds1 = 0.5 * (2.0 - xi)
    assert c.centroid == pytest.approx(tuple(x), abs=1e-12)
    assert c.xi == pytest.approx(x @ x + 0.25 + ds1, abs=1e-12)
    frame.instant = t + 1
    c.update(phi, {1: theirs}, frame)
    x = rot(phi) @ x
    assert c.centroid == pytest.approx(tuple(x), abs=1e-12)
    xi = x @ x + 0.25 + ds1
    ds2 = 0.5 * (2.0 - xi)
    assert c.xi == pytest.approx(x @ x + 0.25 + ds1 + ds2, abs=1e-12)
    ((j, *flow),) = c.shared_flows()
    assert j == 1
    assert flow[:3] == pytest.approx([-x[0], -x[1], -0.25 - ds1 - ds2], abs=1e-12)


def test_every_estimator_has_the_common_shape():
    estimators = [
        RelativePosition(5.0),
        InertiaEstimator(5.0),
        ComRegression(5.0, 4, 2.0, (0.0, 1.0)),
        ComObserver(4, 2.0, (0.0, 1.0), 1.0, 0.5),
        MassEstimator(5.0, 4, (0.0, 1.0)),
    ]
    for est in estimators:
        cls = type(est)
        assert isinstance(est, Estimator), cls
        params = list(inspect.signature(cls.update).parameters)
        assert len(params) >= 3 and params[-1] == "dt", cls  # measured inputs, then dt
        assert isinstance(cls.estimate, property) and isinstance(cls.covariance, property), cls
        assert est.covariance is None, cls
    # What lacks a part of the shape is not an estimator.
    assert not isinstance(FilteredRegression(5.0, 1, 1), Estimator)


def test_settle_detectors_by_step():
    settle = SettleDetectors.of(1, 0.01)
    assert settle.first_settled() == {}
    for tick in (3, 4):
        settle.distances.update((1.0, 2.0), tick)
        settle.com_offset.update((0.1, 0.2), tick + 10)
    assert settle.first_settled() == {1: 4, 3: 4, 5: 14, 6: 14}


# --------------------------------------------------------------------------------------------
# inertia (Sec. V-A), mass (Sec. V-C)
# --------------------------------------------------------------------------------------------


def test_inertia_force_is_k_z_perp_and_pure_torque():
    k = 1.7
    assert inertia_force(k, (2.0, -3.0)) == pytest.approx((3.0 * k, 2.0 * k), abs=0.0)
    rng = np.random.default_rng(31)
    p = rng.uniform(-2, 2, size=(5, 2))
    z = p - p.mean(axis=0)
    forces = np.array([inertia_force(k, tuple(zi)) for zi in z])
    assert np.abs(forces.sum(axis=0)).max() < 1e-12
    q = np.array([4.0, -7.0])  # any point
    torque = sum((Q @ (pi - q)) @ fi for pi, fi in zip(p, forces))
    assert torque == pytest.approx(k * float((z**2).sum()), rel=1e-12)


@pytest.mark.parametrize("irregular", [False, True])
def test_inertia_estimator_constant_torque(irregular):
    inertia, torque, w0 = 12.3795, 0.8, -0.3
    est = InertiaEstimator(5.0)
    times = sample_times(np.random.default_rng(32) if irregular else None, 4.0)
    est.update(w0, torque, 0.0)
    assert est.estimate is None
    for t0, t1 in pairwise(times):
        est.update(w0 + torque / inertia * t1, torque, t1 - t0)
    assert est.estimate == pytest.approx(inertia, rel=1e-9)


def test_inertia_estimator_torque_switching_sign():
    inertia, torque, w0 = 3.5, 1.2, 0.4
    est = InertiaEstimator(5.0)
    omega = w0
    est.update(omega, torque, 0.0)
    for k in range(1, 801):
        tau = torque if k <= 300 else -torque  # reverses at t = 3 s, a sample instant
        omega += tau / inertia * 0.01
        est.update(omega, tau, 0.01)
    # ω(8 s) = w0 + (τ/J)(3 − 5)
    assert omega == pytest.approx(w0 - 2 * torque / inertia, abs=1e-12)
    assert est.estimate == pytest.approx(inertia, rel=1e-9)


@pytest.mark.parametrize("irregular", [False, True])
def test_mass_estimator(irregular):
    mass, n, force, v0 = 5.0, 4, (0.3, -0.7), np.array([0.2, 1.0])
    est = MassEstimator(5.0, n, force)
    accel = n * np.array(force) / mass
    times = sample_times(np.random.default_rng(33) if irregular else None, 3.0)
    est.update(tuple(v0), 1.0, 0.0)
    assert est.estimate is None
    for t0, t1 in pairwise(times):
        est.update(tuple(v0 + accel * t1), 1.0, t1 - t0)
    assert est.estimate == pytest.approx(mass, rel=1e-9)


# --------------------------------------------------------------------------------------------
# centre of mass: regression and observer (24)
# --------------------------------------------------------------------------------------------


def rk4(rhs, state, h, steps):
    for _ in range(steps):
        k1 = rhs(state)
        k2 = rhs([s + 0.5 * h * d for s, d in zip(state, k1)])
        k3 = rhs([s + 0.5 * h * d for s, d in zip(state, k2)])
        k4 = rhs([s + h * d for s, d in zip(state, k3)])
        state = [
            s + h / 6 * (a + 2 * b + 2 * c + d) for s, a, b, c, d in zip(state, k1, k2, k3, k4)
        ]
    return state


def test_com_regression_regressor_closed_form():
    n, inertia, f, c = 4, 2.0, np.array([0.3, 0.5]), np.array([0.3, -0.4])
    reg = ComRegression(5.0, n, inertia, tuple(f))
    for alpha in np.linspace(-3, 3, 13):
        omega_dot = (n / inertia) * (Q @ rot(alpha) @ c) @ f  # (n/J) z_C⊥ᵀ f
        assert np.array(reg.regressor(alpha)) @ c == pytest.approx(omega_dot, abs=1e-12)


def test_com_regression_recovers_offset():
    n, inertia, f, c = 4, 2.0, (0.3, 0.5), (0.3, -0.4)
    k = n / inertia

    def rhs(s):  # s = (α, ω): α̇ = ω, ω̇ = (n/J) (R(α) c)⊥ᵀ f
        ca, sa = math.cos(s[0]), math.sin(s[0])
        zx, zy = ca * c[0] - sa * c[1], sa * c[0] + ca * c[1]
        return [s[1], k * (-zy * f[0] + zx * f[1])]

    reg = ComRegression(5.0, n, inertia, f)
    state = [0.0, 1.0]
    reg.update(state[1], state[0], 1.0, 0.01)
    assert reg.estimate is None and reg.com_offset(0.0) is None
    for _ in range(2000):
        state = rk4(rhs, state, 0.001, 10)
        reg.update(state[1], state[0], 1.0, 0.01)
    assert np.linalg.norm(np.array(reg.estimate) - c) < 1e-6
    for alpha in (state[0], 0.0, -2.0, 1.3):
        assert np.linalg.norm(np.array(reg.com_offset(alpha)) - rot(alpha) @ c) < 1e-6


def _observer_run(force, z0, omega0, n, inertia, seconds=40.0):
    """Integrate the true planar system in W finely; feed ω at 100 Hz to the observer.

    True system: ż_C = ω z_C⊥, ω̇ = z_C⊥ᵀ f̄, f̄ = (n/J) f — i.e. (19)-(20), which is (21)
    in coordinates whose y axis is along f. Returns times, V = ½‖e‖², and the W errors."""
    fb = (n / inertia * force[0], n / inertia * force[1])

    def rhs(s):
        zx, zy, w = s
        return [-w * zy, w * zx, -zy * fb[0] + zx * fb[1]]

    obs = ComObserver(n, inertia, force, 1.0, omega0)
    state = [z0[0], z0[1], omega0]
    out = []
    for k in range(1, round(seconds / 0.01) + 1):
        state = rk4(rhs, state, 0.0005, 20)
        obs.update(state[2], 1.0, 0.01)
        zh = obs.estimate
        e = (state[0] - zh[0], state[1] - zh[1], state[2] - obs.state[2])
        out.append((0.01 * k, 0.5 * (e[0] ** 2 + e[1] ** 2 + e[2] ** 2), math.hypot(*e)))
    return out, obs, state


def _check_observer(out, v0):
    values = [v0] + [v for _, v, _ in out]
    for before, after in pairwise(values):
        # V̇ = −k_e e3² ≤ 0 in continuous time. The observer's RK4 interpolates the sampled ω
        # linearly, an O(dt²) error: at 100 Hz V can rise by ~1e-9 (≈ 2e-6 V) in one step.
        assert after <= before + 1e-9 + 1e-5 * before
    assert values[-1] < 1e-4 * values[0]
    converged = [t for t, _, err in out if err < 1e-2]
    assert converged and converged[0] < 40.0
    assert all(err < 1e-2 for t, _, err in out if t >= converged[0])


def test_com_observer_lyapunov_and_convergence():
    z0, omega0 = (0.3, -0.4), 1.0
    out, obs, _ = _observer_run((0.0, 1.0), z0, omega0, n=1, inertia=1.0)  # f̄_y = 1
    _check_observer(out, 0.5 * (z0[0] ** 2 + z0[1] ** 2))


def test_com_observer_coordinates_for_a_rotated_force():
    beta = 2.0  # force direction, not +y
    fhat = np.array([math.cos(beta), math.sin(beta)])
    xhat = np.array([fhat[1], -fhat[0]])  # x axis with x⊥ = f̂ (right-handed)
    assert tuple(Q @ xhat) == pytest.approx(tuple(fhat))
    n, inertia = 4, 2.0
    force = tuple(0.5 * fhat)  # f̄ = (n/J)|f| = 1
    z0 = tuple(0.3 * xhat - 0.4 * fhat)  # (x1, x2) = (0.3, −0.4) as above
    obs = ComObserver(n, inertia, force, 1.0, 1.0)
    assert obs.fbar == pytest.approx(1.0)
    zw = np.array([0.9, -0.25])
    assert obs.axis_x == pytest.approx(tuple(xhat)) and obs.axis_y == pytest.approx(tuple(fhat))
    obs.state = [zw @ xhat, zw @ fhat, 0.7]
    assert obs.estimate == pytest.approx(tuple(zw), abs=1e-12)

    out, obs, state = _observer_run(force, z0, 1.0, n, inertia)
    _check_observer(out, 0.5 * (z0[0] ** 2 + z0[1] ** 2))
    assert obs.estimate == pytest.approx((state[0], state[1]), abs=1e-3)


# --------------------------------------------------------------------------------------------
# settling
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("window", [1, 5, 40])
def test_settle_constant_sequence(window):
    det = SettleDetector(window, 0.01)
    # `window` quiet updates after the first value.
    for tick in range(window):
        assert det.update((2.0, -1.0), tick) is False
    assert det.update((2.0, -1.0), window) is True
    assert det.first_settled == window


def test_settle_ignores_jitter_but_not_drift():
    window, tol = 10, 0.05
    # Jitter: every step moves by 0.9·tol·size, but it goes nowhere: settles.
    det = SettleDetector(window, tol)
    base = 3.0
    for tick in range(3 * window):
        det.update((base + (0.9 * tol * base if tick % 2 else 0.0),), tick)
    assert det.settled
    # Drift: each step small (tol·size/window·2), but over a window it moves 2·tol: never.
    det = SettleDetector(window, tol)
    x = 1.0
    for tick in range(500):
        x *= 1.0 + 2.0 * tol / window
        assert det.update((x, 0.0), tick) is False
    assert det.first_settled is None
    # A single jump larger than tol·size resets the streak.
    det = SettleDetector(window, tol)
    for tick in range(3 * window):
        det.update((1.0,), tick)
    assert det.settled
    det.update((1.0 + 2 * tol,), 100)
    assert not det.settled


def test_settle_first_tick():
    window, tol = 4, 0.1
    det = SettleDetector(window, tol)
    ticks = list(range(100, 160, 3))
    for idx, tick in enumerate(ticks[:5]):  # big changes: not settled
        det.update((10.0 + 5.0 * idx,), tick)
    assert not det.settled
    for tick in ticks[5:]:
        det.update((30.0,), tick)
    assert det.first_settled == ticks[4 + 2 * window]  # the big values leave the window first
    first = det.first_settled
    det.update((60.0,), 999)  # a jump: unsettled again, first tick kept
    assert not det.settled and det.first_settled == first


def test_settle_uses_floor_near_zero():
    window, tol, floor = 5, 0.1, 1e-3
    limit = tol * floor
    det = SettleDetector(window, tol, floor)
    for tick in range(20):  # around zero: steps of 0.9·tol·floor are tolerated
        det.update((0.45 * limit * (-1) ** tick,), tick)
    assert det.settled
    det = SettleDetector(window, tol, floor)
    for tick in range(20):
        det.update((0.55 * limit * (-1) ** tick,), tick)  # steps of 1.1·tol·floor
    assert not det.settled


# --------------------------------------------------------------------------------------------
# excitation
# --------------------------------------------------------------------------------------------


def _random_connected_edges(rng, n: int) -> set[tuple[int, int]]:
    """A random spanning path of ``n`` nodes plus up to ``n − 1`` random extra edges."""
    order = rng.permutation(n)
    edges = {tuple(sorted((int(order[i]), int(order[i + 1])))) for i in range(n - 1)}
    for _ in range(int(rng.integers(0, n))):
        i, j = rng.choice(n, size=2, replace=False)
        edges.add((int(min(i, j)), int(max(i, j))))
    return edges


@FAST
@given(
    st.integers(0, 10_000),
    st.floats(0.05, 2.0),
    st.booleans(),
    st.floats(0.1, 5.0),
    st.floats(0.2, 3.0),
)
def test_spin_up_force_net_force_and_torque(seed, speed, negative, gain, target):
    rng = np.random.default_rng(seed)
    omega = -speed if negative else speed
    n = int(rng.integers(2, 7))
    p = rng.uniform(-2, 2, size=(n, 2))
    edges = _random_connected_edges(rng, n)
    nb = neighbours_of(n, sorted(edges))
    ref, v = rng.uniform(-1, 1, 2), rng.uniform(-1, 1, 2)
    vel = [v + omega * (Q @ (p[i] - ref)) for i in range(n)]  # rigid-body velocities
    forces = np.array(
        [spin_up_force(gain, target, [tuple(vel[i] - vel[j]) for j in nb[i]]) for i in range(n)]
    )
    assert np.abs(forces.sum(axis=0)).max() < 1e-12
    expected = 0.0
    for i, j in edges:
        dist = np.linalg.norm(p[i] - p[j])
        expected += (1.0 - abs(omega) * dist / target) * dist**2
    expected *= gain * omega
    for q in (np.zeros(2), rng.uniform(-5, 5, 2)):
        torque = sum((Q @ (p[i] - q)) @ forces[i] for i in range(n))
        assert torque == pytest.approx(expected, rel=1e-9, abs=1e-12)


@FAST
@given(st.integers(0, 10_000), st.floats(0.05, 3.0), st.floats(1.0, 60.0), st.floats(0.0, 1.0))
def test_capped_spin_up_force_bounds_each_robot_and_keeps_no_net_force(seed, speed, gain, drive):
    """Each edge's term within ``max_force / max(d_i, d_j)``: no robot's sum beyond
    ``max_force``, and the terms still cancel in pairs (no net force), at gains that would
    otherwise ask for several times ``max_force``."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 8))
    p = rng.uniform(-2, 2, size=(n, 2))
    edges = _random_connected_edges(rng, n)
    nb = neighbours_of(n, sorted(edges))
    degree = [len(nb[i]) for i in range(n)]
    v = rng.uniform(-1, 1, 2)
    vel = [v + speed * (Q @ p[i]) for i in range(n)]
    most = 10.0
    forces = np.array(
        [
            capped_spin_up_force(
                gain,
                1.0,
                [(tuple(vel[i] - vel[j]), most / max(degree[i], degree[j])) for j in nb[i]],
                drive,
            )
            for i in range(n)
        ]
    )
    assert np.abs(forces.sum(axis=0)).max() < 1e-9
    assert np.linalg.norm(forces, axis=1).max() <= most * (1 + 1e-12)
    # Uncapped and at full drive, the capped law is the plain one.
    plain = [spin_up_force(gain, 1.0, [tuple(vel[i] - vel[j]) for j in nb[i]]) for i in range(n)]
    roomy = [
        capped_spin_up_force(gain, 1.0, [(tuple(vel[i] - vel[j]), math.inf) for j in nb[i]])
        for i in range(n)
    ]
    assert np.allclose(roomy, plain, rtol=1e-12, atol=1e-12)


def test_capped_spin_up_force_drive_fades_only_the_terms_that_speed_the_turn_up():
    slow, fast = (0.3, 0.0), (0.0, 1.5)  # below and beyond the target speed of 1 m/s
    assert capped_spin_up_force(10.0, 1.0, [(slow, math.inf)], drive=0.0) == (0.0, 0.0)
    half = capped_spin_up_force(10.0, 1.0, [(slow, math.inf)], drive=0.5)
    assert half == pytest.approx((0.5 * 10.0 * 0.7 * 0.3, 0.0))
    braking = capped_spin_up_force(10.0, 1.0, [(fast, math.inf)], drive=0.0)
    assert braking == pytest.approx((0.0, 10.0 * (1.0 - 1.5) * 1.5))


def test_kick_force_magnitude_and_determinism():
    for seed in (0, 1, 42):
        for robot in range(1, 6):
            f = kick_force(seed, robot, 3.5)
            assert math.hypot(*f) == pytest.approx(3.5, rel=1e-12)
            assert kick_force(seed, robot, 3.5) == f
            g = kick_force(seed, robot, 0.5)  # same direction, other magnitude
            assert g == pytest.approx((f[0] / 7.0, f[1] / 7.0), abs=1e-12)
    directions = [kick_force(7, robot, 1.0) for robot in range(1, 201)]
    assert len(set(directions)) == 200
    mean = np.mean(directions, axis=0)
    assert np.linalg.norm(mean) < 0.3  # spread over all directions, not one bias
    assert kick_force(1, 3, 1.0) != kick_force(2, 3, 1.0)


# --------------------------------------------------------------------------------------------
# safety
# --------------------------------------------------------------------------------------------


def test_saturate_closed_forms():
    assert saturate((3.0, 4.0), 10.0) == (3.0, 4.0)
    assert saturate((30.0, -40.0), 10.0) == pytest.approx((6.0, -8.0), abs=1e-12)
    assert saturate((math.nan, 1.0), 10.0) == (0.0, 0.0)
    assert saturate((1.0, math.inf), 10.0) == (0.0, 0.0)
    assert saturate((-math.inf, math.nan), 10.0) == (0.0, 0.0)
    assert saturate((2.0, 0.0), 0.0) == (0.0, 0.0)


@FAST
@given(lengths, angles, st.one_of(st.just(0.0), st.floats(1e-6, 20.0)))
def test_saturate_bounds_and_keeps_direction(r, a, limit):
    force = tuple(polar(10 * r, a))
    got = saturate(force, limit)
    mag = math.hypot(*got)
    assert mag <= limit * (1 + 1e-12)
    assert mag == pytest.approx(min(10 * r, limit), rel=1e-12, abs=1e-300)
    if mag > 0:
        assert cross(force, got) == pytest.approx(0.0, abs=1e-9 * 10 * r * mag)
        assert force[0] * got[0] + force[1] * got[1] > 0
