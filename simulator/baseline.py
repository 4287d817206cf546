"""The centralized reference: one batch least-squares fit of the load from every robot's
measurements at once (``heft baseline RECORDING``).

Where the agents each see their own contact point and talk to their neighbours, this fit sees
every robot's measured velocity ``v_ik`` and measured force ``f_ik`` at every tick ``k`` of a
run, and shares only the physics with them: the rigid-body model (the paper's Sec. II) and
the floor's friction as the robots' estimators model it. It is what a central computer could
reach, the yardstick for the distributed estimators under noise and friction.

Unknowns: the constants ``m``, ``J``, the floor's friction torque ``τ_c`` (N m) and spin drag
``κ`` (N/m) (and its sliding friction ``F_s``, N, if the load slid), and each contact's arm
``r_i = p_Ci − p_C`` in the load frame (the load frame is ``W`` at the first tick:
``θ_0 = 0``); and the states at each tick, the load's angle ``θ_k`` and its COM's velocity
``u_k`` (the angular velocity ``ω_k`` is the central difference of the angles). With
``Q = [[0, −1], [1, 0]]``, ``R(θ)`` the rotation, ``T`` the period, and over the interval
``[t_{k−1}, t_k]`` the mean states ``ω̄_k = (ω_{k−1} + ω_k)/2``, ``ū_k = (u_{k−1} + u_k)/2``
and the mid angle ``θ̄_k``, the weighted residuals are (``f_ik`` is the force applied over the
interval, as a measurement reports it):

- rigid kinematics, eq. (1): ``(u_k + ω_k Q R(θ_k) r_i − v_ik) / σ_v`` per robot and tick;
- translation: ``(m (u_k − u_{k−1}) − T Σ_i f_ik + T κ ū_k s(ω̄_k)) / (T σ_f √n)`` where the
  load turned, ``+ T F_s ū_k / √(‖ū_k‖² + ε_u²)`` in place of the drag where it slid;
- rotation: ``(J (ω_k − ω_{k−1}) − T Σ_i (Q R(θ̄_k) r_i)ᵀ f_ik + T τ_c ω̄_k s(ω̄_k))
  / (T σ_f ‖r‖)`` where it turned.

The friction model (the robots' estimators'): Coulomb friction ``μ N_s`` at each support
``s`` of the load, against that support's velocity, is to first order in ``‖ṗ_C‖ / (|ω| r_s)``
a torque ``−τ_c sgn ω`` about the COM (``τ_c = μ Σ N_s ‖r_s‖``, exact for a pure spin) and a
drag ``−κ ṗ_C / |ω|`` on the COM (``κ = μ Σ N_s / (2‖r_s‖)``, the supports' anisotropy averaged
out as the load turns). So it assumes that the load spins, the COM's speed small against the
supports' speed about it; that it turns through much of a revolution over the stretch fitted,
or rests on supports symmetric about its COM (a load-fixed force ``−μ sgn ω Σ_s N_s Q r̂_s``,
zero for symmetric supports, is neglected); and Coulomb friction only (a viscous drag is taken
up by ``τ_c`` and ``κ`` as at the run's typical turn rate). ``μ`` and the supports are not
observable apart, only ``τ_c`` and ``κ``. The fit does not constrain their sign: on a
frictionless floor they come out about 0 within their standard deviations, either side.

Where the load slides rather than turns (a push it does not turn under), the same friction is,
to first order in ``|ω| r_s / ‖ṗ_C‖``, a force ``−μ m g ṗ_C/‖ṗ_C‖`` and no torque
(``Σ_s N_s r_s = 0``, statics); the fit adds ``F_s = μ m g`` for those intervals' translation
(rather than leave out the push, the mass's signal) and leaves out their rotation (a small
drag torque ``∝ ω/‖ṗ_C‖`` that neither model has). ``F_s`` is fitted only when the load slid
over :data:`MIN_SLIDING` intervals.

Each model is smooth where it holds. ``sgn ω`` and ``1/|ω|`` are made differentiable with
``s(ω) = 1/√(ω² + ε²)`` (``sgn ω ≈ ω s(ω)``, ``1/|ω| ≈ s(ω)``), where ``ε = σ_ω`` is the
noise of an angular velocity read from one tick's velocities, ``σ_v / √(Σ_i ‖r_i − r̄‖²)``
(``r̄`` the contacts' centroid), and ``ṗ_C/‖ṗ_C‖`` likewise with ``ε_u = σ_v / √n``, the noise
of the COM's velocity read from one tick. The regimes (:func:`regimes`): the load turns in an
interval with ``|ω̄_k| ≥ 3ε`` (below, a load stuck or barely turning, whose turn's sign the
noise hides; at ``3ε``, ``ω s(ω)`` and ``|ω| s(ω)`` are 0.95 of 1, beyond ``10ε`` over 0.995)
and ``‖ū_k‖ ≤ 2ρ |ω̄_k|`` (``ρ`` the contacts' RMS distance from their centroid); beyond that
the spin model's drag ``κ ‖ṗ_C‖ / |ω|`` would exceed ``μ m g``, the most that Coulomb friction
at supports within ``ρ`` of the COM can pull, and the load slides, if ``‖ū_k‖ ≥ 3ε_u``. An
interval in neither (stuck) is left out. The regimes are decided at the starting point, and
once more near the solution, from which the fit goes on. Without friction
(``friction=False``, ``heft baseline --no-friction``) the fit is the rigid-body model alone,
on every interval. (``ω̄_k`` is the mean of the central differences, not ``(θ_k − θ_{k−1})/T``:
the central differences do not see an angle alternating tick by tick, which the data hardly
determine; through ``ω̄`` the friction terms would depend on it, and the fit would crawl.)

Velocity noise enters the kinematic residuals, force noise the dynamic ones (``σ_v`` and
``σ_f``, the sensors' noise, weight them). The fit is Levenberg–Marquardt on the sparse
problem, and the parameters' standard deviations come from the Jacobian at the solution,
``(JᵀJ)⁻¹`` for unit-variance residuals. The starting point comes from the relative
velocities: ``∫ (v_j − v_1) dt`` runs on a circle centred at ``−(p_Cj − p_C1)`` at the first
tick (a circle fit, Kåsa's), which gives the contacts' geometry and ``θ_k``; then ``m, κ, F_s``
and ``J, τ_c`` by linear least squares on the dynamics.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csc_matrix, csr_matrix, diags
from scipy.sparse.linalg import splu

from agent.platform.protocol import GRAVITY

MIN_SIGMA_V = 1e-6
"""m/s: the floor of the velocity noise used as a weight (a noise-free run has none)."""
MIN_SIGMA_F = 1e-4
"""N: the floor of the force noise used as a weight."""
MOVING_EPSILONS = 3.0
"""The load turns in an interval whose ``|ω̄|`` is at least this many ``ε``, and slides in one
whose ``‖ū‖`` is at least this many ``ε_u`` (see the module docstring)."""
MAX_SLIP = 2.0
"""``‖ū‖ / (ρ |ω̄|)`` at which the load stops turning, as the friction model has it, and
slides (see the module docstring)."""
MIN_SLIDING = 20
"""The fewest intervals of sliding that ``F_s`` is fitted on (fewer are left out)."""


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
    friction_torque: float | None
    """``τ_c`` (N m): the floor's friction torque about the COM while the load turns (None:
    fitted without friction)."""
    friction_torque_std: float | None
    spin_drag: float | None
    """``κ`` (N/m): the floor's drag on the COM while the load turns, ``−κ ṗ_C / |ω|``
    (None: fitted without friction)."""
    spin_drag_std: float | None
    sliding_friction: float | None
    """``F_s`` (N): the floor's friction on the load while it slides without turning, ``μ m g``
    against the COM's velocity (None: fitted without friction, or the load never slid)."""
    sliding_friction_std: float | None
    velocity_noise: float
    """σ_v (m/s) that weighted the velocities."""
    force_noise: float
    """σ_f (N) that weighted the forces."""
    ticks: int
    """How many ticks were fitted."""
    turning_intervals: int
    """Of the ``ticks − 1`` intervals between them, how many the load turned in (all of them
    without friction; :func:`regimes`)."""
    sliding_intervals: int
    """How many it slid in, whose translation was fitted with ``F_s`` (:func:`regimes`)."""
    omega_epsilon: float
    """``ε`` (rad/s), the friction model's smoothing of ``sgn ω`` and ``1/|ω|``."""
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
    friction: bool = True,
) -> BaselineFit:
    """Fit ``velocities`` and ``forces`` (``(K + 1, n, 2)`` arrays, ticks ``0..K`` of a run in
    order; ``forces[k]`` applied over ``[t_{k−1}, t_k]``, ``forces[0]`` unused), weighting them
    by the sensors' noise ``velocity_noise`` (m/s) and ``force_noise`` (N) per axis; with the
    floor's friction (``τ_c``, ``κ``, and ``F_s`` if the load slid) unless ``friction`` is
    False.

    The noise must be given (a sensor's datasheet, the scenario's ``[sensors]``): estimated
    from the residuals of a fit, it comes out low for the forces (the fitted velocities absorb
    part of their noise), and the fit then trusts them too much. Raises :class:`ValueError`
    if the data cannot determine the load (too short, not finite, the load never turning)."""
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
    model = _Model(v, f, period_s, sigma_v, sigma_f, friction)
    start = model.start()
    pattern = model.sparsity()
    groups = _column_groups(csc_matrix(pattern))
    if not friction:
        solution = _levenberg_marquardt(model.residuals, start, pattern, groups)
        return model.result(solution, first_tick)
    # Near the solution, to keep the intervals the model holds on there; then to the end from
    # there, with little damping: the first pass's last steps would be the second's first.
    near = _levenberg_marquardt(model.residuals, start, pattern, groups, tolerance=1e-8)
    model.keep(near.x)
    solution = _levenberg_marquardt(model.residuals, near.x, pattern, groups, damping=1e-6)
    return model.result(solution, first_tick)


def truth_friction(truth) -> dict[str, float | None]:
    """The floor's friction as the fit has it, from a recorded
    :class:`~agent.platform.protocol.Truth`'s Coulomb friction ``μ`` (``ground_coulomb``), the
    load's mass and the supports' friction radius ``c``: ``friction_torque`` ``τ_c = μ m g c``,
    ``sliding_friction`` ``F_s = μ m g``, and ``spin_drag`` ``κ`` if the truth gives it (it
    needs each support's load and arm: None otherwise); all 0 on a frictionless floor."""
    weight = getattr(truth, "ground_coulomb", 0.0) * GRAVITY * truth.mass
    return {
        "friction_torque": weight * getattr(truth, "friction_radius", 0.0),
        "spin_drag": getattr(truth, "spin_drag", None) if weight else 0.0,
        "sliding_friction": weight,
    }


def regimes(
    omega: np.ndarray,
    speed: np.ndarray,
    epsilon: float,
    speed_epsilon: float,
    radius: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Which intervals the load turned in and which it slid in, as the friction model has it
    (see the module docstring), from their mean angular velocity ``omega`` (rad/s) and the
    COM's mean speed ``speed`` (m/s): turning, ``|ω̄| ≥ 3ε`` and ``‖ū‖ ≤ 2ρ|ω̄|``; sliding,
    ``‖ū‖ > 2ρ|ω̄|`` and ``‖ū‖ ≥ 3ε_u`` (:data:`MOVING_EPSILONS`, :data:`MAX_SLIP`; ``ε``,
    ``ε_u``, ``ρ``: ``epsilon``, ``speed_epsilon``, ``radius``)."""
    turn = np.abs(omega)
    slipping = speed > MAX_SLIP * radius * turn
    turning = (turn >= MOVING_EPSILONS * epsilon) & ~slipping
    return turning, slipping & (speed >= MOVING_EPSILONS * speed_epsilon)


class _Model:
    """The residuals of the fit (see the module docstring) over the unknowns
    ``x = [m, J, (τ_c, κ, (F_s)), r_1..r_n (2n), θ_1..θ_K, u_0..u_K (2 each)]`` (``τ_c, κ``
    with friction, ``F_s`` when the load slid), weighted by the sensors' noise ``sigma_v`` and
    ``sigma_f``; the dynamic residuals of the intervals in no regime the model holds in are 0
    (:attr:`turning`, :attr:`sliding`)."""

    def __init__(
        self,
        v: np.ndarray,
        f: np.ndarray,
        period_s: float,
        sigma_v: float,
        sigma_f: float,
        friction: bool,
    ):
        self.v, self.f, self.T = v, f, period_s
        self.sigma_v, self.sigma_f = sigma_v, sigma_f
        self.friction = friction
        self.slides = False
        """Whether ``F_s`` is fitted (the load slid over :data:`MIN_SLIDING` intervals)."""
        self.ticks, self.n, _ = v.shape
        self.total_force = f[1:].sum(axis=1)  # (K, 2)
        self._layout()
        self.turning = np.ones(self.ticks - 1, dtype=bool)
        """Per interval ``[t_{k−1}, t_k]`` (at ``k − 1``), whether the load turned in it."""
        self.sliding = np.zeros(self.ticks - 1, dtype=bool)
        """Per interval, whether the load slid in it (counted with :attr:`slides` only)."""
        self.epsilon = 0.0
        self.speed_epsilon = sigma_v / math.sqrt(self.n)
        self.radius = 0.0

    def _layout(self) -> None:
        """Where the unknowns are in ``x``."""
        self.i_r = 2 + (2 + self.slides if self.friction else 0)
        self.i_theta = self.i_r + 2 * self.n  # θ_1..θ_K (θ_0 = 0)
        self.i_u = self.i_theta + (self.ticks - 1)
        self.size = self.i_u + 2 * self.ticks

    def unpack(self, x: np.ndarray):
        n = self.n
        m, j = x[0], x[1]
        friction = x[2 : self.i_r] if self.friction else ()
        r = x[self.i_r : self.i_theta].reshape(n, 2)
        theta = np.concatenate(([0.0], x[self.i_theta : self.i_u]))
        omega = np.gradient(theta, self.T)  # central differences, one-sided at the ends
        u = x[self.i_u :].reshape(self.ticks, 2)
        return m, j, friction, r, theta, omega, u

    def _arms(self, theta: np.ndarray, r: np.ndarray) -> np.ndarray:
        """``R(θ_k) r_i`` for every tick and robot: ``(len(θ), n, 2)``."""
        c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
        return np.stack((c * r[:, 0] - s * r[:, 1], s * r[:, 0] + c * r[:, 1]), axis=2)

    def _torques(self, theta: np.ndarray, r: np.ndarray) -> np.ndarray:
        """``Σ_i (Q R(θ̄_k) r_i)ᵀ f_ik`` over each interval, at its mid angle ``θ̄_k``."""
        arms = self._arms(0.5 * (theta[1:] + theta[:-1]), r)
        return np.einsum("kia,kia->k", _perp(arms), self.f[1:])

    @staticmethod
    def _means(omega: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``ω̄_k`` and ``ū_k`` over each interval."""
        return 0.5 * (omega[1:] + omega[:-1]), 0.5 * (u[1:] + u[:-1])

    def _friction_columns(
        self, turn: np.ndarray, mean_u: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What ``T κ``, ``T F_s`` and ``T τ_c`` multiply in the dynamic residuals: ``ū s(ω̄)``
        where the load turned, ``ū / √(‖ū‖² + ε_u²)`` where it slid, ``ω̄ s(ω̄)``."""
        s = 1.0 / np.sqrt(turn * turn + self.epsilon**2)
        speed = np.sqrt(np.sum(mean_u**2, axis=1) + self.speed_epsilon**2)
        drag = np.where(self.turning[:, None], mean_u * s[:, None], 0.0)
        slide = np.where(self.sliding[:, None], mean_u / speed[:, None], 0.0)
        return drag, slide, turn * s

    def residuals(self, x: np.ndarray) -> np.ndarray:
        m, j, friction, r, theta, omega, u = self.unpack(x)
        T, n = self.T, self.n
        perp = _perp(self._arms(theta, r))
        kinematic = (u[:, None, :] + omega[:, None, None] * perp - self.v) / self.sigma_v
        translation = m * np.diff(u, axis=0) - T * self.total_force
        rotation = j * np.diff(omega) - T * self._torques(theta, r)
        moved = self.turning
        if self.friction:
            drag, slide, spin = self._friction_columns(*self._means(omega, u))
            translation += (T * friction[1]) * drag
            rotation += (T * friction[0]) * spin
            if self.slides:
                translation += (T * friction[2]) * slide
                moved = moved | self.sliding
        translation *= (moved / (T * self.sigma_f * math.sqrt(n)))[:, None]
        rotation *= self.turning / (T * self.sigma_f * max(float(np.sqrt(np.sum(r**2))), 1e-3))
        return np.concatenate((kinematic.ravel(), translation.ravel(), rotation))

    def sparsity(self) -> csr_matrix:
        """Which unknowns each residual depends on (for the finite-difference Jacobian)."""
        n, k1 = self.n, self.ticks
        intervals = np.arange(k1 - 1)
        rows: list[np.ndarray] = []
        cols: list[np.ndarray] = []

        def link(row: np.ndarray, col: np.ndarray) -> None:
            rows.append(np.asarray(row).ravel())
            cols.append(np.asarray(col).ravel())

        def thetas(row: np.ndarray, ticks: np.ndarray) -> None:
            """``row`` on ``θ_ticks`` where those are unknowns (``θ_0`` is not)."""
            inside = (ticks >= 1) & (ticks <= k1 - 1)
            link(row[inside], self.i_theta + ticks[inside] - 1)

        # kinematic rows 2(k n + i) + a: r_i, θ_{k−1..k+1} (θ_k, ω_k), u_k
        k, i, a = np.meshgrid(np.arange(k1), np.arange(n), np.arange(2), indexing="ij")
        k, i, a = k.ravel(), i.ravel(), a.ravel()
        row = 2 * (k * n + i) + a
        for b in range(2):
            link(row, self.i_r + 2 * i + b)
            link(row, self.i_u + 2 * k + b)
        for d in (-1, 0, 1):
            thetas(row, k + d)
        # translation rows over the intervals k = 1..K: m, u_{k−1}, u_k, (κ, F_s, θ_{k−2..k+1})
        base = 2 * n * k1
        k = np.repeat(intervals + 1, 2)
        a = np.tile(np.arange(2), k1 - 1)
        row = base + np.arange(2 * (k1 - 1))
        link(row, np.zeros_like(row))
        for d in (-1, 0):
            link(row, self.i_u + 2 * (k + d) + a)
        if self.friction:
            for c in range(3, self.i_r):
                link(row, np.full_like(row, c))
            for d in (-2, -1, 0, 1):
                thetas(row, k + d)
        # rotation rows: J, (τ_c), every r, θ_{k−2..k+1} (ω_k − ω_{k−1})
        base += 2 * (k1 - 1)
        k = intervals + 1
        row = base + np.arange(k1 - 1)
        link(row, np.ones_like(row))
        if self.friction:
            link(row, np.full_like(row, 2))
        for c in range(self.i_r, self.i_theta):
            link(row, np.full_like(row, c))
        for d in (-2, -1, 0, 1):
            thetas(row, k + d)
        rows_, cols_ = np.concatenate(rows), np.concatenate(cols)
        shape = (base + k1 - 1, self.size)
        pattern = csr_matrix((np.ones(len(rows_), dtype=np.int8), (rows_, cols_)), shape=shape)
        pattern.data[:] = 1  # entries named twice were summed
        return pattern

    def _classify(self, omega: np.ndarray, u: np.ndarray) -> None:
        """The intervals where the load turned and where it slid (:func:`regimes`), from the
        tick states ``omega`` and ``u``; the sliding ones stay as they were if ``F_s`` is
        fitted and too few are left to determine it."""
        turn, mean_u = self._means(omega, u)
        turning, sliding = regimes(
            turn, np.hypot(*mean_u.T), self.epsilon, self.speed_epsilon, self.radius
        )
        if np.count_nonzero(turning) < 2:
            raise ValueError(
                "the load never turned, and the friction model holds only while it turns"
                " (fit without friction)"
            )
        if self.slides and np.count_nonzero(sliding) < MIN_SLIDING:
            sliding = self.sliding
        self.turning, self.sliding = turning, sliding

    def keep(self, x: np.ndarray) -> None:
        """The intervals in each regime at ``x`` (:meth:`_classify`)."""
        _, _, _, _, _, omega, u = self.unpack(x)
        self._classify(omega, u)

    def start(self) -> np.ndarray:
        """A starting point from the relative velocities (see the module docstring); with
        friction, also ``ε``, ``ρ``, the regimes there and whether ``F_s`` is fitted."""
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
        spread = float(np.sum(r**2))  # Σ ‖r_i − r̄‖²
        self.epsilon = self.sigma_v / math.sqrt(max(spread, 1e-12))
        self.radius = math.sqrt(spread / n)
        if self.friction:
            self._classify(omega, u)
            self.slides = np.count_nonzero(self.sliding) >= MIN_SLIDING
            self._layout()
        # m (and κ, F_s), J (and τ_c): linear least squares on the dynamics where they hold
        moved = self.turning | self.sliding if self.slides else self.turning
        turn, mean_u = self._means(omega, u)
        columns = [np.diff(u, axis=0)[moved].ravel()]
        drag, slide, spin = self._friction_columns(turn, mean_u)
        if self.friction:
            columns.append(T * drag[moved].ravel())
            if self.slides:
                columns.append(T * slide[moved].ravel())
        mass = _least_squares(columns, (T * self.total_force[moved]).ravel())
        kept = self.turning
        columns = [np.diff(omega)[kept]]
        if self.friction:
            columns.append(T * spin[kept])
        inertia = _least_squares(columns, T * self._torques(theta, r)[kept])
        parameters = [max(mass[0], 1e-3), max(inertia[0], 1e-4)]
        if self.friction:
            parameters += [inertia[1], *mass[1:]]
        return np.concatenate((parameters, r.ravel(), theta[1:], u.ravel()))

    def _parameter_covariance(self, jac) -> np.ndarray:
        """The covariance of the constants (``m, J, (τ_c, κ, (F_s)), r_1..r_n``) with the
        states marginalised: the leading block of ``(JᵀJ)⁻¹`` (residuals of unit variance),
        from a sparse factorisation."""
        count = self.i_theta
        try:
            factor = splu((jac.T @ jac).tocsc())
            unit = np.zeros((self.size, count))
            unit[np.arange(count), np.arange(count)] = 1.0
            return factor.solve(unit)[:count]
        except (RuntimeError, ValueError):  # singular: the data do not determine the load
            return np.full((count, count), np.nan)

    def result(self, solution, first_tick: int) -> BaselineFit:
        m, j, friction, r, theta, _, _ = self.unpack(solution.x)
        covariance = self._parameter_covariance(solution.jac)
        last = self._arms(theta[-1:], r)[0]
        c, s = math.cos(theta[-1]), math.sin(theta[-1])
        rot = np.array([[c, -s], [s, c]])
        stds = []
        for i in range(self.n):
            at = self.i_r + 2 * i
            block = covariance[at : at + 2, at : at + 2]
            world = rot @ block @ rot.T
            stds.append(float(np.sqrt(max(world[0, 0], world[1, 1], 0.0))))

        def std(index: int) -> float:
            variance = covariance[index, index]
            return float(np.sqrt(variance)) if variance >= 0 else math.nan

        def fitted(index: int) -> tuple[float | None, float | None]:
            """The friction parameter at ``index`` and its std (None: not fitted)."""
            if index >= self.i_r:
                return None, None
            return float(solution.x[index]), std(index)

        (torque, torque_std), (drag, drag_std), (slide, slide_std) = map(fitted, (2, 3, 4))
        return BaselineFit(
            mass=float(m),
            moment=float(j),
            contact_to_com=tuple((float(-a[0]), float(-a[1])) for a in last),
            mass_std=std(0),
            moment_std=std(1),
            contact_to_com_std=tuple(stds),
            friction_torque=torque,
            friction_torque_std=torque_std,
            spin_drag=drag,
            spin_drag_std=drag_std,
            sliding_friction=slide,
            sliding_friction_std=slide_std,
            velocity_noise=self.sigma_v,
            force_noise=self.sigma_f,
            ticks=self.ticks,
            turning_intervals=int(np.count_nonzero(self.turning)),
            sliding_intervals=int(np.count_nonzero(self.sliding)) if self.slides else 0,
            omega_epsilon=self.epsilon,
            first_tick=first_tick,
            angle=float(theta[-1]),
            converged=bool(solution.status > 0),
            cost=float(solution.cost),
        )


def _least_squares(columns: list[np.ndarray], target: np.ndarray) -> np.ndarray:
    """The ``p`` minimising ``‖Σ_c p_c columns[c] − target‖`` (zeros if undetermined)."""
    a = np.column_stack(columns)
    if not np.all(np.isfinite(a)) or a.shape[0] < a.shape[1]:
        return np.zeros(a.shape[1])
    p, *_ = np.linalg.lstsq(a, target, rcond=None)
    return p


@dataclass
class _Solution:
    x: np.ndarray
    jac: csr_matrix
    cost: float
    status: int
    """1 converged (the cost stopped decreasing), 0 out of iterations."""


def _levenberg_marquardt(
    residuals,
    x0: np.ndarray,
    pattern,
    groups: list[np.ndarray],
    iterations: int = 200,
    damping: float = 1e-3,
    tolerance: float = 1e-12,
) -> _Solution:
    """Minimise ``½‖residuals(x)‖²`` from ``x0`` by Levenberg–Marquardt: steps solve
    ``(JᵀJ + λ diag(JᵀJ)) δ = −Jᵀr`` with a sparse LU factorisation, ``J`` by forward
    differences on the ``pattern`` of the residuals' unknowns, perturbing at once the columns
    of each of ``groups`` (:func:`_column_groups`)."""
    rows, cols = csr_matrix(pattern).nonzero()
    x = np.asarray(x0, dtype=float).copy()
    r = residuals(x)
    cost = 0.5 * float(r @ r)
    lam, status = damping, 0
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
        if not improved or decrease < tolerance:
            status = 1
            break
    if jac_at is not x:  # the last step moved x: the covariance needs J there
        jac = _jacobian(residuals, x, r, groups, rows, cols, pattern.shape)
    return _Solution(x, jac, cost, status)


def _column_groups(pattern: csc_matrix) -> list[np.ndarray]:
    """Columns in groups that share no row (greedy colouring, in the columns' order, each
    taking the first colour that none of the columns it shares a row with has): one
    evaluation per group."""
    ones = csc_matrix(pattern, dtype=np.int32)
    ones.data[:] = 1
    adjacent = (ones.T @ ones).tocsr()
    colour = np.full(pattern.shape[1], -1)
    for column in range(pattern.shape[1]):
        near = colour[adjacent.indices[adjacent.indptr[column] : adjacent.indptr[column + 1]]]
        taken = np.zeros(len(near) + 1, dtype=bool)
        taken[near[(near >= 0) & (near < len(taken))]] = True
        colour[column] = int(np.argmin(taken))
    return [np.flatnonzero(colour == c) for c in range(colour.max() + 1)]


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
