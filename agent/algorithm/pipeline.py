"""The paper's seven steps, run by one robot at each estimation instant (see
:mod:`agent.algorithm.inbox` for which instants), and the tracking of when its estimates settle.

At instant ``e``:

1. Step 1, ``z_ij`` for each neighbour ``j`` whose velocity at ``e`` is known, from
   ``ż_ij = ṗ_Ci − ṗ_Cj`` (:class:`~agent.algorithm.estimation.relative_position.RelativePosition`);
2. Step 3, ``ω`` by eq. (5) from the longest edge with a sample at ``e``, and the load's rotation
   since the previous instant (the edge's own turn when it spans the same interval; with the
   robust estimators, the team's, :mod:`agent.algorithm.estimation.rotation`, which every edge's
   direction then follows);
3. Step 2 and eq. (16), ``z_i`` and ``w`` by consensus, turned with the load
   (:class:`~agent.algorithm.estimation.centroid.CentroidConsensus`);
4. while the team applies eq. (14) (the inertia phase), Step 4, ``J``;
5. while it pushes with a common force (the push phase), Step 5, ``z_C`` (by regression, with
   observer (24) beside it), Step 6, ``ṗ_C`` by eq. (7), and once ``z_C`` has settled, Step 7,
   ``m``.

Steps 4–7 use only instants whose ω was measured at that instant (not carried over because every
neighbour's message was lost); the interval since the previous such instant is used whole, and
only if the team applied the phase's force over all of it.

Settling (:class:`~agent.algorithm.estimation.settling.SettleDetectors`): in the excite phase the
distances ``‖z_ij‖``, ``z_i`` in the frame of the longest edge and ``w / n`` are watched at every
instant; ``Ĵ``, ``z_C`` (at the reference instant) and ``m̂`` at the instants they are updated.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from agent.algorithm.estimation.angular_velocity import angular_velocity
from agent.algorithm.estimation.arc_fit import ArcRelativePosition
from agent.algorithm.estimation.centroid import CentroidConsensus, mass_input
from agent.algorithm.estimation.com_fit import ComFit
from agent.algorithm.estimation.com_observer import ComObserver
from agent.algorithm.estimation.com_regression import ComRegression
from agent.algorithm.estimation.com_velocity import com_velocity
from agent.algorithm.estimation.drive_gain import DriveGain
from agent.algorithm.estimation.inertia import InertiaEstimator
from agent.algorithm.estimation.inertia_fit import InertiaFit
from agent.algorithm.estimation.load_change import ProbeFit
from agent.algorithm.estimation.mass import MassEstimator
from agent.algorithm.estimation.mass_fit import MassFit
from agent.algorithm.estimation.relative_position import RelativePosition
from agent.algorithm.estimation.rotation import RotationConsensus, own_turn, turn_weight
from agent.algorithm.estimation.settling import SettleDetectors
from agent.algorithm.tuning import AgentConfig, Estimators
from agent.platform.geometry import Vec2, rotate, turned_covariance
from agent.platform.protocol import Estimates, Phase

PUBLISHED_VARIANCE = {"relative": 0.79, "contact_to_com": 1.57, "moment": 1.52}
"""Factors on the variances the robust estimators publish for ``z_ij``, ``contact_to_com``
and ``Ĵ`` (not on those they settle by): the drives' gains and the reversing push add errors
to ``contact_to_com`` and ``Ĵ`` that their fits do not model, while the direction filters of
the ``z_ij`` take the team's turn for twice as uncertain as independent robots' turns
(:mod:`agent.algorithm.estimation.rotation`), which errs on the safe side. Measured over 40 runs of
``heft bench --noise``'s setting (the paper's scenario at 1 cm/s with the issue's drives),
seeds 20–59: 95 % of the errors fell within 1.96 published standard deviations (2.45 for the
planar ones) with the variances scaled by these factors (the team's ``m̂``'s needed 0.82, and
is published as it is). The benchmark's seeds, 0–19, were not used."""

if TYPE_CHECKING:
    from agent.algorithm.inbox import Inbox
    from agent.algorithm.phase_machine import PhaseMachine


class EstimationPipeline:
    """One robot's estimates, brought up to each estimation instant in turn."""

    def __init__(self, config: AgentConfig, neighbours: tuple[int, ...]):
        tuning = config.tuning
        self.tuning = tuning
        self.n = config.n
        self.neighbours = neighbours
        self.dt = config.period_s
        window = max(1, round(tuning.settle_window_s / self.dt))
        self.robust = tuning.estimator == Estimators.ROBUST
        self.settle = SettleDetectors.of(
            window, tuning.settle_tolerance, tuning.settle_uncertainty if self.robust else 0.0
        )
        self.started: dict[int, int] = {1: 0}
        """Paper step → the instant (or tick, for a phase's steps) it began."""
        memory = tuning.regression_memory_s
        self.forgetting = math.exp(-self.dt / memory) if memory > 0 else 1.0
        self.edges: dict[int, RelativePosition | ArcRelativePosition] = {
            j: ArcRelativePosition(self.forgetting)
            if self.robust
            else RelativePosition(tuning.filter_gain, self.forgetting)
            for j in self.neighbours
        }
        self._edge_instant: dict[int, int] = {}
        """The last instant each edge was sampled at."""
        self._edge_time: dict[int, float] = {j: 0.0 for j in self.neighbours}
        """The time (s) of each edge's last sample used."""
        self._angle_at: dict[int, float] = {}
        """``angle`` at each recent instant."""
        self.rotation = RotationConsensus(len(neighbours), config.n)
        """The team's consensus on the load's rotation, whose level is :attr:`angle` (the
        robust estimators')."""
        self.instant = -1
        """The estimation instant (``-1`` before any)."""
        self.angle = 0.0
        """The load's rotation (rad) since instant 0."""
        self.omega: float | None = None
        """``ω`` (Step 3), measured or carried over."""
        self.measured: int | None = None
        """The last instant whose ω was measured (Steps 4–7 use only those)."""
        self.zdot: dict[int, Vec2] = {}
        """``ż_ij`` at the estimation instant, by neighbour."""
        self.consensus = CentroidConsensus(config.robot, self.neighbours)
        self.inertia: InertiaEstimator | InertiaFit | None = None
        self.com: ComRegression | ComFit | None = None
        self.push_angle = 0.0
        """The load's rotation angle at the push phase's first instant (Step 5's reference)."""
        self.observer: ComObserver | None = None
        self.mass_estimator: MassEstimator | MassFit | None = None
        self.drive = DriveGain()
        """This robot's drive gain (the robust Step 7 scales ``m`` by the team's mean)."""
        self.lag = 0.0
        """``τ_d`` (s), the drives' lag from Step 4's fit (robust estimators; Steps 5 and 7)."""
        self.com_velocity: Vec2 | None = None
        self.probe: ProbeFit | None = None
        """Once done, the current probe's fits (:mod:`agent.algorithm.estimation.load_change`)."""
        self.probe_began = -1
        """The first tick of :attr:`probe`'s probe."""
        self.change_score: float | None = None
        """The last probe's test of the load against the estimates (standard deviations)."""
        self.changed = False
        """Whether a probe found the load changed since the team's last (re)start."""

    # ---------------------------------------------------------------- what the phases read
    @property
    def centroid(self) -> Vec2:
        """``z_i`` (Step 2) at the estimation instant."""
        return self.consensus.centroid

    @property
    def spread(self) -> float:
        """``w / n`` (eq. 16)."""
        return self.consensus.spread

    @property
    def moment(self) -> float | None:
        """``Ĵ`` (Step 4); the robust fit's scaled by ``q / (w/n)``: the drives applied the
        torque ``±k n q`` where the fit assumed ``±k w``
        (:mod:`agent.algorithm.estimation.centroid`)."""
        if self.inertia is None:
            return None
        moment = self.inertia.estimate
        return moment * self._torque_gain if self.robust and moment is not None else moment

    @property
    def _torque_gain(self) -> float:
        """``q / (w/n)``: how much more torque the drives applied in Step 4 than commanded."""
        spread, weighted = self.consensus.spread, self.consensus.gain_spread
        return weighted / spread if spread > 0.0 and weighted > 0.0 else 1.0

    def com_offset(self, alpha: float) -> Vec2 | None:
        """``z_C`` after the rotation ``alpha`` since the push began (Step 5); the robust one
        corrected for the drives' gains. The torque of the push about the COM is
        ``n (h + ḡ z_C) × f`` (:mod:`agent.algorithm.estimation.centroid`), so the fit (with the
        corrected ``Ĵ``) finds ``c' = h + ḡ z_C``, and ``z_C = (c' − h) / ḡ``."""
        z_c = self.com.com_offset(alpha) if self.com is not None else None
        if z_c is None or not self.robust:
            return z_c
        h, gain = self.consensus.gain_centroid, self.consensus.gain
        return ((z_c[0] - h[0]) / gain, (z_c[1] - h[1]) / gain)

    # ---------------------------------------------------------------- one instant
    def drive_gain(self, command: Vec2, measured: Vec2) -> None:
        """The force ``measured`` over the last tick, commanded ``command``: this robot's drive
        gain, the input of the team's mean gain (the robust estimators' only; the paper's take
        every drive for ideal)."""
        if self.robust:
            self.drive.update(command, measured, self.dt)
            self.consensus.gain_input = self.drive.estimate

    @property
    def mass(self) -> float | None:
        """``m̂`` (Step 7); the robust one is the team's information-weighted mean of the
        robots' fits (:meth:`~agent.algorithm.estimation.centroid.CentroidConsensus.team_mass`), or
        this robot's own until that is known."""
        if self.mass_estimator is None:
            return None
        if not self.robust:
            return self.mass_estimator.estimate
        return self._robust_mass()[0]

    def _robust_mass(self) -> tuple[float | None, float | None]:
        """``(m̂, σ)``: the team's mass and its standard deviation, or this robot's own
        (:meth:`_own_mass`) until the team's is known."""
        own, std = self._own_mass()
        team = None if own is None else self.consensus.team_mass(own)
        return (own, std) if team is None else (team[0], team[0] * team[1])

    def _own_mass(self) -> tuple[float | None, float | None]:
        """This robot's robust mass fit scaled by the drives' mean gain ``ḡ``, and its
        standard deviation (with that of ``ḡ``, every robot's gain taken as uncertain as this
        one's): ``(None, None)`` before the fit."""
        fit = self.mass_estimator
        mass = None if fit is None else fit.estimate
        if mass is None:
            return (None, None)
        gain = self.consensus.gain
        std = fit.std
        if std is not None:
            team_gain_std = (self.drive.std or 0.0) / math.sqrt(self.n)
            std = math.hypot(std * gain, mass * gain * team_gain_std)
        return (mass * gain, std)

    def estimate_at(self, e: int, inbox: Inbox, phases: PhaseMachine) -> None:
        """Steps 1–7 at instant ``e`` (the one after :attr:`instant`)."""
        t = e * self.dt
        previous = self.instant
        self.instant = e
        v_i = inbox.own_velocity.get(e)
        zdots: dict[int, Vec2] = {}
        self.zdot = zdots
        if v_i is not None:
            heard = inbox.neighbour_velocity
            for j in self.neighbours:
                v_j = heard[j].get(e)
                if v_j is None:
                    continue
                zdot = (v_i[0] - v_j[0], v_i[1] - v_j[1])
                edge = self.edges[j]
                if self.robust:  # Step 1 (its direction follows the team's rotation below)
                    edge.update(zdot, t - self._edge_time[j], follow=False)
                else:
                    edge.update(zdot, t - self._edge_time[j])  # Step 1
                if edge.moving:
                    self._edge_time[j] = t
                self._edge_instant[j] = e
                zdots[j] = zdot
        # Step 3 (eq. 5) and the load's rotation since the last instant, from the longest
        # edge that has both a fresh sample and a distance estimate; the robust estimators
        # take the team's rotation instead (:mod:`agent.algorithm.estimation.rotation`).
        ref = None
        for j in zdots:
            d = self.edges[j].distance
            if d is not None and (ref is None or d > self.edges[ref].distance):
                ref = j
        interval = (e - previous) * self.dt
        turn = None  # else ω times the interval, ω of this instant if it is measured
        if self.robust:
            turn = self._team_turn(zdots, interval, inbox, (self.omega or 0.0) * interval)
        elif ref is not None and abs(self.edges[ref].last_dt - interval) < 1e-9:
            turn = self.edges[ref].last_turn
        if ref is not None:
            self.omega = angular_velocity(self.edges[ref].estimate, zdots[ref])
            self.started.setdefault(2, e)
            self.started.setdefault(3, e)
        if turn is None:
            turn = (self.omega or 0.0) * interval
        self.angle += turn
        self._angle_at[e] = self.angle
        if self.robust:  # this robot's own mass fit, the input of the team's (Step 7)
            self.consensus.mass_input = mass_input(*self._own_mass())
        self.consensus.update(turn, inbox.latest, self, (e - previous) * self.dt)  # Step 2
        if phases.barrier.phase == Phase.EXCITE:  # later, Steps 1-3 are done: nothing reads these
            self._track_excite_settling(e)
        if self.omega is None or ref is None:
            return
        prev, self.measured = self.measured, e
        span = (e - prev) * self.dt if prev is not None else self.dt
        self._moment_of_inertia(e, prev, span, phases)
        self._centre_of_mass_and_mass(e, prev, span, phases, inbox)

    def _team_turn(
        self, zdots: dict[int, Vec2], interval: float, inbox: Inbox, fallback: float
    ) -> float:
        """The team's rotation since the last instant (:mod:`agent.algorithm.estimation.rotation`):
        this robot's own turn, from the edges sampled over the whole interval (else
        ``fallback``), plus the consensus on the neighbours' levels; each such edge's direction
        filter then follows it."""
        fresh = [
            j
            for j in zdots
            if self.edges[j].moving and abs(self.edges[j].last_dt - interval) < 1e-9
        ]
        turns = []
        for j in fresh:
            edge, z = self.edges[j], zdots[j]
            radius = edge.distance if edge.centre is not None else None
            weight = turn_weight(
                radius=radius, speed2=z[0] * z[0] + z[1] * z[1], noise=edge.noise, dt=interval
            )
            turns.append((edge.last_turn, weight))
        own = own_turn(turns)
        heard = (
            (j, s.degree, s.instant, s.rotation, s.rotation_variance)
            for j, s in inbox.latest.items()
            if j in self.edges
        )
        turn, variance = (fallback, None) if own is None else own
        rotation = self.rotation
        turn = rotation.update(self.instant, turn, variance, heard, self._angle_at.get)
        for j in zdots:
            edge = self.edges[j]
            if j in fresh:
                edge.follow(turn, rotation.turn_variance)
            else:
                edge.follow(edge.last_turn)
        return turn

    def _track_excite_settling(self, e: int) -> None:
        distances = [self.edges[j].distance for j in self.neighbours]
        if None in distances:
            return
        # The robust estimates' own uncertainty: the least certain distance's for the
        # distances, the least certain z_ij's for z_i and w / n (the consensus of the z_ij).
        std = radius_std = None
        if self.robust:
            radius_std = max(self.edges[j].distance_std for j in self.neighbours)
            std = max(self.edges[j].std for j in self.neighbours)
        self.settle.distances.update(distances, e, radius_std)
        # z_i in the frame of the longest edge (always the same one): constant once converged.
        longest = max(self.neighbours, key=lambda j: self.edges[j].distance)
        z = self.relative_position(longest)
        if z is None:
            return
        d = math.hypot(*z)
        u = (z[0] / d, z[1] / d)
        x = self.consensus.centroid
        # z_i may be small (a contact near the centroid): judged against the load's size.
        size = math.sqrt(max(self.consensus.spread, 0.0))
        self.settle.centroid.update(
            (x[0] * u[0] + x[1] * u[1], u[0] * x[1] - u[1] * x[0]), e, std, size
        )
        spread_std = None if std is None else 2.0 * math.hypot(*x) * std
        self.settle.spread.update((self.consensus.spread,), e, spread_std)

    def _moment_of_inertia(
        self, e: int, prev: int | None, span: float, phases: PhaseMachine
    ) -> None:
        """Step 4 over the interval ``span`` from the instant ``prev`` to ``e``."""
        if self.inertia is None:
            return
        k_inertia = phases.entered.get(Phase.INERTIA)
        if k_inertia is None or e < k_inertia:
            return
        # The paper's estimator reads ω (eq. 15), the robust one the rotation angle.
        observed = self.angle if self.robust else self.omega
        if not self.inertia.started:
            self.inertia.update(observed, 0.0, span)  # starts the filters
        elif prev >= k_inertia and phases.phase_at(e - 1) == Phase.INERTIA:
            self.inertia.update(observed, phases.mean_torque(prev, e), span)
            moment = self.inertia.estimate
            if moment is not None:
                std = self.inertia.std if self.robust else None
                self.settle.moment.update((moment,), e, std)

    def _centre_of_mass_and_mass(
        self, e: int, prev: int | None, span: float, phases: PhaseMachine, inbox: Inbox
    ) -> None:
        """Steps 5–7 over the interval ``span`` from the instant ``prev`` to ``e``."""
        if self.com is None:
            return
        k_push = phases.entered.get(Phase.PUSH)
        if k_push is None or e < k_push:
            return
        omega = self.omega
        # The regressions hold only while the common force acts, over the whole interval.
        pushing = prev is not None and prev >= k_push and phases.phase_at(e - 1) == Phase.PUSH
        # The paper's estimators read ω (eq. 18), the robust ones the rotation angle.
        if not self.com.started:
            self.push_angle = self.angle
            self.observer = ComObserver(
                self.n, phases.moment_used, phases.push, self.tuning.observer_gain, omega
            )
            self._update_com(omega, 0.0, 1.0, span)  # starts the filters
            return
        alpha = self.angle - self.push_angle
        sign = phases.mean_push_sign(prev, e) if pushing else 0.0
        added = phases.mean_push_damping(prev, e) if pushing else (0.0, 0.0)
        if pushing:
            self.observer.update(omega, sign, span)
            self._update_com(omega, alpha, sign, span, added)
        ref_offset = self.com.estimate
        if ref_offset is None:
            return
        if pushing:
            std = self.com.std if self.robust else None
            # An offset (perhaps small) is judged against a tenth of the load's size √(w/n).
            self.settle.com_offset.update(ref_offset, e, std, 0.1 * math.sqrt(self.spread))
        if not (self.settle.com_offset.settled or self.robust) and self.mass_estimator is None:
            return  # (the robust mass fit starts with the push: see MassFit)
        z_c = self.com_offset(alpha)
        x = self.consensus.centroid
        offset = (x[0] + z_c[0], x[1] + z_c[1])
        v_i = inbox.own_velocity.get(e)
        if v_i is None:
            return
        self.com_velocity = com_velocity(v_i, omega, offset)  # Step 6, eq. (7)
        if not pushing:
            self._watch(e, prev, span, phases)
            return
        if self.mass_estimator is None:
            self.mass_estimator = (
                MassFit(self.n, phases.push, self.forgetting, self.lag)
                if self.robust
                else MassEstimator(self.tuning.filter_gain, self.n, phases.push, self.forgetting)
            )
            self.started[6] = e
            self.started[7] = e
        if self.robust:
            self.mass_estimator.update(v_i, offset, self.angle, sign, span, added=added)
        else:
            self.mass_estimator.update(self.com_velocity, sign, span)
        mass = self.mass_estimator.estimate
        if mass is not None:
            std = self.mass_estimator.std if self.robust else None
            self.settle.mass.update((mass,), e, std)

    def _watch(self, e: int, prev: int, span: float, phases: PhaseMachine) -> None:
        """Once done, each probe's fit over the interval ``span`` from ``prev`` to ``e``, and at
        the probe's last instant its test against the estimates
        (:mod:`agent.algorithm.estimation.load_change`)."""
        start = phases.probe_start(e)
        if start is None or self.mass_estimator is None or self.com_velocity is None:
            return
        if self.probe is not None and self.probe_began != start:
            self.probe = None  # (its last instant was never measured)
        if e == start:
            mass = self.mass_estimator.estimate
            if mass is None or mass <= 0.0:
                return
            self.probe = ProbeFit(self.n, mass, phases.push, self.lag, self.angle)
            self.probe_began = start
            self.probe.update(self.com_velocity, self.omega, self.angle, 0.0, 0.0)
            return
        end = start + phases.probe_ticks
        if self.probe is None or prev < start or e > end:
            return
        sign = sum(phases.probe_sign(t) for t in range(prev, e)) / (e - prev)
        self.probe.update(self.com_velocity, self.omega, self.angle, sign, span)
        if e < end:
            return
        probe, self.probe = self.probe, None
        published = self._published_load()
        if published is None:
            return
        scores = probe.score(*published)
        if scores is not None:
            self.change_score = max(scores)
            self.changed = self.changed or self.change_score > self.tuning.change_threshold

    def _published_load(self) -> tuple[float, tuple[float, float, float]] | None:
        """The published relative standard deviation of ``m̂`` and covariance of this robot's
        ``contact_to_com``, now (``None`` if either is not known)."""
        relative = {j: z for j in self.neighbours if (z := self.relative_position(j)) is not None}
        z_c = self.com_offset(self.angle - self.push_angle)
        mass = self.mass
        if z_c is None or not mass:
            return None
        z_i = self.consensus.centroid
        published = self._uncertainty(relative, (-(z_i[0] + z_c[0]), -(z_i[1] + z_c[1])))
        mass_std, cov = published["mass_std"], published.get("contact_to_com_cov")
        if mass_std is None or cov is None:
            return None
        return mass_std / mass, cov

    def _update_com(
        self, omega: float, alpha: float, sign: float, span: float, added: Vec2 = (0.0, 0.0)
    ) -> None:
        if self.robust:
            self.com.update(alpha, sign, span, added=added)
        else:
            self.com.update(omega, alpha, sign, span)

    # ---------------------------------------------------------------- phases
    def enter(self, phase: Phase, k: int, phases: PhaseMachine) -> None:
        """The team begins ``phase`` at tick ``k``: start the steps that run in it."""
        if phase == Phase.INERTIA:
            if phases.epoch:  # a changed load: Steps 4-7 again (the contacts have not moved)
                self._forget_load()
            self.started[4] = k
            self.inertia = (
                InertiaFit(self.forgetting, self._torque_scale_std())
                if self.robust
                else InertiaEstimator(self.tuning.filter_gain, self.forgetting)
            )
            if not self.robust:  # (the arcs hold in every phase: they learn all along)
                for edge in self.edges.values():
                    edge.learning = False  # Step 1 is done: keep the distances, track directions.
        elif phase == Phase.PUSH:
            self.started[5] = k
            # The drives' lag, which Step 4's fit found, for Steps 5 and 7's.
            self.lag = self.inertia.lag if self.robust else 0.0
            self.com = (
                ComFit(self.n, phases.moment_used, phases.push, self.forgetting, self.lag)
                if self.robust
                else ComRegression(
                    self.tuning.filter_gain,
                    self.n,
                    phases.moment_used,
                    phases.push,
                    self.forgetting,
                )
            )

    def _forget_load(self) -> None:
        """Drop Steps 4–7's estimates and settling, and the probes' verdict."""
        self.com = self.observer = self.mass_estimator = self.probe = None
        self.com_velocity = None
        self.changed = False
        for step in (5, 6, 7):
            self.started.pop(step, None)
        self.settle = self.settle.with_load_forgotten()

    def _torque_scale_std(self) -> float:
        """The relative standard deviation of ``w = Σ‖z_i‖²``, which scales the torque Step 4
        assumes (``±k w``) and so ``Ĵ``: ``2 σ_z / ‖z_i‖`` per robot, ``σ_z`` the mean of
        this robot's edges' (the others' taken alike), averaged over ``n`` robots."""
        stds = [edge.std for edge in self.edges.values() if edge.std is not None]
        size = math.sqrt(self.spread) if self.spread > 0.0 else 0.0
        if not stds or size == 0.0:
            return 0.0
        return 2.0 * (sum(stds) / len(stds)) / size / math.sqrt(self.n)

    # ---------------------------------------------------------------- the load's frame
    def relative_position(self, j: int) -> Vec2 | None:
        """``z_ij`` at the estimation instant (turned forward if its sample is stale)."""
        z = self.edges[j].estimate
        last = self._edge_instant.get(j)
        if z is None or last is None:
            return None
        if last != self.instant:
            z = rotate(z, self.angle - self._angle_at.get(last, self.angle))
        return z

    def turned_since(self, instant: int) -> float:
        """The load's rotation (rad) from ``instant`` to the estimation instant."""
        angle = self._angle_at.get(instant)
        if angle is None:
            return (self.omega or 0.0) * (self.instant - instant) * self.dt
        return self.angle - angle

    def forget(self, before: int) -> None:
        """Drop what is too old to be asked for at tick ``before + HISTORY_TICKS``."""
        self._angle_at.pop(before - 1, None)

    # ---------------------------------------------------------------- reporting
    def estimates(self, robot: int, phases: PhaseMachine) -> Estimates:
        """The current estimates, at the estimation instant (see :class:`Estimates`)."""
        relative = {}
        for j in self.neighbours:
            z = self.relative_position(j)
            if z is not None:
                relative[j] = z
        z_i = self.consensus.centroid if 2 in self.started else None
        z_c = None
        observed = None
        k_push = phases.entered.get(Phase.PUSH)
        if self.com is not None and k_push is not None and self.instant >= k_push:
            z_c = self.com_offset(self.angle - self.push_angle)
            if self.observer is not None:
                observed = self.observer.estimate
        contact_to_com = None
        if z_i is not None and z_c is not None:
            contact_to_com = (-(z_i[0] + z_c[0]), -(z_i[1] + z_c[1]))
        uncertainty = self._uncertainty(relative, contact_to_com) if self.robust else {}
        return Estimates(
            robot=robot,
            tick=self.instant,
            phase=phases.phase,
            phase_since=phases.since,
            omega=self.omega,
            relative_positions=relative,
            centroid_offset=z_i,
            spread=self.n * self.consensus.spread if 2 in self.started else None,
            moment=self.moment,
            com_offset=z_c,
            com_observer=observed,
            com_velocity=self.com_velocity,
            mass=self.mass,
            contact_to_com=contact_to_com,
            started=dict(self.started),
            settled=self.settle.first_settled(),
            epoch=phases.epoch,
            change_score=self.change_score,
            **uncertainty,
        )

    def _uncertainty(self, relative: dict[int, Vec2], contact_to_com: Vec2 | None) -> dict:
        """The robust estimators' standard deviations and covariances, for :class:`Estimates`.

        ``Cov(p_C − p_Ci) = Cov(z_i) + Cov(z_C)``, taking the two as independent: ``Cov(z_i)``
        as the mean of the robot's own edges' (the consensus averages edges like them), and
        ``Cov(z_C)`` as the push fit's turned with the load, plus ``c cᵀ (σ_J/J)²`` for the
        ``Ĵ`` it was computed with (``c ∝ J``), plus that of the gains' correction ``h``;
        then scaled as calibrated (:data:`PUBLISHED_VARIANCE`)."""
        edges = {}
        for j in relative:
            cov = self.edges[j].covariance
            if cov is not None:
                turned = self.angle - self._angle_at.get(self._edge_instant[j], self.angle)
                edges[j] = _packed(turned_covariance(cov, turned))
        # The gains' corrections: every robot's gain taken as uncertain as this one's, ``σ_g``;
        # ḡ and q / (w/n) then have about σ_g / √n relative, and h = Σ g_i z_i / n has
        # σ_g² w / (2 n²) per axis.
        gain_std = self.drive.std or 0.0
        team_gain_std = gain_std / math.sqrt(self.n)
        moment = self.moment
        moment_std = self.inertia.std if self.inertia is not None else None
        if moment_std is not None:
            moment_std = math.hypot(moment_std * self._torque_gain, moment * team_gain_std)
        _, mass_std = self._robust_mass()
        scale = PUBLISHED_VARIANCE["relative"]
        out: dict = {
            "drive_gain": None if self.drive.std is None else self.drive.estimate,
            "drive_gain_std": self.drive.std,
            "relative_positions_cov": {
                j: tuple(scale * e for e in cov) for j, cov in edges.items()
            },
            "moment_std": None
            if moment_std is None
            else moment_std * math.sqrt(PUBLISHED_VARIANCE["moment"]),
            "mass_std": mass_std,
        }
        com_cov = self.com.covariance if self.com is not None else None
        if contact_to_com is not None and edges and com_cov is not None:
            alpha = self.angle - self.push_angle
            (a, b), (_, d) = turned_covariance(com_cov, alpha)
            c = self.com.com_offset(alpha)
            rel2 = (moment_std / moment) ** 2 if moment and moment_std is not None else 0.0
            count = len(edges)
            weighted = gain_std * gain_std * self.spread / (2.0 * self.n)  # σ_g² w / 2n²
            xx = sum(e[0] for e in edges.values()) / count + a + rel2 * c[0] * c[0] + weighted
            xy = sum(e[1] for e in edges.values()) / count + b + rel2 * c[0] * c[1]
            yy = sum(e[2] for e in edges.values()) / count + d + rel2 * c[1] * c[1] + weighted
            scale = PUBLISHED_VARIANCE["contact_to_com"]
            out["contact_to_com_cov"] = (scale * xx, scale * xy, scale * yy)
        return out


def _packed(cov) -> tuple[float, float, float]:
    (a, b), (_, d) = cov
    return (a, b, d)
