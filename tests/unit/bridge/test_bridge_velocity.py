"""The AGV bridge with the velocity profile: a base's ``MotionFeedback`` and its force/torque
sensor's ``ForceTorque`` make the agent's measurement (the force tared), the agent's command
steps the admittance loop into a ``MotionCommand``, and two stops (a silent agent, a stale
sensor) hold the base at standstill; its config and its loop on a virtual bus."""

from __future__ import annotations

import dataclasses
import logging
import tomllib

import can
import pytest

from agent.platform.config import ConfigError, from_table
from agent.platform.process import RejectLog
from agent.platform.protocol import BridgeStatus, Command, Measurement, decode, encode
from bridge.admittance import Admittance, AdmittanceSettings, Tracking
from bridge.bridge import Bridge
from bridge.codec import (
    AgvCodec,
    AppliedForce,
    ForceTorque,
    MotionCommand,
    MotionFeedback,
    Odometry,
    Sync,
)
from bridge.config import CanSettings, can_table, load_bridge_config
from bridge.dbc import MAX_COMMAND_SPEED, MAX_FORCE
from bridge.timing import SyncTicks
from tests.unit.bridge.test_bridge import (
    ROBOT,
    Clock,
    answer,
    bridge_on_virtual_bus,
)

CODEC = AgvCodec("velocity")
LOG = logging.getLogger("test.bridge.velocity")
PERIOD = 0.01
SETTINGS = AdmittanceSettings(mass=2.0, deadzone_n=0.0, tare_samples=4)
BIAS = (0.5, -0.25)
"""The sensor's raw reading with nothing touching it (exact at the DBC's resolution)."""


def make_bridge(settings: AdmittanceSettings = SETTINGS, watchdog_s: float = 0.1, admittance=None):
    return Bridge(
        robot=2,
        node=2,
        period_s=PERIOD,
        watchdog_s=watchdog_s,
        ticks=SyncTicks(),
        rejects=RejectLog(LOG, "bridge"),
        wall=Clock(),
        codec=CODEC,
        admittance=admittance or Admittance(settings, PERIOD),
    )


def feed(bridge: Bridge, *frames, at: float = 0.0) -> list[Measurement]:
    """The ``frames`` (frames or messages), read at ``at``; the measurements they make."""
    out: list[Measurement] = []
    for frame in frames:
        message = frame if isinstance(frame, can.Message) else CODEC.encode(frame)
        out += bridge.receive(message, at)
    return out


def raw(force) -> tuple[float, float]:
    return (force[0] + BIAS[0], force[1] + BIAS[1])


def tick_frames(tick: int, v=(0.5, -0.25), f=(0.0, 0.0), status: int = 0) -> list:
    """Tick ``tick``'s frames: the sensor reads the contact force ``f`` plus its bias."""
    return [Sync(tick), MotionFeedback(2, tick % 16, v), ForceTorque(2, tick % 16, raw(f), status)]


def tared(bridge: Bridge, ticks: int = 4) -> list[Measurement]:
    """The first ``ticks`` ticks, nothing pushing: the loop tares the sensor."""
    out = []
    for tick in range(ticks):
        out += feed(bridge, *tick_frames(tick))
    return out


def sent(frames: list[can.Message]) -> list:
    return [CODEC.decode(frame) for frame in frames]


# ------------------------------------------------------------------------- measurements
def test_the_feedback_and_the_sensor_of_a_tick_make_its_measurement_with_the_tared_force():
    bridge = make_bridge()
    out = []
    for tick in range(4):  # taring: the raw readings differ a little, their mean is the bias
        wobble = (0.25 * (tick - 1.5), 0.0)
        out += feed(bridge, Sync(tick), MotionFeedback(2, tick, (0.0, 0.0)))
        out += feed(bridge, ForceTorque(2, tick, raw(wobble)))
    assert bridge.admittance.tared and bridge.admittance.bias == BIAS
    assert [m.tick for m in out] == [0, 1, 2, 3]
    out = feed(bridge, Sync(4), ForceTorque(2, 4, raw((12.5, -3.0))))
    assert out == []  # one of the pair is not a measurement
    (m,) = feed(bridge, MotionFeedback(2, 4, (0.75, -0.125)))
    assert m == Measurement(2, 4, 4 * PERIOD, (0.75, -0.125), (12.5, -3.0))
    status = bridge.status()
    assert (status.frames_in, status.missed_ticks, status.decode_errors) == (15, 0, 0)
    assert status.profile == "velocity"


def test_a_repeated_tick_is_measured_again_but_tared_once() -> None:
    """Lockstep: the bus master sends a tick again; the tare must not count it twice."""
    bridge = make_bridge()
    first = feed(bridge, *tick_frames(0, f=(1.0, 0.0)))
    again = feed(bridge, *tick_frames(0, f=(1.0, 0.0)))
    assert first == again and len(first) == 1
    tared(bridge, 4)  # ticks 0..3 once each: tared after the fourth, not the third
    assert bridge.admittance.tared
    assert bridge.admittance.bias == pytest.approx((BIAS[0] + 0.25, BIAS[1]))


def test_a_sensor_sample_with_a_status_bit_is_not_used_and_the_tick_has_no_measurement():
    bridge = make_bridge()
    out = tared(bridge)
    out += feed(bridge, *tick_frames(4, status=0b10))  # FAULT
    out += feed(bridge, *tick_frames(5, status=0b01))  # OVERRANGE
    out += feed(bridge, *tick_frames(6))
    assert [m.tick for m in out] == [0, 1, 2, 3, 6]
    assert bridge.counts["sensor faults"] == 2
    assert bridge.status().missed_ticks == 2


def test_the_other_profiles_frames_are_refused_and_our_own_commands_are_foreign() -> None:
    bridge = make_bridge()
    force = AgvCodec("force")
    frames = [
        Sync(0),
        force.encode(Odometry(2, 0, (0.1, 0.1))),
        force.encode(AppliedForce(2, 0, (1.0, 1.0))),
        MotionCommand(2, 0, (1.0, 0.0)),
        MotionFeedback(3, 0, (1.0, 1.0)),
    ]
    assert feed(bridge, *frames) == []
    reasons = bridge.rejects.reasons
    assert reasons["can frame", "wrong profile"] == 2
    assert reasons["can frame", "foreign"] == 1
    assert bridge.counts["other nodes"] == 1
    status = bridge.status()
    assert status.decode_errors == 2 and status.wrong_profile == 2


def test_a_contact_force_beyond_the_limit_commands_standstill_counted_and_logged(caplog) -> None:
    bridge = make_bridge(dataclasses.replace(SETTINGS, max_contact_force=20.0))
    tared(bridge)
    caplog.set_level(logging.WARNING, logger="heft.bridge")
    assert drive(bridge, 4, at=0.04).velocity != (0.0, 0.0)
    stops = []
    for tick in (5, 6):  # the contact carries 25 N
        feed(bridge, *tick_frames(tick, f=(15.0, 20.0)))
        (frame,) = sent(bridge.command(Command(2, tick, (10.0, 0.0)), at=tick * PERIOD))
        stops.append(frame)
    assert stops == [MotionCommand(2, tick % 16, (0.0, 0.0)) for tick in (5, 6)]
    assert bridge.status().overload_stops == 2
    logged = [r.getMessage() for r in caplog.records if "max_contact_force" in r.getMessage()]
    assert len(logged) == 1 and "25.0 N" in logged[0]  # once per episode
    assert drive(bridge, 7, at=0.07).velocity != (0.0, 0.0)  # 2 N again: it drives
    assert bridge.status().overload_stops == 2


# ------------------------------------------------------------------------- the loop
def test_a_command_steps_the_admittance_loop_into_its_ticks_motion_command() -> None:
    """The bridge's frames carry what the loop gives for the same samples and commands."""
    bridge = make_bridge()
    reference = Admittance(SETTINGS, PERIOD)
    pushes = [(20.0, -10.0), (20.0, -10.0), (5.0, 2.5), (0.0, 0.0), (-7.5, 1.0)]
    contact = [(0.0, 0.0), (3.0, -1.5), (9.5, -4.0), (4.0, 1.0), (-1.0, 0.5)]
    velocities = []
    for tick in range(4 + len(pushes)):
        f = contact[tick - 4] if tick >= 4 else (0.0, 0.0)
        feed(bridge, *tick_frames(tick, f=f))
        reference.measure(raw(f))
        push = pushes[tick - 4] if tick >= 4 else (0.0, 0.0)
        (frame,) = sent(bridge.command(Command(2, tick, push), at=tick * PERIOD))
        expected = CODEC.quantize_command_velocity(reference.step(push))
        assert frame == MotionCommand(2, tick % 16, expected, drive=True)
        velocities.append(frame.velocity)
    assert velocities[:4] == [(0.0, 0.0)] * 4  # taring, no push
    assert velocities[4] != (0.0, 0.0)
    assert bridge.status().force_error_rms == reference.tracking().rms > 0
    assert bridge.status().force_error_p95 == reference.tracking().p95
    assert bridge.counts["commands"] == 4 + len(pushes)


def test_the_loop_steps_once_a_tick_and_needs_the_ticks_sample() -> None:
    bridge = make_bridge()
    tared(bridge)
    feed(bridge, Sync(4), MotionFeedback(2, 4, (0.0, 0.0)))  # its ForceTorque not in yet
    assert bridge.command(Command(2, 4, (10.0, 0.0)), at=1.0) == []
    assert bridge.rejects.reasons["command", "no sample"] == 1
    feed(bridge, ForceTorque(2, 4, raw((0.0, 0.0))))
    first = bridge.command(Command(2, 4, (10.0, 0.0)), at=1.0)
    again = bridge.command(Command(2, 4, (10.0, 0.0)), at=1.001)  # the bus repeated tick 4
    assert first == again and len(first) == 1
    reference = Admittance(SETTINGS, PERIOD)
    for _ in range(4):
        reference.measure(BIAS)
    reference.measure(BIAS)
    expected = CODEC.quantize_command_velocity(reference.step((10.0, 0.0)))
    assert sent(first)[0].velocity == expected  # one step, not two
    feed(bridge, *tick_frames(5))
    assert len(bridge.command(Command(2, 5, (10.0, 0.0)), at=1.01)) == 1
    assert bridge.command(Command(2, 4, (10.0, 0.0)), at=1.02) == []
    assert bridge.rejects.reasons["command", "out of order"] == 1
    assert bridge.status().rejected_commands == 2


class Runaway:
    """A loop that asks for more than the DBC carries (the real one cannot: its
    ``max_speed`` is at most 8 m/s)."""

    bias = (0.0, 0.0)
    overloaded = False

    def measure(self, raw):
        return raw

    def step(self, commanded):
        return (12.0, -9.0)

    def stop(self):
        return (0.0, 0.0)

    def tracking(self):
        return Tracking(0, 0.0, 0.0)


def test_commands_and_velocities_are_clamped_to_the_dbc_and_counted() -> None:
    bridge = make_bridge()
    tared(bridge)
    (frame,) = sent(bridge.command(Command(2, 3, (900.0, 0.0)), at=1.0))
    assert bridge.status().clamped == 1
    assert bridge.admittance.tracking().rms == MAX_FORCE  # the loop was asked for 500 N
    reference = Admittance(SETTINGS, PERIOD)
    for _ in range(4):
        reference.measure(BIAS)
    assert frame.velocity == CODEC.quantize_command_velocity(reference.step((MAX_FORCE, 0.0)))
    runaway = make_bridge(admittance=Runaway())
    feed(runaway, *tick_frames(0))
    (frame,) = sent(runaway.command(Command(2, 0, (1.0, 0.0)), at=1.0))
    assert frame.velocity == (MAX_COMMAND_SPEED, -MAX_COMMAND_SPEED)
    assert runaway.status().clamped == 1


# ------------------------------------------------------------------------- the two stops
def drive(bridge: Bridge, tick: int, at: float, push=(10.0, 0.0)) -> MotionCommand:
    """Tick ``tick``'s frames read at ``at``, and the agent's ``push`` for it; the frame sent."""
    feed(bridge, *tick_frames(tick, f=(2.0, 0.0)), at=at)
    (frame,) = sent(bridge.command(Command(2, tick, push), at=at))
    return frame


def test_a_silent_agent_stops_the_base_within_the_watchdog_then_it_drives_again() -> None:
    bridge = make_bridge(watchdog_s=0.1)
    tared(bridge)
    for tick in range(4, 10):
        frame = drive(bridge, tick, at=tick * PERIOD)
    assert frame.drive and frame.velocity != (0.0, 0.0)
    assert bridge.admittance.velocity != (0.0, 0.0)
    last = 9 * PERIOD
    assert bridge.watchdog(last + 0.099) == []
    (stop,) = sent(bridge.watchdog(last + 0.1001))
    assert stop == MotionCommand(2, 9, (0.0, 0.0), drive=False)
    assert bridge.admittance.velocity == (0.0, 0.0)  # the loop's state forgotten
    status = bridge.status()
    assert status.watchdog and status.watchdog_trips == 1 and not status.sensor_stale
    assert bridge.watchdog(last + 0.15) == []  # no new tick: the next a watchdog_s later
    feed(bridge, *tick_frames(10, f=(2.0, 0.0)))
    (stop,) = sent(bridge.watchdog(last + 0.16))  # one for the new tick
    assert stop == MotionCommand(2, 10, (0.0, 0.0), drive=False)
    assert bridge.counts["stop frames"] == 2
    (frame,) = sent(bridge.command(Command(2, 10, (10.0, 0.0)), at=last + 0.17))
    assert frame.drive and not bridge.tripped


def test_a_stale_sensor_stops_the_base_within_the_watchdog_once_a_trip(caplog) -> None:
    bridge = make_bridge(watchdog_s=0.1)
    tared(bridge)
    drive(bridge, 4, at=0.0)
    caplog.set_level(logging.WARNING, logger="heft.bridge")
    frames = []
    for i, tick in enumerate(range(5, 30)):  # the bus ticks, the sensor is silent
        at = 0.01 * (i + 1)
        feed(bridge, Sync(tick), MotionFeedback(2, tick % 16, (0.0, 0.0)))
        bridge.command(Command(2, 4, (10.0, 0.0)), at=at)  # the agent is not silent
        frames += [(at, f) for f in sent(bridge.watchdog(at))]
    assert frames, "no stop"
    first_at, first = frames[0]
    assert first == MotionCommand(2, first.counter, (0.0, 0.0), drive=False)
    # The last sample came with tick 4 (at 0.0), tick 5 opened without one at 0.01: the stop
    # comes a watchdog after the last sample (this loop looks once a period).
    assert 0.1 - 1e-9 <= first_at <= 0.1 + PERIOD + 1e-9
    assert all(not f.drive for _, f in frames)
    status = bridge.status()
    assert status.sensor_stale and status.sensor_stale_trips == 1 and not status.watchdog
    stale = [r.getMessage() for r in caplog.records if "sensor stale" in r.getMessage()]
    assert len(stale) == 1 and "no ForceTorque frame" in stale[0]
    # The sensor is back: the base drives again with the next command.
    frame = drive(bridge, 30, at=0.31)
    assert frame.drive and not bridge.sensor_stale
    assert bridge.status().sensor_stale_trips == 1


def test_a_sensor_reporting_a_fault_is_stale_and_says_why(caplog) -> None:
    bridge = make_bridge(watchdog_s=0.05)
    tared(bridge)
    caplog.set_level(logging.WARNING, logger="heft.bridge")
    stops = []
    for tick in range(4, 20):
        at = tick * PERIOD
        feed(bridge, *tick_frames(tick, status=0b10))
        stops += sent(bridge.watchdog(at))
    assert stops and bridge.sensor_stale
    (line,) = [r.getMessage() for r in caplog.records if "sensor stale" in r.getMessage()]
    assert "it reports FAULT" in line


def test_the_sensor_is_not_stale_before_its_first_sample_nor_while_the_bus_stands() -> None:
    bridge = make_bridge(watchdog_s=0.1)
    feed(bridge, Sync(0), MotionFeedback(2, 0, (0.0, 0.0)))
    for tick in range(1, 30):  # no ForceTorque ever: nothing to call stale
        feed(bridge, Sync(tick))
        assert bridge.watchdog(tick * PERIOD) == []
    stands = make_bridge(watchdog_s=0.1)
    tared(stands)
    assert stands.watchdog(0.0) == []
    assert stands.watchdog(100.0) == []  # no tick opened since the last sample
    assert not stands.sensor_stale and stands.next_check(100.0) == 100.0 + PERIOD


def test_next_check_is_the_stale_sensors_deadline_a_watchdog_after_the_last_sample() -> None:
    """However late the tick without a sample opens (a driver that hiccups), the stop comes
    a watchdog after the last sample was read."""
    for opened in (5.0, 5.03):
        bridge = make_bridge(watchdog_s=0.1)
        tared(bridge)
        drive(bridge, 4, at=4.99)
        feed(bridge, Sync(5), at=opened)
        bridge.command(Command(2, 4, (10.0, 0.0)), at=opened)  # the agent is not silent
        assert bridge.watchdog(opened) == []
        due = bridge.next_check(opened)
        assert 5.09 < due < 5.091
        assert bridge.watchdog(due - 2e-4) == [] and not bridge.sensor_stale
        assert len(bridge.watchdog(due)) == 1 and bridge.sensor_stale and not bridge.tripped


def test_a_bus_that_stood_still_gives_its_next_ticks_sample_half_a_watchdog() -> None:
    """A lockstep bus master waited a second for its plant: the tick it opens then is owed
    its sample, which comes a frame later; the sensor is not stale for that."""
    bridge = make_bridge(watchdog_s=0.1)
    tared(bridge)
    drive(bridge, 4, at=4.99)
    feed(bridge, Sync(5), at=6.0)
    bridge.command(Command(2, 4, (10.0, 0.0)), at=6.0)  # the agent's watchdog holds off
    assert bridge.watchdog(6.0) == []
    due = bridge.next_check(6.0)
    assert 6.05 < due < 6.051
    assert bridge.watchdog(6.04) == []
    drive(bridge, 5, at=6.045)  # its sample, late as it may be on a loaded host
    assert bridge.watchdog(6.06) == [] and not bridge.sensor_stale
    feed(bridge, Sync(6), at=9.0)  # stood still again, and this time no sample comes
    bridge.command(Command(2, 5, (10.0, 0.0)), at=9.0)
    assert bridge.watchdog(9.0) == []
    assert bridge.watchdog(9.049) == [] and not bridge.sensor_stale
    assert len(bridge.watchdog(9.0501)) == 1 and bridge.sensor_stale


def test_the_velocity_status_crosses_the_wire() -> None:
    bridge = make_bridge()
    tared(bridge)
    drive(bridge, 4, at=0.0)
    status = bridge.status()
    assert status.force_error_rms > 0
    assert decode(BridgeStatus, encode(status)) == status


def test_the_force_profile_reports_no_tracking() -> None:
    force = Bridge(2, 2, PERIOD, 0.1, SyncTicks(), RejectLog(LOG, "b"), Clock(), AgvCodec())
    status = force.status()
    assert (status.profile, status.force_error_rms, status.force_error_p95) == ("force", 0, 0)
    assert force.admittance is None


# ------------------------------------------------------------------------- config
def test_the_profile_and_the_admittance_table_are_read(tmp_path) -> None:
    path = tmp_path / "robot.toml"
    text = '[can]\nprofile = "velocity"\n[can.admittance]\nmass = 4.5\ntare_samples = 50\n'
    path.write_text(ROBOT + text, encoding="utf-8")
    config = load_bridge_config(path)
    assert config.can.profile == "velocity"
    assert config.can.admittance == AdmittanceSettings(mass=4.5, tare_samples=50)
    assert CanSettings().profile == "force"


def test_can_table_reads_back_exactly(tmp_path) -> None:
    can_settings = CanSettings(
        channel="vcan3",
        profile="velocity",
        admittance=AdmittanceSettings(mass=3.25, damping=12.5, max_speed=0.75, tare_samples=9),
    )
    path = tmp_path / "robot.toml"
    path.write_text(ROBOT + can_table(can_settings), encoding="utf-8")
    assert load_bridge_config(path).can == can_settings
    table = tomllib.loads(can_table(can_settings))["can"]
    assert from_table(CanSettings, table, "can") == can_settings


@pytest.mark.parametrize(
    "table, words",
    [
        ('[can]\nprofile = "torque"', "can.profile: expected force or velocity, got 'torque'"),
        ("[can]\nprofile = 1", "can.profile: expected a string"),
        ("[can]\n[can.admittance]\nmass = 0", "can.admittance.mass: expected a number in"),
        ("[can]\n[can.admittance]\nmax_speed = 9.0", "can.admittance.max_speed"),
        ("[can]\n[can.admittance]\ngain = 1.0", "can.admittance.gain: unknown key"),
        ("[can]\nadmittance = 5", "can.admittance: expected a table"),
    ],
)
def test_a_bad_profile_or_admittance_is_one_line_naming_the_key(tmp_path, table, words) -> None:
    path = tmp_path / "robot.toml"
    path.write_text(ROBOT + table + "\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=words.replace("(", r"\(")) as caught:
        load_bridge_config(path)
    assert "\n" not in str(caught.value)


# ------------------------------------------------------------------------- the loop
def test_the_velocity_bridge_loop_on_a_virtual_bus(tmp_path) -> None:
    """Base and sensor frames on a python-can virtual bus → tared measurements; commands →
    MotionCommands; STOP once commands stop; STOP again when the bridge stops."""
    table = (
        '[can]\ninterface = "virtual"\nchannel = "t-velocity"\nprofile = "velocity"\n'
        "[can.admittance]\ntare_samples = 4\n"
    )
    with bridge_on_virtual_bus(tmp_path, table, "t-velocity") as (port, base):
        commands: list[MotionCommand] = []
        for tick in range(12):
            for frame in tick_frames(tick, f=(1.0, 0.0) if tick >= 4 else (0.0, 0.0)):
                base.send(CODEC.encode(frame))
            answer(port, tick, (5.0, 0.0))
            message = base.recv(1.0)
            assert message is not None
            commands.append(CODEC.decode(message))
        assert [m.tick for m in port.sent] == list(range(12))
        assert port.sent[-1].force == pytest.approx((1.0, 0.0))
        assert [(c.counter, c.drive) for c in commands] == [(t % 16, True) for t in range(12)]
        assert commands[2].velocity == (0.0, 0.0) and commands[-1].velocity[0] > 0  # tared at 3
        stop = base.recv(1.0)  # nothing more from the agent: the watchdog (100 ms)
        assert stop is not None and CODEC.decode(stop).drive is False
    last = None
    while (message := base.recv(0.2)) is not None:
        last = CODEC.decode(message)
    assert last == MotionCommand(2, 11, (0.0, 0.0), drive=False)
    assert port.reports[-1].profile == "velocity"
    base.shutdown()
