"""The paper's seven steps, run by one robot at each estimation instant (see
:mod:`agent.inbox` for which instants), and the tracking of when its estimates settle.

At instant ``e``:

1. Step 1, ``z_ij`` for each neighbour ``j`` whose velocity at ``e`` is known, from
   ``ż_ij = ṗ_Ci − ṗ_Cj`` (:class:`~agent.estimation.relative_position.RelativePosition`);
2. Step 3, ``ω`` by eq. (5) from the longest edge with a sample at ``e``, and the load's rotation
   since the previous instant (the edge's own turn when it spans the same interval);
3. Step 2 and eq. (16), ``z_i`` and ``w`` by consensus, turned with the load
   (:class:`~agent.estimation.centroid.CentroidConsensus`);
4. while the team applies eq. (14) (the inertia phase), Step 4, ``J``;
5. while it pushes with a common force (the push phase), Step 5, ``z_C`` (by regression, with
   observer (24) beside it), Step 6, ``ṗ_C`` by eq. (7), and once ``z_C`` has settled, Step 7,
   ``m``.

Steps 4–7 use only instants whose ω was measured at that instant (not carried over because every
neighbour's message was lost); the interval since the previous such instant is used whole, and
only if the team applied the phase's force over all of it.

Settling (:class:`~agent.estimation.settling.SettleDetectors`): in the excite phase the distances
``‖z_ij‖``, ``z_i`` in the frame of the longest edge and ``w / n`` are watched at every instant;
``Ĵ``, ``z_C`` (at the reference instant) and ``m̂`` at the instants they are updated.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from agent.config import AgentConfig
from agent.estimation.angular_velocity import angular_velocity
from agent.estimation.centroid import CentroidConsensus
from agent.estimation.com_observer import ComObserver
from agent.estimation.com_regression import ComRegression
from agent.estimation.com_velocity import com_velocity
from agent.estimation.geometry import Vec2, rotate
from agent.estimation.inertia import InertiaEstimator
from agent.estimation.mass import MassEstimator
from agent.estimation.relative_position import RelativePosition
from agent.estimation.settling import SettleDetectors
from agent.protocol import Estimates, Phase

if TYPE_CHECKING:
    from agent.inbox import Inbox
    from agent.phase_machine import PhaseMachine


class EstimationPipeline:
    """One robot's estimates, brought up to each estimation instant in turn."""

    def __init__(self, config: AgentConfig, neighbours: tuple[int, ...]):
        tuning = config.tuning
        self.tuning = tuning
        self.n = config.n
        self.neighbours = neighbours
        self.dt = config.period_s
        window = max(1, round(tuning.settle_window_s / self.dt))
        self.settle = SettleDetectors.of(window, tuning.settle_tolerance)
        self.started: dict[int, int] = {1: 0}
        """Paper step → the instant (or tick, for a phase's steps) it began."""
        memory = tuning.regression_memory_s
        self.forgetting = math.exp(-self.dt / memory) if memory > 0 else 1.0
        self.edges = {
            j: RelativePosition(tuning.filter_gain, self.forgetting) for j in self.neighbours
        }
        self._edge_instant: dict[int, int] = {}
        """The last instant each edge was sampled at."""
        self._edge_time: dict[int, float] = {j: 0.0 for j in self.neighbours}
        """The time (s) of each edge's last sample used."""
        self._angle_at: dict[int, float] = {}
        """``angle`` at each recent instant."""
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
        self.inertia: InertiaEstimator | None = None
        self.com: ComRegression | None = None
        self.push_angle = 0.0
        """The load's rotation angle at the push phase's first instant (Step 5's reference)."""
        self.observer: ComObserver | None = None
        self.mass_estimator: MassEstimator | None = None
        self.com_velocity: Vec2 | None = None

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
        """``Ĵ`` (Step 4)."""
        return self.inertia.estimate if self.inertia is not None else None

    # ---------------------------------------------------------------- one instant
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
                edge.update(zdot, t - self._edge_time[j])  # Step 1
                if edge.moving:
                    self._edge_time[j] = t
                self._edge_instant[j] = e
                zdots[j] = zdot
        # Step 3 (eq. 5) and the load's rotation since the last instant, from the longest
        # edge that has both a fresh sample and a distance estimate.
        ref = None
        for j in zdots:
            d = self.edges[j].distance
            if d is not None and (ref is None or d > self.edges[ref].distance):
                ref = j
        if ref is not None:
            edge = self.edges[ref]
            self.omega = angular_velocity(edge.estimate, zdots[ref])
            if abs(edge.last_dt - (e - previous) * self.dt) < 1e-9:
                turn = edge.last_turn
            else:
                turn = self.omega * (e - previous) * self.dt
            self.started.setdefault(2, e)
            self.started.setdefault(3, e)
        else:
            turn = (self.omega or 0.0) * (e - previous) * self.dt
        self.angle += turn
        self._angle_at[e] = self.angle
        self.consensus.update(turn, inbox.latest, self, (e - previous) * self.dt)  # Step 2
        if phases.barrier.phase == Phase.EXCITE:  # later, Steps 1-3 are done: nothing reads these
            self._track_excite_settling(e)
        if self.omega is None or ref is None:
            return
        prev, self.measured = self.measured, e
        span = (e - prev) * self.dt if prev is not None else self.dt
        self._moment_of_inertia(e, prev, span, phases)
        self._centre_of_mass_and_mass(e, prev, span, phases, inbox)

    def _track_excite_settling(self, e: int) -> None:
        distances = [self.edges[j].distance for j in self.neighbours]
        if None in distances:
            return
        self.settle.distances.update(distances, e)
        # z_i in the frame of the longest edge (always the same one): constant once converged.
        longest = max(self.neighbours, key=lambda j: self.edges[j].distance)
        z = self.relative_position(longest)
        if z is None:
            return
        d = math.hypot(*z)
        u = (z[0] / d, z[1] / d)
        x = self.consensus.centroid
        self.settle.centroid.update((x[0] * u[0] + x[1] * u[1], u[0] * x[1] - u[1] * x[0]), e)
        self.settle.spread.update((self.consensus.spread,), e)

    def _moment_of_inertia(
        self, e: int, prev: int | None, span: float, phases: PhaseMachine
    ) -> None:
        """Step 4 over the interval ``span`` from the instant ``prev`` to ``e``."""
        if self.inertia is None:
            return
        k_inertia = phases.entered.get(Phase.INERTIA)
        if k_inertia is None or e < k_inertia:
            return
        omega = self.omega
        if not self.inertia.regression.started:
            self.inertia.update(omega, 0.0, span)  # starts the filters
        elif prev >= k_inertia and phases.phase_at(e - 1) == Phase.INERTIA:
            self.inertia.update(omega, phases.mean_torque(prev, e), span)
            moment = self.inertia.estimate
            if moment is not None:
                self.settle.moment.update((moment,), e)

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
        if not self.com.regression.started:
            self.push_angle = self.angle
            self.observer = ComObserver(
                self.n, phases.moment_used, phases.push, self.tuning.observer_gain, omega
            )
            self.com.update(omega, 0.0, span)  # starts the filters
            return
        alpha = self.angle - self.push_angle
        if pushing:
            self.observer.update(omega, span)
            self.com.update(omega, alpha, span)
        ref_offset = self.com.estimate
        if ref_offset is None:
            return
        if pushing:
            self.settle.com_offset.update(ref_offset, e)
        if not self.settle.com_offset.settled and self.mass_estimator is None:
            return
        z_c = self.com.com_offset(alpha)
        x = self.consensus.centroid
        offset = (x[0] + z_c[0], x[1] + z_c[1])
        v_i = inbox.own_velocity.get(e)
        if v_i is None:
            return
        self.com_velocity = com_velocity(v_i, omega, offset)  # Step 6, eq. (7)
        if not pushing:
            return
        if self.mass_estimator is None:
            self.mass_estimator = MassEstimator(
                self.tuning.filter_gain, self.n, phases.push, self.forgetting
            )
            self.started[6] = e
            self.started[7] = e
        self.mass_estimator.update(self.com_velocity, span)
        mass = self.mass_estimator.estimate
        if mass is not None:
            self.settle.mass.update((mass,), e)

    # ---------------------------------------------------------------- phases
    def enter(self, phase: Phase, k: int, phases: PhaseMachine) -> None:
        """The team begins ``phase`` at tick ``k``: start the steps that run in it."""
        if phase == Phase.INERTIA:
            self.started[4] = k
            self.inertia = InertiaEstimator(self.tuning.filter_gain, self.forgetting)
            for edge in self.edges.values():
                edge.learning = False  # Step 1 is done: keep the distances, track directions.
        elif phase == Phase.PUSH:
            self.started[5] = k
            self.com = ComRegression(
                self.tuning.filter_gain, self.n, phases.moment_used, phases.push, self.forgetting
            )

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
            z_c = self.com.com_offset(self.angle - self.push_angle)
            if self.observer is not None:
                observed = self.observer.estimate
        contact_to_com = None
        if z_i is not None and z_c is not None:
            contact_to_com = (-(z_i[0] + z_c[0]), -(z_i[1] + z_c[1]))
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
            mass=self.mass_estimator.estimate if self.mass_estimator is not None else None,
            contact_to_com=contact_to_com,
            started=dict(self.started),
            settled=self.settle.first_settled(),
        )
