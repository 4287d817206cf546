"""The centralized reference: one batch least-squares fit of the load from every robot's
measurements at once (``heft baseline RECORDING``).

Where the agents each see their own contact point and talk to their neighbours, this fit sees
every robot's measured velocity ``v_ik`` and measured force ``f_ik`` at every tick ``k`` of a
run, and shares only the rigid-body model with them (the paper's Sec. II). It is what a central
computer could reach, the yardstick for the distributed estimators under noise.

Unknowns: the constants ``m``, ``J`` and each contact's arm ``r_i = p_Ci − p_C`` in the load
frame (the load frame is ``W`` at the first tick: ``θ_0 = 0``); and the states at each tick,
the load's angle ``θ_k`` and its COM's velocity ``u_k`` (the angular velocity ``ω_k`` is the
central difference of the angles). With ``Q = [[0, −1], [1, 0]]``, ``R(θ)`` the rotation
and ``T`` the period, the weighted residuals are (``f_ik`` is the force applied over
``[t_{k−1}, t_k]``, as a measurement reports it):

- rigid kinematics, eq. (1): ``(u_k + ω_k Q R(θ_k) r_i − v_ik) / σ_v`` per robot and tick;
- translation: ``(m (u_k − u_{k−1}) − T Σ_i f_ik) / (T σ_f √n)``;
- rotation: ``(J (ω_k − ω_{k−1}) − T Σ_i (Q R(θ̄_k) r_i)ᵀ f_ik) / (T σ_f ‖r‖)``, ``θ̄_k`` the
  interval's mid angle.

Velocity noise enters the kinematic residuals, force noise the dynamic ones (``σ_v`` and
``σ_f``, the sensors' noise, weight them). The fit is Levenberg–Marquardt on the sparse
problem, and the parameters' standard deviations come from the Jacobian at the solution,
``(JᵀJ)⁻¹`` for unit-variance residuals. The starting point comes from the relative
velocities: ``∫ (v_j − v_1) dt`` runs on a circle centred at ``−(p_Cj − p_C1)`` at the first
tick (a circle fit, Kåsa's), which gives the contacts' geometry and ``θ_k``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csc_matrix, csr_matrix, diags, lil_matrix
from scipy.sparse.linalg import splu

MIN_SIGMA_V = 1e-6
"""m/s: the floor of the velocity noise used as a weight (a noise-free run has none)."""
MIN_SIGMA_F = 1e-4
"""N: the floor of the force noise used as a weight."""


@dataclass(frozen=True)
class BaselineFit:
    """What the batch fit found. Arms and offsets are in ``W`` at the last tick fitted."""

    mass: float
    moment: float
    contact_to_com: tuple[tuple[float, float], ...]
    """``p_C − p_Ci`` for robot ``i = 1..n``."""
    mass_std: float
    moment_std: float
    contact_to_com_std: tuple[float, ...]
    """The larger axis' standard deviation of each ``p_C − p_Ci`` (m)."""
    velocity_noise: float
    """σ_v (m/s) that weighted the velocities."""
    force_noise: float
    """σ_f (N) that weighted the forces."""
    ticks: int
    """How many ticks were fitted."""
    first_tick: int
    angle: float
    """θ at the last tick (rad), the load's turn since the first."""
    converged: bool
    """Whether the cost stopped decreasing (False: the solver ran out of iterations)."""
    cost: float
    """``½‖r‖²`` of the weighted residuals at the solution."""

    def relative_position(self, i: int, j: int) -> tuple[float, float]:
        """``z_ij = p_Ci − p_Cj`` at the last tick."""
        a, b = self.contact_to_com[i - 1], self.contact_to_com[j - 1]
        return (b[0] - a[0], b[1] - a[1])


def fit(
    velocities: np.ndarray,
    forces: np.ndarray,
    period_s: float,
    velocity_noise: float,
    force_noise: float,
    first_tick: int = 0,
) -> BaselineFit:
    """Fit ``velocities`` and ``forces`` (``(K + 1, n, 2)`` arrays, ticks ``0..K`` of a run in
    order; ``forces[k]`` applied over ``[t_{k−1}, t_k]``, ``forces[0]`` unused), weighting them
    by the sensors' noise ``velocity_noise`` (m/s) and ``force_noise`` (N) per axis.

    The noise must be given (a sensor's datasheet, the scenario's ``[sensors]``): estimated
    from the residuals of a fit, it comes out low for the forces (the fitted velocities absorb
    part of their noise), and the fit then trusts them too much. Raises :class:`ValueError`
    if the data cannot determine the load (too short, not finite)."""
    v = np.asarray(velocities, dtype=float)
    f = np.asarray(forces, dtype=float)
    if v.ndim != 3 or v.shape[2] != 2 or f.shape != v.shape:
        raise ValueError("expected velocities and forces of shape (ticks, robots, 2)")
    ticks, n, _ = v.shape
    if n < 2 or ticks < 10:
        raise ValueError(f"{ticks} ticks of {n} robots: too few to fit")
    if not (np.all(np.isfinite(v)) and np.all(np.isfinite(f))):
        raise ValueError("the measurements hold non-finite values")
    sigma_v, sigma_f = max(velocity_noise, MIN_SIGMA_V), max(force_noise, MIN_SIGMA_F)
    model = _Model(v, f, period_s, sigma_v, sigma_f)
    solution = _levenberg_marquardt(model.residuals, model.start(), model.sparsity())
    return model.result(solution, first_tick)


class _Model:
    """The residuals of the fit (see the module docstring) over the unknowns
    ``x = [m, J, r_1..r_n (2n), θ_1..θ_K, u_0..u_K (2 each)]``, weighted by the sensors'
    noise ``sigma_v`` and ``sigma_f``."""

    def __init__(
        self, v: np.ndarray, f: np.ndarray, period_s: float, sigma_v: float, sigma_f: float
    ):
        self.v, self.f, self.T = v, f, period_s
        self.sigma_v, self.sigma_f = sigma_v, sigma_f
        self.ticks, self.n, _ = v.shape
        self.total_force = f[1:].sum(axis=1)  # (K, 2)
        n, k1 = self.n, self.ticks
        self.i_r = 2
        self.i_theta = self.i_r + 2 * n  # θ_1..θ_K (θ_0 = 0)
        self.i_u = self.i_theta + (k1 - 1)
        self.size = self.i_u + 2 * k1

    def unpack(self, x: np.ndarray):
        n = self.n
        m, j = x[0], x[1]
        r = x[self.i_r : self.i_theta].reshape(n, 2)
        theta = np.concatenate(([0.0], x[self.i_theta : self.i_u]))
        omega = np.gradient(theta, self.T)  # central differences, one-sided at the ends
        u = x[self.i_u :].reshape(self.ticks, 2)
        return m, j, r, theta, omega, u

    def _arms(self, theta: np.ndarray, r: np.ndarray) -> np.ndarray:
        """``R(θ_k) r_i`` for every tick and robot: ``(len(θ), n, 2)``."""
        c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
        return np.stack((c * r[:, 0] - s * r[:, 1], s * r[:, 0] + c * r[:, 1]), axis=2)

    def _torques(self, theta: np.ndarray, r: np.ndarray) -> np.ndarray:
        """``Σ_i (Q R(θ̄_k) r_i)ᵀ f_ik`` over each interval, at its mid angle ``θ̄_k``."""
        arms = self._arms(0.5 * (theta[1:] + theta[:-1]), r)
        return np.einsum("kia,kia->k", _perp(arms), self.f[1:])

    def residuals(self, x: np.ndarray) -> np.ndarray:
        m, j, r, theta, omega, u = self.unpack(x)
        T, n = self.T, self.n
        perp = _perp(self._arms(theta, r))
        kinematic = (u[:, None, :] + omega[:, None, None] * perp - self.v) / self.sigma_v
        translation = (m * np.diff(u, axis=0) - T * self.total_force) / (
            T * self.sigma_f * math.sqrt(n)
        )
        scale = T * self.sigma_f * max(float(np.sqrt(np.sum(r**2))), 1e-3)
        rotation = (j * np.diff(omega) - T * self._torques(theta, r)) / scale
        return np.concatenate((kinematic.ravel(), translation.ravel(), rotation))

    def sparsity(self):
        """Which unknowns each residual depends on (for the finite-difference Jacobian)."""
        n, k1 = self.n, self.ticks
        rows = 2 * n * k1 + 2 * (k1 - 1) + (k1 - 1)
        s = lil_matrix((rows, self.size), dtype=np.int8)

        def thetas(first: int, last: int) -> list[int]:
            """The columns of θ_first..θ_last that are unknowns (θ_0 is not)."""
            return [self.i_theta + k - 1 for k in range(max(first, 1), min(last, k1 - 1) + 1)]

        row = 0
        for k in range(k1):
            near = thetas(k - 1, k + 1)  # θ_k and ω_k's central difference
            for i in range(n):
                for _ in range(2):
                    s[row, self.i_r + 2 * i : self.i_r + 2 * i + 2] = 1
                    s[row, near] = 1
                    s[row, self.i_u + 2 * k : self.i_u + 2 * k + 2] = 1
                    row += 1
        for k in range(1, k1):
            for _ in range(2):
                s[row, 0] = 1
                s[row, self.i_u + 2 * (k - 1) : self.i_u + 2 * k + 2] = 1
                row += 1
        for k in range(1, k1):
            s[row, 1] = 1
            s[row, self.i_r : self.i_theta] = 1
            s[row, thetas(k - 2, k + 1)] = 1
            row += 1
        return s.tocsr()

    def start(self) -> np.ndarray:
        """A starting point from the relative velocities (see the module docstring)."""
        v, T, n = self.v, self.T, self.n
        # Each robot's position relative to robot 1, up to a constant: ∫ (v_j − v_1) dt.
        rel = np.cumsum(np.concatenate((np.zeros((1, n, 2)), 0.5 * T * (v[1:] + v[:-1]))), axis=0)
        rel = rel - rel[:, :1, :]
        offsets = np.zeros((n, 2))  # p_Cj − p_C1 at the first tick
        for j in range(1, n):
            offsets[j] = -_circle_centre(rel[:, j, :])
        longest = int(np.argmax(np.hypot(offsets[:, 0], offsets[:, 1])))
        now = rel[:, longest, :] + offsets[longest]
        theta = np.unwrap(np.arctan2(now[:, 1], now[:, 0]))
        theta = theta - theta[0]
        omega = np.gradient(theta, T)
        r = offsets - offsets.mean(axis=0)  # the COM guessed at the contacts' centroid
        u = v.mean(axis=1)
        du = np.diff(u, axis=0).ravel()
        impulse = (T * self.total_force).ravel()
        m = float(du @ impulse / max(du @ du, 1e-12))
        torque = T * self._torques(theta, r)
        dw = np.diff(omega)
        j = float(dw @ torque / max(dw @ dw, 1e-12))
        return np.concatenate(([max(m, 1e-3), max(j, 1e-4)], r.ravel(), theta[1:], u.ravel()))

    def _parameter_covariance(self, jac) -> np.ndarray:
        """The covariance of ``m, J, r_1..r_n`` with the states marginalised: the leading
        block of ``(JᵀJ)⁻¹`` (residuals of unit variance), from a sparse factorisation."""
        count = self.i_theta
        try:
            factor = splu((jac.T @ jac).tocsc())
            unit = np.zeros((self.size, count))
            unit[np.arange(count), np.arange(count)] = 1.0
            return factor.solve(unit)[:count]
        except (RuntimeError, ValueError):  # singular: the data do not determine the load
            return np.full((count, count), np.nan)

    def result(self, solution, first_tick: int) -> BaselineFit:
        m, j, r, theta, _, _ = self.unpack(solution.x)
        covariance = self._parameter_covariance(solution.jac)
        last = self._arms(theta[-1:], r)[0]
        c, s = math.cos(theta[-1]), math.sin(theta[-1])
        rot = np.array([[c, -s], [s, c]])
        stds = []
        for i in range(self.n):
            block = covariance[2 + 2 * i : 4 + 2 * i, 2 + 2 * i : 4 + 2 * i]
            world = rot @ block @ rot.T
            stds.append(float(np.sqrt(max(world[0, 0], world[1, 1], 0.0))))
        return BaselineFit(
            mass=float(m),
            moment=float(j),
            contact_to_com=tuple((float(-a[0]), float(-a[1])) for a in last),
            mass_std=float(np.sqrt(covariance[0, 0])) if covariance[0, 0] >= 0 else math.nan,
            moment_std=float(np.sqrt(covariance[1, 1])) if covariance[1, 1] >= 0 else math.nan,
            contact_to_com_std=tuple(stds),
            velocity_noise=self.sigma_v,
            force_noise=self.sigma_f,
            ticks=self.ticks,
            first_tick=first_tick,
            angle=float(theta[-1]),
            converged=bool(solution.status > 0),
            cost=float(solution.cost),
        )


@dataclass
class _Solution:
    x: np.ndarray
    jac: csr_matrix
    cost: float
    status: int
    """1 converged (the cost stopped decreasing), 0 out of iterations."""


def _levenberg_marquardt(residuals, x0: np.ndarray, pattern, iterations: int = 200) -> _Solution:
    """Minimise ``½‖residuals(x)‖²`` from ``x0`` by Levenberg–Marquardt: steps solve
    ``(JᵀJ + λ diag(JᵀJ)) δ = −Jᵀr`` with a sparse LU factorisation, ``J`` by forward
    differences, perturbing at once the columns that share no residual (``pattern``)."""
    groups = _column_groups(csc_matrix(pattern))
    rows, cols = csr_matrix(pattern).nonzero()
    x = np.asarray(x0, dtype=float).copy()
    r = residuals(x)
    cost = 0.5 * float(r @ r)
    lam, status = 1e-3, 0
    jac, jac_at = None, None  # the Jacobian and the point it was taken at
    for _ in range(iterations):
        jac, jac_at = _jacobian(residuals, x, r, groups, rows, cols, pattern.shape), x
        normal = (jac.T @ jac).tocsc()
        gradient = jac.T @ r
        scale = normal.diagonal() + 1e-12
        improved = False
        while lam < 1e12:
            try:
                step = splu((normal + diags(lam * scale)).tocsc()).solve(-gradient)
            except RuntimeError:  # singular: damp more
                lam *= 10.0
                continue
            trial = x + step
            r_trial = residuals(trial)
            cost_trial = 0.5 * float(r_trial @ r_trial)
            if cost_trial < cost:
                improved = True
                decrease = (cost - cost_trial) / max(cost, 1e-300)
                x, r, cost = trial, r_trial, cost_trial
                lam = max(lam / 3.0, 1e-12)
                break
            lam *= 4.0
        if not improved or decrease < 1e-12:
            status = 1
            break
    if jac_at is not x:  # the last step moved x: the covariance needs J there
        jac = _jacobian(residuals, x, r, groups, rows, cols, pattern.shape)
    return _Solution(x, jac, cost, status)


def _column_groups(pattern: csc_matrix) -> list[np.ndarray]:
    """Columns in groups that share no row (greedy colouring): one evaluation per group."""
    used: list[np.ndarray] = []
    members: list[list[int]] = []
    for column in range(pattern.shape[1]):
        rows = pattern.indices[pattern.indptr[column] : pattern.indptr[column + 1]]
        for colour, taken in enumerate(used):
            if not taken[rows].any():
                taken[rows] = True
                members[colour].append(column)
                break
        else:
            taken = np.zeros(pattern.shape[0], dtype=bool)
            taken[rows] = True
            used.append(taken)
            members.append([column])
    return [np.array(m) for m in members]


def _jacobian(residuals, x, r, groups, rows, cols, shape) -> csr_matrix:
    """Forward differences of ``residuals`` at ``x`` (``r`` its value), on the pattern."""
    steps = 1e-7 * np.maximum(1.0, np.abs(x))
    column_of_group = np.empty(shape[1], dtype=int)
    derivative = np.zeros((len(groups), shape[0]))
    for g, members in enumerate(groups):
        column_of_group[members] = g
        shifted = x.copy()
        shifted[members] += steps[members]
        derivative[g] = residuals(shifted) - r
    values = derivative[column_of_group[cols], rows] / steps[cols]
    return csr_matrix((values, (rows, cols)), shape=shape)


def _perp(vectors: np.ndarray) -> np.ndarray:
    """``Q v`` for every vector of ``vectors`` (``(..., 2)``): ``(−v_y, v_x)``."""
    return np.stack((-vectors[..., 1], vectors[..., 0]), axis=-1)


def _circle_centre(points: np.ndarray) -> np.ndarray:
    """The centre of the circle through ``points`` (``(k, 2)``) in the least-squares sense of
    Kåsa: ``x² + y² + D x + E y + F = 0`` is linear in ``D, E, F``."""
    x, y = points[:, 0], points[:, 1]
    a = np.column_stack((x, y, np.ones_like(x)))
    b = -(x**2 + y**2)
    (d, e, _), *_ = np.linalg.lstsq(a, b, rcond=None)
    return np.array([-d / 2.0, -e / 2.0])


# ------------------------------------------------------------------------------ recordings
MAX_TICKS = 3000
"""The most ticks fitted (30 s at 100 Hz): the first ones of the longest complete stretch."""


@dataclass(frozen=True)
class RecordedRun:
    """A recording's measurements, every robot at every tick of one stretch, and its truth."""

    velocities: np.ndarray
    forces: np.ndarray
    period_s: float
    first_tick: int
    truth: object | None
    """The recorded :class:`~agent.platform.protocol.Truth` at the stretch's last tick, if any."""


def read_recording(path) -> RecordedRun:
    """The longest stretch of consecutive ticks at which every robot's measurement was
    recorded in the MCAP file ``path`` (at most :data:`MAX_TICKS`). Raises
    :class:`ValueError` (one line) when the file holds no such stretch."""
    from agent.platform.protocol import Measurement, Truth
    from dashboard.replay import Recording

    recording = Recording(path)
    samples: dict[int, dict[int, Measurement]] = {}
    truths: dict[int, Truth] = {}
    for recorded in recording.messages({Measurement, Truth}):
        message = recorded.message
        if isinstance(message, Measurement):
            samples.setdefault(message.tick, {})[message.robot] = message
        else:
            truths[message.tick] = message
    if not samples:
        raise ValueError(f"{path}: no robot measurements recorded")
    robots = sorted(set().union(*(set(s) for s in samples.values())))
    if robots != list(range(1, len(robots) + 1)):
        raise ValueError(f"{path}: measurements of robots {robots}, expected 1..n")
    complete = sorted(k for k, s in samples.items() if len(s) == len(robots))
    best, start = (0, -1), None
    for index, tick in enumerate(complete):
        if index == 0 or tick != complete[index - 1] + 1:
            start = tick
        if tick - start + 1 > best[0]:
            best = (tick - start + 1, start)
    length, first = best
    length = min(length, MAX_TICKS)
    if length < 10:
        raise ValueError(f"{path}: no 10 consecutive ticks with every robot's measurement")
    ticks = range(first, first + length)
    velocities = np.array([[samples[k][i].velocity for i in robots] for k in ticks])
    forces = np.array([[samples[k][i].force for i in robots] for k in ticks])
    a, b = samples[ticks[0]][1], samples[ticks[-1]][1]
    period = (b.time_s - a.time_s) / (length - 1)
    if not period > 0.0:
        raise ValueError(f"{path}: the measurements' times do not advance")
    return RecordedRun(velocities, forces, period, first, truths.get(ticks[-1]))
