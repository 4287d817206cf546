"""The team's phases (force regimes) and the force each robot applies in them.

The phases are switched by the team's barrier (:mod:`agent.algorithm.coordination`) once every
robot's own estimates have settled; every robot switches at the same agreed tick:

======== ======================================= ===========================================
phase     forces                                  estimates that settle in it
======== ======================================= ===========================================
excite    kick, then geometry-free spin-up        Step 1 ``z_ij``, Step 2 ``z_i``, Step 3 ω, ``w``
          and damping
inertia   ``f_i = ±k z_i⊥`` (eq. 14)                Step 4 ``J``
push      common ``±f`` (eq. 17)                  Step 5 ``z_C``, Step 6 ``ṗ_C``, Step 7 ``m``
done      damping: the load comes to rest, or     (tracking goes on; with ``robust``, the
          (``robust``) probes and damping         probes test the load for a change)
halted    zero                                    (a robot was lost: the team stops until
                                                  every robot is back, then begins again)
======== ======================================= ===========================================

A changed load (``robust``): a robot whose probe finds the load no longer the one estimated
(:mod:`agent.algorithm.estimation.load_change`) is ready to leave ``done``, and the team restarts at
``inertia`` in a new epoch at an agreed tick (:mod:`agent.algorithm.coordination`).

``halted`` is entered by :meth:`PhaseMachine.halt` when a neighbour is lost, and reaches the
rest of the team through the barrier's catch-up rule (it is the highest phase). The paper
assumes ``n`` robots that all push; estimates made without one of them would be wrong, so the
team stops and says so rather than carrying on. A halted robot is ready to leave ``halted``
once every neighbour is alive again (:attr:`PhaseMachine.team_back`); when all are, the team
begins again from Step 1 in a new generation (:mod:`agent.algorithm.coordination`,
:mod:`agent.algorithm.agent`).

The force laws:

- *excite*: for ``kick_duration_s`` a seeded random kick, then the spin-up
  ``f_i = k Σ_j (1 − ‖ż_ij‖/v*) ż_ij`` (:mod:`agent.algorithm.estimation.excitation`) plus the
  damping ``−b ṗ_Ci`` (``brake_gain``, Remark V.2), which takes out the kick's drift: Steps 1–3
  need the load to turn, not to travel;
- *inertia*: ``f_i = ±k z_i⊥`` with ``k = F/√w`` (eq. 14,
  :mod:`agent.algorithm.estimation.inertia`): the torque ``±k w`` speeds the turn the load
  already has up until ``|ω|`` reaches ``inertia_max_omega``, then brakes it down to half of
  that, and so on. ``ω`` at the tick is predicted from its last measurement, the torque applied since and ``Ĵ``: without noise every
  robot predicts the same value, so they all reverse at the same tick. With ``estimator =
  "robust"`` the robots' ω differ by their noise, so the torque instead speeds up for
  ``inertia_flip_s`` and brakes for as long, in turn, from the agreed tick on (after braking
  first for ``inertia_brake_s``: with half a flip, ω swings about the turn the load had, by
  half of what speeding up first adds to it, which keeps a compact, light load's turn on its
  floor);
- *push*: the common force ``f = max(f̄_y Ĵ/n, push_min_force)`` along ``push_direction``, at
  most ``max_force`` (eq. 17 and Sec. VI, ``f_y = J/n`` for ``f̄_y = 1``); with ``estimator =
  "robust"`` the configured ``push_force``, the same for every robot whatever its Ĵ. The paper
  pushes one way, and the load's speed grows without bound; on a bounded floor the push
  reverses on the agreed clock (``push_flip_s = T``): ``+f`` for ``T/2``, then ``−f`` and
  ``+f`` for ``T`` each, in turn (:meth:`PhaseMachine.push_sign`), so that the COM's velocity
  swings about the one it had and it travels back and forth; with ``push_damping = b`` each
  robust robot also adds ``−b ṗ̂_G``, the damping of the centroid's velocity (which every robot
  estimates alike), so that a light load's speed stays within about ``f/b`` and a heavy one's
  drift dies out (Steps 5 and 7 take the force as commanded);
- *done*: the damping ``−b ṗ_Ci`` alone brings the load to rest. With ``estimator =
  "robust"`` (and ``change_threshold`` > 0) the team keeps watching the load instead, in cycles
  on the agreed clock: a gap of ``monitor_gap_s`` in which each robot damps the COM's velocity,
  ``−b ṗ̂_C`` (Step 6's estimate: the load keeps its turn, which Step 5's fit needs, and loses
  its drift), then a *probe* of ``probe_s = T``, the push's common force ``+f`` for ``T/4``,
  ``−f`` for ``T/2`` and ``+f`` for ``T/4``: the COM's velocity and place come back to where
  they were, after a swing of ``n f T²/16m``; every other probe swings the other way.

Every command is bounded by ``max_force`` (:func:`agent.algorithm.safety.saturate`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Protocol

from agent.algorithm.coordination import PhaseBarrier
from agent.algorithm.estimation.excitation import kick_force, spin_up_force
from agent.algorithm.estimation.inertia import inertia_force
from agent.algorithm.safety import saturate
from agent.algorithm.tuning import AgentConfig, Estimators
from agent.platform.geometry import Vec2, rotate
from agent.platform.protocol import Phase, Share

if TYPE_CHECKING:
    from agent.algorithm.estimation.settling import SettleDetectors


class OwnEstimates(Protocol):
    """What the phase machine reads of its own robot's estimates (an
    :class:`~agent.algorithm.pipeline.EstimationPipeline`)."""

    instant: int
    """The estimation instant."""
    omega: float | None
    """``ω`` at the estimation instant (Step 3)."""
    measured: int | None
    """The last instant whose ``ω`` was measured."""
    zdot: dict[int, Vec2]
    """``ż_ij`` at the estimation instant, by neighbour."""
    settle: SettleDetectors

    com_velocity: Vec2 | None
    """``ṗ_C`` (Step 6)."""
    changed: bool
    """Whether a probe found the load changed (:mod:`agent.algorithm.estimation.load_change`)."""

    @property
    def centroid(self) -> Vec2:
        """``z_i`` at the estimation instant (Step 2)."""
        ...

    @property
    def spread(self) -> float:
        """``w / n`` (eq. 16)."""
        ...

    @property
    def moment(self) -> float | None:
        """``Ĵ`` (Step 4)."""
        ...


class PhaseMachine:
    """One robot's phase, when it was entered, and the force law of each phase."""

    def __init__(self, config: AgentConfig, barrier: PhaseBarrier | None = None):
        tuning = config.tuning
        self.tuning = tuning
        self.n = config.n
        self.dt = config.period_s
        self.barrier = barrier or PhaseBarrier(config.robot, config.n, tuning.switch_margin_ticks)
        """The team's phase (a new generation's machine takes over the barrier that began it)."""
        self.team_back = False
        """Whether every neighbour is alive: in ``halted``, this robot is then ready."""
        self.entered: dict[Phase, int] = {Phase.EXCITE: 0}
        """The tick at which each phase was entered (phases skipped are not listed)."""
        self.kick_ticks = round(tuning.kick_duration_s / self.dt)
        self.kick = kick_force(config.seed, config.robot, tuning.kick_force)
        self.inertia_min_ticks = round(tuning.inertia_min_s / self.dt)
        self.robust = tuning.estimator == Estimators.ROBUST
        self.flip_ticks = round(tuning.inertia_flip_s / self.dt)
        self.brake_ticks = round(tuning.inertia_brake_s / self.dt)
        self.spin_sign = 0.0
        """``sign(ω)`` when the inertia phase began: the torque first speeds that turn up."""
        self.inertia_gain = 0.0
        """``k = F/√w`` of eq. (14)."""
        self.inertia_torque = 0.0
        """``sign(ω) k w``: the team's torque while speeding up."""
        self.direction = 1.0
        """``+1`` while the inertia phase speeds the turn up, ``−1`` while it brakes."""
        self._torque: dict[int, float] = {}
        """The team's torque (``±k w``) during each tick of the inertia phase."""
        self._damping: dict[int, Vec2] = {}
        """What this robot added to the common push during each tick (``push_damping``)."""
        self.moment_used: float | None = None
        """The ``Ĵ`` the push force was sized with (Steps 5 and 7 use it too)."""
        self.push: Vec2 = (0.0, 0.0)
        """The common force ``f`` of the push phase (eq. 17), before its sign."""
        self.push_flip_ticks = round(tuning.push_flip_s / self.dt)
        self.monitoring = self.robust and tuning.change_threshold > 0.0
        """Whether the team probes the load once done (see the module docstring)."""
        self.probe_ticks = 4 * max(1, round(tuning.probe_s / (4 * self.dt)))
        """A probe's length: a multiple of 4 ticks."""
        self.gap_ticks = max(1, round(tuning.monitor_gap_s / self.dt))
        self.monitor_ticks = self.gap_ticks + self.probe_ticks
        """A monitoring cycle: the gap, then a probe."""
        self._ready: Callable[[int, OwnEstimates], bool]
        self._law: Callable[[int, OwnEstimates, Vec2], Vec2]
        self._begin(Phase.EXCITE)

    @property
    def phase(self) -> Phase:
        return self.barrier.phase

    @property
    def epoch(self) -> int:
        """How many times the team has restarted for a changed load."""
        return self.barrier.epoch

    @property
    def since(self) -> int:
        """The tick at which the current phase was entered."""
        return self.entered[self.barrier.phase]

    def phase_at(self, tick: int) -> Phase:
        """The phase during tick ``tick`` (as far as this robot knows)."""
        phase = Phase.EXCITE
        for p, start in self.entered.items():
            if start <= tick and p > phase:
                phase = p
        return phase

    # ---------------------------------------------------------------- switching
    def ready(self, k: int, own: OwnEstimates) -> bool:
        """Whether this robot is ready to leave its phase at tick ``k``: the phase's estimates
        have settled (and the phase has lasted long enough)."""
        return self._ready(k, own)

    def step(self, k: int, own: OwnEstimates, shares: Iterable[Share]) -> bool:
        """Tick ``k`` of the barrier, on this robot's readiness and its neighbours' latest
        messages; returns ``True`` if a new phase begins at ``k`` (its force law is then set
        up from ``own``)."""
        if not self.barrier.step(k, self._ready(k, own), shares):
            return False
        phase = self.barrier.phase
        if not self._can_enter(phase, own):
            # Caught up (or told) to a phase this robot has not the estimates for: it could
            # only push wrongly, so it stops the team instead.
            self.halt(k)
            return True
        if phase == Phase.INERTIA:  # (again, in a new epoch: the later phases are to come)
            self.entered = {p: t for p, t in self.entered.items() if p < Phase.INERTIA}
        self.entered[phase] = k
        if phase == Phase.INERTIA:
            w = self.n * own.spread
            self.inertia_gain = self.tuning.inertia_force / math.sqrt(w)
            self.spin_sign = math.copysign(1.0, own.omega or 1.0)
            self.inertia_torque = self.spin_sign * self.inertia_gain * w
        elif phase == Phase.PUSH:
            self.moment_used = own.moment
            t = self.tuning
            if self.robust:
                magnitude = t.push_force
            else:
                magnitude = max(t.push_fbar * self.moment_used / self.n, t.push_min_force)
            self.push = _unit(t.push_direction, min(magnitude, t.max_force))
        self._begin(phase)
        return True

    @staticmethod
    def _can_enter(phase: Phase, own: OwnEstimates) -> bool:
        """Whether ``own`` has what ``phase``'s force law needs: ``w > 0`` for the inertia
        phase (eq. 14), ``Ĵ`` for the push (eq. 17)."""
        if phase == Phase.INERTIA:
            return own.spread > 0.0
        if phase == Phase.PUSH:
            return own.moment is not None
        return True

    def halt(self, tick: int) -> None:
        """Stop the team from tick ``tick`` on (see the module docstring)."""
        self.barrier.halt()
        self.entered.setdefault(Phase.HALTED, tick)
        self._begin(Phase.HALTED)

    def force(self, k: int, own: OwnEstimates, velocity: Vec2) -> Vec2:
        """The force to apply during tick ``k``, given the contact's velocity ``ṗ_Ci`` measured
        at ``t_k``, bounded by ``max_force``."""
        return saturate(self._law(k, own, velocity), self.tuning.max_force)

    # ---------------------------------------------------------------- each phase's laws
    def _begin(self, phase: Phase) -> None:
        """Take up ``phase``'s readiness test and force law (looked up once, not every tick)."""
        laws = {
            Phase.EXCITE: (self._excite_ready, self._excite_force),
            Phase.INERTIA: (self._inertia_ready, self._inertia_force),
            Phase.PUSH: (self._push_ready, self._push_force),
            Phase.DONE: (self._changed, self._monitor_force)
            if self.monitoring
            else (_never_ready, self._brake_force),
            Phase.HALTED: (self._back, _no_force),
        }
        self._ready, self._law = laws.get(phase, (_never_ready, _no_force))

    def _back(self, k: int, own: OwnEstimates) -> bool:
        """Halted: ready to begin again once every neighbour is alive."""
        return self.team_back

    def _excite_ready(self, k: int, own: OwnEstimates) -> bool:
        s = own.settle
        return (
            k >= self.kick_ticks
            and s.distances.settled
            and s.centroid.settled
            and s.spread.settled
            and own.spread > 0.0
        )

    def _excite_force(self, k: int, own: OwnEstimates, velocity: Vec2) -> Vec2:
        """The kick, then the spin-up and the damping."""
        if k < self.kick_ticks:
            return self.kick
        t = self.tuning
        spin = spin_up_force(t.spin_gain, t.spin_speed, own.zdot.values())
        brake = self._brake_force(k, own, velocity)
        return (spin[0] + brake[0], spin[1] + brake[1])

    def _brake_force(self, k: int, own: OwnEstimates, velocity: Vec2) -> Vec2:
        """Remark V.2's damping ``−b ṗ_Ci``."""
        b = self.tuning.brake_gain
        return (-b * velocity[0], -b * velocity[1])

    def _inertia_ready(self, k: int, own: OwnEstimates) -> bool:
        return own.settle.moment.settled and k - self.since >= self.inertia_min_ticks

    def _inertia_force(self, k: int, own: OwnEstimates, velocity: Vec2) -> Vec2:
        """Eq. (14) with the torque's sign for tick ``k`` (records the team's torque)."""
        if self.robust:
            # Speed up, then brake as long (after braking for inertia_brake_s), from the
            # agreed tick on: every robot takes the same decisions whatever the noise on its ω.
            since = k - self.since - self.brake_ticks
            flips = since // max(1, self.flip_ticks)
            self.direction = 1.0 if since >= 0 and flips % 2 == 0 else -1.0
        else:
            # Speed the turn up until |ω| reaches the limit, then brake down to half of it.
            speed = abs(self.omega_at(k, own))
            limit = self.tuning.inertia_max_omega
            if speed >= limit:
                self.direction = -1.0
            elif speed <= 0.5 * limit:
                self.direction = 1.0
        self._torque[k] = self.direction * self.inertia_torque
        # z_i turned to the middle of [t_k, t_k+1): the torque then averages ±k w.
        lead = (own.omega or 0.0) * (k + 0.5 - own.instant) * self.dt
        z = rotate(own.centroid, lead)
        return inertia_force(self.direction * self.spin_sign * self.inertia_gain, z)

    def _push_ready(self, k: int, own: OwnEstimates) -> bool:
        s = own.settle
        return s.com_offset.settled and s.mass.settled

    def _push_force(self, k: int, own: OwnEstimates, velocity: Vec2) -> Vec2:
        sign = self.push_sign(k)
        push = (sign * self.push[0], sign * self.push[1])
        b = self.tuning.push_damping
        if not (self.robust and b > 0.0):
            return push
        # ṗ_G = ṗ_Ci − ω Q z_i, z_i turned to t_k from the estimation instant.
        omega = own.omega or 0.0
        z = rotate(own.centroid, omega * (k - own.instant) * self.dt)
        centroid_velocity = (velocity[0] + omega * z[1], velocity[1] - omega * z[0])
        force = saturate(
            (push[0] - b * centroid_velocity[0], push[1] - b * centroid_velocity[1]),
            self.tuning.max_force,
        )
        self._damping[k] = (force[0] - push[0], force[1] - push[1])
        return force

    @staticmethod
    def _changed(k: int, own: OwnEstimates) -> bool:
        return own.changed

    def probe_start(self, tick: int) -> int | None:
        """The first tick of the last probe begun by tick ``tick`` (``None`` while the team is
        not done, not probing, or in the gap before the first probe)."""
        done = self.entered.get(Phase.DONE)
        if not self.monitoring or done is None or tick < done + self.gap_ticks:
            return None
        since = tick - done - self.gap_ticks
        return tick - since % self.monitor_ticks

    def probe_sign(self, tick: int) -> float:
        """The common force's sign during tick ``tick`` of a probe: ``+`` for ``T/4``, ``−``
        for ``T/2``, ``+`` for ``T/4`` (``T`` = ``probe_s``), every other probe the other way
        round; 0 in the gaps between probes."""
        start = self.probe_start(tick)
        if start is None:
            return 0.0
        since, quarter = tick - start, self.probe_ticks // 4
        if since >= self.probe_ticks:
            return 0.0
        first = (start - self.entered[Phase.DONE]) // self.monitor_ticks % 2 == 0
        middle = quarter <= since < self.probe_ticks - quarter
        return -1.0 if middle == first else 1.0

    def _monitor_force(self, k: int, own: OwnEstimates, velocity: Vec2) -> Vec2:
        """A probe's common force, or the gap's damping of the COM's velocity."""
        sign = self.probe_sign(k)
        if sign:
            return (sign * self.push[0], sign * self.push[1])
        v = own.com_velocity or velocity
        b = self.tuning.brake_gain
        return (-b * v[0], -b * v[1])

    def push_sign(self, tick: int) -> float:
        """The sign of the common force during tick ``tick`` of the push phase: ``+`` for the
        first ``T/2``, then ``−`` and ``+`` for ``T`` each (``T`` = ``push_flip_s``; always
        ``+`` for ``T = 0``); the other way round in the robust estimators' odd epochs (a
        changed load's push swings the load back towards where it started)."""
        period = self.push_flip_ticks
        since = tick - self.entered.get(Phase.PUSH, tick)
        first = -1.0 if self.robust and self.epoch % 2 else 1.0
        if period <= 0 or since < period // 2:
            return first
        return -first if (since - period // 2) // period % 2 == 0 else first

    def mean_push_damping(self, first: int, last: int) -> Vec2:
        """The mean of what each robot added to the common force over ticks ``first..last − 1``
        (``push_damping``; zero without it)."""
        added = [self._damping.get(t, (0.0, 0.0)) for t in range(first, last)]
        return (
            sum(a[0] for a in added) / len(added),
            sum(a[1] for a in added) / len(added),
        )

    def mean_push_sign(self, first: int, last: int) -> float:
        """The mean sign of the common force over ticks ``first..last − 1`` (Steps 5–7's
        input over an interval)."""
        return sum(self.push_sign(t) for t in range(first, last)) / (last - first)

    # ---------------------------------------------------------------- for Step 4
    def omega_at(self, tick: int, own: OwnEstimates) -> float:
        """ω at ``t_tick``, predicted from the last instant it was measured with the torque the
        team applied since (eq. 15) and ``Ĵ``: every robot, whichever messages it has received,
        predicts the same value, so they all take the same decisions."""
        omega = own.omega or 0.0
        moment = own.moment
        if own.measured is None or moment is None:
            return omega
        impulse = sum(self._torque.get(t, 0.0) for t in range(own.measured, tick))
        return omega + impulse * self.dt / moment

    def mean_torque(self, first: int, last: int) -> float:
        """The team's mean torque (Step 4's input ``±k w``) over ticks ``first..last − 1``."""
        torques = [self._torque.get(t, 0.0) for t in range(first, last)]
        return sum(torques) / len(torques)

    def forget(self, before: int) -> None:
        """Drop the torque and the damping of tick ``before`` (too old to be asked for)."""
        self._torque.pop(before, None)
        self._damping.pop(before, None)


def _never_ready(k: int, own: OwnEstimates) -> bool:
    return False


def _no_force(k: int, own: OwnEstimates, velocity: Vec2) -> Vec2:
    return (0.0, 0.0)


def _unit(direction: tuple[float, float], magnitude: float) -> Vec2:
    d = math.hypot(direction[0], direction[1])
    return (magnitude * direction[0] / d, magnitude * direction[1] / d)
