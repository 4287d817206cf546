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
done      damping: the load comes to rest, or     (tracking goes on; the robust family's
          (robust) probes and damping             probes test the load for a change)
halted    zero                                    (a robot was lost: the team stops until
                                                  every robot is back, then begins again)
======== ======================================= ===========================================

``halted`` is entered by :meth:`PhaseMachine.halt` when a neighbour is lost, and reaches the
rest of the team through the barrier's catch-up rule (it is the highest phase). The paper
assumes ``n`` robots that all push; estimates made without one of them would be wrong, so the
team stops and says so rather than carrying on. A halted robot is ready to leave ``halted``
once every neighbour is alive again (:attr:`PhaseMachine.team_back`); when all are, the team
begins again from Step 1 (a rejoin, :mod:`agent.algorithm.coordination`,
:mod:`agent.algorithm.agent`).

The force laws every family shares:

- *excite*: for ``kick_duration_s`` a seeded random kick, then the spin-up
  ``f_i = k Σ_j (1 − ‖ż_ij‖/v*) ż_ij`` (:mod:`agent.algorithm.estimation.excitation`) plus the
  damping ``−b ṗ_Ci`` (``brake_gain``, Remark V.2), which takes out the kick's drift: Steps 1–3
  need the load to turn, not to travel;
- *inertia*: ``f_i = ±k z_i⊥`` with ``k = F/√w`` (eq. 14,
  :mod:`agent.algorithm.estimation.inertia`): the torque ``±k w`` speeds the turn the load
  already has up and brakes it, in turn, as the family decides
  (:meth:`PhaseMachine._inertia_direction`);
- *push*: a common force ``f`` along ``push_direction`` whose size the family gives
  (:meth:`PhaseMachine._push_magnitude`), at most ``max_force``. The paper pushes one way, and
  the load's speed grows without bound; on a bounded floor the push reverses on the agreed
  clock (``push_flip_s = T``): ``+f`` for ``T/2``, then ``−f`` and ``+f`` for ``T`` each, in
  turn (:meth:`PhaseMachine.push_sign`), so that the COM's velocity swings about the one it had
  and it travels back and forth;
- *done*: the damping ``−b ṗ_Ci`` alone brings the load to rest (a family may watch the load
  instead: :meth:`PhaseMachine._done_laws`).

Every command is bounded by ``max_force`` (:func:`agent.algorithm.safety.saturate`). The
families' machines: :class:`agent.algorithm.paper.phases.PaperPhases`,
:class:`agent.algorithm.robust.phases.RobustPhases`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable

from agent.algorithm.coordination import PhaseBarrier
from agent.algorithm.estimation.excitation import kick_force, spin_up_force
from agent.algorithm.estimation.inertia import inertia_force
from agent.algorithm.interfaces import OwnEstimates
from agent.algorithm.safety import saturate
from agent.algorithm.tuning import AgentConfig
from agent.platform.geometry import Vec2, rotate
from agent.platform.protocol import Barrier, Phase

Ready = Callable[[int, OwnEstimates], bool]
Law = Callable[[int, OwnEstimates, Vec2], Vec2]


class PhaseMachine:
    """One robot's phase, when it was entered, and the force law of each phase (the part every
    family shares; a family overrides the hooks at the end)."""

    held = False
    """Whether the floor holds the load beyond what the team's forces can move (a family that
    tells): the robot pushes no more."""
    held_because = ""
    """Why, for the run's verdict."""

    def __init__(self, config: AgentConfig, barrier: PhaseBarrier | None = None):
        tuning = config.tuning
        self.tuning = tuning
        self.n = config.n
        self.dt = config.period_s
        self.barrier = barrier or PhaseBarrier(config.robot, config.n, tuning.switch_margin_ticks)
        """The team's phase (a rejoin's machine takes over the barrier that began it)."""
        self.team_back = False
        """Whether every neighbour is alive: in ``halted``, this robot is then ready."""
        self.degrees: dict[int, int] = {}
        """Each neighbour's degree, as its last share gave it."""
        self.entered: dict[Phase, int] = {Phase.EXCITE: 0}
        """The tick at which each phase was entered (phases skipped are not listed)."""
        self.kick_ticks = round(tuning.kick_duration_s / self.dt)
        self.kick = kick_force(config.seed, config.robot, tuning.kick_force)
        self.spin_torque = 0.0
        """N m: this robot's filtered torque in Step 1's spin-up (a family may measure it)."""
        self.kick_level = tuning.kick_force
        """N: the size of this robot's kick (a family may grow it while the load is still)."""
        self.inertia_min_ticks = round(tuning.inertia_min_s / self.dt)
        self.spin_sign = 0.0
        """``sign(ω)`` when the inertia phase began: the torque first speeds that turn up."""
        self.inertia_gain = 0.0
        """``k = F/√w`` of eq. (14)."""
        self.inertia_torque = 0.0
        """``sign(ω) k w``: the team's torque while speeding up."""
        self.direction = 1.0
        """``+1`` while the inertia phase speeds the turn up, ``−1`` while it brakes."""
        self._torque: dict[int, float] = {}
        """The team's torque during each tick: Step 4's ``±k w``; in Step 5's swing, what the family
        adds beyond a constant torque; in Step 7's stage, the torque that holds the turn
        (:meth:`mean_torque`)."""
        self._added: dict[int, Vec2] = {}
        """What this robot added to the common push ``s(t) f`` during each tick (the robust
        family's ``push_damping``, and its push across ``f`` in Step 7's stage)."""
        self.moment_used: float | None = None
        """The ``Ĵ`` the push force was sized with (Steps 5 and 7 use it too)."""
        self.friction_used = 0.0
        """The floor's friction torque ``τ̂_c`` (N m) when the push began (0: none estimated):
        a family may keep the load turning against it (:meth:`_pushing`)."""
        self.push: Vec2 = (0.0, 0.0)
        """The common force ``f`` of the push phase (eq. 17), before its sign."""
        self.push_flip_ticks = round(tuning.push_flip_s / self.dt)
        self._ready: Ready
        self._law: Law
        self._begin(Phase.EXCITE)

    @property
    def phase(self) -> Phase:
        return self.barrier.phase

    @property
    def load_changes(self) -> int:
        """How many times the team has restarted for a changed load."""
        return self.barrier.load_changes

    @property
    def since(self) -> int:
        """The tick at which the current phase was entered."""
        return self.entered[self.barrier.phase]

    def began(self, phase: Phase) -> int | None:
        """The tick at which ``phase`` was entered (``None``: not entered)."""
        return self.entered.get(phase)

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

    def step(self, k: int, own: OwnEstimates, barriers: Iterable[Barrier]) -> bool:
        """Tick ``k`` of the barrier, on this robot's readiness and its neighbours' latest
        views of it; returns ``True`` if a new phase begins at ``k`` (its force law is then set
        up from ``own``)."""
        ready = self._ready(k, own)
        levels = self._levels(own) if ready and self.barrier.phase == Phase.EXCITE else (0, 0)
        if not self.barrier.step(k, ready, barriers, levels):
            return False
        phase = self.barrier.phase
        if not self._can_enter(phase, own):
            # Caught up (or told) to a phase this robot has not the estimates for: it could
            # only push wrongly, so it stops the team instead.
            self.halt(k)
            return True
        if phase == Phase.INERTIA:  # (again, after a load change: the later phases are to come)
            self.entered = {p: t for p, t in self.entered.items() if p < Phase.INERTIA}
        self.entered[phase] = k
        if phase == Phase.INERTIA:
            w = self.n * own.mean_square_offset
            self.inertia_gain = self._inertia_size(own) / math.sqrt(w)
            self.spin_sign = math.copysign(1.0, own.omega or 1.0)
            self.inertia_torque = self.spin_sign * self.inertia_gain * w
        elif phase == Phase.PUSH:
            self.moment_used = own.moment
            friction = own.friction_torque
            # no more than Step 4's own torque: a load that turned under it met less friction
            most = abs(self.inertia_torque)
            self.friction_used = min(max(friction[0], 0.0), most) if friction is not None else 0.0
            magnitude = self._push_magnitude(self.moment_used)
            self.push = _unit(self.tuning.push_direction, min(magnitude, self.tuning.max_force))
        self._begin(phase)
        return True

    @staticmethod
    def _can_enter(phase: Phase, own: OwnEstimates) -> bool:
        """Whether ``own`` has what ``phase``'s force law needs: ``w > 0`` for the inertia
        phase (eq. 14), ``Ĵ`` for the push (eq. 17)."""
        if phase == Phase.INERTIA:
            return own.mean_square_offset > 0.0
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
        if self.held:
            return (0.0, 0.0)
        return saturate(self._law(k, own, velocity), self.tuning.max_force)

    # ---------------------------------------------------------------- each phase's laws
    def _begin(self, phase: Phase) -> None:
        """Take up ``phase``'s readiness test and force law (looked up once, not every tick)."""
        laws = {
            Phase.EXCITE: (self._excite_ready, self._excite_force),
            Phase.INERTIA: (self._inertia_ready, self._inertia_force),
            Phase.PUSH: (self._push_ready, self._push_force),
            Phase.DONE: self._done_laws(),
            Phase.HALTED: (self._back, _no_force),
        }
        self._ready, self._law = laws.get(phase, (_never_ready, _no_force))

    def _back(self, k: int, own: OwnEstimates) -> bool:
        """Halted: ready to begin again once every neighbour is alive."""
        return self.team_back

    def _excite_ready(self, k: int, own: OwnEstimates) -> bool:
        return k >= self.kick_ticks and own.settled(Phase.EXCITE) and own.mean_square_offset > 0.0

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
        return own.settled(Phase.INERTIA) and k - self.since >= self.inertia_min_ticks

    def _inertia_force(self, k: int, own: OwnEstimates, velocity: Vec2) -> Vec2:
        """Eq. (14) with the torque's sign for tick ``k`` (records the team's torque); nothing
        once the load is found stuck: the team cannot break it away."""
        if own.stuck:
            self._torque[k] = 0.0
            return (0.0, 0.0)
        self.direction = self._inertia_direction(k, own)
        self._torque[k] = self.direction * self.inertia_torque
        # z_i turned to the middle of [t_k, t_k+1): the torque then averages ±k w.
        z = self._turned_centroid(k, own)
        return inertia_force(self.direction * self.spin_sign * self.inertia_gain, z)

    def _turned_centroid(self, k: int, own: OwnEstimates) -> Vec2:
        """``z_i`` turned to the middle of tick ``k``."""
        return rotate(own.centroid, self._lead(k, own))

    def _lead(self, k: int, own: OwnEstimates) -> float:
        """The load's turn from the estimation instant to the middle of tick ``k`` (rad)."""
        return (own.omega or 0.0) * (k + 0.5 - own.instant) * self.dt

    def _push_ready(self, k: int, own: OwnEstimates) -> bool:
        return own.settled(Phase.PUSH)

    def _push_force(self, k: int, own: OwnEstimates, velocity: Vec2) -> Vec2:
        sign = self.push_sign(k)
        return self._pushing(k, own, velocity, (sign * self.push[0], sign * self.push[1]))

    def push_sign(self, tick: int) -> float:
        """The sign of the common force during tick ``tick`` of the push phase: ``+`` for the
        first ``T/2``, then ``−`` and ``+`` for ``T`` each (``T`` = ``push_flip_s``; always
        ``+`` for ``T = 0``), all the other way round if the family's first sign is ``−``
        (:meth:`_first_push_sign`)."""
        return self._flip_sign(tick - self.entered.get(Phase.PUSH, tick), self.push_flip_ticks)

    def _flip_sign(self, since: int, period: int) -> float:
        """The sign ``since`` ticks into a push reversed every ``period`` ticks: the family's
        first sign for ``period/2``, then the other and the first for ``period`` each (always
        the first for ``period ≤ 0``)."""
        first = self._first_push_sign()
        if period <= 0 or since < period // 2:
            return first
        return -first if (since - period // 2) // period % 2 == 0 else first

    def swinging(self, first: int, last: int) -> bool:
        """Whether ticks ``first..last − 1`` are all in the push's stage for Step 5 (the load
        swinging about its COM as it turns): the whole push, unless a family stages it."""
        return True

    def translating(self, first: int, last: int) -> bool:
        """Whether ticks ``first..last − 1`` are all in the push's stage for Step 7: the whole
        push, unless a family stages it."""
        return True

    def mean_push_added(self, first: int, last: int) -> Vec2:
        """The mean of what each robot added to the common force over ticks ``first..last − 1``
        (zero unless the family damps the push or pushes across it)."""
        added, none = self._added, (0.0, 0.0)
        x = y = 0.0  # each sum from 0.0, term by term (as ``sum`` adds floats up to 3.11)
        for t in range(first, last):
            a = added.get(t, none)
            x += a[0]
            y += a[1]
        return (x / (last - first), y / (last - first))

    def mean_push_sign(self, first: int, last: int) -> float:
        """The mean sign of the common force over ticks ``first..last − 1`` (Steps 5–7's
        input over an interval)."""
        total = 0.0
        for t in range(first, last):
            total += self.push_sign(t)
        return total / (last - first)

    def mean_torque(self, first: int, last: int) -> float:
        """The team's mean torque over ticks ``first..last − 1``: Step 4's input ``±k w``, and
        in Step 5's swing what the family adds beyond a constant torque (the robust family's
        brake near ``max_turn_rate``), in Step 7's stage the torque that holds the turn."""
        torque, total = self._torque, 0.0
        for t in range(first, last):
            total += torque.get(t, 0.0)
        return total / (last - first)

    def forget(self, before: int) -> None:
        """Drop the torque and the force added of tick ``before`` (too old to be asked for)."""
        self._torque.pop(before, None)
        self._added.pop(before, None)

    # ---------------------------------------------------------------- a family's hooks
    def _inertia_direction(self, k: int, own: OwnEstimates) -> float:
        """``+1`` to speed the turn up during tick ``k`` of the inertia phase, ``−1`` to brake."""
        raise NotImplementedError

    def _push_magnitude(self, moment: float) -> float:
        """The common force's size (N) for the push, given ``Ĵ`` (before ``max_force``)."""
        raise NotImplementedError

    def _inertia_size(self, own: OwnEstimates) -> float:
        """``F`` of eq. (14)'s gain ``k = F/√w`` (N): ``inertia_force``."""
        return self.tuning.inertia_force

    def _levels(self, own: OwnEstimates) -> tuple[int, int]:
        """The levels of Step 4's torque and of the push that this robot asks for as it
        becomes ready to leave Step 1 (:attr:`~agent.platform.protocol.Barrier.levels`): none."""
        return (0, 0)

    def _pushing(self, k: int, own: OwnEstimates, velocity: Vec2, push: Vec2) -> Vec2:
        """The force of tick ``k`` of the push, given the common force ``push`` with its sign."""
        return push

    def _first_push_sign(self) -> float:
        """The common force's sign in the first half period of the push."""
        return 1.0

    def _done_laws(self) -> tuple[Ready, Law]:
        """Once done: when the robot is ready to leave ``done``, and the force law."""
        return (_never_ready, self._brake_force)


def _never_ready(k: int, own: OwnEstimates) -> bool:
    return False


def _no_force(k: int, own: OwnEstimates, velocity: Vec2) -> Vec2:
    return (0.0, 0.0)


def _unit(direction: tuple[float, float], magnitude: float) -> Vec2:
    d = math.hypot(direction[0], direction[1])
    return (magnitude * direction[0] / d, magnitude * direction[1] / d)
