"""The robust estimators at each instant: the same steps, on noisy sensors and real drives.

Step 1 by the arc fit (:class:`~agent.algorithm.robust.arc_fit.ArcRelativePosition`), whose
directions follow the team's agreed rotation of the load (:mod:`agent.algorithm.robust.
rotation`); Steps 4, 5 and 7 by least squares on that rotation angle and on the COM's
displacement (:class:`~agent.algorithm.robust.inertia_fit.InertiaFit`,
:class:`~agent.algorithm.robust.com_fit.ComFit`, :class:`~agent.algorithm.robust.mass_fit.
MassFit`), corrected for the drives' gains (:mod:`agent.algorithm.robust.drive_gain`,
:mod:`agent.algorithm.robust.team_mass`); the team's mass as a consensus on information; once
done, probes that test the load for a change (:mod:`agent.algorithm.robust.load_change`).
Settling is judged by each estimate's own uncertainty, and the uncertainties are published
(:mod:`agent.algorithm.robust.uncertainty`).
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from agent.algorithm.estimation.com_velocity import com_velocity
from agent.algorithm.pipeline import EstimationPipeline
from agent.algorithm.robust.arc_fit import ArcRelativePosition
from agent.algorithm.robust.com_fit import ComFit
from agent.algorithm.robust.drive_gain import DriveGain
from agent.algorithm.robust.hold_fit import HoldFit
from agent.algorithm.robust.inertia_fit import InertiaFit
from agent.algorithm.robust.load_change import ProbeFit
from agent.algorithm.robust.mass_fit import MassFit
from agent.algorithm.robust.rotation import (
    MIN_NOISE,
    RotationConsensus,
    neighbourhood_turn,
    own_turn,
    own_variance,
    turn_variance,
    turn_weight,
    wrapped,
)
from agent.algorithm.robust.team_mass import disagreement, inputs, mass_input, team_mass
from agent.algorithm.robust.uncertainty import (
    PUBLISHED_VARIANCE,
    STEP5_COM_VARIANCE,
    FitShares,
    packed,
)
from agent.algorithm.tuning import AgentConfig
from agent.platform.geometry import Vec2, largest_std, rotate, turned_covariance
from agent.platform.protocol import Estimates
from agent.platform.team import MAX_DISTANCE

if TYPE_CHECKING:
    from agent.algorithm.inbox import Inbox
    from agent.algorithm.interfaces import ProbeSchedule, Schedule


STUCK_TURN = 0.02
"""rad: a load that has turned less than this over :data:`STUCK_FLIPS` of Step 4's flips is
held by the floor: the team's torque does not break it away, so nothing more can be
estimated, and the robot stops pushing and says so."""
STUCK_FLIPS = 2
TEAM_COM_SIGMAS = 3.0
"""The team's mean ``ẑ_C`` is published once within this many of this robot's own standard
deviations (along its least certain axis) of its own (:meth:`RobustPipeline.com_offset`)."""
SWUNG_TURN = 0.3
"""rad: a Step 7 stage in which the load turned back by more than this from its furthest turn
either way (:attr:`~agent.algorithm.robust.hold_fit.HoldFit.swung`) swung under the push:
Step 5's ``ẑ_C`` was too far off for the push to act through the COM, and the mass fit, whose
model is a load that translates, is not backed: no ``m̂`` nor ``μ̂`` is published from it, and
no ``ẑ_C`` either, nor what is made of it (``p_C − p_Ci``, Step 6's ``ṗ_C``): the swing is the
evidence that it is wrong (generated load 47, seeds as below: its ``p_C − p_Ci`` 396 mm off on
every robot, outside every published 95 % ellipse, whose standard deviations were 105–108 mm).
On the noise benchmark's floor (``heft bench noise --generated 40 --coulomb-range 0.005
0.03``, 2026-11-28) generated load 47 swung by 0.66 rad (Step 5 had left its ``ẑ_C`` 27 cm
off; its ``m̂`` was 56 % off behind a published 95 % interval of about ±28 %); generated load
11, the next, by 0.12 rad, its ``m̂`` 1.5 % off within its interval. A turn one way is no
swing: without noise, generated load 1 (``heft bench generated``) began the stage turning at
0.19 rad/s, and turned 0.18 rad in it."""
SWUNG_HIDES = ("com_offset", "com_velocity", "contact_to_com", "contact_to_com_cov")
"""The estimates made of ``ẑ_C``, not published after a swing (:data:`SWUNG_TURN`)."""
PUBLISHED_FROM = 0.25
"""The relative standard deviation at most which ``m̂`` and ``Ĵ`` are published: a fit's
first instants say nothing yet (Step 7's first mass is typically 11 ± 11 kg on the paper's
5 kg load), and a display would draw them as if they did."""


class RobustPipeline(EstimationPipeline):
    """One robot's estimates by the robust estimators."""

    mass_after_com = False  # the mass fit starts with the push (see MassFit)

    def __init__(self, config: AgentConfig, neighbours: tuple[int, ...]):
        self._settle_uncertainty = config.tuning.robust.settle_uncertainty
        self.drive = DriveGain()
        """This robot's drive gain (Step 7 scales ``m`` by the team's mean)."""
        self._mass_input = (0.0, 0.0, 0.0, 0.0)
        """This robot's ``(ι_i, ι_i m_i, ι_i ln m_i, ι_i (ln m_i)²)``, the inputs of the
        team's mass."""
        self._torque_input = 0.0
        """This robot's torque in Step 1's spin-up, the input of the team's mean."""
        self._kick_input = config.tuning.kick_force
        """This robot's kick size in Step 1, the input of the team's mean."""
        self._com_input: Vec2 | None = None
        """This robot's own ``ẑ_C`` (:meth:`_own_com`), the input of the team's."""
        self._variance_input = 0.0
        """This robot's own turn's variance (rad²), the input of the team's mean ``ν``."""
        super().__init__(config, neighbours)
        self.rotation = RotationConsensus(len(neighbours))
        """The team's consensus on the load's rotation, whose level is :attr:`angle`."""
        self._rotation_weight = 0.0
        """``w_i``: the weight of this robot's last turn (:meth:`_own_turn`), sent and used by
        the rotation's consensus."""
        self.lag = 0.0
        """``τ_d`` (s), the drives' lag from Step 4's fit (Steps 5 and 7)."""
        self.probe: ProbeFit | None = None
        """Once done, the current probe's fits (:mod:`agent.algorithm.robust.load_change`)."""
        self.probe_began = -1
        """The first tick of :attr:`probe`'s probe."""
        self.hold: HoldFit | None = None
        """Step 7's refinement of ``z_C`` (:meth:`_held`), once its stage has begun."""
        self._turns: deque[tuple[float, float]] = deque()
        """``(t, θ)`` over Step 4's last :data:`STUCK_FLIPS` flips (is the load stuck?)."""

    # ---------------------------------------------------------------- the drives' gains
    @property
    def moment(self) -> float | None:
        """``Ĵ`` scaled by ``q / (w/n)``: the drives applied the torque ``±k n q`` where the fit
        assumed ``±k w`` (:mod:`agent.algorithm.robust.team_mass`)."""
        if self.inertia is None:
            return None
        moment = self.inertia.estimate
        return moment * self._torque_gain if moment is not None else moment

    @property
    def _torque_gain(self) -> float:
        """``q / (w/n)``: how much more torque the drives applied in Step 4 than commanded."""
        xi = self.mean_square_offset
        weighted = self.consensus["mean_gain_square_offset"]
        return weighted / xi if xi > 0.0 and weighted > 0.0 else 1.0

    def com_offset(self, alpha: float) -> Vec2 | None:
        """``z_C`` as published: the team's mean of the robots' own (:meth:`_own_com`), the
        consensus ``mean_weighted_com / mean_com_weight`` (each robot's fit has nearly the
        same information, and their errors differ by each robot's own noise), once that is
        within :data:`TEAM_COM_SIGMAS` standard deviations of this robot's own (its fit's,
        scaled as Step 5's, :data:`~agent.algorithm.robust.uncertainty.STEP5_COM_VARIANCE`:
        a consensus whose inputs have just appeared is not yet a mean), else its own."""
        own = self._own_com(alpha)
        if own is None:
            return None
        team = self._team_com(alpha)
        if team is None:
            return own
        fit = self._com_fit
        cov = None if fit is None else fit.covariance
        if cov is None:
            return own
        (a, b), (_, d) = cov
        limit = TEAM_COM_SIGMAS * math.sqrt(STEP5_COM_VARIANCE) * largest_std(a, b, d)
        if math.hypot(team[0] - own[0], team[1] - own[1]) > limit:
            return own
        return team

    @property
    def com_offset_now(self) -> Vec2 | None:
        """``z_C`` at the estimation instant that Step 7's push acts through: the team's mean
        of the robots' own (:meth:`_team_com`) once there is one, else this robot's Step 5
        ``ẑ_C``. Every robot holds the load's turn with ``(τ/w) z_i⊥``, ``τ = −n ẑ_C × c``
        (:meth:`~agent.algorithm.robust.phases.RobustPhases._not_turning`), whose sum over the
        team is no force only if every robot's ``τ`` is the same: with each robot's own
        ``ẑ_C`` (12 cm apart on generated load 14), about 1 N of a 15 N push went unmodelled,
        and every robot's ``m̂`` was 3–5 % low."""
        alpha = self.angle - self.push_angle
        team = self._team_com(alpha)
        return team if team is not None else self._push_offset(alpha)

    def _team_com(self, alpha: float) -> Vec2 | None:
        """The consensus ``mean_weighted_com / mean_com_weight`` after the rotation ``alpha``
        since the push began (``None`` before the robots have given it any)."""
        c = self.consensus
        weight = c["mean_com_weight"]
        if not weight > 0.0:
            return None
        now = self.angle - self.push_angle
        team = rotate(c["mean_weighted_com"], alpha - now)
        return (team[0] / weight, team[1] / weight)

    @property
    def _com_fit(self) -> ComFit | None:
        """The fit of this robot's own ``ẑ_C``: Step 7's once its stage has refined Step 5's
        (:mod:`agent.algorithm.robust.hold_fit`), else Step 5's."""
        hold = self.hold
        return self.com if hold is None or hold.estimate is None else hold

    def _own_com(self, alpha: float) -> Vec2 | None:
        """This robot's own ``ẑ_C`` after the rotation ``alpha`` since the push began
        (:attr:`_com_fit`'s), corrected for the drives' gains (:meth:`_corrected`)."""
        fit = self._com_fit
        return None if fit is None else self._corrected(fit.com_offset(alpha))

    def _push_offset(self, alpha: float) -> Vec2 | None:
        """Step 5's ``z_C``, corrected for the drives' gains (:meth:`_corrected`)."""
        return self._corrected(super().com_offset(alpha))

    def _corrected(self, z_c: Vec2 | None) -> Vec2 | None:
        """``z_C`` from the offset that the fits find. The torque of the push about the COM is
        ``n (h + ḡ z_C) × f`` (:mod:`agent.algorithm.robust.team_mass`), so a fit (with the
        corrected ``Ĵ``) finds ``c' = h + ḡ z_C``, and ``z_C = (c' − h) / ḡ``."""
        if z_c is None:
            return z_c
        h, gain = self.consensus["mean_gain_offset"], self.consensus["mean_gain"]
        return ((z_c[0] - h[0]) / gain, (z_c[1] - h[1]) / gain)

    def applied(self, command: Vec2, measured: Vec2) -> None:
        """This robot's drive gain, the input of the team's mean gain."""
        self.drive.update(command, measured, self.dt)

    @property
    def drive_share(self) -> float | None:
        """``ĝ``, this robot's drive gain, once its fit has one
        (:class:`~agent.algorithm.robust.drive_gain.DriveGain`)."""
        return self.drive.fitted

    @property
    def mass(self) -> float | None:
        """``m̂``: the team's information-weighted mean of the robots' fits
        (:func:`~agent.algorithm.robust.team_mass.team_mass`), or this robot's own until that
        is known."""
        if self.mass_estimator is None:
            return None
        return self._robust_mass()[0]

    def _robust_mass(self) -> tuple[float | None, float | None]:
        """``(m̂, σ)``: the team's mass and its standard deviation, or this robot's own
        (:meth:`_own_mass`) until the team's is known."""
        own, std = self._own_mass()
        c = self.consensus
        team = (
            None
            if own is None
            else team_mass(c["mean_mass_information"], c["mean_weighted_mass"], own)
        )
        return (own, std) if team is None else (team[0], team[0] * team[1])

    def _settling_mass(self) -> tuple[float | None, float | None]:
        """The team's ``m̂``, the one published, and its standard deviation
        (:meth:`_robust_mass`): Step 7 ends once the team knows its mass, not once every robot
        knows its own. The last robot to know its own is the one whose fit is the noisiest (on
        generated load 94, 49 kg under three robots, robot 1's was 0.87 % where the others'
        were 0.21 and 0.24 %), and the team's ``m̂`` weighs it by its information."""
        return self._robust_mass()

    def _own_mass(self) -> tuple[float | None, float | None]:
        """This robot's mass fit scaled by the drives' mean gain ``ḡ``, and its standard
        deviation (with that of ``ḡ``, every robot's gain taken as uncertain as this one's):
        ``(None, None)`` before the fit."""
        fit = self.mass_estimator
        mass = None if fit is None else fit.estimate
        if mass is None:
            return (None, None)
        gain = self.consensus["mean_gain"]
        std = fit.std
        if std is not None:
            team_gain_std = (self.drive.std or 0.0) / math.sqrt(self.n)
            std = math.hypot(std * gain, mass * gain * team_gain_std)
        return (mass * gain, std)

    # ---------------------------------------------------------------- hooks
    def _new_edge(self) -> ArcRelativePosition:
        return ArcRelativePosition(self.forgetting)

    def _sample_edge(self, edge: Any, zdot: Vec2, dt: float) -> None:
        edge.update(zdot, dt, follow=False)  # its direction follows the team's rotation

    def _inputs(self, x: Vec2) -> Sequence[float]:
        return inputs(
            x,
            self.drive.estimate,
            self._mass_input,
            self._torque_input,
            self._kick_input,
            self._com_input,
            self._variance_input,
        )

    def _before_consensus(self, schedule: Schedule) -> None:
        self._mass_input = mass_input(*self._own_mass())  # the input of the team's (Step 7)
        self._com_input = self._own_com(self.angle - self.push_angle)
        self._torque_input = schedule.spin_torque
        self._kick_input = schedule.kick_level

    def _turn(
        self, zdots: dict[int, Vec2], interval: float, inbox: Inbox, ref: int | None
    ) -> float:
        """The team's rotation since the last instant (:mod:`agent.algorithm.robust.rotation`):
        this robot's own turn, from the edges sampled over the whole interval (else the last
        ω times the interval), plus the consensus on the neighbours' levels; each such edge's
        direction filter then follows it."""
        fallback = (self.omega or 0.0) * interval
        edges = self.edges
        fresh = [
            edges[j] for j in zdots if edges[j].moving and abs(edges[j].last_dt - interval) < 1e-9
        ]
        own, self._rotation_weight = self._own_turn(fresh, interval)
        heard = (
            (
                j,
                s.degree,
                s.instant,
                s.consensus.rotation,
                s.consensus.rotation_weight,
            )
            for j, s in inbox.latest.items()
            if j in edges
        )
        turn, variance = (fallback, None) if own is None else own
        if variance is not None:
            self._variance_input = own_variance(variance)
        turn = self.rotation.update(
            self.instant, turn, heard, self._angle_at.get, self._rotation_weight
        )
        # the team's, from the last instant's consensus (this one's runs after the turn)
        variance = turn_variance(self.consensus["mean_turn_variance"], self.n)
        for j in zdots:
            edge = edges[j]
            if edge in fresh:
                edge.follow(turn, variance)
            else:
                edge.follow(edge.last_turn)
        return turn

    def _own_turn(
        self, fresh: list[ArcRelativePosition], interval: float
    ) -> tuple[tuple[float, float] | None, float]:
        """``((δ_i, Var(δ_i)), w_i)`` from the ``fresh`` edges (sampled over the whole
        interval): the turn of this robot's neighbourhood fitted with its translation once
        every one's ``ẑ_ij`` is known (:func:`~agent.algorithm.robust.rotation.
        neighbourhood_turn`), else the weighted mean of their own turns
        (:func:`~agent.algorithm.robust.rotation.own_turn`); ``w_i`` is its information in the
        fit's units, ``σ_e² Δt² / (4 Var(δ_i))`` (``D_i`` for the fit; 0: no turn)."""
        if not fresh:
            return None, 0.0
        noise = max(sum(e.noise for e in fresh) / len(fresh), MIN_NOISE)
        scale = 0.25 * noise * interval * interval
        estimates = [e.estimate for e in fresh]
        if None not in estimates:
            local = neighbourhood_turn(
                (z, e.step, e.last_turn, e.arc) for z, e in zip(estimates, fresh)
            )
            if local is not None:
                turn, spread = local
                return (turn, scale / spread), spread
        own = own_turn(
            (
                e.last_turn,
                turn_weight(radius=e.distance, speed2=e.speed2, noise=e.noise, dt=interval),
            )
            for e in fresh
        )
        return own, 0.0 if own is None else scale / own[1]

    def _excite_stds(self) -> tuple[float | None, float | None]:
        """The least certain distance's, and the least certain ``z_ij``'s for ``z_i`` and
        ``w / n`` (the consensus of the ``z_ij``)."""
        edges = [self.edges[j] for j in self.neighbours]
        return (max(e.distance_std for e in edges), max(e.std for e in edges))

    def _std(self, estimator: Any) -> float | None:
        return estimator.std

    def _new_inertia(self) -> InertiaFit:
        return InertiaFit(self.forgetting, self._torque_scale_std())

    def _update_inertia(self, torque: float, span: float) -> None:
        # the rotation angle, not ω; friction's torque against the turn
        fit = self.inertia
        if not fit.started:
            self._turns.clear()
        fit.update(self.angle, torque, span, spin=self._spin)
        # held by the floor: turned less than STUCK_TURN over the last STUCK_FLIPS flips
        window, turns = STUCK_FLIPS * self.tuning.robust.inertia_flip_s, self._turns
        turns.append((fit.t, self.angle))
        while turns and turns[0][0] < fit.t - window:
            turns.popleft()
        if fit.t >= window and not self.stuck:
            self.stuck = abs(self.angle - turns[0][1]) < STUCK_TURN

    @property
    def _spin(self) -> float:
        """``sgn ω``: the way the load turns now."""
        return math.copysign(1.0, self.omega or 1.0)

    @property
    def friction_torque(self) -> tuple[float, float] | None:
        """``(τ̂_c, σ)`` (N m): the floor's friction torque about the COM while the load turns
        (Step 4's fit, :mod:`agent.algorithm.robust.inertia_fit`), scaled like ``Ĵ`` by the
        drives' gains, and its standard deviation (with the gains')."""
        found = None if self.inertia is None else self.inertia.friction_torque
        if found is None:
            return None
        torque, std = found
        gain = self._torque_gain
        team_gain_std = (self.drive.std or 0.0) / math.sqrt(self.n)
        return torque * gain, math.hypot(std * gain, torque * gain * team_gain_std)

    def _new_com(self, schedule: ProbeSchedule) -> ComFit:
        self.lag = self.inertia.lag  # the drives' lag, which Step 4's fit found
        return ComFit(
            self.n, schedule.moment_used, schedule.push, self.forgetting, self.lag, falling=True
        )

    def _update_com(
        self, alpha: float, sign: float, span: float, added: Vec2, torque: float = 0.0
    ) -> None:
        fall = 0.0
        if self.com.falling and self.velocity is not None:
            radius = math.sqrt(self.mean_square_offset)
            z_c = self._push_offset(alpha) if self.com.estimate is not None else (0.0, 0.0)
            omega = self.omega or 0.0
            velocity = com_velocity(self.velocity, omega, self._contact_offset(z_c))
            fall = radius * HoldFit.drag(omega, velocity, radius) - self._spin
        self.com.update(alpha, sign, span, added=added, spin=self._spin, torque=torque, fall=fall)

    def _held(self, alpha: float, sign: float, span: float, added: Vec2, torque: float) -> None:
        """Step 7's refinement of ``z_C`` (:class:`~agent.algorithm.robust.hold_fit.HoldFit`),
        begun at the stage's first instant from Step 5's estimate and its fit's covariance
        scaled by :data:`~agent.algorithm.robust.uncertainty.STEP5_COM_VARIANCE`. The team's
        holding torque is this robot's, ``−n ẑ_C × c`` and the damping ``−b ω w``
        (``turn_damping``), scaled by the drives' torque gain."""
        com = self.com
        if self.hold is None:
            c, cov = com.estimate, com.covariance
            if c is None or cov is None:
                return
            k = STEP5_COM_VARIANCE
            (a, b), (_, d) = cov
            prior = ((k * a, k * b), (k * b, k * d))
            self.hold = HoldFit(self.n, 1.0 / com.inverse_moment, com.force, self.lag, c, prior)
            self.hold.update(alpha, 1.0, span)  # starts the integrals
            return
        omega = self.omega or 0.0
        radius = math.sqrt(self.mean_square_offset)
        drag = HoldFit.drag(omega, self.com_velocity or (0.0, 0.0), radius)
        gain = self._torque_gain
        damping = gain * self.tuning.robust.turn_damping * self.n * self.mean_square_offset
        self.hold.update(
            alpha, sign, span, added=added, drag=drag, torque=torque * gain, damping=damping
        )

    def _new_mass(self, schedule: ProbeSchedule) -> MassFit:
        """Step 7's fit, the offset it is given as uncertain as Step 5's fit makes ``ẑ_C``: the
        largest standard deviation of that fit's covariance, scaled by Step 5's calibrated
        factor (:data:`~agent.algorithm.robust.uncertainty.STEP5_COM_VARIANCE`)."""
        offset_std = 0.0
        cov = self.com.covariance if self.com is not None else None
        if cov is not None:
            (a, b), (_, d) = cov
            offset_std = math.sqrt(STEP5_COM_VARIANCE) * largest_std(a, b, d)
        return MassFit(self.n, schedule.push, self.forgetting, self.lag, offset_std=offset_std)

    def _update_mass(
        self, velocity: Vec2, offset: Vec2, sign: float, span: float, added: Vec2
    ) -> None:
        self.mass_estimator.update(
            velocity,
            offset,
            self.angle,
            sign,
            span,
            added=added,
            com_velocity=self.com_velocity,
        )

    @property
    def coulomb(self) -> tuple[float, float] | None:
        """``(μ̂, σ)``: the floor's kinetic friction coefficient (Step 7's fit while the load
        translates, :mod:`agent.algorithm.robust.mass_fit`)."""
        fit = self.mass_estimator
        return None if fit is None else fit.coulomb

    def _forget_load(self) -> None:
        super()._forget_load()
        self.probe = None
        self.hold = None

    def _torque_scale_std(self) -> float:
        """The relative standard deviation of ``w = Σ‖z_i‖²``, which scales the torque Step 4
        assumes (``±k w``) and so ``Ĵ``: ``2 σ_z / ‖z_i‖`` per robot, ``σ_z`` the mean of
        this robot's edges' (the others' taken alike), averaged over ``n`` robots."""
        stds = [edge.std for edge in self.edges.values() if edge.std is not None]
        xi = self.mean_square_offset
        size = math.sqrt(xi) if xi > 0.0 else 0.0
        if not stds or size == 0.0:
            return 0.0
        return 2.0 * (sum(stds) / len(stds)) / size / math.sqrt(self.n)

    # ---------------------------------------------------------------- once done: probes
    def _once_pushed(self, e: int, prev: int, span: float, schedule: ProbeSchedule) -> None:
        """Each probe's fit over the interval ``span`` from ``prev`` to ``e``, and at the probe's
        last instant its test against the estimates (:mod:`agent.algorithm.robust.load_change`)."""
        start = schedule.probe_start(e)
        if start is None or self.mass_estimator is None or self.com_velocity is None:
            return
        if self.probe is not None and self.probe_began != start:
            self.probe = None  # (its last instant was never measured)
        if e == start:
            mass = self.mass_estimator.estimate
            if mass is None or mass <= 0.0:
                return
            self.probe = ProbeFit(self.n, mass, schedule.push, self.lag, self.angle)
            self.probe_began = start
            self.probe.update(self.com_velocity, self.omega, self.angle, 0.0, 0.0)
            return
        end = start + schedule.probe_ticks
        if self.probe is None or prev < start or e > end:
            return
        sign = sum(schedule.probe_sign(t) for t in range(prev, e)) / (e - prev)
        self.probe.update(self.com_velocity, self.omega, self.angle, sign, span)
        if e < end:
            return
        probe, self.probe = self.probe, None
        load = self._published_load()
        if load is None:
            return
        scores = probe.score(*load)
        if scores is not None:
            self.change_score = max(scores)
            threshold = self.tuning.robust.change_threshold
            self.changed = self.changed or self.change_score > threshold

    def _published_load(self) -> tuple[float, tuple[float, float, float]] | None:
        """The published relative standard deviation of ``m̂`` and covariance of this robot's
        ``contact_to_com``, now (``None`` if either is not known)."""
        relative = self.known_relative_positions()
        z_c = self.com_offset(self.angle - self.push_angle)
        mass = self.mass
        if z_c is None or not mass:
            return None
        z_i = self.consensus.centroid
        reported = self._reported(relative, (-(z_i[0] + z_c[0]), -(z_i[1] + z_c[1])))
        mass_std, cov = reported["mass_std"], reported.get("contact_to_com_cov")
        if mass_std is None or cov is None:
            return None
        return mass_std / mass, cov

    # ---------------------------------------------------------------- reporting
    def estimates(self, robot: int, schedule) -> Estimates:
        """The estimates (:meth:`EstimationPipeline.estimates`), but ``m̂`` and ``Ĵ`` only once
        known to :data:`PUBLISHED_FROM` of themselves: not yet, rather than a number that
        means nothing; and neither ``m̂``, ``μ̂`` nor the COM (:data:`SWUNG_HIDES`) once a
        Step 7 stage has swung the load (:data:`SWUNG_TURN`)."""
        found = super().estimates(robot, schedule)
        hidden = {}
        for key in ("mass", "moment"):
            value, std = getattr(found, key), getattr(found, key + "_std")
            if value is not None and not (std is not None and std <= PUBLISHED_FROM * abs(value)):
                hidden[key] = hidden[key + "_std"] = None
        if self.hold is not None and self.hold.swung > SWUNG_TURN:
            for key in ("mass", "coulomb"):
                hidden[key] = hidden[key + "_std"] = None
            hidden.update(dict.fromkeys(SWUNG_HIDES))
        return dataclasses.replace(found, **hidden) if hidden else found

    def fit_shares(self) -> FitShares:
        """The shares of ``Ĵ``'s and of this robot's own ``m̂``'s uncertainties that their fits
        give (:class:`~agent.algorithm.robust.uncertainty.FitShares`), now."""
        inertia, mass_fit = self.inertia, self.mass_estimator
        fit_std = None if inertia is None else inertia.fit_std
        own, std = self._own_mass()
        mass_std = None if mass_fit is None else mass_fit.std
        return FitShares(
            moment=None if fit_std is None else fit_std * self._torque_gain,
            own_mass=None
            if own is None or std is None or mass_std is None
            else (own, std, mass_std * self.consensus["mean_gain"]),
            push_offset=self._push_contact_to_com(),
        )

    def _push_contact_to_com(self) -> tuple[Vec2, tuple[float, float, float]] | None:
        """``contact_to_com`` from Step 5's ``ẑ_C`` alone and its covariance before
        :data:`~agent.algorithm.robust.uncertainty.STEP5_COM_VARIANCE`, as this robot would
        publish them had Step 7 not refined it (``None``: no Step 5 fit, or a swung load's)."""
        com = self.com
        if com is None or (self.hold is not None and self.hold.swung > SWUNG_TURN):
            return None
        relative = self.known_relative_positions()
        edges = self._edge_covariances(relative)
        z_c = self._push_offset(self.angle - self.push_angle)
        cov = self._offset_covariance(com, edges, self._moment_std())
        if z_c is None or cov is None:
            return None
        z_i = self.consensus.centroid
        return (-(z_i[0] + z_c[0]), -(z_i[1] + z_c[1])), cov

    def consensus_state(self):
        """The consensus' states, with this robot's level of the load's rotation (sent modulo
        ``2π``) and the weight of its turns."""
        consensus = self.consensus
        consensus.set("rotation", wrapped(self.angle))
        consensus.set("rotation_weight", min(self._rotation_weight, MAX_DISTANCE**2))  # its bound
        return consensus.state

    def _reported(self, relative: dict[int, Vec2], contact_to_com: Vec2 | None) -> dict:
        """The published standard deviations and covariances, for
        :class:`~agent.platform.protocol.Estimates` (:mod:`agent.algorithm.robust.uncertainty`):
        ``relative`` are the ``z_ij`` reported, ``contact_to_com`` the offset reported (``None``:
        not yet)."""
        edges = self._edge_covariances(relative)
        drive_std = self.drive.std
        moment_std = self._moment_std()
        _, mass_std = self._robust_mass()
        if mass_std is not None:
            c = self.consensus
            mass_std *= math.sqrt(PUBLISHED_VARIANCE["mass"]) * disagreement(
                c["mean_mass_information"],
                c["mean_weighted_log_mass"],
                c["mean_weighted_square_log_mass"],
                self.n,
            )
        scale = PUBLISHED_VARIANCE["relative"]
        out: dict = {
            "drive_gain": None if drive_std is None else self.drive.estimate,
            "drive_gain_std": drive_std,
            "relative_positions_cov": {
                j: (scale * xx, scale * xy, scale * yy) for j, (xx, xy, yy) in edges.items()
            },
            "moment_std": None
            if moment_std is None
            else moment_std * math.sqrt(PUBLISHED_VARIANCE["moment"]),
            "mass_std": mass_std,
        }
        for key, found in (
            ("friction_torque", self.friction_torque),
            ("coulomb", self.coulomb),
        ):
            if found is not None:
                scale = math.sqrt(PUBLISHED_VARIANCE[key])
                out[key], out[key + "_std"] = found[0], found[1] * scale
        fit = self._com_fit
        if contact_to_com is not None and edges and fit is not None:
            found_cov = self._offset_covariance(fit, edges, moment_std)
            if found_cov is not None:
                scale = self._com_variance_factor
                out["contact_to_com_cov"] = tuple(scale * v for v in found_cov)
        return out

    def _edge_covariances(self, relative: dict[int, Vec2]) -> dict[int, tuple[float, float, float]]:
        """Each reported ``z_ij``'s covariance (its direction filter's, turned with the load
        since the edge's instant), before its factor, ``(xx, xy, yy)``."""
        edges = {}
        for j in relative:
            cov = self.edges[j].covariance
            if cov is not None:
                turned = self.angle - self._angle_at.get(self._edge_instant[j], self.angle)
                edges[j] = packed(turned_covariance(cov, turned))
        return edges

    def _moment_std(self) -> float | None:
        """``Ĵ``'s standard deviation before its factor: the inertia fit's, scaled by the
        drives' torque gain, and that of the team's mean gain (``σ_g / √n`` relative)."""
        if self.inertia is None or self.inertia.std is None:
            return None
        team_gain_std = (self.drive.std or 0.0) / math.sqrt(self.n)
        return math.hypot(self.inertia.std * self._torque_gain, self.moment * team_gain_std)

    def _offset_covariance(
        self,
        fit: ComFit,
        edges: dict[int, tuple[float, float, float]],
        moment_std: float | None,
    ) -> tuple[float, float, float] | None:
        """``Cov(p_C − p_Ci)`` from the ``ẑ_C`` of ``fit`` (Step 5's or Step 7's), before its
        factor: the mean of ``edges`` (this robot's ``z_ij``'s), ``fit``'s covariance turned
        with the load, ``c cᵀ (σ_J/J)²``, and the gains' ``σ_g² w / (2 n²)`` per axis
        (:mod:`agent.algorithm.robust.uncertainty`); ``None`` before ``fit`` has one."""
        com_cov = fit.covariance
        if com_cov is None or not edges:
            return None
        alpha = self.angle - self.push_angle
        (a, b), (_, d) = turned_covariance(com_cov, alpha)
        c = fit.com_offset(alpha)
        moment = self.moment
        rel2 = (moment_std / moment) ** 2 if moment and moment_std is not None else 0.0
        count = len(edges)
        gain_std = self.drive.std or 0.0
        weighted = gain_std * gain_std * self.mean_square_offset / (2.0 * self.n)
        xx = sum(e[0] for e in edges.values()) / count + a + rel2 * c[0] * c[0] + weighted
        xy = sum(e[1] for e in edges.values()) / count + b + rel2 * c[0] * c[1]
        yy = sum(e[2] for e in edges.values()) / count + d + rel2 * c[1] * c[1] + weighted
        return (xx, xy, yy)

    @property
    def _com_variance_factor(self) -> float:
        """The factor on the variance of this robot's own ``ẑ_C`` (and its ``contact_to_com``):
        ``contact_to_com``'s in :data:`~agent.algorithm.robust.uncertainty.PUBLISHED_VARIANCE`
        once Step 7 has refined it, Step 5's (:data:`~agent.algorithm.robust.uncertainty.
        STEP5_COM_VARIANCE`) before."""
        if self._com_fit is self.com:
            return STEP5_COM_VARIANCE
        return PUBLISHED_VARIANCE["contact_to_com"]
