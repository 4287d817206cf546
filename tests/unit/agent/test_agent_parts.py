"""The agent's parts on scripted input: no plant, every message and sample built by hand.

- :class:`~agent.algorithm.inbox.Inbox`: which instants can be estimated, early, late and
  bad messages;
- :class:`~agent.algorithm.phase_machine.PhaseMachine`: the switch tick the team agrees on, a halt
  spreading through messages, and the force laws (kick, spin-up, inertia torque with its
  reversals, push), on scripted estimates of its own robot;
- :class:`~agent.algorithm.agent.Agent`: the parts composed, on a rigid body's exact contact
  velocities.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
import pytest

from agent.algorithm.agent import Agent
from agent.algorithm.estimation.excitation import kick_force, spin_up_force
from agent.algorithm.families import FAMILIES
from agent.algorithm.inbox import HISTORY_TICKS, Inbox
from agent.algorithm.paper.tuning import PaperTuning
from agent.algorithm.phase_machine import PhaseMachine
from agent.algorithm.robust.phases import ACROSS_SCALE, PUSH_HEADROOM, TURN_STOP_SHARE
from agent.algorithm.robust.tuning import RobustTuning
from agent.algorithm.tuning import PAPER_REFERENCE, AgentConfig, AgentTuning, Estimators
from agent.platform.config import from_table
from agent.platform.geometry import Vec2, cross, rotate
from agent.platform.protocol import Barrier, Measurement, Phase, Share
from agent.platform.resend import ResendTimeout
from agent.platform.team import ConsensusState

DT = 0.01
TUNING = replace(
    from_table(AgentTuning, PAPER_REFERENCE, "agent"), kick_duration_s=0.05, switch_margin_ticks=2
)


def measurement(robot: int, tick: int, velocity: Vec2 = (0.0, 0.0)) -> Measurement:
    return Measurement(robot, tick, tick * DT, velocity, (0.0, 0.0))


def share(sender: int, tick: int, velocity: Vec2 = (0.0, 0.0), **fields) -> Share:
    return Share(sender=sender, tick=tick, velocity=velocity, degree=1, **fields)


# --------------------------------------------------------------------------------------------
# inbox
# --------------------------------------------------------------------------------------------


def test_inbox_estimation_instant_waits_for_every_neighbour():
    inbox = Inbox((2, 3))
    assert inbox.receive(measurement(1, 0), []) == -1  # nobody heard yet
    assert inbox.receive(measurement(1, 1), [share(2, 0), share(3, 0)]) == 0
    # Robot 3's message of tick 1 is late: the instant stays at 0.
    assert inbox.receive(measurement(1, 2), [share(2, 1, (0.5, 0.0))]) == 0
    # It arrives with the next one: the instant jumps to k − 1, 1 and 2 to be caught up.
    late = [share(3, 2, (0.0, 3.0)), share(3, 1, (0.0, 2.0)), share(2, 2)]
    assert inbox.receive(measurement(1, 3, (1.0, 1.0)), late) == 2
    assert inbox.neighbour_velocity[3] == {0: (0.0, 0.0), 1: (0.0, 2.0), 2: (0.0, 3.0)}
    assert inbox.neighbour_velocity[2][1] == (0.5, 0.0)
    assert inbox.own_velocity[3] == (1.0, 1.0)
    assert inbox.latest[3].tick == 2  # the older one arrived after it: not "latest"
    assert inbox.rejected == 0


def test_inbox_early_messages_wait_and_bad_ones_are_rejected():
    inbox = Inbox((2,))
    early = share(2, 5, (1.0, 0.0))  # stamped at the current tick: from a faster clock
    far = share(2, 5 + HISTORY_TICKS)
    bad = [
        share(2, 4, (math.nan, 0.0)),
        share(2, 4, consensus=ConsensusState(centroid_offset=(math.inf, 0.0))),
        share(2, 4, consensus=ConsensusState(mean_square_offset=math.nan)),
        share(3, 4),  # not a neighbour
        far,
    ]
    assert inbox.receive(measurement(1, 5), [early, *bad]) == -1
    assert inbox.rejected == len(bad)
    assert 5 not in inbox.neighbour_velocity[2] and not inbox.latest
    assert inbox.receive(measurement(1, 6), []) == 5  # used from the tick after its own
    assert inbox.neighbour_velocity[2][5] == (1.0, 0.0)
    assert inbox.latest[2] is early and inbox.rejected == len(bad)


def test_inbox_forgets_old_ticks():
    inbox = Inbox((2,))
    for k in range(3):
        inbox.receive(measurement(1, k), [share(2, k - 1)] if k else [])
    inbox.forget(0)
    assert sorted(inbox.own_velocity) == [1, 2] and sorted(inbox.neighbour_velocity[2]) == [1]


# --------------------------------------------------------------------------------------------
# phase machine
# --------------------------------------------------------------------------------------------


@dataclass
class Own:
    """Scripted estimates of the machine's own robot (what it reads of them:
    :class:`agent.algorithm.interfaces.OwnEstimates`)."""

    instant: int = -1
    omega: float | None = None
    measured: int | None = None
    zdot: dict[int, Vec2] = field(default_factory=dict)
    velocity: Vec2 | None = None
    ready: set[Phase] = field(default_factory=set)
    """The phases whose estimates have settled."""
    centroid: Vec2 = (0.0, 0.0)
    mean_square_offset: float = 0.0
    moment: float | None = None
    friction_torque: tuple[float, float] | None = None
    com_velocity: Vec2 | None = None
    com_offset_now: Vec2 | None = None
    stuck: bool = False
    changed: bool = False

    def settled(self, phase: Phase) -> bool:
        return phase in self.ready


PAPER_KEYS = set(PaperTuning.__dataclass_fields__)
ROBUST_KEYS = set(RobustTuning.__dataclass_fields__)


def machine(robot: int = 1, n: int = 3, seed: int = 1, **tuning) -> PhaseMachine:
    """A phase machine of the family ``tuning`` names (the paper's by default), with the
    common and the family's keys given."""
    neighbours = tuple(j for j in (robot - 1, robot + 1) if 1 <= j <= n)
    paper = {k: tuning.pop(k) for k in list(tuning) if k in PAPER_KEYS}
    robust = {k: tuning.pop(k) for k in list(tuning) if k in ROBUST_KEYS}
    full = replace(
        TUNING,
        paper=replace(TUNING.paper, **paper),
        robust=replace(TUNING.robust, **robust),
        **tuning,
    )
    config = AgentConfig(robot, n, neighbours, DT, seed, full)
    return FAMILIES[full.estimator].phases(config)


def state(sender: int, tick: int, m: PhaseMachine) -> Barrier:
    """The barrier's part of ``sender``'s message after its step at ``tick``."""
    return m.barrier.state


def run_team(machines, owns, ticks, start=0, events=None):
    """Steps a path of machines: at tick ``k`` each hears its neighbours' states of ``k − 1``.
    ``events[k](machines, owns)`` runs before tick ``k``. Returns each robot's forces."""
    n = len(machines)
    sent: dict[int, Barrier] = {}
    forces = {i: {} for i in machines}
    for k in range(start, start + ticks):
        if events and k in events:
            events[k](machines, owns)
        for i, m in machines.items():
            heard = [sent[j] for j in (i - 1, i + 1) if 1 <= j <= n and j in sent]
            m.step(k, owns[i], heard)
            forces[i][k] = m.force(k, owns[i], (0.0, 0.0))
        sent = {i: state(i, k, m) for i, m in machines.items()}
    return forces


def make_ready(*robots):
    def event(machines, owns):
        for i in robots:
            owns[i].ready.add(Phase.EXCITE)

    return event


def test_every_robot_switches_at_the_same_agreed_tick():
    n = 3
    machines = {i: machine(i, n) for i in range(1, n + 1)}
    owns = {i: Own(mean_square_offset=0.5, omega=0.4, centroid=(0.3 * i, -0.2)) for i in machines}
    ready = {1: 8, 2: 20, 3: 14}
    events = {tick: make_ready(i) for i, tick in ready.items()}
    forces = run_team(machines, owns, 60, events=events)
    switch = {m.since for m in machines.values()}
    assert len(switch) == 1 and all(m.phase is Phase.INERTIA for m in machines.values())
    (k,) = switch
    margin = TUNING.switch_margin_ticks
    assert 20 + n + margin <= k <= 20 + 2 * n + margin
    for i, m in machines.items():
        assert m.phase_at(k - 1) is Phase.EXCITE and m.phase_at(k) is Phase.INERTIA
        assert forces[i][k - 1] == (0.0, 0.0)  # spin-up with nothing turning
        assert math.hypot(*forces[i][k]) > 0.1  # eq. (14) from the switch tick on


def test_no_robot_is_ready_during_the_kick():
    m = machine()
    own = Own(mean_square_offset=0.5)
    own.ready.add(Phase.EXCITE)
    assert [m.ready(k, own) for k in range(7)] == [False] * 5 + [True, True]
    own.mean_square_offset = 0.0  # w = 0: eq. (14) would divide by zero
    assert not m.ready(6, own)


def test_a_halt_reaches_the_team_through_its_messages():
    n = 3
    machines = {i: machine(i, n) for i in range(1, n + 1)}
    owns = {i: Own(mean_square_offset=0.5, omega=0.4, centroid=(0.3, -0.2)) for i in machines}

    def halt(machines, owns):
        machines[1].halt(31)

    forces = run_team(machines, owns, 60, events={31: halt, 8: make_ready(1, 2, 3)})
    assert [m.since for m in machines.values()] == [31, 32, 33]
    for i, m in machines.items():
        assert m.phase is Phase.HALTED
        assert m.phase_at(m.since - 1) is not Phase.HALTED
        assert all(f == (0.0, 0.0) for k, f in forces[i].items() if k >= m.since)
        assert any(f != (0.0, 0.0) for k, f in forces[i].items() if k < m.since)


def test_the_kick_is_seeded_of_its_magnitude_and_only_during_kick_duration():
    m = machine(robot=2, seed=7, kick_force=1.5)
    own = Own(zdot={1: (0.0, 0.0), 3: (0.0, 0.0)})
    still = (0.0, 0.0)
    forces = [m.force(k, own, still) for k in range(8)]
    kick = kick_force(7, 2, 1.5)
    assert forces[:5] == [kick] * 5 and math.hypot(*kick) == pytest.approx(1.5)
    assert forces[5:] == [(0.0, 0.0)] * 3  # the spin-up, with nothing turning or moving
    # The kick's drift is damped: −b ṗ_Ci after the kick, not during it.
    assert m.force(4, own, (0.2, -0.1)) == kick
    b = TUNING.brake_gain
    assert m.force(5, own, (0.2, -0.1)) == pytest.approx((-0.2 * b, 0.1 * b), rel=1e-12)
    assert machine(robot=2, seed=7, kick_force=1.5).kick == kick
    assert machine(robot=2, seed=8, kick_force=1.5).kick != kick
    assert machine(robot=3, seed=7, kick_force=1.5).kick != kick
    # After the kick, the geometry-free spin-up on the relative velocities.
    own.zdot = {1: (0.1, -0.2), 3: (-0.3, 0.05)}
    expected = spin_up_force(TUNING.spin_gain, TUNING.spin_speed, own.zdot.values())
    assert m.force(5, own, still) == expected != (0.0, 0.0)


def enter(m: PhaseMachine, phase: Phase, k: int, own: Own) -> None:
    """A neighbour's message says the team is in ``phase``: catch up at tick ``k``."""
    assert m.step(k, own, [Barrier(phase=phase)]) is True
    assert m.phase is phase and m.since == k


@pytest.mark.parametrize("spin", [1.0, -1.0])
def test_inertia_torque_reverses_at_the_limit_and_at_half_of_it(spin):
    limit = 1.0
    m = machine(inertia_max_omega=limit, inertia_force=2.0)
    own = Own(mean_square_offset=0.5, omega=0.3 * spin, centroid=(0.6, -0.8))
    enter(m, Phase.INERTIA, 10, own)
    w = 3 * 0.5
    gain = 2.0 / math.sqrt(w)
    assert m.inertia_gain == pytest.approx(gain) and m.spin_sign == spin
    script = [0.3, 0.99, 1.0, 0.7, 0.51, 0.5, 0.8, 1.2, 0.2]
    expected = [1, 1, -1, -1, -1, 1, 1, -1, 1]  # +1: speed the turn up, −1: brake it
    for k, (speed, direction) in enumerate(zip(script, expected), start=10):
        own.omega, own.instant = spin * speed, k - 1
        f = m.force(k, own, (0.3, 0.1))  # (eq. 14 does not damp)
        lead = own.omega * (k + 0.5 - own.instant) * DT
        z = rotate(own.centroid, lead)
        # f = ±k z_i⊥: torque ±k ‖z_i‖² about p_G, signed to speed up (or brake) the turn.
        assert cross(z, f) == pytest.approx(direction * spin * gain, rel=1e-12), k
        assert m.mean_torque(k, k + 1) == pytest.approx(direction * spin * gain * w), k


def test_inertia_torque_reverses_on_the_predicted_omega():
    """ω last measured at tick 10; the prediction adds the team's torque since, over ``Ĵ``."""
    moment = 2.0
    m = machine(inertia_max_omega=1.0, inertia_force=2.0)
    own = Own(mean_square_offset=0.5, omega=0.9, centroid=(1.0, 0.0), measured=10, instant=10)
    enter(m, Phase.INERTIA, 11, own)
    own.moment = moment
    torque = 2.0 * math.sqrt(1.5)  # k w, applied from tick 11 on
    braking_from = None
    for k in range(11, 40):
        m.force(k, own, (0.0, 0.0))
        assert m.omega_at(k + 1, own) == pytest.approx(
            0.9 + DT / moment * sum(m.mean_torque(t, t + 1) for t in range(10, k + 1))
        )
        if braking_from is None and m.direction < 0:
            braking_from = k
    # Measured ω stays 0.9 (no new measurement): only the prediction can reach the limit.
    steps = math.ceil((1.0 - 0.9) / (torque * DT / moment))  # ticks of torque to reach 1.0
    assert braking_from == 11 + steps


@pytest.mark.parametrize(
    "moment, magnitude",
    [(6.0, 2.0), (1.5, 1.0), (60.0, 10.0)],  # f̄_y J/n; push_min_force; max_force
)
def test_push_force(moment, magnitude):
    m = machine(push_fbar=1.0, push_min_force=1.0, max_force=10.0, push_direction=(3.0, 4.0))
    own = Own(moment=moment, omega=0.2)
    enter(m, Phase.PUSH, 50, own)
    expected = (magnitude * 0.6, magnitude * 0.8)
    assert m.moment_used == moment
    for k in range(50, 55):
        own.omega, own.moment = -1.0, 99.0  # later estimates do not change it
        assert m.force(k, own, (1.0, 0.0)) == pytest.approx(expected, rel=1e-12)
    assert math.hypot(*m.force(60, own, (0.0, 0.0))) <= 10.0


def test_the_push_reverses_on_the_agreed_clock():
    """``+f`` for ``T/2``, then ``−f`` and ``+f`` for ``T`` each: the COM's velocity swings
    about the one it had, and its travel stays bounded (``push_flip_s = T``)."""
    m = machine(push_flip_s=0.1, push_min_force=2.0, push_direction=(0.0, 1.0))
    own = Own(moment=1.0)
    enter(m, Phase.PUSH, 50, own)
    signs = [m.force(k, own, (0.0, 0.0))[1] / 2.0 for k in range(50, 80)]
    assert signs == [1.0] * 5 + [-1.0] * 10 + [1.0] * 10 + [-1.0] * 5
    assert [m.push_sign(k) for k in range(50, 80)] == signs
    assert m.mean_push_sign(53, 57) == 0.0 and m.mean_push_sign(55, 60) == -1.0
    # The impulse of each whole period is zero: the velocity comes back every T.
    assert sum(signs[5:25]) == 0.0 and sum(signs[:5]) + sum(signs[25:]) == 0.0
    one_way = machine(push_flip_s=0.0, push_min_force=2.0)
    enter(one_way, Phase.PUSH, 50, own)
    assert {one_way.push_sign(k) for k in range(50, 500)} == {1.0}


def test_the_robust_push_damps_the_centroids_velocity_and_says_by_how_much():
    """``push_damping = b``: each robot adds ``−b ṗ̂_G``, ``ṗ̂_G = ṗ_Ci − ω Q z_i`` all at the
    estimation instant (so that every robot adds the same force, whatever ω does until the
    tick), to the common force, and the pipeline's fits are told what was added, tick by
    tick."""
    m = machine(
        estimator=Estimators.ROBUST,
        push_force=2.0,
        push_damping=2.0,
        push_direction=(0.0, 1.0),
        spin_up_s=0.0,  # the push's stage for Step 5 at once
    )
    own = Own(moment=1.0, omega=0.5, centroid=(0.4, 0.0), instant=49, velocity=(0.1, 0.2))
    enter(m, Phase.PUSH, 50, own)
    # ṗ̂_G = (0.1 + 0.5 · 0, 0.2 − 0.5 · 0.4) = (0.1, 0), whatever the tick's own velocity
    assert m.force(50, own, (0.7, -0.3)) == pytest.approx((-0.2, 2.0))
    # at rest at the next instant: ṗ̂_G = −ω Q z_i = (0, −0.2)
    own.instant, own.velocity = 50, (0.0, 0.0)
    assert m.force(51, own, (0.3, 0.3)) == pytest.approx((0.0, 2.4))
    assert m.mean_push_added(50, 51) == pytest.approx((-0.2, 0.0))
    assert m.mean_push_added(50, 52) == pytest.approx((-0.1, 0.2))
    assert m.mean_push_added(60, 61) == (0.0, 0.0)  # no force commanded then: nothing added
    own.velocity = None  # no velocity at the instant: nothing to damp
    assert m.force(52, own, (0.3, 0.3)) == pytest.approx((0.0, 2.0))
    paper = machine(push_damping=2.0, push_min_force=2.0, push_direction=(0.0, 1.0))
    enter(paper, Phase.PUSH, 50, own)
    assert paper.force(50, own, (0.1, 0.2)) == pytest.approx((0.0, 2.0))  # robust only


def test_the_translating_push_acts_through_the_estimated_com_and_damps_the_turn():
    """Step 7's stage: the team's common force (the push along ``f`` and across it, and its
    damping) acts at the contacts' centroid; each robot adds ``(τ/w) z_i⊥``,
    ``τ = −n ẑ_C × c − b ω̂ w``, so that
    the team's wrench about the COM that Step 5 found is the common force and the turn's
    damping alone, whatever ``ẑ_C``."""
    n, z_c, omega, b = 3, (0.3, -0.2), 0.4, 4.0
    centroids = [(0.9, 0.1), (-0.5, 0.6), (-0.4, -0.7)]  # Σ z_i = 0
    w = sum(x * x + y * y for x, y in centroids)
    forces = []
    for robot, z in enumerate(centroids, start=1):
        m = machine(
            robot=robot,
            n=n,
            estimator=Estimators.ROBUST,
            push_force=2.0,
            push_damping=2.0,
            turn_damping=b,
            push_direction=(0.0, 1.0),
            spin_up_s=0.0,
            pendulum_s=0.1,
            translate_brake_s=0.1,
        )
        own = Own(moment=1.0, omega=0.0, centroid=z, instant=49, mean_square_offset=w / n)
        enter(m, Phase.PUSH, 50, own)
        k = 50 + m.translate_from
        assert m._push_stage(k) == 2
        own.instant, own.omega, own.com_offset_now = k - 1, omega, z_c
        # the COM's velocity (0, 0.1): ṗ_Ci = ṗ_C + ω Q (z_i + z_C)
        own.velocity = (-omega * (z[1] + z_c[1]), 0.1 + omega * (z[0] + z_c[0]))
        lead = omega * 1.5 * DT  # z_i and ẑ_C turned to the middle of tick k
        forces.append((rotate(z, lead), m.force(k, own, own.velocity)))
        # the common force: the push along f and across it (s'(t) Q f, s' reversed at half
        # the period), and −b ṗ̂_G with ṗ̂_G = ṗ_C + ω Q z_C; what is beyond s(t) f recorded
        r, sign = ACROSS_SCALE, m.push_sign(k)
        across = r * m._flip_sign(0, m.push_flip_ticks // 2)  # the stage's first tick: +
        damping = (2.0 * omega * z_c[1], -2.0 * (0.1 + omega * z_c[0]))
        common = (-2.0 * across + damping[0], r * sign * 2.0 + damping[1])
        assert m.mean_push_added(k, k + 1) == pytest.approx(
            (common[0], common[1] - sign * 2.0), abs=1e-12
        )
    arm = rotate(z_c, lead)
    net = (sum(f[0] for _, f in forces), sum(f[1] for _, f in forces))
    torque = sum(cross((z[0] + arm[0], z[1] + arm[1]), f) for z, f in forces)
    assert net == pytest.approx((n * common[0], n * common[1]), abs=1e-12)
    assert torque == pytest.approx(-b * omega * w, rel=1e-9)


def test_the_translating_push_keeps_its_common_force_whole_within_max_force():
    """Where ``max_force`` cannot give the common force and the torque's forces both, the
    common force (which Step 7's fit takes as commanded) is applied whole, the torque's
    forces scaled down to what is left."""
    z, z_c, most = (-0.9, 0.1), (1.2, -0.8), 3.2
    m = machine(
        estimator=Estimators.ROBUST,
        max_force=most,
        push_force=1.6,  # at most half of max_force (PUSH_HEADROOM)
        push_damping=2.0,
        push_direction=(0.0, 1.0),
        spin_up_s=0.0,
        pendulum_s=0.1,
        translate_brake_s=0.1,
    )
    own = Own(moment=1.0, omega=0.0, centroid=z, instant=49, mean_square_offset=0.4)
    enter(m, Phase.PUSH, 50, own)
    k = 50 + m.translate_from
    omega = 1.5
    own.instant, own.omega, own.com_offset_now, own.velocity = k - 1, omega, z_c, (0.0, 0.0)
    force = m.force(k, own, own.velocity)
    # the push along f and across it, scaled to keep their sum within PUSH_HEADROOM of
    # max_force, and −b ṗ̂_G whole
    r = min(ACROSS_SCALE, PUSH_HEADROOM * most / (math.sqrt(2.0) * 1.6))
    sign, across = m.push_sign(k), r * m._flip_sign(0, m.push_flip_ticks // 2)
    damping = (-2.0 * omega * z[1], 2.0 * omega * z[0])
    common = (-1.6 * across + damping[0], r * sign * 1.6 + damping[1])
    assert m.mean_push_added(k, k + 1) == pytest.approx((common[0], common[1] - sign * 1.6))
    assert math.hypot(*force) == pytest.approx(most)
    turning = (force[0] - common[0], force[1] - common[1])
    assert math.hypot(*turning) > 0.1
    turned = rotate(z, omega * 1.5 * DT)  # z_i at the middle of tick k
    assert turned[0] * turning[0] + turned[1] * turning[1] == pytest.approx(0.0, abs=1e-12)


def test_done_brakes_and_halted_applies_no_force():
    m = machine()
    enter(m, Phase.DONE, 5, Own())
    # Remark V.2's damping brings the load to rest.
    b = TUNING.brake_gain
    assert m.force(5, Own(zdot={2: (1.0, 0.0)}), (0.5, -0.25)) == (-0.5 * b, 0.25 * b)
    assert m.force(6, Own(), (0.0, 0.0)) == (0.0, 0.0)
    m.halt(9)
    assert m.phase is Phase.HALTED and m.since == 9
    assert m.force(9, Own(), (0.5, 0.5)) == (0.0, 0.0)
    m.halt(12)  # told again: still halted since 9
    assert m.since == 9


# --------------------------------------------------------------------------------------------
# the agent, composed
# --------------------------------------------------------------------------------------------


def agents(n: int, seed: int = 3) -> dict[int, Agent]:
    return {
        i: Agent(
            AgentConfig(
                robot=i,
                n=n,
                neighbours=tuple(j for j in (i - 1, i + 1) if 1 <= j <= n),
                period_s=DT,
                seed=seed,
                tuning=TUNING,
            )
        )
        for i in range(1, n + 1)
    }


def run_agents(team, ticks, velocity=lambda i, t: (0.0, 0.0), before=None):
    """Each agent steps on its sample and its neighbours' messages of the previous tick."""
    sent: dict[int, Share] = {}
    commands = {i: [] for i in team}
    for k in range(ticks):
        if before and k in before:
            before[k](team)
        shares = {}
        for i, a in team.items():
            heard = [sent[j] for j in a.neighbours if j in sent]
            command, shares[i] = a.step(measurement(i, k, velocity(i, k * DT)), heard)
            commands[i].append(command.force)
        sent = shares
    return commands


def test_agent_kick_then_halt_through_messages():
    team = agents(2, seed=11)
    commands = run_agents(team, 10, before={4: lambda team: team[1].halt()})
    for i, a in team.items():
        assert commands[i][:4] == [kick_force(11, i, TUNING.kick_force)] * 4
        est = a.estimates()
        assert a.phase is Phase.HALTED and est.phase is Phase.HALTED
        assert est.phase_since == 3 + i  # robot 2 hears of it one tick later
        assert commands[i][3 + i :] == [(0.0, 0.0)] * (7 - i)


def test_agent_estimates_a_turning_body_from_its_exact_velocities():
    """Three contacts of a rigid body turning at ω about its moving COM: Steps 1-3 and the
    consensus settle, and the team agrees to leave the excite phase (no force reaches the
    body: its motion is scripted)."""
    omega, v = 0.8, np.array([0.1, -0.05])
    r = {1: np.array([1.0, 0.4]), 2: np.array([-0.5, 1.1]), 3: np.array([0.2, -1.3])}

    def rot(a):
        return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])

    def velocity(i, t):
        u = rot(omega * t) @ r[i]
        return (float(v[0] - omega * u[1]), float(v[1] + omega * u[0]))

    team = agents(3)
    run_agents(team, 301, velocity)
    t = 299 * DT  # the estimation instant of tick 300
    centroid = np.mean([r[i] for i in r], axis=0)
    for i, a in team.items():
        est = a.estimates()
        assert a.instant == est.tick == 299
        assert est.phase is Phase.INERTIA and est.phase_since == team[1].estimates().phase_since
        assert sorted(est.settled) == [1, 2, 3] and max(est.settled.values()) < est.phase_since
        assert est.omega == pytest.approx(omega, abs=1e-9)
        for j, z in est.relative_positions.items():
            assert np.linalg.norm(np.array(z) - rot(omega * t) @ (r[i] - r[j])) < 1e-9
        assert sorted(est.relative_positions) == list(a.neighbours)
        z_i = rot(omega * t) @ (r[i] - centroid)
        assert np.linalg.norm(np.array(est.centroid_offset) - z_i) < 1e-6
        w = sum(float(np.sum((r[j] - centroid) ** 2)) for j in r)
        assert est.w == pytest.approx(w, rel=1e-6)


# --------------------------------------------------------------------------------------------
# what a neighbour's message cannot do
# --------------------------------------------------------------------------------------------


def test_ready_bits_of_robots_outside_the_team_are_ignored():
    m = machine(robot=2, n=3)
    forged = Barrier(phase=Phase.EXCITE, ready=2**64 - 1)  # every bit, not only 1..3
    m.step(1, Own(), [forged])
    assert m.barrier.ready == 0b111  # the three robots: the team can still agree
    assert m.barrier.switch_at == 1 + 3 + TUNING.switch_margin_ticks


def test_a_switch_tick_no_robot_could_have_proposed_is_ignored():
    m = machine(robot=2, n=3)
    too_late = 100 + 3 + TUNING.switch_margin_ticks + 1
    m.step(100, Own(), [Barrier(phase=Phase.EXCITE, switch_at=too_late)])
    assert m.barrier.switch_at == -1
    m.step(101, Own(), [Barrier(phase=Phase.EXCITE, switch_at=too_late)])
    assert m.barrier.switch_at == too_late  # now it could have been proposed


@pytest.mark.parametrize(
    "phase, own",
    [
        (Phase.PUSH, Own(mean_square_offset=1.0, moment=None)),
        (Phase.INERTIA, Own(mean_square_offset=0.0)),
    ],
    ids=["push without J", "inertia without w"],
)
def test_a_phase_this_robot_has_no_estimates_for_halts_the_team(phase, own):
    """Caught up (or told) into a phase whose force law needs what the robot has not
    estimated: it stops the team rather than push wrongly (or crash)."""
    m = machine(robot=2, n=3)
    assert m.step(40, own, [Barrier(phase=phase)])
    assert m.phase is Phase.HALTED and m.since == 40
    assert m.force(40, own, (0.3, 0.0)) == (0.0, 0.0)


# ------------------------------------------------------------------------- resend timeout
def test_the_resend_timeout_follows_the_pace_within_its_bounds():
    """RFC 6298's estimator: the floor before any sample and while ticks are fast; the time a
    tick takes plus four deviations once ticks are slow; the ceiling however slow."""
    timeout = ResendTimeout(floor_s=0.2, ceiling_s=5.0)  # the default ceiling is 1 s
    assert timeout.timeout_s == 0.2
    for _ in range(50):
        timeout.observe(0.01)
    assert timeout.timeout_s == 0.2
    slow = ResendTimeout(floor_s=0.2, ceiling_s=5.0)
    slow.observe(0.5)  # first sample: SRTT = 0.5, RTTVAR = 0.25
    assert slow.timeout_s == pytest.approx(0.5 + 4 * 0.25)
    for _ in range(200):
        slow.observe(0.5)
    assert slow.timeout_s == pytest.approx(0.5, rel=1e-3)  # steady: the deviation decays
    slow.observe(-1.0)  # not a duration: ignored
    assert slow.timeout_s == pytest.approx(0.5, rel=1e-3)
    for _ in range(50):
        slow.observe(30.0)
    assert slow.timeout_s == 5.0


def test_the_brake_before_the_translation_stops_the_turn_within_step_4s_torque():
    """Between Step 5's stage and Step 7's, each robot adds the torque ``−Ĵ ω̂ / τ_s``
    (``τ_s`` a fifth of ``translate_brake_s``) as eq. (14)'s forces, at most Step 4's torque:
    the contacts' brake alone, ``−b ṗ_Ci``, left a heavy load turning while it translated."""
    z = (-0.9, 0.1)
    m = machine(estimator=Estimators.ROBUST, spin_up_s=0.0, pendulum_s=0.1, translate_brake_s=1.0)
    own = Own(moment=2.0, omega=0.0, centroid=z, instant=49, mean_square_offset=0.4)
    enter(m, Phase.INERTIA, 40, own)
    enter(m, Phase.PUSH, 50, own)
    k = 50 + m.pendulum_ticks
    assert m._push_stage(k) == 1
    w = m.n * own.mean_square_offset
    for omega in (0.05, -0.05, 3.0):
        own.instant, own.omega = k - 1, omega
        force = m.force(k, own, (0.0, 0.0))  # the contact still: no brake force
        turned = rotate(z, omega * 1.5 * DT)
        torque = (
            (turned[0] * force[1] - turned[1] * force[0]) * w / (turned[0] ** 2 + turned[1] ** 2)
        )
        wanted = -2.0 * omega / (TURN_STOP_SHARE * 1.0)
        most = abs(m.inertia_torque)
        assert torque == pytest.approx(min(max(wanted, -most), most))
    assert abs(-2.0 * 3.0 / 0.2) > abs(m.inertia_torque)  # the last was bounded
