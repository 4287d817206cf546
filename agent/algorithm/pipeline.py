"""The paper's seven steps, run by one robot at each estimation instant (see
:mod:`agent.algorithm.inbox` for which instants), and the tracking of when its estimates settle.

What every family of estimators shares is here, in :class:`EstimationPipeline`; each family
(:mod:`agent.algorithm.paper`, :mod:`agent.algorithm.robust`) is a subclass that supplies its
estimators of Steps 1, 4, 5 and 7, its rotation of the load and its uncertainties. At instant
``e``:

1. Step 1, ``z_ij`` for each neighbour ``j`` whose velocity at ``e`` is known, from
   ``ż_ij = ṗ_Ci − ṗ_Cj``;
2. Step 3, ``ω`` by eq. (5) from the longest edge with a sample at ``e``, and the load's rotation
   since the previous instant (the family's :meth:`EstimationPipeline._turn`);
3. Step 2 and eq. (16), ``z_i``, ``w`` and the team's other means by consensus, turned with the
   load (:class:`~agent.algorithm.estimation.team_consensus.TeamConsensus`);
4. while the team applies eq. (14) (the inertia phase), Step 4, ``J``;
5. while it pushes with a common force (the push phase), Step 5, ``z_C`` (with observer (24)
   beside it), Step 6, ``ṗ_C`` by eq. (7), and Step 7, ``m``.

Steps 4–7 use only instants whose ω was measured at that instant (not carried over because every
neighbour's message was lost); the interval since the previous such instant is used whole, and
only if the team applied the phase's force over all of it.

Settling (:class:`~agent.algorithm.estimation.settling.SettleDetectors`): in the excite phase
the distances ``‖z_ij‖``, ``z_i`` in the frame of the longest edge and ``w / n`` are watched at
every instant; ``Ĵ``, ``z_C`` (at the reference instant) and ``m̂`` at the instants they are
updated.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, ClassVar

from agent.algorithm.estimation.angular_velocity import angular_velocity
from agent.algorithm.estimation.com_observer import ComObserver
from agent.algorithm.estimation.com_velocity import com_velocity
from agent.algorithm.estimation.settling import SettleDetectors
from agent.algorithm.estimation.team_consensus import TeamConsensus
from agent.algorithm.tuning import AgentConfig
from agent.platform.geometry import Vec2, rotate
from agent.platform.protocol import Estimates, Phase

if TYPE_CHECKING:
    from agent.algorithm.inbox import Inbox
    from agent.algorithm.interfaces import Schedule


class EstimationPipeline:
    """One robot's estimates, brought up to each estimation instant in turn (the part every
    family shares; a family overrides the hooks below the public methods)."""

    mass_after_com: ClassVar[bool] = True
    """Whether Step 7 begins only once Step 5's ``z_C`` has settled (Step 6 needs it)."""

    def __init__(self, config: AgentConfig, neighbours: tuple[int, ...]):
        tuning = config.tuning
        self.tuning = tuning
        self.n = config.n
        self.neighbours = neighbours
        self.dt = config.period_s
        window = max(1, round(tuning.settle_window_s / self.dt))
        self.settle = SettleDetectors.of(window, tuning.settle_tolerance, self._settle_uncertainty)
        self.started: dict[int, int] = {1: 0}
        """Paper step → the instant (or tick, for a phase's steps) it began."""
        memory = tuning.regression_memory_s
        self.forgetting = math.exp(-self.dt / memory) if memory > 0 else 1.0
        self.edges: dict[int, Any] = {j: self._new_edge() for j in self.neighbours}
        """Step 1's estimator of each edge's ``z_ij``."""
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
        self.swung = False
        """Whether the push's stage for Step 5 is over (a family that stages the push: its
        ``ẑ_C`` is then as good as it gets, and counts as settled, with its uncertainty)."""
        self.zdot: dict[int, Vec2] = {}
        """``ż_ij`` at the estimation instant, by neighbour."""
        self.velocity: Vec2 | None = None
        """``ṗ_Ci``, this robot's own velocity, at the estimation instant."""
        self.consensus = TeamConsensus(config.robot, self.neighbours, self._inputs)
        """Step 2 and the team's means (:mod:`agent.algorithm.estimation.team_consensus`)."""
        self.inertia: Any = None
        """Step 4's estimator, from the inertia phase on."""
        self.com: Any = None
        """Step 5's estimator, from the push phase on."""
        self.push_angle = 0.0
        """The load's rotation angle at the push phase's first instant (Step 5's reference)."""
        self.observer: ComObserver | None = None
        self.mass_estimator: Any = None
        """Step 7's estimator, once it begins."""
        self.com_velocity: Vec2 | None = None
        self.changed = False
        """Whether a probe found the load changed since the team's last (re)start (robust)."""
        self.stuck = False
        """Whether Step 4's torque left the load where it was (a family that watches for it:
        the floor holds the load, and nothing more can be estimated)."""
        self.change_score: float | None = None
        """The last probe's test of the load against the estimates (standard deviations)."""

    # ---------------------------------------------------------------- what the phases read
    @property
    def centroid(self) -> Vec2:
        """``z_i`` (Step 2) at the estimation instant."""
        return self.consensus.centroid

    @property
    def mean_square_offset(self) -> float:
        """``w / n`` (eq. 16)."""
        return self.consensus["mean_square_offset"]

    @property
    def mean_spin_torque(self) -> float:
        """The team's mean torque about the centroid in Step 1's spin-up (N m; 0 for a family
        that does not measure it)."""
        return self.consensus["mean_spin_torque"]

    @property
    def mean_kick_level(self) -> float:
        """The team's mean kick size in Step 1 (N; 0 for a family that does not average it)."""
        return self.consensus["mean_kick_level"]

    @property
    def drive_share(self) -> float | None:
        """How much of its command this robot's drive applies (``None``: the paper takes every
        drive for ideal and does not estimate it)."""
        return None

    @property
    def moment(self) -> float | None:
        """``Ĵ`` (Step 4)."""
        return None if self.inertia is None else self.inertia.estimate

    @property
    def mass(self) -> float | None:
        """``m̂`` (Step 7)."""
        return None if self.mass_estimator is None else self.mass_estimator.estimate

    @property
    def friction_torque(self) -> tuple[float, float] | None:
        """``(τ̂_c, σ)``: the floor's friction torque (``None``: the family estimates none)."""
        return None

    @property
    def com_offset_now(self) -> Vec2 | None:
        """``z_C`` as Step 5 found it at the estimation instant, which the push uses
        (``None`` before the push)."""
        return self._push_offset(self.angle - self.push_angle)

    def com_offset(self, alpha: float) -> Vec2 | None:
        """``z_C`` after the rotation ``alpha`` since the push began (Step 5), as
        published."""
        return self.com.com_offset(alpha) if self.com is not None else None

    def settled(self, phase: Phase) -> bool:
        """Whether the estimates that ``phase`` is for have settled."""
        s = self.settle
        if phase == Phase.EXCITE:
            return s.distances.settled and s.centroid.settled and s.mean_square_offset.settled
        if phase == Phase.INERTIA:
            return s.moment.settled and not self.stuck
        if phase == Phase.PUSH:
            return (s.com_offset.settled or self.swung) and s.mass.settled
        return False

    # ---------------------------------------------------------------- one instant
    def applied(self, command: Vec2, measured: Vec2) -> None:
        """The force ``measured`` over the last tick, commanded ``command`` (the paper takes
        every drive for ideal: nothing to do)."""

    def estimate_at(self, e: int, inbox: Inbox, schedule: Schedule) -> None:
        """Steps 1–7 at instant ``e`` (the one after :attr:`instant`)."""
        t = e * self.dt
        previous = self.instant
        self.instant = e
        v_i = inbox.own_velocity.get(e)
        self.velocity = v_i
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
                self._sample_edge(edge, zdot, t - self._edge_time[j])  # Step 1
                if edge.moving:
                    self._edge_time[j] = t
                self._edge_instant[j] = e
                zdots[j] = zdot
        # Step 3 (eq. 5) from the longest edge that has both a fresh sample and a distance
        # estimate, and the load's rotation since the last instant (the family's).
        ref = None
        for j in zdots:
            d = self.edges[j].distance
            if d is not None and (ref is None or d > self.edges[ref].distance):
                ref = j
        interval = (e - previous) * self.dt
        turn = self._turn(zdots, interval, inbox, ref)
        if ref is not None:
            self.omega = angular_velocity(self.edges[ref].estimate, zdots[ref])
            self.started.setdefault(2, e)
            self.started.setdefault(3, e)
        if turn is None:  # ω times the interval, ω of this instant if it is measured
            turn = (self.omega or 0.0) * interval
        self.angle += turn
        self._angle_at[e] = self.angle
        self._before_consensus(schedule)
        self.consensus.update(turn, inbox.latest, self)  # Step 2
        if schedule.phase == Phase.EXCITE:  # later, Steps 1-3 are done: nothing reads these
            self._track_excite_settling(e)
        if self.omega is None or ref is None:
            return
        prev, self.measured = self.measured, e
        span = (e - prev) * self.dt if prev is not None else self.dt
        self._moment_of_inertia(e, prev, span, schedule)
        self._centre_of_mass_and_mass(e, prev, span, schedule, inbox)

    def _track_excite_settling(self, e: int) -> None:
        distances = [self.edges[j].distance for j in self.neighbours]
        if None in distances:
            return
        radius_std, std = self._excite_stds()
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
        size = math.sqrt(max(self.mean_square_offset, 0.0))
        self.settle.centroid.update(
            (x[0] * u[0] + x[1] * u[1], u[0] * x[1] - u[1] * x[0]), e, std, size
        )
        xi_std = None if std is None else 2.0 * math.hypot(*x) * std
        self.settle.mean_square_offset.update((self.mean_square_offset,), e, xi_std)

    def _moment_of_inertia(self, e: int, prev: int | None, span: float, schedule: Schedule) -> None:
        """Step 4 over the interval ``span`` from the instant ``prev`` to ``e``."""
        if self.inertia is None:
            return
        k_inertia = schedule.began(Phase.INERTIA)
        if k_inertia is None or e < k_inertia:
            return
        if not self.inertia.started:
            self._update_inertia(0.0, span)  # starts the filters
        elif prev >= k_inertia and schedule.phase_at(e - 1) == Phase.INERTIA:
            self._update_inertia(schedule.mean_torque(prev, e), span)
            moment = self.inertia.estimate
            if moment is not None:
                self.settle.moment.update((moment,), e, self._std(self.inertia))

    def _contact_offset(self, z_c: Vec2) -> Vec2:
        """``o = p_Ci − p_C = z_i + z_C``: this robot's contact from the COM, with ``z_i`` its
        offset from the contacts' centroid (the team's consensus) and ``z_C`` the COM's."""
        x = self.consensus.centroid
        return (x[0] + z_c[0], x[1] + z_c[1])

    def _centre_of_mass_and_mass(
        self, e: int, prev: int | None, span: float, schedule: Schedule, inbox: Inbox
    ) -> None:
        """Steps 5–7 over the interval ``span`` from the instant ``prev`` to ``e``."""
        if self.com is None:
            return
        k_push = schedule.began(Phase.PUSH)
        if k_push is None or e < k_push:
            return
        omega = self.omega
        # The regressions hold only while the common force acts, over the whole interval.
        pushing = prev is not None and prev >= k_push and schedule.phase_at(e - 1) == Phase.PUSH
        if not self.com.started:
            if not schedule.swinging(e, e + 1):
                return
            self.push_angle = self.angle
            self.observer = ComObserver(
                self.n, schedule.moment_used, schedule.push, self.tuning.observer_gain, omega
            )
            self._update_com(0.0, 1.0, span, (0.0, 0.0))  # starts the filters
            return
        alpha = self.angle - self.push_angle
        sign = schedule.mean_push_sign(prev, e) if pushing else 0.0
        added = schedule.mean_push_added(prev, e) if pushing else (0.0, 0.0)
        swinging = pushing and schedule.swinging(prev, e)
        self.swung = self.swung or (pushing and not swinging)
        if swinging:
            self.observer.update(omega, sign, span)
            self._update_com(alpha, sign, span, added, schedule.mean_torque(prev, e))
        ref_offset = self.com.estimate
        if ref_offset is None:
            return
        if swinging:
            # An offset (perhaps small) is judged against a tenth of the load's size √(w/n).
            self.settle.com_offset.update(
                ref_offset, e, self._std(self.com), 0.1 * math.sqrt(self.mean_square_offset)
            )
        if self.mass_after_com and not self.settle.com_offset.settled:
            if self.mass_estimator is None:
                return
        offset = self._contact_offset(self._push_offset(alpha))
        v_i = inbox.own_velocity.get(e)
        if v_i is None:
            return
        self.com_velocity = com_velocity(v_i, omega, offset)  # Step 6, eq. (7)
        if pushing and not schedule.translating(prev, e):
            return
        if not pushing:
            self._once_pushed(e, prev, span, schedule)
            return
        if self.mass_estimator is None:
            self.mass_estimator = self._new_mass(schedule)
            self.started[6] = e
            self.started[7] = e
        self._held(alpha, sign, span, added, schedule.mean_torque(prev, e))
        self._update_mass(v_i, offset, sign, span, added)
        mass, std = self._settling_mass()
        if mass is not None:
            self.settle.mass.update((mass,), e, std)

    # ---------------------------------------------------------------- phases
    def enter(self, phase: Phase, k: int, schedule: Schedule) -> None:
        """The team begins ``phase`` at tick ``k``: start the steps that run in it."""
        if phase == Phase.INERTIA:
            if schedule.load_changes:  # a changed load: Steps 4-7 again (contacts unmoved)
                self._forget_load()
            self.started[4] = k
            self.inertia = self._new_inertia()
        elif phase == Phase.PUSH:
            self.started[5] = k
            self.com = self._new_com(schedule)

    def _forget_load(self) -> None:
        """Drop Steps 4–7's estimates and settling."""
        self.swung = False
        self.com = self.observer = self.mass_estimator = None
        self.com_velocity = None
        self.changed = False
        for step in (5, 6, 7):
            self.started.pop(step, None)
        self.settle = self.settle.with_load_forgotten()

    # ---------------------------------------------------------------- the load's frame
    def known_relative_positions(self) -> dict[int, Vec2]:
        """``{j: ẑ_ij}`` for every neighbour whose edge has an estimate now."""
        return {j: z for j in self.neighbours if (z := self.relative_position(j)) is not None}

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
    def consensus_state(self):
        """This robot's states of the team's quantities, to share
        (:class:`~agent.platform.team.ConsensusState`)."""
        return self.consensus.state

    def estimates(self, robot: int, schedule: Schedule) -> Estimates:
        """The current estimates, at the estimation instant (see :class:`Estimates`)."""
        relative = self.known_relative_positions()
        z_i = self.consensus.centroid if 2 in self.started else None
        z_c = None
        observed = None
        k_push = schedule.began(Phase.PUSH)
        if self.com is not None and k_push is not None and self.instant >= k_push:
            z_c = self.com_offset(self.angle - self.push_angle)
            if self.observer is not None:
                observed = self.observer.estimate
        contact_to_com = None
        if z_i is not None and z_c is not None:
            contact_to_com = (-(z_i[0] + z_c[0]), -(z_i[1] + z_c[1]))
        return Estimates(
            robot=robot,
            tick=self.instant,
            phase=schedule.phase,
            phase_since=schedule.began(schedule.phase),
            omega=self.omega,
            relative_positions=relative,
            centroid_offset=z_i,
            w=self.n * self.mean_square_offset if 2 in self.started else None,
            moment=self.moment,
            com_offset=z_c,
            com_observer=observed,
            com_velocity=self.com_velocity,
            mass=self.mass,
            contact_to_com=contact_to_com,
            started=dict(self.started),
            settled=self.settle.first_settled(),
            load_changes=schedule.load_changes,
            change_score=self.change_score,
            stuck_torque=abs(schedule.inertia_torque) if self.stuck or schedule.held else None,
            **self._reported(relative, contact_to_com),
        )

    # ---------------------------------------------------------------- a family's hooks
    _settle_uncertainty: ClassVar[float] = 0.0
    """The relative standard deviation below which an estimate with one may settle (0: the
    estimates carry none; settling is judged by drift alone)."""

    def _new_edge(self) -> Any:
        """Step 1's estimator of one edge."""
        raise NotImplementedError

    def _sample_edge(self, edge: Any, zdot: Vec2, dt: float) -> None:
        """Feed an edge ``ż_ij`` sampled ``dt`` after its last sample used."""
        edge.update(zdot, dt)

    def _turn(
        self, zdots: dict[int, Vec2], interval: float, inbox: Inbox, ref: int | None
    ) -> float | None:
        """The load's rotation (rad) over ``interval`` since the previous instant, before ω is
        measured at this one; ``None``: ω (of this instant, once measured) times it."""
        raise NotImplementedError

    def _inputs(self, x: Vec2) -> Sequence[float]:
        """This robot's inputs of the team's means, given its offsets iterate ``x``
        (:class:`~agent.algorithm.estimation.team_consensus.TeamConsensus`)."""
        raise NotImplementedError

    def _before_consensus(self, schedule: Schedule) -> None:
        """Anything the consensus' inputs need at this instant."""

    def _excite_stds(self) -> tuple[float | None, float | None]:
        """The standard deviations of the distances and of the ``z_ij`` the excite phase's
        settling is judged by (``None``: by drift)."""
        return (None, None)

    def _settling_mass(self) -> tuple[float | None, float | None]:
        """The ``m̂`` that Step 7 settles by and its standard deviation (``None``: by its
        drift): this robot's fit's."""
        fit = self.mass_estimator
        return fit.estimate, self._std(fit)

    def _std(self, estimator: Any) -> float | None:
        """An estimator's standard deviation, for settling (``None``: by drift)."""
        return None

    def _new_inertia(self) -> Any:
        raise NotImplementedError

    def _update_inertia(self, torque: float, span: float) -> None:
        raise NotImplementedError

    def _new_com(self, schedule: Schedule) -> Any:
        raise NotImplementedError

    def _update_com(
        self, alpha: float, sign: float, span: float, added: Vec2, torque: float = 0.0
    ) -> None:
        raise NotImplementedError

    def _push_offset(self, alpha: float) -> Vec2 | None:
        """``z_C`` as Step 5 found it, after a rotation ``alpha``: what Steps 6 and 7 use,
        and the push (:attr:`com_offset_now`), while the team pushes."""
        return self.com_offset(alpha)

    def _held(self, alpha: float, sign: float, span: float, added: Vec2, torque: float) -> None:
        """Over an interval ``span`` of Step 7's stage: the rotation ``alpha`` since the push
        began, the push's mean sign, the mean force each robot added and the team's mean
        torque beyond the push's (a family's hook: nothing here)."""

    def _new_mass(self, schedule: Schedule) -> Any:
        raise NotImplementedError

    def _update_mass(
        self, velocity: Vec2, offset: Vec2, sign: float, span: float, added: Vec2
    ) -> None:
        raise NotImplementedError

    def _once_pushed(self, e: int, prev: int, span: float, schedule: Schedule) -> None:
        """Each instant after the push, once ``ṗ_C`` is known (the team is done)."""

    def _reported(self, relative: dict[int, Vec2], contact_to_com: Vec2 | None) -> dict:
        """The family's extra fields of :class:`Estimates` (uncertainties)."""
        return {}
