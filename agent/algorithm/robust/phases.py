"""The robust estimators' force laws where the families differ.

- *excite*: a floor may hold the load against the kick that starts Step 1, and the spin-up
  (a force in proportion to the contacts' relative velocities) has nothing to work on while the
  load is still. So the kick goes on for as long as the load does not move, growing (doubling
  every ``kick_duration_s`` after the first, up to ``max_force``) and taking another seeded
  direction every ``kick_duration_s`` (another wrench), until the robot's contact, or its
  velocity relative to a neighbour's, filtered over :data:`MOVING_TIME_CONSTANT_S`, is faster
  than ``breakaway_speed``, and no longer (a light load kicked for all of ``kick_duration_s``
  was thrown at 1.8 m/s); the kick comes back whenever the load stops. The spin-up's gain is
  the team's mean kick size ``Ā`` times its setting (``spin_gain Ā / kick_force``), so that it
  keeps the load turning against the floor, the same on every robot, and each edge's term is
  bounded alike at both its ends (:meth:`RobustPhases._spin_up_edges`): the terms then cancel
  in pairs, and the spin-up is a torque with no net force, which a robot's own gain or its
  saturation broke (generated load 54, 47 kg: a net force of 9 N and 3.7 m of travel in Step
  1). It speeds the turn up less as ``|ω̂|`` nears ``max_turn_rate``, and the brake
  ``−b ṗ_Ci`` fades out over :data:`EXCITE_BRAKE_S` after the last kick. A load that
  ``max_force``'s kick has not moved within ``breakaway_s`` is held by its floor: the robot
  stops pushing (:attr:`RobustPhases.held`) and the run ends with "cannot break the load
  away". Each robot also filters its
  torque about the centroid in the spin-up, ``τ_i = z_i × f_i``
  (:attr:`RobustPhases.spin_torque`); the team averages it (``mean_spin_torque``,
  :mod:`agent.platform.team`), and once Step 1 has settled (a steady turn) ``τ̂₁ = n |τ̄|`` is
  the floor's friction torque: Step 4's torque and the push's force are sized against it
  (:meth:`RobustPhases._levels`), rounded up to a step the team agrees on at the phase
  barrier;
- *inertia*: the robots' ω differ by their noise, so rather than reverse on ``|ω|`` the torque
  speeds up for ``inertia_flip_s`` and brakes for as long (with ``inertia_brake_level`` of it:
  the floor's friction brakes too), in turn, from the agreed tick on, fading as the turn nears
  ``max_turn_rate`` in the torque's direction (:meth:`RobustPhases._turn_room`)
  (after braking first for ``inertia_brake_s``: with half a flip, ω swings about the turn the
  load had, by half of what speeding up first adds to it, which keeps a compact, light load's
  turn on its floor);
- *push*: the configured ``push_force``, the same for every robot whatever its Ĵ, plus the
  torque that keeps the load turning against the floor's friction: ``f_i += s_ω (τ̂_c / w)
  z_i⊥`` (eq. 14's form: no net force, torque ``s_ω τ̂_c``, ``τ̂_c`` Step 4's estimate when
  the push began), so that Step 5's stage sees a load that turns fast compared with its COM's
  speed, where friction is a torque alone to first order (docs/estimator.md, "On a real floor:
  friction"), less a brake as the turn nears ``max_turn_rate`` (:meth:`RobustPhases.
  _keep_turning`: the push, off the COM, swings the turn); the push runs in stages
  (:meth:`_push_stage`), Step 7's in translation, where the torque ``−n ẑ_C × c`` makes the
  common force ``c`` act through the COM that Step 5 found rather than the contacts'
  centroid, and the turn is damped (:meth:`RobustPhases._not_turning`), and the common force
  goes along ``f`` and across it (:meth:`RobustPhases._translation_push`: the turn the team
  holds against then measures ``z_C`` again, :mod:`agent.algorithm.robust.hold_fit`); with
  ``push_damping = b`` each robot also adds ``−b ṗ̂_G``, the damping of the centroid's velocity
  at the estimation instant (which every robot estimates alike), so that a light load's speed
  stays within about ``f/b`` and a heavy one's drift dies out (Steps 5 and 7 take the force as
  commanded); after an odd number of load changes the push begins the other way, swinging the
  load back towards where it started;
- *done* (with ``change_threshold`` > 0): the team keeps watching the load, in cycles on the
  agreed clock: a gap of ``monitor_gap_s`` in which each robot damps the COM's velocity,
  ``−b ṗ̂_C`` (Step 6's estimate: the load loses its drift), and turns the load up to
  ``pendulum_spin`` (a probe tells a moved COM by the turn), then a *probe* of
  ``probe_s = T``, the push's common force ``+f`` for ``T/4``, ``−f`` for ``T/2`` and ``+f``
  for ``T/4``: the COM's velocity and place come back to where they were, after a swing of
  ``n f T²/16m``; every other probe swings the other way. A robot
  whose probe finds the load no longer the one estimated (:mod:`agent.algorithm.robust.
  load_change`) is ready to leave ``done``, and the team restarts at ``inertia`` at an agreed
  tick (:mod:`agent.algorithm.coordination`).
"""

from __future__ import annotations

import math

from agent.algorithm.estimation.excitation import capped_spin_up_force, kick_force
from agent.algorithm.estimation.inertia import inertia_force
from agent.algorithm.interfaces import OwnEstimates
from agent.algorithm.phase_machine import Law, PhaseMachine, Ready, _never_ready
from agent.algorithm.safety import saturate
from agent.algorithm.tuning import AgentConfig
from agent.platform.geometry import Vec2, rotate
from agent.platform.protocol import HELD_LEVEL, Phase

MOVING_TIME_CONSTANT_S = 0.1
"""s: the time constant of the first-order filters of the robot's contact velocity and of its
relative velocities that tell whether the load moves (Step 1's kick): with ``σ_v`` = 1 cm/s
per sample at 100 Hz, a relative velocity's filtered noise is about 0.3 cm/s a component,
a sixteenth of the default ``breakaway_speed``."""
SPIN_TORQUE_TIME_CONSTANT_S = 1.0
"""s: the time constant of the first-order filter of the robot's torque ``z_i × f_i`` in Step
1's spin-up (:attr:`RobustPhases.spin_torque`): Step 1 ends once the turn has been steady for
``settle_window_s``, when the team's torque is the floor's friction torque."""
INERTIA_FRICTION_MARGIN = 4.0
"""Step 4's torque is at least this many times the friction torque that Step 1's spin-up met:
speeding up, ``T − τ_c``, and braking at ``inertia_brake_level`` = 0.5, ``T/2 + τ_c``, are then
equal, and the turn neither dies nor grows from flip to flip."""
LEAST_FRICTION_MARGIN = 2.0
"""Step 4's torque within ``max_force`` at least this many times ``τ̂₁``, or the team stops
with the verdict that it cannot break the load away: braking, the floor and the brake together
would stop the turn at every flip, and the load would stick and slip, which Step 4's fit does
not model (``pallet.toml`` with robots of 80 N, 86 N m against its 41 N m: the load turned
at up to 6.2 rad/s, three times its floor's ``|ω|``, and its J's interval was ±30 %)."""
PUSH_FRICTION_MARGIN = 4.0
"""The push's common force makes the team's ``n f`` at least this many times the floor's
friction force, taken as ``τ̂₁ / r`` with ``r = √(w/n)`` the contacts' root-mean-square
distance from their centroid (the supports' friction radius ``c`` is less for a load pushed at
its rim: 0.61 of it on generated load 38): the translation of Step 7's stage then slides
the load, and its velocity passes quickly through zero at each reversal, where the fit's
direction of motion is the noise's for as long as the speed is within it (with 3, generated
load 49, 39 kg on μ = 1.3 %: m̂ 6.7 % off; with 4, 0.06 %). More speeds the load up beyond
its floor where the friction is high: with 5, the paper's load on casters at μ = 5 % reached
2.6 m/s, with 4, 1.7 m/s (the push reverses every ``push_flip_s``, and its speed grows by
``(PUSH_FRICTION_MARGIN − 1) μ g`` a second)."""
PLAUSIBLE_TURNS = 4.0
"""Step 1's spin-up fades as ``|ω̂|`` nears ``max_turn_rate`` (:meth:`RobustPhases._turn_room`),
unless ``|ω̂|`` is more than this many times it: the arcs' first guesses, before the load has
turned, divide by a distance of almost nothing (hundreds of rad/s)."""
EXCITE_BRAKE_S = 5.0
"""s: Step 1's spin-up adds the brake ``−b ṗ_Ci`` (``brake_gain``) after the robot's last kick,
fading linearly from whole to none over this long: it takes out the kick's drift, and no more.
Braking every contact's velocity makes the load turn about the contacts' centroid rather than
its COM; a COM far from that centroid then orbits it and meets the floor's friction at that arm,
which Step 1 measures as the floor's friction torque (generated load 47, 10.5 kg under 3 robots,
its COM 1.8 m from their centroid: 3.9 m of travel in Step 1 and 7.9 N m measured for its
1.33 N m, the verdict that the team could not move it). Cut off 3 s after the kick, the brake
left the COM with the orbit's speed, a drift that no friction takes out on a frictionless floor
(the paper's load on casters, ``μ`` = 0, seed 28: 8.7 m of travel); faded over 5 s, the turn's
centre moves to the COM slowly enough that most of the drift goes with it (seeds 28, 32 and 33:
within 2.8 m; seed 12 keeps 0.3 m/s and leaves its floor), and the brake is gone before the
turn Step 1 measures (load 47, faded over 8 s: the verdict again)."""
APPLIED_SHARE = 0.5
"""A drive that applied less than this share of its commanded kick (:attr:`~agent.algorithm.
interfaces.OwnEstimates.drive_share`) did not pass the force on: a load it did not move is not
found held by the floor."""
TURN_STOP_SHARE = 0.2
"""The brake stage before Step 7's translation stops the load's turn with the time constant
``TURN_STOP_SHARE × translate_brake_s`` (``e⁻⁵`` of it left by the end): the contacts' brake
alone, ``−b ṗ_Ci``, gives ``J / (b w)``, seconds for a heavy load, which then turned while it
translated, its supports sliding across its path with less friction than ``μ m g``."""
TURN_RATE_TAPER = 0.25
"""Step 4's torque is whole while the load turns slower than ``1 − TURN_RATE_TAPER`` of
``max_turn_rate`` in the torque's own direction, and none at ``max_turn_rate``: every robot's
``ω̂`` is the team's (:mod:`agent.algorithm.robust.rotation`), so the robots fade their torques
alike, and each records the torque it assumes the team applied."""
PUSH_HEADROOM = 0.5
"""The push's common force is at most this share of ``max_force``: Step 7's stage adds to it
the forces that move its line of action to the COM and damp the turn and the drift, which the
fits take as applied (a common force at ``max_force`` left them none)."""
ACROSS_SCALE = 2.0 / math.sqrt(5.0)
"""Step 7's push along ``f`` and across it (``s'(t) Q f`` at half the period) are both this
share of the push: the load's speed swings by ``n f T / 2m`` along ``f`` and half that
across, so that the two together swing it no faster than the push along ``f`` alone,
``√(1 + 1/4) ACROSS_SCALE = 1``."""
LEVELS_PER_DOUBLING = 4
"""Step 4's ``F`` and the push's ``f`` are their settings times ``2^(q/4)``, ``q`` the level
the team agreed on (the largest any robot asked for, :mod:`agent.algorithm.coordination`):
the robots' consensus on ``τ̄`` agrees to far better than that step, but not always on which
side of a step's boundary it lies (a generated load of 8 robots took two levels, ``Ĵ`` 12 %
off on the robots that assumed the lower)."""


class RobustPhases(PhaseMachine):
    """The phase machine of the robust estimators."""

    def __init__(self, config: AgentConfig, barrier=None):
        robust = config.tuning.robust
        dt = config.period_s
        self.flip_ticks = round(robust.inertia_flip_s / dt)
        self.brake_ticks = round(robust.inertia_brake_s / dt)
        self.brake_level = robust.inertia_brake_level
        self.spin_up_ticks = round(robust.spin_up_s / dt)
        self.pendulum_ticks = self.spin_up_ticks + round(robust.pendulum_s / dt)
        self.pendulum_flip_ticks = round(robust.pendulum_flip_s / dt)
        self.translate_from = self.pendulum_ticks + round(robust.translate_brake_s / dt)
        """Ticks into the push when its stages end: Step 5's, then the brake's."""
        self.monitoring = robust.change_threshold > 0.0
        """Whether the team probes the load once done (see the module docstring)."""
        self.probe_ticks = 4 * max(1, round(robust.probe_s / (4 * dt)))
        """A probe's length: a multiple of 4 ticks."""
        self.gap_ticks = max(1, round(robust.monitor_gap_s / dt))
        self.monitor_ticks = self.gap_ticks + self.probe_ticks
        """A monitoring cycle: the gap, then a probe."""
        tuning = config.tuning
        self.kick_growth = 2.0 ** (dt / tuning.kick_duration_s)
        """The kick's growth a tick while the load does not move (doubling every
        ``kick_duration_s``)."""
        self.breakaway_speed = robust.breakaway_speed
        self.held_ticks = round(robust.breakaway_s / dt)
        self._filter = -math.expm1(-dt / MOVING_TIME_CONSTANT_S)
        self._torque_filter = -math.expm1(-dt / SPIN_TORQUE_TIME_CONSTANT_S)
        self._filtered: dict[int, Vec2] = {}
        """The filtered velocities of the breakaway test: the contact's (key 0), each edge's."""
        self.seed, self.robot = config.seed, config.robot
        self._still = 0
        """Ticks the load has been still after the kick's first ``kick_duration_s``: each
        ``kick_duration_s`` of them the kick takes another direction."""
        self._still_at_most = 0
        """Ticks the kick has been at ``max_force`` with the load still."""
        self.held = False
        """Whether ``max_force``'s kick has not moved the load within ``breakaway_s``: the
        floor holds it (or the drive does not pass the force on: :attr:`held_because`), and
        this robot pushes no more."""
        self.spin_torque = 0.0
        """N m: ``τ_i``, this robot's torque ``z_i × f_i`` about the centroid in Step 1's
        spin-up, filtered over :data:`SPIN_TORQUE_TIME_CONSTANT_S`."""
        self.push_level = 1.0
        """The push's ``f`` is ``push_force`` times this (fixed at the start of Step 4)."""
        self.excite_brake_ticks = max(round(EXCITE_BRAKE_S / dt), 1)
        self.degree = max(len(config.neighbours), 1)
        self._kicked = 0
        """The last tick of Step 1 at which this robot kicked."""
        super().__init__(config, barrier)

    # ---------------------------------------------------------------- Step 1: break away
    def _excite_force(self, k: int, own: OwnEstimates, velocity: Vec2) -> Vec2:
        """The kick, growing for as long as the load does not move, else the spin-up
        (:meth:`_spin_up_edges`) with the brake fading out over :data:`EXCITE_BRAKE_S` after
        the last kick; nothing once the floor is found to hold the load."""
        moving = self._moving(own, velocity)
        t = self.tuning
        if moving:
            spin = self._spin_up_edges(own)
            share = 1.0 - (k - self._kicked) / self.excite_brake_ticks
            if share > 0.0:
                brake = self._brake_force(k, own, velocity)
                force = saturate(
                    (spin[0] + share * brake[0], spin[1] + share * brake[1]), t.max_force
                )
            else:
                force = spin
            z = own.centroid
            self.spin_torque += self._torque_filter * (
                z[0] * force[1] - z[1] * force[0] - self.spin_torque
            )
            return force
        if k >= self.kick_ticks:
            self._grow_kick(own)
            still = self._still + 1
            self._still = still
            attempt, left = divmod(still, self.kick_ticks)
            if left == 0:  # another direction, another wrench
                self.kick = kick_force(self.seed, self.robot, t.kick_force, attempt)
        self._kicked = k
        scale = self.kick_level / t.kick_force
        return (scale * self.kick[0], scale * self.kick[1])

    def _spin_up_edges(self, own: OwnEstimates) -> Vec2:
        """The spin-up (:func:`~agent.algorithm.estimation.excitation.capped_spin_up_force`)
        with the gain ``spin_gain Ā / kick_force``, ``Ā`` the team's mean kick size
        (``mean_kick_level``), and each edge's term within ``max_force / max(d_i, d_j)``: the
        same gain and cap at both ends of every edge, so that the terms cancel in pairs. The
        terms that speed the turn up fade as ``|ω̂|`` (the team's) nears ``max_turn_rate``
        (:meth:`_turn_room`; a light, compact load spun at 2.6 rad/s), unless ``|ω̂|`` is
        beyond :data:`PLAUSIBLE_TURNS` times it."""
        t = self.tuning
        level = max(own.mean_kick_level, t.kick_force)
        gain = t.spin_gain * level / t.kick_force
        own_degree = self.degree
        edges = (
            (zdot, t.max_force / max(own_degree, self.degrees.get(j, own_degree)))
            for j, zdot in own.zdot.items()
        )
        omega = abs(own.omega or 0.0)
        drive = self._turn_room(omega) if omega < PLAUSIBLE_TURNS * t.robust.max_turn_rate else 1.0
        return capped_spin_up_force(gain, t.spin_speed, edges, drive)

    def _grow_kick(self, own: OwnEstimates) -> None:
        """One tick of the load still after the kick's first ``kick_duration_s``: the kick
        grows, up to ``max_force``, where ``breakaway_s`` of it finds the load held: by the
        floor, unless the robot's drive applied less than :data:`APPLIED_SHARE` of the kick
        (its sensor's force against its command): then the force did not reach the load."""
        most = self.tuning.max_force
        if self.kick_level < most:
            self.kick_level = min(most, self.kick_level * self.kick_growth)
            return
        self._still_at_most += 1
        if self._still_at_most >= self.held_ticks:
            self.held = True
            kick = (
                f"Step 1's kick, grown to max_force = {most:g} N a robot, did not move the load"
                f" within breakaway_s = {self.tuning.robust.breakaway_s:g} s"
            )
            share = own.drive_share
            if share is not None and share < APPLIED_SHARE:
                self.held_because = (
                    f"{kick}, but robot {self.robot}'s drive applied only {100 * share:.0f} % of"
                    " it (its sensor's force against its command): the force did not reach the"
                    " load"
                )
            else:
                self.held_because = f"{kick}: the floor holds it"

    def _moving(self, own: OwnEstimates, velocity: Vec2) -> bool:
        """Whether the filtered contact velocity, or a filtered relative velocity, is faster
        than ``breakaway_speed`` (each filter first-order, :data:`MOVING_TIME_CONSTANT_S`)."""
        a, filtered = self._filter, self._filtered
        fastest = 0.0
        for key, (vx, vy) in ((0, velocity), *own.zdot.items()):
            fx, fy = filtered.get(key, (0.0, 0.0))
            fx, fy = fx + a * (vx - fx), fy + a * (vy - fy)
            filtered[key] = (fx, fy)
            fastest = max(fastest, fx * fx + fy * fy)
        return fastest > self.breakaway_speed**2

    def _levels(self, own: OwnEstimates) -> tuple[int, int]:
        """The levels this robot asks for (the team takes the largest, :mod:`agent.algorithm.
        coordination`), from the floor's friction torque met by Step 1's spin-up,
        ``τ̂₁ = n |τ̄|`` (the team's mean torque ``mean_spin_torque``): Step 4's ``F`` at least
        :data:`INERTIA_FRICTION_MARGIN` ``τ̂₁ / √w``, and the push's ``n f`` at least
        :data:`PUSH_FRICTION_MARGIN` times the friction force ``τ̂₁ / √(w/n)``, each in quarter
        doublings of its setting (``inertia_force``, ``push_force``); :data:`~agent.platform.
        protocol.HELD_LEVEL` for Step 4 if that ``F`` would be more than ``max_force``
        :data:`INERTIA_FRICTION_MARGIN` / :data:`LEAST_FRICTION_MARGIN`."""
        t = self.tuning
        w = self.n * own.mean_square_offset
        if not w > 0.0:
            return (0, 0)
        friction = self.n * abs(own.mean_spin_torque)
        push = PUSH_FRICTION_MARGIN * friction / math.sqrt(self.n * w)
        needed = INERTIA_FRICTION_MARGIN * friction / math.sqrt(w)
        if needed > t.max_force * INERTIA_FRICTION_MARGIN / LEAST_FRICTION_MARGIN:
            inertia = HELD_LEVEL  # Step 4 would stall in every brake: stick-slip
        else:
            inertia = _quarter_doublings(needed / t.inertia_force)
        return (inertia, _quarter_doublings(push / t.robust.push_force))

    def _inertia_size(self, own: OwnEstimates) -> float:
        """``F`` of Step 4's torque ``F √w``: ``inertia_force`` at the team's agreed level
        (:meth:`_levels`), within ``max_force``; also fixes the push's level
        (:meth:`_push_magnitude`). At :data:`~agent.platform.protocol.HELD_LEVEL` the robot
        pushes no more: some robot found that the floor's friction torque asks more of Step 4
        than ``max_force`` gives."""
        t = self.tuning
        inertia, push = self.barrier.levels
        self.push_level = _level(push)
        if inertia >= HELD_LEVEL:
            w = self.n * own.mean_square_offset
            friction = self.n * abs(own.mean_spin_torque)
            self.held = True
            # The level is the largest any robot asked for when it became ready: this
            # robot's own estimate now may be less than the one that decided.
            self.held_because = (
                f"the floor's friction torque met in Step 1, {friction:.3g} N m by this robot's"
                " estimate now (the team sizes Step 4 on the largest any robot measured when it"
                f" was ready), asks more of Step 4 than max_force = {t.max_force:g} N a robot"
                f" gives ({t.max_force * math.sqrt(w):.3g} N m, less than"
                f" {LEAST_FRICTION_MARGIN:g} times the largest): turned back and forth by it,"
                " the load would stick and slip, which Step 4's fit does not model, so the team"
                " stops pushing (the floor may still give way to that torque)"
            )
            return t.max_force
        return min(t.inertia_force * _level(inertia), t.max_force)

    def _inertia_direction(self, k: int, own: OwnEstimates) -> float:
        """Speed up, then brake as long (after braking for ``inertia_brake_s``), from the
        agreed tick on: every robot takes the same decisions whatever the noise on its ω."""
        since = k - self.since - self.brake_ticks
        flips = since // max(1, self.flip_ticks)
        direction = 1.0 if since >= 0 and flips % 2 == 0 else -self.brake_level
        along = math.copysign(1.0, direction) * self.spin_sign * (own.omega or 0.0)
        return direction * self._turn_room(along)

    def _turn_room(self, along: float) -> float:
        """The share of Step 4's torque applied while the load turns at ``along`` rad/s in
        the torque's direction: 1 up to ``1 − TURN_RATE_TAPER`` of ``max_turn_rate``, falling
        linearly to 0 at it (:data:`TURN_RATE_TAPER`)."""
        most = self.tuning.robust.max_turn_rate
        return min(max((most - along) / (TURN_RATE_TAPER * most), 0.0), 1.0)

    def _push_magnitude(self, moment: float) -> float:
        """``push_force`` at the agreed level, within :data:`PUSH_HEADROOM` of ``max_force``."""
        t = self.tuning
        return min(t.robust.push_force * self.push_level, PUSH_HEADROOM * t.max_force)

    # ---------------------------------------------------------------- the push's stages
    def _push_stage(self, tick: int) -> int:
        """−1 while the load is turned up, 0 while it swings (Step 5), 1 while it is braked,
        2 while it translates (Step 7), by the ticks since the push began: every robot changes
        stage together."""
        since = tick - self.entered.get(Phase.PUSH, tick)
        if since < self.spin_up_ticks:
            return -1
        if since < self.pendulum_ticks:
            return 0
        return 1 if since < self.translate_from else 2

    def swinging(self, first: int, last: int) -> bool:
        return self._push_stage(first) == 0 and self._push_stage(last - 1) == 0

    def translating(self, first: int, last: int) -> bool:
        return self._push_stage(first) == 2

    def push_sign(self, tick: int) -> float:
        """The common force's sign: as the push's (``+f`` for ``T/2``, then ``−f`` and ``+f``
        for ``T`` each) from the start of each of its pushing stages, 0 while braking."""
        stage = self._push_stage(tick)
        if stage in (-1, 1):
            return 0.0
        if stage == 2:
            return super().push_sign(tick - self.translate_from)
        since = tick - self.entered.get(Phase.PUSH, tick) - self.spin_up_ticks
        return self._flip_sign(since, self.pendulum_flip_ticks)

    def _push_force(self, k: int, own: OwnEstimates, velocity: Vec2) -> Vec2:
        """Each stage's law: the swinging push (with the torque against friction), the brake,
        the translating push with the load's turn damped."""
        stage = self._push_stage(k)
        if stage == 1:
            brake, stop = self._brake_force(k, own, velocity), self._stop_turning(k, own)
            return (brake[0] + stop[0], brake[1] + stop[1])
        if stage == -1:
            return self._spin_up(k, own)
        sign = self.push_sign(k)
        push = (sign * self.push[0], sign * self.push[1])
        if stage == 0:
            return self._pushing(k, own, velocity, push)
        return self._pushing(k, own, velocity, push, keep=False)

    def _translation_push(self, k: int, push: Vec2) -> Vec2:
        """Step 7's common force at tick ``k``, whose part along ``f`` is ``push``: that part
        and ``s'(t) Q f`` (``s'`` reversed at half the push's period, :meth:`_flip_sign`), both
        scaled by :data:`ACROSS_SCALE`, or less to keep their sum within
        :data:`PUSH_HEADROOM` of ``max_force``: the load's turn then measures both components
        of ``z_C`` (:mod:`agent.algorithm.robust.hold_fit`)."""
        fx, fy = self.push
        size = math.hypot(fx, fy)
        most = PUSH_HEADROOM * self.tuning.max_force
        scale = min(ACROSS_SCALE, most / (math.sqrt(2.0) * size)) if size > 0.0 else 1.0
        since = k - self.entered.get(Phase.PUSH, k) - self.translate_from
        across = scale * self._flip_sign(since, self.push_flip_ticks // 2)
        return (scale * push[0] - across * fy, scale * push[1] + across * fx)

    def _spin_up(self, k: int, own: OwnEstimates) -> Vec2:
        """The torque ``s_ω (τ̂_c + Ĵ (ω* − |ω̂|) / spin_up_s)`` as eq. (14)'s forces, within
        Step 4's torque ``±k w`` (each way: the turn brought up to ``pendulum_spin`` against the
        floor's friction, and never driven past it however far off ``τ̂_c`` or ``Ĵ``)."""
        w = self.n * own.mean_square_offset
        robust = self.tuning.robust
        if not w > 0.0 or self.moment_used is None:
            return (0.0, 0.0)
        short = robust.pendulum_spin - abs(own.omega or 0.0)
        torque = self.friction_used + self.moment_used * short / max(robust.spin_up_s, self.dt)
        most = abs(self.inertia_torque)  # no more than Step 4's torque, either way
        torque = min(max(torque, -most), most)
        return inertia_force(self.spin_sign * torque / w, self._turned_centroid(k, own))

    def _stop_turning(self, k: int, own: OwnEstimates) -> Vec2:
        """The torque ``−Ĵ ω̂ / τ_s`` as eq. (14)'s forces (``τ_s`` a fifth of
        ``translate_brake_s``: :data:`TURN_STOP_SHARE`), within Step 4's torque: the brake
        stage leaves the load still, however large its ``J``, for Step 7's translation."""
        w = self.n * own.mean_square_offset
        if not w > 0.0 or self.moment_used is None:
            return (0.0, 0.0)
        stop_s = max(TURN_STOP_SHARE * self.tuning.robust.translate_brake_s, self.dt)
        torque = -self.moment_used * (own.omega or 0.0) / stop_s
        most = abs(self.inertia_torque)
        torque = min(max(torque, -most), most)
        return inertia_force(torque / w, self._turned_centroid(k, own))

    def _first_push_sign(self) -> float:
        return -1.0 if self.load_changes % 2 else 1.0

    def _pushing(
        self, k: int, own: OwnEstimates, velocity: Vec2, push: Vec2, keep: bool = True
    ) -> Vec2:
        """The push with the torque against friction (with ``keep``; else Step 7's,
        :meth:`_not_turning`) and ``push_damping``'s ``−b ṗ̂_G`` added (the damping recorded
        for Steps 5 and 7). In Step 7's stage the common force, which the fit takes as
        commanded, is applied whole within ``max_force``, and the torque's forces take what it
        leaves (scaled down together: a generated load pushed at 9.5 N a robot under
        ``max_force`` = 10 N had its common force cut at every tick, m̂ 4 % off)."""
        b = self.tuning.robust.push_damping
        damped = b > 0.0 and own.velocity is not None
        damping = (0.0, 0.0)
        nominal = push  # the fits' s(t) f: what the robot adds beyond it is recorded
        if damped:
            # ṗ_G = ṗ_Ci − ω Q z_i, all three at the estimation instant: every robot then adds
            # the same force, as Steps 5 and 7 take it. (This tick's ṗ_Ci with the instant's ω
            # would differ from robot to robot by the change of ω times z_i, a torque the fits
            # miss.)
            omega, v, z = own.omega or 0.0, own.velocity, own.centroid
            damping = (-b * (v[0] + omega * z[1]), -b * (v[1] - omega * z[0]))
        most = self.tuning.max_force
        if not keep:  # the common force first, the torque within what max_force leaves
            push = self._translation_push(k, push)
            common = saturate((push[0] + damping[0], push[1] + damping[1]), most)
            self._added[k] = (common[0] - nominal[0], common[1] - nominal[1])
            turning, torque = self._not_turning(k, own, common)
            part = _within(common, turning, most)
            self._torque[k] = part * torque
            return (common[0] + part * turning[0], common[1] + part * turning[1])
        turning = self._keep_turning(k, own, record=True)
        push = (push[0] + turning[0], push[1] + turning[1])
        if not damped:
            return push
        force = saturate((push[0] + damping[0], push[1] + damping[1]), most)
        self._added[k] = (force[0] - push[0], force[1] - push[1])
        return force

    def _not_turning(self, k: int, own: OwnEstimates, common: Vec2) -> tuple[Vec2, float]:
        """Step 7's stage: ``(τ/w) z_i⊥`` (eq. 14's form, no net force) with
        ``τ = −n ẑ_C × c − b ω̂ w``: the team's common force ``c`` (the push and its damping),
        which acts at the contacts' centroid, ``n ẑ_C × c`` about the COM, then acts through the
        COM that Step 5 found, and ``turn_damping = b`` damps what turn is left, so that the
        load translates (``z_i`` and ``ẑ_C`` turned to the middle of tick ``k``); and
        ``−n ẑ_C × c`` (N m), which :meth:`_pushing` records, as applied, for the team's (Step
        7's ``z_C`` from the turn it holds, :mod:`agent.algorithm.robust.hold_fit`, which
        takes the damping from the angle: every robot's ``ω̂`` has its own noise)."""
        w = self.n * own.mean_square_offset
        if not w > 0.0:
            return (0.0, 0.0), 0.0
        z_c = own.com_offset_now
        push_torque = 0.0
        if z_c is not None:
            z_c = rotate(z_c, self._lead(k, own))
            push_torque = self.n * (z_c[0] * common[1] - z_c[1] * common[0])
        b = self.tuning.robust.turn_damping
        gain = -b * (own.omega or 0.0) - push_torque / w
        return inertia_force(gain, self._turned_centroid(k, own)), -push_torque

    def _keep_turning(self, k: int, own: OwnEstimates, record: bool = False) -> Vec2:
        """``(τ/w) z_i⊥``, ``z_i`` turned to the middle of tick ``k``, with the team's torque
        ``τ = s_ω τ̂_c`` against the floor's friction (zero on a frictionless floor) while the
        load turns slower than ``1 − TURN_RATE_TAPER`` of ``max_turn_rate`` in the spin's
        direction, less a brake that grows linearly from there to ``τ̂_c`` plus Step 4's torque
        at ``max_turn_rate`` (and beyond): the push, acting off the COM, swings the turn, by
        more than the floor's friction on a light load pushed hard (generated load 22, 3.5 kg
        on μ = 2.7 %: 2.2 rad/s without the brake, 1.6 with it). With ``record`` (Step 5's
        swing) the brake's torque is recorded as the team's for tick ``k``
        (:meth:`mean_torque`): Step 5's fit takes its turn out of the angle."""
        w = self.n * own.mean_square_offset
        if not w > 0.0:
            return (0.0, 0.0)
        brake = 1.0 - self._turn_room(self.spin_sign * (own.omega or 0.0))
        braking = brake * (self.friction_used + abs(self.inertia_torque))
        if record:
            self._torque[k] = -self.spin_sign * braking
        torque = self.friction_used - braking
        if torque == 0.0:
            return (0.0, 0.0)
        return inertia_force(self.spin_sign * torque / w, self._turned_centroid(k, own))

    # ---------------------------------------------------------------- once done: probes
    def _done_laws(self) -> tuple[Ready, Law]:
        if self.monitoring:
            return (_changed, self._monitor_force)
        return (_never_ready, self._brake_force)

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
        """A probe's common force with the torque that keeps the load turning against the
        floor's friction, or the gap's damping of the COM's velocity with the load turned up
        to ``pendulum_spin`` (a probe tells a moved COM by the turn: Step 7's stage left the
        load still)."""
        sign = self.probe_sign(k)
        if sign:
            keep = self._keep_turning(k, own)
            return (sign * self.push[0] + keep[0], sign * self.push[1] + keep[1])
        v = own.com_velocity or velocity
        b = self.tuning.brake_gain
        spin = self._spin_up(k, own)
        return (-b * v[0] + spin[0], -b * v[1] + spin[1])


def _within(base: Vec2, extra: Vec2, most: float) -> float:
    """The largest ``a`` in [0, 1] with ``‖base + a extra‖ ≤ most`` (``‖base‖ ≤ most``)."""
    ee = extra[0] * extra[0] + extra[1] * extra[1]
    be = base[0] * extra[0] + base[1] * extra[1]
    room = most * most - base[0] * base[0] - base[1] * base[1]
    if ee + 2.0 * be <= room:
        return 1.0
    return max(0.0, min(1.0, (-be + math.sqrt(max(be * be + ee * room, 0.0))) / ee))


def _changed(k: int, own: OwnEstimates) -> bool:
    return own.changed


def _quarter_doublings(ratio: float) -> int:
    """The least ``q ≥ 0`` with ``2^(q/4) ≥ ratio`` (:data:`LEVELS_PER_DOUBLING`), below
    :data:`~agent.platform.protocol.HELD_LEVEL`."""
    if not ratio > 1.0:
        return 0
    q = math.ceil(LEVELS_PER_DOUBLING * math.log2(ratio) - 1e-9)
    return min(q, HELD_LEVEL - 1)


def _level(q: int) -> float:
    """``2^(q/4)``: the factor of a level on its setting."""
    return 2.0 ** (q / LEVELS_PER_DOUBLING)
