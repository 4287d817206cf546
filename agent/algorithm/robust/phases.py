"""The robust estimators' force laws where the families differ.

- *inertia*: the robots' ω differ by their noise, so rather than reverse on ``|ω|`` the torque
  speeds up for ``inertia_flip_s`` and brakes for as long (with ``inertia_brake_level`` of it:
  the floor's friction brakes too), in turn, from the agreed tick on
  (after braking first for ``inertia_brake_s``: with half a flip, ω swings about the turn the
  load had, by half of what speeding up first adds to it, which keeps a compact, light load's
  turn on its floor);
- *push*: the configured ``push_force``, the same for every robot whatever its Ĵ, plus the
  torque that keeps the load turning against the floor's friction: ``f_i += s_ω (τ̂_c / w)
  z_i⊥`` (eq. 14's form: no net force, torque ``s_ω τ̂_c``, ``τ̂_c`` Step 4's estimate when
  the push began), so that Step 5's stage sees a load that turns fast compared with its COM's
  speed, where friction is a torque alone to first order (docs/estimator.md, "On a real floor:
  friction"); the push runs in stages (:meth:`_push_stage`), Step 7's in translation; with
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

from agent.algorithm.estimation.inertia import inertia_force
from agent.algorithm.interfaces import OwnEstimates
from agent.algorithm.phase_machine import Law, PhaseMachine, Ready, _never_ready
from agent.algorithm.safety import saturate
from agent.algorithm.tuning import AgentConfig
from agent.platform.geometry import Vec2, rotate
from agent.platform.protocol import Phase


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
        super().__init__(config, barrier)

    def _inertia_direction(self, k: int, own: OwnEstimates) -> float:
        """Speed up, then brake as long (after braking for ``inertia_brake_s``), from the
        agreed tick on: every robot takes the same decisions whatever the noise on its ω."""
        since = k - self.since - self.brake_ticks
        flips = since // max(1, self.flip_ticks)
        return 1.0 if since >= 0 and flips % 2 == 0 else -self.brake_level

    def _push_magnitude(self, moment: float) -> float:
        return self.tuning.robust.push_force

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
            return self._brake_force(k, own, velocity)
        if stage == -1:
            return self._spin_up(k, own)
        sign = self.push_sign(k)
        push = (sign * self.push[0], sign * self.push[1])
        if stage == 0:
            return self._pushing(k, own, velocity, push)
        b = self.tuning.robust.turn_damping
        damp = inertia_force(-b * (own.omega or 0.0), self._turned_centroid(k, own))
        return self._pushing(k, own, velocity, (push[0] + damp[0], push[1] + damp[1]), keep=False)

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

    def _turned_centroid(self, k: int, own: OwnEstimates) -> Vec2:
        """``z_i`` turned to the middle of tick ``k``."""
        lead = (own.omega or 0.0) * (k + 0.5 - own.instant) * self.dt
        return rotate(own.centroid, lead)

    def _first_push_sign(self) -> float:
        return -1.0 if self.load_changes % 2 else 1.0

    def _pushing(
        self, k: int, own: OwnEstimates, velocity: Vec2, push: Vec2, keep: bool = True
    ) -> Vec2:
        """The push with the torque against friction (with ``keep``) and ``push_damping``'s
        ``−b ṗ̂_G`` added (the damping recorded for Steps 5 and 7)."""
        if keep:
            turning = self._keep_turning(k, own)
            push = (push[0] + turning[0], push[1] + turning[1])
        b = self.tuning.robust.push_damping
        if not b > 0.0 or own.velocity is None:
            return push
        # ṗ_G = ṗ_Ci − ω Q z_i, all three at the estimation instant: every robot then adds the
        # same force, as Steps 5 and 7 take it. (This tick's ṗ_Ci with the instant's ω would
        # differ from robot to robot by the change of ω times z_i, a torque the fits miss.)
        omega, v, z = own.omega or 0.0, own.velocity, own.centroid
        centroid_velocity = (v[0] + omega * z[1], v[1] - omega * z[0])
        force = saturate(
            (push[0] - b * centroid_velocity[0], push[1] - b * centroid_velocity[1]),
            self.tuning.max_force,
        )
        self._damping[k] = (force[0] - push[0], force[1] - push[1])
        return force

    def _keep_turning(self, k: int, own: OwnEstimates) -> Vec2:
        """``s_ω (τ̂_c / w) z_i⊥``, ``z_i`` turned to the middle of tick ``k``: the team's torque
        ``s_ω τ̂_c`` against the floor's friction (zero on a frictionless floor)."""
        w = self.n * own.mean_square_offset
        if not self.friction_used > 0.0 or not w > 0.0:
            return (0.0, 0.0)
        return inertia_force(self.spin_sign * self.friction_used / w, self._turned_centroid(k, own))

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


def _changed(k: int, own: OwnEstimates) -> bool:
    return own.changed
