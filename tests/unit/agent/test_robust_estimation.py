"""The robust estimators (``[agent] estimator = "robust"``), each alone against the rigid-body
model: exact without noise, and under noise far better than the paper's estimators with the
same samples, with standard deviations of the size of their errors."""

from __future__ import annotations

import inspect
import math

import numpy as np
import pytest

from agent.algorithm.estimation.estimator import Estimator
from agent.algorithm.estimation.settling import SettleDetector, SettleDetectors
from agent.algorithm.paper.relative_position import RelativePosition
from agent.algorithm.robust import drive_gain
from agent.algorithm.robust.arc_fit import ArcRelativePosition
from agent.algorithm.robust.com_fit import ComFit
from agent.algorithm.robust.drive_gain import DriveGain
from agent.algorithm.robust.inertia_fit import InertiaFit
from agent.algorithm.robust.least_squares import LeastSquares
from agent.algorithm.robust.mass_fit import MassFit
from agent.algorithm.robust.normal_equations import accumulator, quadratic_form, solver
from agent.algorithm.robust.phases import RobustPhases
from agent.algorithm.robust.tuning import RobustTuning
from agent.algorithm.tuning import AgentConfig, AgentTuning, Estimators
from agent.platform.config import ConfigError, from_table, to_toml
from agent.platform.geometry import rotate
from agent.platform.protocol import GRAVITY, Phase

DT = 0.01


# ------------------------------------------------------------------------------ least squares
def test_least_squares_matches_numpy() -> None:
    rng = np.random.default_rng(3)
    a = rng.normal(size=(200, 4))
    b = a @ np.array([1.0, -2.0, 0.5, 3.0]) + 0.01 * rng.normal(size=200)
    fit = LeastSquares(4)
    for row, target in zip(a, b):
        fit.add(tuple(row), float(target))
    solution = fit.solve()
    expected, rss, *_ = np.linalg.lstsq(a, b, rcond=None)
    assert solution.estimate == pytest.approx(expected, abs=1e-10)
    assert solution.variance == pytest.approx(rss[0] / (200 - 4), rel=1e-6)
    covariance = solution.variance * np.linalg.inv(a.T @ a)
    assert np.array(solution.covariance()) == pytest.approx(covariance, rel=1e-6, abs=1e-15)
    g = np.array([0.0, 1.0, -1.0, 2.0])
    assert solution.variance_of(g) == pytest.approx(g @ covariance @ g, rel=1e-6)


def test_least_squares_is_none_until_the_rows_determine_it() -> None:
    fit = LeastSquares(3)
    assert fit.solve() is None
    for _ in range(10):
        fit.add((1.0, 2.0, 3.0), 1.0)  # always the same row: rank 1
    assert fit.solve() is None
    with pytest.raises(ValueError):
        LeastSquares(0)
    with pytest.raises(ValueError):
        LeastSquares(2, forgetting=0.0)


def test_least_squares_forgetting_follows_a_change() -> None:
    fit = LeastSquares(1, forgetting=math.exp(-DT / 0.5))
    for k in range(1000):
        fit.add((1.0,), 1.0 if k < 500 else 2.0)
    assert fit.solve().estimate[0] == pytest.approx(2.0, abs=1e-3)


def _dot(pairs) -> float:
    """``Σ a·b``, term by term from the first (0.0 for none)."""
    total = None
    for a, b in pairs:
        total = a * b if total is None else total + a * b
    return 0.0 if total is None else total


def _solved_by_loops(m: list[float], v: list[float], p: int):
    """The normal equations solved by the textbook loops that the generated solver writes
    out (``normal_equations``' docstring): ``(p̂, M⁻¹, p̂ᵀ v)``, or ``None``."""
    scale = max(abs(m[i * p + i]) for i in range(p))
    if scale == 0.0 or not math.isfinite(scale):
        return None
    low = [0.0] * (p * p)
    for i in range(p):
        for j in range(i + 1):
            total = m[i * p + j] - _dot((low[i * p + k], low[j * p + k]) for k in range(j))
            if i == j:
                if total <= 1e-13 * scale:
                    return None
                low[i * p + i] = math.sqrt(total)
            else:
                low[i * p + j] = total / low[j * p + j]
    inv_low = [0.0] * (p * p)
    for i in range(p):
        inv_low[i * p + i] = 1.0 / low[i * p + i]
        for j in range(i):
            total = _dot((low[i * p + k], inv_low[k * p + j]) for k in range(j, i))
            inv_low[i * p + j] = -total / low[i * p + i]
    inverse = tuple(
        _dot((inv_low[k * p + i], inv_low[k * p + j]) for k in range(max(i, j), p))
        for i in range(p)
        for j in range(p)
    )
    estimate = tuple(_dot((inverse[i * p + j], v[j]) for j in range(p)) for i in range(p))
    return estimate, inverse, _dot(zip(estimate, v))


@pytest.mark.parametrize("p", range(1, 8))
def test_normal_equations_are_the_loops_bit_for_bit(p: int) -> None:
    rng = np.random.default_rng(p)
    for trial in range(20):
        rows = rng.normal(size=(3 * p, p)) * rng.uniform(1e-3, 1e3, size=p)
        if trial % 5 == 0:
            rows[:, -1] = 0.0  # a parameter the rows never reach: singular
        m, v = [0.0] * (p * p), [0.0] * p
        m_loops, v_loops = [0.0] * (p * p), [0.0] * p
        add = accumulator(p)
        for row, target in zip(rows.tolist(), rng.normal(size=3 * p).tolist()):
            add(m, v, row, target)
            for i in range(p):  # the loops it writes out (here over all of M)
                v_loops[i] += row[i] * target
                for j in range(p):
                    m_loops[i * p + j] += row[i] * row[j]
        assert v == v_loops
        assert [m[i * p + j] for i in range(p) for j in range(i + 1)] == [
            m_loops[i * p + j] for i in range(p) for j in range(i + 1)
        ]
        expected = _solved_by_loops(m_loops, v, p)
        assert solver(p)(m, v) == expected
        assert (expected is None) == (trial % 5 == 0)
        if expected is not None:
            inverse = expected[1]
            g = (rng.normal(size=p) * (rng.uniform(size=p) < 0.7)).tolist()  # some g_i = 0
            form = 0.0
            for i in range(p):
                if g[i]:
                    form += g[i] * _dot((inverse[i * p + j], g[j]) for j in range(p))
            assert quadratic_form(p)(inverse, g) == form


# ------------------------------------------------------------------------------ Step 1
def _arc(r: float, phase0: float, omega, sigma: float, seconds: float, seed: int):
    """Samples of ``ż_ij`` for a contact pair ``r`` apart on a load turning by ``omega(t)``
    (its integral given as ``(ω(t), θ(t))``), with white noise ``σ`` per axis and robot, and
    the true ``z_ij`` at the last sample."""
    rng = np.random.default_rng(seed)
    samples = []
    for k in range(round(seconds / DT)):
        w, angle = omega(k * DT)
        z = (r * math.cos(phase0 + angle), r * math.sin(phase0 + angle))
        noise = math.sqrt(2.0) * sigma * rng.normal(size=2)
        samples.append((-w * z[1] + noise[0], w * z[0] + noise[1]))
    return samples, z


def _varying(t: float) -> tuple[float, float]:
    return 0.3 + 0.2 * math.sin(t), 0.3 * t - 0.2 * math.cos(t) + 0.2


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_arc_fit_is_exact_without_noise(sign: float) -> None:
    def omega(t):
        w, a = _varying(t)
        return sign * w, sign * a

    samples, z = _arc(1.7, 0.4, omega, 0.0, 8.0, 1)
    edge = ArcRelativePosition()
    for zdot in samples:
        edge.update(zdot, DT)
    assert edge.distance == pytest.approx(1.7, abs=1e-5)
    assert math.dist(edge.estimate, z) < 2e-5


def test_arc_fit_waits_for_an_arc_and_for_motion() -> None:
    edge = ArcRelativePosition()
    for _ in range(50):
        edge.update((0.0, 0.0), DT)  # at rest: nothing to fit
    assert not edge.moving and edge.estimate is None and edge.covariance is None
    samples, _ = _arc(1.5, 0.0, _varying, 0.01, 0.05, 2)
    for zdot in samples:
        edge.update(zdot, DT)
    assert edge.estimate is None  # five samples: no circle yet


def test_arc_fit_under_noise_beats_the_paper_and_knows_its_error() -> None:
    """1 cm/s per axis and robot, 10 s of a load turning at 0.3 ± 0.2 rad/s, 20 seeds."""
    arc_errors, paper_errors, ratios = [], [], []
    for seed in range(20):
        samples, z = _arc(1.5, seed, _varying, 0.01, 10.0, seed)
        edge, paper = ArcRelativePosition(), RelativePosition(5.0)
        for zdot in samples:
            edge.update(zdot, DT)
            paper.update(zdot, DT)
        error = np.subtract(edge.estimate, z)
        arc_errors.append(np.linalg.norm(error))
        paper_errors.append(math.dist(paper.estimate, z))
        (xx, xy), (_, yy) = edge.covariance
        ratios.append(error @ np.linalg.inv([[xx, xy], [xy, yy]]) @ error / 2.0)
    assert np.median(arc_errors) < 0.01  # m: under a centimetre
    assert np.median(arc_errors) < 0.2 * np.median(paper_errors)
    assert 0.3 < np.mean(ratios) < 3.0  # the published covariance is of the error's size


# ------------------------------------------------------------------------------ Step 4
def _spin(moment: float, seconds: float, noise: float = 0.0, seed: int = 0, friction: float = 0.0):
    """A load spun by ``±τ`` in turns of 0.5 s against a floor's friction torque
    ``−friction sgn ω`` (it keeps turning one way): ``(angle, torque)`` samples."""
    rng = np.random.default_rng(seed)
    theta, omega, out = 0.3, 0.5, [(0.3, 0.0)]
    for k in range(round(seconds / DT)):
        torque = 7.0 if (k // 50) % 2 == 0 else -7.0
        felt = torque - math.copysign(friction, omega)
        theta += omega * DT + 0.5 * felt / moment * DT * DT
        omega += felt / moment * DT
        assert omega > 0.0
        out.append((theta + noise * rng.normal(), torque))
    return out


def test_inertia_fit_is_exact_without_noise() -> None:
    fit = InertiaFit()
    assert fit.estimate is None and fit.std is None and fit.covariance is None
    for angle, torque in _spin(12.3795, 2.0):
        fit.update(angle, torque, DT)
    assert fit.estimate == pytest.approx(12.3795, rel=1e-9)


def test_inertia_fit_finds_the_floors_friction_torque() -> None:
    """A friction torque the fit left out would read as a larger ``J`` (it brakes the turn
    while the torque speeds it up, helps while it brakes): with its column, both are exact."""
    fit = InertiaFit()
    for angle, torque in _spin(12.3795, 2.0, friction=1.5):
        fit.update(angle, torque, DT)
    assert fit.estimate == pytest.approx(12.3795, rel=1e-9)
    assert fit.friction_torque[0] == pytest.approx(1.5, rel=1e-9)
    frictionless = InertiaFit()
    for angle, torque in _spin(12.3795, 2.0):
        frictionless.update(angle, torque, DT)
    assert frictionless.friction_torque[0] == pytest.approx(0.0, abs=1e-9)


def test_inertia_fit_std_grows_with_the_angle_noise_and_the_torque_scale() -> None:
    stds = []
    for noise in (1e-4, 1e-3):
        fit = InertiaFit()
        for angle, torque in _spin(12.0, 3.0, noise, 7):
            fit.update(angle, torque, DT)
        assert fit.estimate == pytest.approx(12.0, rel=0.05)
        assert fit.fit_std == fit.std  # no torque scale: the fit's share is all of it
        stds.append(fit.std)
    assert stds[1] > 5 * stds[0]
    scaled = InertiaFit(torque_scale_std=0.01)
    for angle, torque in _spin(12.0, 3.0):
        scaled.update(angle, torque, DT)
    assert scaled.std == pytest.approx(0.01 * 12.0, rel=1e-3)  # Ĵ ∝ w: 1 % of w, 1 % of J
    assert scaled.fit_std < 1e-3 * scaled.std  # noise-free: the torque scale's alone


# ------------------------------------------------------------------------------ Step 5
def test_com_fit_is_exact_without_noise() -> None:
    """A load pushed by ``n`` robots with ``f`` each turns by ``J θ̈ = n (Q R(α) c)ᵀ f``."""
    n, moment, force, c = 4, 12.0, (0.0, 3.0), (-0.12, 0.05)
    theta, omega, fine = 0.0, 0.6, 100
    fit = ComFit(n, moment, force)
    fit.update(0.0, 1.0, DT)
    for _ in range(300):
        for _ in range(fine):  # the plant, finer than the samples
            zc = rotate(c, theta)
            torque = n * (-zc[1] * force[0] + zc[0] * force[1])
            omega += torque / moment * DT / fine
            theta += omega * DT / fine
        fit.update(theta, 1.0, DT)
    assert math.dist(fit.estimate, c) < 1e-5
    assert math.dist(fit.com_offset(theta), rotate(c, theta)) < 1e-5
    assert fit.std < 1e-3


# ------------------------------------------------------------------------------ Step 7
def test_mass_fit_is_exact_without_noise() -> None:
    """The COM accelerates at ``n f / m``; a contact ``o`` away from it turns at 0.8 rad/s."""
    n, mass, force, offset0 = 4, 5.0, (0.0, 3.0), (1.2, -0.7)
    fit = MassFit(n, force)
    v0 = (0.1, -0.2)
    for k in range(400):
        t = k * DT
        angle = 0.8 * t
        offset = rotate(offset0, angle)  # p_Ci − p_C
        com_velocity = (v0[0] + n * force[0] / mass * t, v0[1] + n * force[1] / mass * t)
        contact_velocity = (com_velocity[0] - 0.8 * offset[1], com_velocity[1] + 0.8 * offset[0])
        fit.update(contact_velocity, offset, angle, 1.0, DT, com_velocity=com_velocity)
    assert fit.estimate == pytest.approx(mass, rel=1e-4)
    assert fit.std < 1e-3


def test_mass_fit_widens_by_an_uncertain_offset_as_the_load_turns() -> None:
    """A contact's offset to the COM given 5 cm off: as the load turns the fit's COM
    displacement is off by ``(R(α) − I) δ``. Told the offset's uncertainty, the published
    ``m̂`` holds the truth; told nothing, it is as confidently wrong as the data are clean."""
    n, mass, force, offset0, delta = 4, 5.0, (0.0, 3.0), (1.2, -0.7), (0.05, 0.0)
    v0 = (0.1, -0.2)

    def fitted(offset_std: float, rate: float) -> MassFit:
        fit = MassFit(n, force, offset_std=offset_std)
        for k in range(400):
            t = k * DT
            angle = rate * t
            offset = rotate(offset0, angle)  # p_Ci − p_C
            told = rotate((offset0[0] + delta[0], offset0[1] + delta[1]), angle)
            com_velocity = (v0[0] + n * force[0] / mass * t, v0[1] + n * force[1] / mass * t)
            contact = (com_velocity[0] - rate * offset[1], com_velocity[1] + rate * offset[0])
            fit.update(contact, told, angle, 1.0, DT, com_velocity=com_velocity)
        return fit

    blind, told = fitted(0.0, 0.8), fitted(0.05, 0.8)
    error = abs(blind.estimate - mass)
    assert error > 0.01 * mass  # the offset's error moves the mass by over 1 %
    assert error > 5 * blind.std  # and nothing says so
    assert told.estimate == blind.estimate  # the estimate is the same, its uncertainty not
    assert error < 1.96 * told.std < 20 * error
    still = fitted(0.05, 0.0)  # a load that does not turn: the offset's error moves nothing
    assert still.estimate == pytest.approx(mass, rel=1e-4)
    assert still.std == pytest.approx(fitted(0.0, 0.0).std, rel=1e-9)


@pytest.mark.parametrize(
    ("mu", "mass", "push", "tolerance", "mu_tolerance"),
    [
        (0.0, 5.0, 4.0, 2e-3, 2e-4),
        (0.02, 5.0, 4.0, 2e-3, 2e-4),
        (0.3, 20.0, 25.0, 5e-3, 2e-3),
    ],
)
def test_mass_fit_finds_the_floors_coulomb_friction_while_the_load_translates(
    mu: float, mass: float, push: float, tolerance: float, mu_tolerance: float
) -> None:
    """A load that translates (no turn) under a reversing push ``±n f`` slides against
    ``−μ m g v̂_C``: the fit finds ``m`` and ``μ`` (the velocity is taken to change linearly
    over a tick, which places a reversal within a fraction of one: the larger ``μ``, the more
    that costs; on μ = 0.3, m 0.34 % and μ 0.0012 off)."""
    n, force, offset = 4, (0.0, push), (1.2, -0.7)
    commanded, _ = _reversing_push(8.0, 2.0)
    fit = MassFit(n, force)
    velocity, fine = [0.0, 0.1], 100
    for k, sign in enumerate(commanded):
        fit.update(
            tuple(velocity),
            offset,
            0.0,
            commanded[k - 1] if k else 1.0,
            DT,
            com_velocity=tuple(velocity),
        )
        for _ in range(fine):
            speed = math.hypot(*velocity)
            drag = (
                (0.0, 0.0)
                if speed == 0
                else (-mu * GRAVITY * velocity[0] / speed, -mu * GRAVITY * velocity[1] / speed)
            )
            velocity[0] += (n * sign * force[0] / mass + drag[0]) * DT / fine
            velocity[1] += (n * sign * force[1] / mass + drag[1]) * DT / fine
    assert fit.estimate == pytest.approx(mass, rel=tolerance)
    assert fit.coulomb[0] == pytest.approx(mu, abs=mu_tolerance)


def test_every_robust_estimator_has_the_common_shape() -> None:
    for est in (
        ArcRelativePosition(),
        InertiaFit(),
        ComFit(4, 2.0, (0.0, 1.0)),
        MassFit(4, (0, 1)),
    ):
        cls = type(est)
        assert isinstance(est, Estimator), cls
        positional = [
            name
            for name, p in inspect.signature(cls.update).parameters.items()
            if p.kind is p.POSITIONAL_OR_KEYWORD
        ]
        assert positional[-1] == "dt", cls
        assert est.estimate is None and est.covariance is None, cls


# ------------------------------------------------------------------------------ settling
def test_settling_by_uncertainty() -> None:
    det = SettleDetector(3, 1e-4, uncertainty=0.01)
    for tick in range(10):  # above 1 % and shrinking: not yet, however still it is
        assert not det.update((1.0,), tick, std=0.05 * 0.9**tick)
    for tick in range(10, 12):
        assert not det.update((1.3,), tick, std=0.005)  # it moved, but knows it within 0.5 %
    assert det.update((1.2,), 12, std=0.005)  # a third update in a row: settled
    assert det.first_settled == 12
    # A small vector judged against a scale (an offset against the load's size).
    det = SettleDetector(1, 1e-4, uncertainty=0.01)
    assert not det.update((0.01, 0.0), 0, std=0.001)
    det = SettleDetector(1, 1e-4, uncertainty=0.01)
    det.update((0.01, 0.0), 0, std=0.001, scale=1.0)
    assert det.update((0.01, 0.0), 1, std=0.001, scale=1.0)


def test_an_uncertainty_that_stopped_shrinking_settles_too() -> None:
    """A small load under much noise may never reach 1 %: once its uncertainty stops shrinking
    (by under 2 % over a window) the estimate counts as settled, at its honest σ."""
    det = SettleDetector(3, 1e-4, uncertainty=0.01)
    ticks = [tick for tick in range(20) if det.update((1.0,), tick, std=0.2)]
    assert ticks[0] == 5  # σ a window apart from tick 3 on, then three such updates in a row


def test_settling_an_iterated_estimate_needs_its_drift_within_its_uncertainty() -> None:
    det = SettleDetector(5, 1e-4, uncertainty=0.01, iterated=True)
    x = 1.0
    for tick in range(50):  # small uncertainty, but it drifts by 10 σ per window
        x += 0.002
        assert not det.update((x,), tick, std=0.001)
    for tick in range(50, 60):
        det.update((x + 0.0005 * (-1) ** tick,), tick, std=0.001)  # jitter within 3 σ
    assert det.settled
    detectors = SettleDetectors.of(5, 1e-4, 0.01)
    assert [d.iterated for d in _fields(detectors)] == [
        True,
        True,
        True,
        True,
        False,
        False,
    ]


def _fields(detectors: SettleDetectors) -> list[SettleDetector]:
    return [getattr(detectors, name) for name in detectors.__dataclass_fields__]


# ------------------------------------------------------------------------------ configuration
def test_the_estimator_is_chosen_by_name() -> None:
    tuning = from_table(AgentTuning, {"estimator": "robust"}, "agent")
    assert tuning.estimator is Estimators.ROBUST
    assert AgentTuning().estimator is Estimators.ROBUST  # the default, for real robots
    assert from_table(AgentTuning, {"estimator": "paper"}, "agent").estimator is Estimators.PAPER
    assert 'estimator = "robust"' in to_toml(tuning)
    assert from_table(AgentTuning, {"estimator": "robust"}, "agent") == tuning
    with pytest.raises(ConfigError, match="agent.estimator: expected one of paper, robust"):
        from_table(AgentTuning, {"estimator": "kalman"}, "agent")
    with pytest.raises(ConfigError, match="robust.push_force"):
        AgentTuning(robust=RobustTuning(push_force=20.0)).validate("agent")


class _Own:
    """What the phase machine reads of a robot's estimates, with a given ω."""

    def __init__(self, omega: float):
        self.instant = 0
        self.omega = omega
        self.measured = 0
        self.zdot = {}
        self.centroid = (1.0, 0.5)
        self.mean_square_offset = 2.0
        self.moment = 12.0
        self.stuck = False


def test_robust_inertia_torque_follows_the_clock_not_each_robots_noisy_omega() -> None:
    """Two robots whose ω differ by their noise reverse the torque at the same ticks: speeding
    up and braking (with ``inertia_brake_level`` of the torque) for a flip each, after braking
    for ``inertia_brake_s`` if it is set."""
    schedules = []
    for omega, brake in ((0.49, 0.0), (0.51, 0.0), (0.5, 0.25)):
        robust = RobustTuning(inertia_flip_s=0.5, inertia_brake_s=brake)
        tuning = AgentTuning(estimator=Estimators.ROBUST, robust=robust)
        machine = RobustPhases(AgentConfig(1, 4, (2,), DT, tuning=tuning))
        machine.entered[Phase.INERTIA] = 100
        machine.barrier.phase = Phase.INERTIA
        machine.inertia_torque, machine.inertia_gain, machine.spin_sign = 2.8, 1.4, 1.0
        machine._begin(Phase.INERTIA)
        own = _Own(omega)
        for k in range(100, 300):
            machine.force(k, own, (0.0, 0.0))
        torques = [machine._torque[k] for k in range(100, 300)]
        braking = -2.8 * robust.inertia_brake_level
        if brake:
            torques = torques[25:]  # braking first for 0.25 s
            assert machine._torque[100] == braking and machine._torque[124] == braking
        assert torques[:50] == [2.8] * 50 and torques[50:100] == [braking] * 50
        schedules.append(torques[:175])
    assert schedules[0] == schedules[1] == schedules[2]


# ------------------------------------------------------------------------------ the push reverses
def _reversing_push(seconds: float, flip_s: float, lag: float = 0.0):
    """The common force's sign each tick (``+`` for ``T/2``, then ``−``, ``+`` for ``T``
    each, as :meth:`~agent.algorithm.phase_machine.PhaseMachine.push_sign`) and the sign each drive
    applies after its first-order lag ``lag``, averaged over the tick (fine steps)."""
    period, fine = round(flip_s / DT), 100
    commanded, applied, level = [], [], 0.0
    for k in range(round(seconds / DT)):
        sign = 1.0 if k < period // 2 else (-1.0 if (k - period // 2) // period % 2 == 0 else 1.0)
        commanded.append(sign)
        total = 0.0
        for _ in range(fine):
            level = sign if lag == 0 else level + (sign - level) * (DT / fine) / lag
            total += level / fine
        applied.append(total)
    return commanded, applied


@pytest.mark.parametrize("lag", [0.0, 0.02])
def test_mass_fit_with_a_reversing_push_and_lagging_drives(lag: float) -> None:
    """The COM swings back and forth under ``±n f``; the drives' lag (Step 4 finds it) is
    taken up by ``S − τ_d Σ + τ_d² s``."""
    n, mass, force, offset0, v0 = 4, 5.0, (0.0, 3.0), (1.2, -0.7), (0.1, -0.2)
    commanded, applied = _reversing_push(6.0, 1.0, lag)
    fits = {"modelled": MassFit(n, force, lag=lag), "ignored": MassFit(n, force)}
    velocity = list(v0)
    travel = 0.0
    for k, level in enumerate(applied):
        angle = 0.8 * k * DT
        offset = rotate(offset0, angle)
        contact = (velocity[0] - 0.8 * offset[1], velocity[1] + 0.8 * offset[0])
        for fit in fits.values():
            before = commanded[k - 1] if k else 1.0
            fit.update(contact, offset, angle, before, DT, com_velocity=tuple(velocity))
        velocity[1] += n * force[1] * level / mass * DT
        travel = max(travel, abs(velocity[1] - v0[1]))
    assert travel < n * force[1] * 1.0 / mass  # the speed swings by at most n f T / 2m each way
    error = {name: abs(fit.estimate - mass) / mass for name, fit in fits.items()}
    assert error["modelled"] < (3e-5 if lag == 0 else 1e-3), error
    if lag:
        assert error["ignored"] > 5 * error["modelled"], error


def test_com_fit_with_a_reversing_push() -> None:
    """The torque ``n (Q R(α) c)ᵀ f`` reverses with the push: the fit follows the sign."""
    n, moment, force, c = 4, 12.0, (0.0, 3.0), (-0.12, 0.05)
    commanded, _ = _reversing_push(3.0, 1.0)
    theta, omega, fine = 0.0, 0.6, 100
    fit = ComFit(n, moment, force)
    fit.update(0.0, 1.0, DT)
    for sign in commanded:
        for _ in range(fine):
            zc = rotate(c, theta)
            torque = sign * n * (-zc[1] * force[0] + zc[0] * force[1])
            omega += torque / moment * DT / fine
            theta += omega * DT / fine
        fit.update(theta, sign, DT)
    assert math.dist(fit.estimate, c) < 5e-5


def _started(**fits: ComFit) -> dict[str, ComFit]:
    """``fits`` by name, each started at the push's first instant (α = 0)."""
    for fit in fits.values():
        fit.update(0.0, 1.0, DT)
    return fits


def _push_torque(n: int, force, c, theta: float) -> float:
    """``n z_C × f`` about the COM, ``z_C = R(θ) c``: the common force ``f`` at the centroid."""
    zc = rotate(c, theta)
    return n * (zc[0] * force[1] - zc[1] * force[0])


@pytest.mark.parametrize("lag", [0.02, 0.05])
def test_com_fit_through_lagging_drives_while_the_load_turns(lag: float) -> None:
    """The drives lag the push in ``W`` while ``z_C`` turns with the load: the torque is
    ``n z_C(t) × K[s f](t)``. The fit that takes the drives' response in place of the sign finds
    ``c`` to a small fraction of the rotation by ``τ_d ω`` that lagging the regressor itself
    would leave (``τ_d ω |c|``: 1.6 and 3.9 mm here), and one that ignores the lag is off."""
    n, moment, force, c = 4, 12.0, (0.0, 3.0), (-0.12, 0.05)
    commanded, _ = _reversing_push(4.0, 1.0)
    theta, omega, fine, level = 0.0, 0.6, 100, 0.0
    fits = _started(modelled=ComFit(n, moment, force, lag=lag), ignored=ComFit(n, moment, force))
    for sign in commanded:
        for _ in range(fine):
            level += (sign - level) * (1.0 - math.exp(-DT / fine / lag))
            omega += level * _push_torque(n, force, c, theta) / moment * DT / fine
            theta += omega * DT / fine
        for fit in fits.values():
            fit.update(theta, sign, DT)
    error = {name: math.dist(fit.estimate, c) for name, fit in fits.items()}
    assert error["modelled"] < 0.05 * lag * omega * math.hypot(*c), error
    assert error["ignored"] > 20 * error["modelled"], error


def test_com_fit_takes_the_floors_torque_falling_as_the_com_moves() -> None:
    """On a floor the torque against the turn is ``τ_c ρ d``, ``d = ω / √(v² + ω² ρ²)``: it
    falls as the COM speeds up under the push, whose sign the speed follows, so it turns the
    load as the push does. Step 5's sixth column takes that fall up; the fit without it is 13 mm
    off."""
    n, moment, force, c = 4, 12.0, (0.0, 3.0), (-0.12, 0.05)
    radius, friction, keep, mass = 0.8, 2.0, 2.0, 20.0
    commanded, _ = _reversing_push(6.0, 2.0)
    theta, omega, speed, fine = 0.0, 1.0, 0.0, 100
    fits = _started(fall=ComFit(n, moment, force, falling=True), none=ComFit(n, moment, force))
    for sign in commanded:
        for _ in range(fine):
            push = sign * _push_torque(n, force, c, theta)
            fall = radius * omega / math.sqrt(speed * speed + (omega * radius) ** 2)
            omega += (push + keep - friction * fall) / moment * DT / fine
            theta += omega * DT / fine
            speed += sign * n * force[1] / mass * DT / fine
        fall = radius * omega / math.sqrt(speed * speed + (omega * radius) ** 2) - 1.0
        for name, fit in fits.items():
            fit.update(theta, sign, DT, fall=fall if name == "fall" else 0.0)
    error = {name: math.dist(fit.estimate, c) for name, fit in fits.items()}
    assert error["fall"] < 1e-4, error
    assert error["none"] > 100 * error["fall"] and error["none"] > 5e-3, error


def test_mass_and_com_fits_take_a_damped_push() -> None:
    """Every robot adds ``a = −b ṗ_G`` to the reversing push (``push_damping``): the COM's speed
    stays within ``f / b``, and both fits, told ``a`` per tick, stay exact."""
    n, mass, moment, force, b = 4, 2.0, 3.0, (0.0, 3.0), 2.0
    c, offset0, v0 = (-0.12, 0.05), (1.2, -0.7), [0.3, -0.2]
    commanded, _ = _reversing_push(6.0, 1.0)
    mass_fit, com_fit = MassFit(n, force), ComFit(n, moment, force)
    com_fit.update(0.0, 1.0, DT)
    velocity, theta, omega, fine, fastest = list(v0), 0.0, 0.6, 100, 0.0
    previous = (0.0, 0.0)
    for k, sign in enumerate(commanded):
        offset = rotate(offset0, theta)
        contact = (velocity[0] - omega * offset[1], velocity[1] + omega * offset[0])
        # ṗ_G = ṗ_C + ω Q z_C, as every robot estimates it from Step 2 (here exactly)
        zc = rotate(c, theta)
        added = (-b * (velocity[0] - omega * zc[1]), -b * (velocity[1] + omega * zc[0]))
        before = commanded[k - 1] if k else 1.0
        mass_fit.update(
            contact, offset, theta, before, DT, added=previous, com_velocity=tuple(velocity)
        )
        if k:
            com_fit.update(theta, commanded[k - 1], DT, added=previous)
        total = (sign * force[0] + added[0], sign * force[1] + added[1])
        for _ in range(fine):
            zc = rotate(c, theta)
            torque = n * (-zc[1] * total[0] + zc[0] * total[1])
            omega += torque / moment * DT / fine
            theta += omega * DT / fine
            velocity[0] += n * total[0] / mass * DT / fine
            velocity[1] += n * total[1] / mass * DT / fine
        fastest = max(fastest, math.hypot(*velocity))
        previous = added
    assert fastest < 1.2 * math.hypot(*force) / b  # undamped: n f T / 2m = 3 m/s
    assert abs(mass_fit.estimate - mass) / mass < 2e-3
    assert math.dist(com_fit.estimate, c) < 1e-3


# ------------------------------------------------------------------------------ drive gain
def _drive(gain: float, lag: float, ticks: int, noise: float, seed: int = 3):
    """Commands that change every tick (as the spin-up's do), through a drive of ``gain``
    and first-order ``lag`` integrated finely; each tick's mean force plus white noise."""
    rng = np.random.default_rng(seed)
    fine, force = 50, np.zeros(2)
    command = np.array([2.0, -1.0])
    rows = []
    for _ in range(ticks):
        command = command + rng.normal(0.0, 0.3, 2) if rng.random() > 0.02 else -command
        total = np.zeros(2)
        for _ in range(fine):
            target = gain * command
            force = target if lag == 0 else force + (target - force) * (DT / fine) / lag
            total += force / fine
        rows.append((tuple(command), tuple(total + rng.normal(0.0, noise, 2))))
    return rows


@pytest.mark.parametrize("lag", [0.0, 0.02, 0.05])
def test_drive_gain_through_a_lagging_drive(lag: float) -> None:
    """The commands change every tick, so the lag must be modelled exactly: the lag of the
    grid whose residual is least gives the gain."""
    drive = DriveGain()
    assert drive.estimate == 1.0 and drive.std is None  # an ideal drive until measured
    for command, measured in _drive(1.03, lag, 1000, 0.0):
        drive.update(command, measured, DT)
    assert drive.estimate == pytest.approx(1.03, rel=2e-3)


@pytest.mark.parametrize("gain", [0.3, 0.0, -0.5])
def test_what_a_drive_applies_is_known_even_where_the_gain_assumed_stays_1(gain: float) -> None:
    """A drive that applies a third of its commands, none of them, or their opposite: the
    fitted share says so (at least 0), where the estimate the team's mean takes stays 1 for a
    fit that is not positive."""
    drive = DriveGain()
    assert drive.fitted is None
    for command, measured in _drive(gain, 0.02, 300, 0.05):
        drive.update(command, measured, DT)
    assert drive.fitted == pytest.approx(max(gain, 0.0), abs=0.02)
    assert drive.estimate == (pytest.approx(gain, abs=0.02) if gain > 0 else 1.0)


def test_drive_gain_narrows_to_the_lags_near_its_best(monkeypatch) -> None:
    """After 2 s only the lags near the best run on, and the gain is the whole grid's."""
    rows = _drive(0.97, 0.02, 1500, 0.5, 3)
    narrowed = DriveGain()
    for command, measured in rows:
        narrowed.update(command, measured, DT)
    monkeypatch.setattr(drive_gain, "NARROW_ROWS", 10**9)
    whole = DriveGain()
    for command, measured in rows:
        whole.update(command, measured, DT)
    assert len(narrowed._lags) == 2 * drive_gain.NARROW_LAGS + 1 < len(whole._lags)
    assert narrowed.estimate == whole.estimate and narrowed.std == whole.std


def test_drive_gain_under_force_noise_and_its_uncertainty() -> None:
    errors = []
    for seed in range(20):
        drive = DriveGain()
        for command, measured in _drive(0.97, 0.02, 1500, 0.5, seed):
            drive.update(command, measured, DT)
        errors.append((drive.estimate - 0.97) / drive.std)
    # The published standard deviation is honest: the errors are about one of it.
    assert 0.5 < float(np.std(errors)) < 1.5 and abs(float(np.mean(errors))) < 1.0
