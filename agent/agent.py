"""One robot's agent: the paper's seven steps, run by each robot on its own data.

An :class:`Agent` knows its id, ``n``, its neighbours' ids and its tuning. Each sensor tick it
is handed its own :class:`~agent.protocol.Measurement` and the :class:`~agent.protocol.Share`
messages its neighbours sent at earlier ticks; it returns the force to apply until the next
tick and the message for its neighbours. It never sees the plant, global truth, or any other
robot's internals, and it does no I/O: transports and processes live outside it.

Timing. Robot ``i`` has its own sample of tick ``k`` but its neighbours' samples only up to
``k − 1`` (they arrive with their messages). So its estimates at tick ``k`` refer to the
*estimation instant* ``e``, the newest instant with every neighbour's velocity: ``k − 1`` when
messages arrive within a tick, earlier when they are late (instants skipped are caught up in
order). The force for ``[t_k, t_{k+1})`` is predicted from them. A step uses only messages
stamped before ``k``, so a run whose messages arrive in time is reproducible whatever the
transport's timing.

Phases (force regimes), switched by the team's barrier (:mod:`agent.coordination`) once every
robot's own estimates have settled:

======== ======================================= ===========================================
phase     forces                                  estimates that settle in it
======== ======================================= ===========================================
excite    kick, then geometry-free spin-up        Step 1 ``z_ij``, Step 2 ``z_i``, Step 3 ω, ``w``
inertia   ``f_i = ±k z_i⊥`` (eq. 14)                Step 4 ``J``
push      common ``f`` (eq. 17)                   Step 5 ``z_C``, Step 6 ``ṗ_C``, Step 7 ``m``
done      zero: the load coasts                   (tracking goes on)
halted    zero                                    (a robot was lost: the team stops)
======== ======================================= ===========================================

``halted`` is entered by :meth:`Agent.halt` when a neighbour is lost, and reaches the rest of
the team through the barrier's catch-up rule (it is the highest phase). The paper assumes
``n`` robots that all push; estimates made without one of them would be wrong, so the team
stops and says so rather than carrying on.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from agent.config import AgentConfig
from agent.coordination import PhaseBarrier
from agent.estimation.angular_velocity import angular_velocity
from agent.estimation.centroid import centroid_term
from agent.estimation.com_observer import ComObserver
from agent.estimation.com_regression import ComRegression
from agent.estimation.com_velocity import com_velocity
from agent.estimation.consensus import consensus_term, metropolis_weight
from agent.estimation.excitation import kick_force, spin_up_force
from agent.estimation.flows import EdgeFlows
from agent.estimation.geometry import Vec2, rotate
from agent.estimation.inertia import InertiaEstimator, inertia_force
from agent.estimation.mass import MassEstimator
from agent.estimation.relative_position import RelativePosition
from agent.estimation.settling import SettleDetector
from agent.protocol import Command, Estimates, Measurement, Share
from agent.safety import saturate

PHASES = ("excite", "inertia", "push", "done", "halted")
EXCITE, INERTIA, PUSH, DONE, HALTED = range(5)
HISTORY_TICKS = 64


class Agent:
    """The estimator and force law of one robot (see the module docstring)."""

    def __init__(self, config: AgentConfig):
        self.config = config
        tuning = config.tuning
        self.tuning = tuning
        self.robot = config.robot
        self.n = config.n
        self.neighbours = tuple(sorted(config.neighbours))
        self.degree = len(self.neighbours)
        self.dt = config.period_s
        self.barrier = PhaseBarrier(self.robot, self.n, tuning.switch_margin_ticks)
        self.phase_start: dict[int, int] = {EXCITE: 0}
        self.kick_ticks = round(tuning.kick_duration_s / self.dt)
        self.kick = kick_force(config.seed, self.robot, tuning.kick_force)
        window = max(1, round(tuning.settle_window_s / self.dt))
        tol = tuning.settle_tolerance
        self.settle = {
            1: SettleDetector(window, tol),
            2: SettleDetector(window, tol),
            "spread": SettleDetector(window, tol),
            4: SettleDetector(window, tol),
            5: SettleDetector(window, tol),
            7: SettleDetector(window, tol),
        }
        self.started: dict[int, int] = {1: 0}
        memory = tuning.regression_memory_s
        self.forgetting = math.exp(-self.dt / memory) if memory > 0 else 1.0
        self.edges = {
            j: RelativePosition(tuning.filter_gain, self.forgetting) for j in self.neighbours
        }
        self._edge_instant: dict[int, int] = {}
        self._own_velocity: dict[int, Vec2] = {}
        self._neighbour_velocity: dict[int, dict[int, Vec2]] = {j: {} for j in self.neighbours}
        self._latest: dict[int, Share] = {}
        self._angle_at: dict[int, float] = {}
        self.rejected = 0
        self._pending: list[Share] = []
        self.instant = -1
        self.angle = 0.0
        self.omega: float | None = None
        self.zdot: dict[int, Vec2] = {}
        self.centroid: Vec2 = (0.0, 0.0)
        self.spread = 0.0
        self.flows = EdgeFlows(self.neighbours)
        self._fresh: set[int] = set()
        self.spin_sign = 0.0
        self.inertia: InertiaEstimator | None = None
        self.inertia_gain = 0.0
        self.inertia_torque = 0.0
        self.inertia_direction = 1.0
        self._inertia_torque: dict[int, float] = {}
        self.moment_used: float | None = None
        self.push: Vec2 = (0.0, 0.0)
        self.com: ComRegression | None = None
        self.push_angle = 0.0
        self._measured: int | None = None
        """The last instant whose ω was measured (Steps 4–7 use only those)."""
        """The load's rotation angle at the push phase's first instant (Step 5's reference)."""
        self.observer: ComObserver | None = None
        self.mass_estimator: MassEstimator | None = None
        self.com_velocity: Vec2 | None = None

    # ---------------------------------------------------------------- the tick
    @property
    def phase(self) -> int:
        return self.barrier.phase

    def step(self, measurement: Measurement, shares: Iterable[Share]) -> tuple[Command, Share]:
        """One sensor tick: returns the force command for this tick and the share to send."""
        k = measurement.tick
        self._own_velocity[k] = measurement.velocity
        incoming, self._pending = self._pending, []
        incoming.extend(shares)
        for s in incoming:
            history = self._neighbour_velocity.get(s.sender)
            if history is None or not _usable(s, k):
                self.rejected += 1  # not from a neighbour, or unusable: never used
                continue
            if s.tick >= k:
                self._pending.append(s)  # early: used from tick s.tick + 1 on
                continue
            history[s.tick] = s.velocity
            latest = self._latest.get(s.sender)
            if latest is None or s.tick > latest.tick:
                self._latest[s.sender] = s
                self._fresh.add(s.sender)
        # The newest instant every neighbour has reported (k - 1 unless messages are late);
        # instants skipped since the last step are estimated in order.
        newest = k - 1 if len(self._latest) == self.degree else -1
        for s in self._latest.values():
            if s.tick < newest:
                newest = s.tick
        for e in range(self.instant + 1, min(k - 1, newest) + 1):
            self._estimate(e)
        if self.barrier.step(k, self._ready(k), self._latest.values()):
            self._enter(self.barrier.phase, k)
        force = saturate(self._force(k), self.tuning.max_force)
        share = Share(
            sender=self.robot,
            tick=k,
            velocity=measurement.velocity,
            degree=self.degree,
            centroid=self.centroid,
            spread=self.spread,
            phase=self.barrier.phase,
            ready=self.barrier.ready,
            switch_at=self.barrier.switch_at,
            flows=tuple((j, *f) for j, f in self.flows.flows.items()),
            instant=self.instant,
        )
        self._forget(k - HISTORY_TICKS)
        return Command(self.robot, k, force), share

    # ---------------------------------------------------------------- estimation
    def _estimate(self, e: int) -> None:
        t = e * self.dt
        previous = self.instant
        self.instant = e
        v_i = self._own_velocity.get(e)
        self.zdot = {}
        if v_i is not None:
            for j in self.neighbours:
                v_j = self._neighbour_velocity[j].get(e)
                if v_j is None:
                    continue
                zdot = (v_i[0] - v_j[0], v_i[1] - v_j[1])
                self.edges[j].update(zdot, t)
                self._edge_instant[j] = e
                self.zdot[j] = zdot
        # Step 3 (eq. 5) and the load's rotation since the last instant, from the longest
        # edge that has both a fresh sample and a distance estimate.
        ref = None
        for j in self.zdot:
            d = self.edges[j].distance
            if d is not None and (ref is None or d > self.edges[ref].distance):
                ref = j
        if ref is not None:
            edge = self.edges[ref]
            self.omega = angular_velocity(edge.relative_position, self.zdot[ref])
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
        self._centroid_and_spread(turn)
        if self.barrier.phase == EXCITE:  # later, Steps 1-3 are done: nothing reads these
            self._track_settling(e)
        self._phase_estimates(e, measured=ref is not None)

    def relative_position(self, j: int) -> Vec2 | None:
        """``z_ij`` at the current estimation instant (turned forward if its sample is stale)."""
        z = self.edges[j].relative_position
        last = self._edge_instant.get(j)
        if z is None or last is None:
            return None
        if last != self.instant:
            z = rotate(z, self.angle - self._angle_at.get(last, self.angle))
        return z

    def _turned_since(self, instant: int) -> float:
        angle = self._angle_at.get(instant)
        if angle is None:
            return (self.omega or 0.0) * (self.instant - instant) * self.dt
        return self.angle - angle

    def _centroid_and_spread(self, turn: float) -> None:
        """Step 2 (Aragues et al.) and eq. (16) for ``w``, in flow form, in ``W`` now:
        ``x_i = −Σ_j F_ij`` and ``ξ_i = ‖x_i‖² − Σ_j F^s_ij``."""
        flows = self.flows
        flows.turn(turn)
        for j in self._fresh:
            s = self._latest[j]
            for k, fx, fy, fs in s.flows:
                if k == self.robot:
                    vx, vy = rotate((fx, fy), self._turned_since(s.instant))
                    flows.adopt(j, (vx, vy, fs))
        self._fresh.clear()
        fx, fy, fs = flows.outflow()
        x = (-fx, -fy)
        xi = x[0] * x[0] + x[1] * x[1] - fs
        previous = self.instant - 1
        for j in self.neighbours:
            s = self._latest.get(j)
            if s is None:
                continue
            a = metropolis_weight(self.degree, s.degree)
            dx = dy = 0.0
            if s.centroid is not None:
                # Usually one tick old: turned by this tick's turn, already applied to the flows.
                if s.instant == previous:
                    x_j = flows.turned(s.centroid)
                else:
                    x_j = rotate(s.centroid, self._turned_since(s.instant))
                dx, dy = centroid_term(a, x, x_j, self.relative_position(j) or (0.0, 0.0))
            ds = consensus_term(a, xi, s.spread)
            flows.push(j, dx, dy, ds)
            fx -= dx
            fy -= dy
            fs -= ds
        self.centroid = (-fx, -fy)
        self.spread = fx * fx + fy * fy - fs

    def _track_settling(self, e: int) -> None:
        distances = [self.edges[j].distance for j in self.neighbours]
        if None in distances:
            return
        self.settle[1].update(distances, e)
        # z_i in the frame of the longest edge (always the same one): constant once converged.
        longest = max(self.neighbours, key=lambda j: self.edges[j].distance)
        z = self.relative_position(longest)
        if z is None:
            return
        d = math.hypot(*z)
        u = (z[0] / d, z[1] / d)
        x = self.centroid
        self.settle[2].update((x[0] * u[0] + x[1] * u[1], u[0] * x[1] - u[1] * x[0]), e)
        self.settle["spread"].update((self.spread,), e)

    def _phase_of_tick(self, tick: int) -> int:
        phase = EXCITE
        for p, start in self.phase_start.items():
            if start <= tick and p > phase:
                phase = p
        return phase

    def _phase_estimates(self, e: int, measured: bool) -> None:
        """Steps 4–7. They use only instants whose ω was measured at that instant (not carried
        over because every neighbour's message was lost); the interval since the previous such
        instant is used whole."""
        if self.omega is None or not measured:
            return
        omega = self.omega
        prev, self._measured = self._measured, e
        span = (e - prev) * self.dt if prev is not None else self.dt
        k_inertia = self.phase_start.get(INERTIA)
        if self.inertia is not None and k_inertia is not None and e >= k_inertia:
            if not self.inertia.regression.started:
                self.inertia.update(omega, span, 0.0)  # starts the filters
            elif prev >= k_inertia and self._phase_of_tick(e - 1) == INERTIA:
                torques = [self._inertia_torque.get(t, 0.0) for t in range(prev, e)]
                self.inertia.update(omega, span, sum(torques) / len(torques))
                moment = self.inertia.moment
                if moment is not None:
                    self.settle[4].update((moment,), e)
        k_push = self.phase_start.get(PUSH)
        if self.com is None or k_push is None or e < k_push:
            return
        # The regressions hold only while the common force acts, over the whole interval.
        pushing = prev is not None and prev >= k_push and self._phase_of_tick(e - 1) == PUSH
        if not self.com.regression.started:
            self.push_angle = self.angle
            self.observer = ComObserver(
                self.n, self.moment_used, self.push, self.tuning.observer_gain, omega
            )
            self.com.update(omega, 0.0, span)  # starts the filters
            return
        alpha = self.angle - self.push_angle
        if pushing:
            self.observer.update(omega, span)
            self.com.update(omega, alpha, span)
        ref_offset = self.com.reference_offset
        if ref_offset is None:
            return
        if pushing:
            self.settle[5].update(ref_offset, e)
        if not self.settle[5].settled and self.mass_estimator is None:
            return
        z_c = self.com.com_offset(alpha)
        offset = (self.centroid[0] + z_c[0], self.centroid[1] + z_c[1])
        v_i = self._own_velocity.get(e)
        if v_i is None:
            return
        self.com_velocity = com_velocity(v_i, omega, offset)  # Step 6, eq. (7)
        if not pushing:
            return
        if self.mass_estimator is None:
            self.mass_estimator = MassEstimator(
                self.tuning.filter_gain, self.n, self.push, self.forgetting
            )
            self.started[6] = e
            self.started[7] = e
        self.mass_estimator.update(self.com_velocity, span)
        mass = self.mass_estimator.mass
        if mass is not None:
            self.settle[7].update((mass,), e)

    # ---------------------------------------------------------------- phases and forces
    def halt(self) -> None:
        """Stop the team: from now on this robot applies no force, and every robot that hears
        of it does the same (see the module docstring)."""
        self.barrier.halt(HALTED)

    def _ready(self, k: int) -> bool:
        phase = self.barrier.phase
        s = self.settle
        if phase == EXCITE:
            return (
                k >= self.kick_ticks
                and s[1].settled
                and s[2].settled
                and s["spread"].settled
                and self.spread > 0.0
            )
        if phase == INERTIA:
            min_ticks = round(self.tuning.inertia_min_s / self.dt)
            return s[4].settled and k - self.phase_start[INERTIA] >= min_ticks
        if phase == PUSH:
            return s[5].settled and s[7].settled
        return False

    def _enter(self, phase: int, k: int) -> None:
        self.phase_start[phase] = k
        if phase == INERTIA:
            self.started[4] = k
            w = self.n * self.spread
            self.inertia_gain = self.tuning.inertia_force / math.sqrt(w)
            self.spin_sign = math.copysign(1.0, self.omega or 1.0)
            self.inertia_torque = self.spin_sign * self.inertia_gain * w
            self.inertia = InertiaEstimator(self.tuning.filter_gain, self.forgetting)
            for edge in self.edges.values():
                edge.learning = False  # Step 1 is done: keep the distances, track directions.
        elif phase == PUSH:
            self.started[5] = k
            self.moment_used = self.inertia.moment
            t = self.tuning
            magnitude = max(t.push_fbar * self.moment_used / self.n, t.push_min_force)
            self.push = _unit(t.push_direction, min(magnitude, t.max_force))
            self.com = ComRegression(
                self.tuning.filter_gain, self.n, self.moment_used, self.push, self.forgetting
            )

    def _force(self, k: int) -> Vec2:
        phase = self.barrier.phase
        if phase == EXCITE:
            if k < self.kick_ticks:
                return self.kick
            return spin_up_force(self.tuning.spin_gain, self.tuning.spin_speed, self.zdot.values())
        if phase == INERTIA:
            # Speed the turn up until |ω| reaches the limit, then brake down to half of it.
            speed = abs(self._omega_at(k))
            if speed >= self.tuning.inertia_max_omega:
                self.inertia_direction = -1.0
            elif speed <= 0.5 * self.tuning.inertia_max_omega:
                self.inertia_direction = 1.0
            self._inertia_torque[k] = self.inertia_direction * self.inertia_torque
            # z_i turned to the middle of [t_k, t_k+1): the torque then averages ±k w.
            lead = (self.omega or 0.0) * (k + 0.5 - self.instant) * self.dt
            z = rotate(self.centroid, lead)
            return inertia_force(self.inertia_direction * self.spin_sign * self.inertia_gain, z)
        if phase == PUSH:
            return self.push
        return (0.0, 0.0)

    def _omega_at(self, tick: int) -> float:
        """ω at ``t_tick``, predicted from the last instant it was measured with the torque the
        team applied since (Step 4) and ``Ĵ``: every robot, whichever messages it has received,
        predicts the same value, so they all take the same decisions."""
        omega = self.omega or 0.0
        moment = self.inertia.moment if self.inertia is not None else None
        if self._measured is None or moment is None:
            return omega
        impulse = sum(self._inertia_torque.get(t, 0.0) for t in range(self._measured, tick))
        return omega + impulse * self.dt / moment

    def _forget(self, before: int) -> None:
        self._own_velocity.pop(before, None)
        self._angle_at.pop(before - 1, None)
        self._inertia_torque.pop(before, None)
        for history in self._neighbour_velocity.values():
            history.pop(before, None)

    # ---------------------------------------------------------------- reporting
    def estimates(self) -> Estimates:
        """The current estimates, at the estimation instant (see :class:`Estimates`)."""
        relative = {}
        for j in self.neighbours:
            z = self.relative_position(j)
            if z is not None:
                relative[j] = z
        z_i = self.centroid if 2 in self.started else None
        z_c = None
        observed = None
        k_push = self.phase_start.get(PUSH)
        if self.com is not None and k_push is not None and self.instant >= k_push:
            z_c = self.com.com_offset(self.angle - self.push_angle)
            if self.observer is not None:
                observed = self.observer.com_offset
        contact_to_com = None
        if z_i is not None and z_c is not None:
            contact_to_com = (-(z_i[0] + z_c[0]), -(z_i[1] + z_c[1]))
        settled = {}
        for step, key in ((1, 1), (2, 2), (3, 1), (4, 4), (5, 5), (6, 5), (7, 7)):
            tick = self.settle[key].first_settled
            if tick is not None:
                settled[step] = tick
        return Estimates(
            robot=self.robot,
            tick=self.instant,
            phase=PHASES[self.barrier.phase],
            omega=self.omega,
            relative_positions=relative,
            centroid_offset=z_i,
            spread=self.n * self.spread if 2 in self.started else None,
            moment=self.inertia.moment if self.inertia is not None else None,
            com_offset=z_c,
            com_observer=observed,
            com_velocity=self.com_velocity,
            mass=self.mass_estimator.mass if self.mass_estimator is not None else None,
            contact_to_com=contact_to_com,
            started=dict(self.started),
            settled=settled,
        )


def _usable(share: Share, tick: int) -> bool:
    """A share whose numbers an agent can use at ``tick``: finite, and not stamped so far
    ahead that it could only come from a clock gone wrong."""
    vx, vy = share.velocity
    c = share.centroid or (0.0, 0.0)
    # x - x == 0 exactly for every finite float, and is NaN for NaN and ±inf.
    return vx - vx + vy - vy + c[0] - c[0] + c[1] - c[1] + share.spread - share.spread == 0.0 and (
        share.tick < tick + HISTORY_TICKS
    )


def _unit(direction: tuple[float, float], magnitude: float) -> Vec2:
    d = math.hypot(direction[0], direction[1])
    return (magnitude * direction[0] / d, magnitude * direction[1] / d)
