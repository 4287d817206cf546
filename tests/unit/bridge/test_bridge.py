"""The AGV bridge without a kernel bus: its logic (frames → measurements, commands → frames,
sequence counters, the watchdog), its tick sources, its config, and the bridge's loop on
python-can's ``virtual`` bus. The same bridge on real vcan is in tests/hil/test_hil.py."""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import time

import can
import pytest

from agent.platform.config import ConfigError
from agent.platform.process import RejectLog
from agent.platform.protocol import BridgeStatus, Command, Measurement, decode, encode
from agent.platform.robot_io import AgentsPort
from bridge.bridge import CAN_ERR_BUSOFF, Bridge
from bridge.codec import (
    REASONS,
    AgvCodec,
    AppliedForce,
    ForceCommand,
    ForceTorque,
    Heartbeat,
    MotionCommand,
    MotionFeedback,
    Odometry,
    Sync,
)
from bridge.config import CanSettings, load_bridge_config
from bridge.dbc import MAX_FORCE, PROFILES
from bridge.node import BUS_TIME_S, BridgeNode, bus_time, log_aside, open_bus
from bridge.timing import EPOCH, ClockTicks, SyncTicks
from tests.helpers.random_frames import random_frames

CODEC = AgvCodec()
LOG = logging.getLogger("test.bridge")
PERIOD = 0.01


class Clock:
    """A settable clock for the watchdog and the Unix time."""

    def __init__(self, now: float = 100.0) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now


def make_bridge(ticks=None, wall=None, watchdog_s: float = 0.1) -> Bridge:
    return Bridge(
        robot=2,
        node=2,
        period_s=PERIOD,
        watchdog_s=watchdog_s,
        ticks=ticks or SyncTicks(),
        rejects=RejectLog(LOG, "bridge"),
        wall=wall or Clock(),
        codec=CODEC,
    )


def feed(bridge: Bridge, *frames, at: float = 0.0) -> list[Measurement]:
    """The ``frames`` (frames or messages), read at ``at``; the measurements they make."""
    out: list[Measurement] = []
    for frame in frames:
        message = frame if isinstance(frame, can.Message) else CODEC.encode(frame)
        out += bridge.receive(message, at)
    return out


def tick_frames(tick: int, node: int = 2, v=(0.5, -0.25), f=(10.0, -3.0)) -> list:
    return [Sync(tick), Odometry(node, tick % 16, v), AppliedForce(node, tick % 16, f)]


# ------------------------------------------------------------------------- measurements
def test_a_ticks_odometry_and_applied_force_make_one_measurement() -> None:
    bridge = make_bridge()
    out = []
    for tick in range(40):
        out += feed(bridge, *tick_frames(tick))
    assert [m.tick for m in out] == list(range(40))
    m = out[17]
    assert m == Measurement(2, 17, 17 * PERIOD, (0.5, -0.25), (10.0, -3.0))
    status = bridge.status()
    assert (status.frames_in, status.missed_ticks, status.decode_errors) == (120, 0, 0)
    assert (status.repeats, status.counter_jumps, status.lost_frames) == (0, 0, 0)
    assert status.tick == 39


def test_a_tick_without_both_frames_is_missing_and_counted_never_invented() -> None:
    bridge = make_bridge()
    out = feed(bridge, *tick_frames(0))
    out += feed(bridge, Sync(1), Odometry(2, 1, (0.1, 0.1)))  # its AppliedForce lost
    out += feed(bridge, Sync(2), AppliedForce(2, 2, (1.0, 1.0)))  # its Odometry lost
    out += feed(bridge, *tick_frames(3))
    assert [m.tick for m in out] == [0, 3]
    status = bridge.status()
    assert status.missed_ticks == 2
    assert status.counter_jumps == 2 and status.lost_frames == 2  # one of each kind skipped


def test_a_sample_whose_counter_is_not_the_open_ticks_is_stale() -> None:
    bridge = make_bridge()
    feed(bridge, Sync(5))
    assert feed(bridge, Odometry(2, 4, (0, 0)), AppliedForce(2, 4, (0, 0))) == []
    assert bridge.rejects.reasons["can frame", "stale"] == 2


def test_a_repeated_tick_is_counted_and_measured_again() -> None:
    """Lockstep: the bus master sends a tick again when the command did not come back."""
    bridge = make_bridge()
    first = feed(bridge, *tick_frames(7))
    again = feed(bridge, *tick_frames(7))
    assert first == again and len(first) == 1
    assert bridge.status().repeats == 3  # Sync, Odometry, AppliedForce
    assert bridge.status().missed_ticks == 0


def test_frames_of_other_nodes_are_ignored_and_bad_frames_counted_by_reason() -> None:
    bridge = make_bridge()
    good = CODEC.encode(Odometry(2, 0, (0.1, 0.2)))
    corrupt = can.Message(
        arbitration_id=good.arbitration_id,
        data=bytes(good.data[:7]) + bytes([good.data[7] ^ 0xFF]),
        is_extended_id=False,
    )
    frames = [
        Sync(0),
        Odometry(3, 0, (1.0, 1.0)),
        can.Message(arbitration_id=0x7FF, data=bytes(8), is_extended_id=False),
        can.Message(
            arbitration_id=good.arbitration_id, data=bytes(good.data[:6]), is_extended_id=False
        ),
        corrupt,
        can.Message(is_error_frame=True, arbitration_id=0x40, data=bytes(8)),
        ForceCommand(2, 0, (1.0, 1.0)),
    ]
    assert feed(bridge, *frames) == []
    reasons = bridge.rejects.reasons
    assert bridge.counts["other nodes"] == 1
    assert reasons["can frame", "unknown id"] == 1
    assert reasons["can frame", "wrong length"] == 1
    assert reasons["can frame", "checksum"] == 1
    assert reasons["can frame", "bus off"] == 1 and bridge.status().bus_errors == 1
    assert reasons["can frame", "foreign"] == 1
    assert bridge.status().decode_errors == 3


def test_the_drivers_heartbeat_is_reported() -> None:
    bridge = make_bridge()
    assert bridge.status().driver_mode == -1
    feed(bridge, Heartbeat(2, 0, 2, 0b101))
    status = bridge.status()
    assert (status.driver_mode, status.driver_faults) == (2, 0b101)


# ------------------------------------------------------------------------- commands
def test_a_command_becomes_its_ticks_force_frame_clamped_to_the_dbc() -> None:
    bridge = make_bridge()
    feed(bridge, Sync(20))
    (frame,) = bridge.command(Command(2, 20, (12.5, -3.25)), at=1.0)
    assert CODEC.decode(frame) == ForceCommand(2, 4, (12.5, -3.25), True)
    (frame,) = bridge.command(Command(2, 19, (900.0, -900.0)), at=1.0)
    assert CODEC.decode(frame) == ForceCommand(2, 3, (MAX_FORCE, -MAX_FORCE), True)
    assert bridge.status().clamped == 1


@pytest.mark.parametrize(
    "tick, why", [(21, "ahead of the bus"), (4, "too old")], ids=["ahead", "too-old"]
)
def test_commands_for_ticks_the_bus_cannot_name_are_refused(tick: int, why: str) -> None:
    bridge = make_bridge()
    feed(bridge, Sync(20))
    assert bridge.command(Command(2, tick, (1.0, 1.0)), at=1.0) == []
    assert bridge.rejects.reasons["command", why] == 1
    assert bridge.status().rejected_commands == 1


def test_before_the_first_sync_no_command_goes_out() -> None:
    bridge = make_bridge()
    assert bridge.command(Command(2, 0, (1.0, 1.0)), at=1.0) == []


# ------------------------------------------------------------------------- the watchdog
def test_the_watchdog_commands_zero_force_then_clears_when_commands_return() -> None:
    bridge = make_bridge(watchdog_s=0.1)
    feed(bridge, Sync(3))
    assert bridge.watchdog(0.0) == []  # not armed before the first command
    bridge.command(Command(2, 3, (5.0, 5.0)), at=1.0)
    assert bridge.watchdog(1.099) == []  # within watchdog_s: still fine
    (zero,) = bridge.watchdog(1.1001)
    assert CODEC.decode(zero) == ForceCommand(2, 3, (0.0, 0.0), False)
    assert bridge.tripped and bridge.status().watchdog and bridge.status().watchdog_trips == 1
    assert bridge.watchdog(1.15) == []  # no new tick: the next one a watchdog_s later
    assert len(bridge.watchdog(1.2002)) == 1
    feed(bridge, Sync(4))
    assert bridge.watchdog(1.205) == []  # a new tick, but at most one frame a period
    (zero,) = bridge.watchdog(1.2103)  # one for the new tick
    assert CODEC.decode(zero) == ForceCommand(2, 4, (0.0, 0.0), False)
    assert bridge.watchdog(1.22) == []
    (frame,) = bridge.command(Command(2, 4, (1.0, 0.0)), at=1.23)
    assert CODEC.decode(frame).apply and not bridge.tripped
    assert bridge.watchdog(1.28) == []
    assert len(bridge.watchdog(1.34)) == 1 and bridge.status().watchdog_trips == 2


def test_a_command_sent_before_the_agent_fell_silent_does_not_clear_the_watchdog() -> None:
    """Commands still in flight when the watchdog trips (for ticks the bus opened before the
    trip) are refused as stale after a stop, counted, and leave the base held; one for a tick
    opened at the trip or after clears it."""
    bridge = make_bridge(watchdog_s=0.1)
    feed(bridge, Sync(3))
    bridge.command(Command(2, 3, (5.0, 5.0)), at=1.0)
    for k in range(4, 10):
        feed(bridge, Sync(k))
    (zero,) = bridge.watchdog(1.1001)
    assert not CODEC.decode(zero).apply and bridge.tripped
    for k, at in ((4, 1.12), (8, 1.13)):
        assert bridge.command(Command(2, k, (1.0, 0.0)), at=at) == []
        assert bridge.tripped
    assert bridge.rejects.reasons["command", "stale after a stop"] == 2
    assert bridge.watchdog(1.15) == [] and bridge.tripped  # paced: no new tick
    (frame,) = bridge.command(Command(2, 9, (1.0, 0.0)), at=1.16)
    assert CODEC.decode(frame) == ForceCommand(2, 9, (1.0, 0.0), True) and not bridge.tripped
    assert bridge.command(Command(2, 5, (1.0, 0.0)), at=1.17) != []  # not tripped: in time


def _late_agent_run(round_trip_s, ticks: int):
    """The bridge's loop in simulated time: the bus opens tick ``k`` at ``k T`` (``Sync``,
    then ``Odometry`` and ``AppliedForce`` 0.5 and 1 ms later, the force naming the tick),
    the agent answers each measurement ``round_trip_s(k)`` seconds after it, in order (a
    command never overtakes an earlier one), and stops after the last tick; the watchdog is
    checked after every frame and command and at every :meth:`Bridge.next_check`, as
    :class:`bridge.node.BridgeNode` does, until 1 s after the last tick. Returns the bridge,
    when each tick's command reached it, and ``(time, frame)`` of every frame it wrote."""
    bridge = make_bridge(watchdog_s=0.1)
    frames = []
    for k in range(ticks):
        for i, frame in enumerate(tick_frames(k, f=(k * 0.25, -3.0))):
            frames.append((k * PERIOD + i * 5e-4, frame))
    end = (ticks - 1) * PERIOD + 1.0
    commands: list[tuple[float, Command]] = []
    arrived: dict[int, float] = {}
    written: list[tuple[float, ForceCommand]] = []
    now = 0.0

    def wrote(out: list) -> None:
        out = out + bridge.watchdog(now)
        written.extend((now, CODEC.decode(m)) for m in out)

    while True:
        due = max(bridge.next_check(now), now + 1e-6)  # a real clock moves on
        nxt = min([t for t, _ in frames[:1]] + [t for t, _ in commands[:1]], default=math.inf)
        if due < nxt:
            if due > end:
                return bridge, arrived, written
            now = due
            wrote([])
        elif commands and (not frames or commands[0][0] <= frames[0][0]):
            now, command = commands.pop(0)
            arrived[command.tick] = now
            wrote(bridge.command(command, now))
        else:
            now, frame = frames.pop(0)
            for m in feed(bridge, frame):
                back = max([now + round_trip_s(m.tick)] + [t for t, _ in commands[-1:]])
                commands.append((back, Command(2, m.tick, m.force)))
            wrote([])


def test_a_command_back_too_late_to_name_its_tick_is_refused_and_the_watchdog_covers_it() -> None:
    """Why a bridge cannot promise a frame on every tick: the agent's command for tick ``k``
    names it by ``k mod 16`` only while the bus has opened at most 15 later ticks, so one
    that comes back later is refused and counted; and the watchdog commands zero force only
    once no valid command came for ``watchdog_s``. A round trip that grows past 15 ticks (a
    backlog on the agent's side: a flood on a loaded machine) leaves ticks without a frame:
    the driver keeps the force it was last given, for at most the watchdog time. What the
    bridge promises instead, checked here: every command is forwarded naming its tick, or
    refused as too old, and counted, never lost; and the driver never goes longer than
    ``watchdog_s`` without a ``ForceCommand``, up to the zero force after the agent's last
    command."""
    ticks = 300

    def round_trip_s(k: int) -> float:  # 40 ms, a backlog up to 400 ms, then 40 ms again
        return 0.04 + max(0.0, 0.36 - abs(k - 150) * 0.006)

    bridge, arrived, written = _late_agent_run(round_trip_s, ticks)
    assert sorted(arrived) == list(range(ticks))
    # The bus's newest tick when a command arrived (none arrives on a tick's instant).
    in_time = [k for k in range(ticks) if min(ticks - 1, int(arrived[k] / PERIOD)) - k <= 15]
    assert 0 < len(in_time) < ticks
    commands = [f for _, f in written if f.apply]
    assert [(f.counter, f.force) for f in commands] == [(k % 16, (k * 0.25, -3.0)) for k in in_time]
    assert bridge.rejects.reasons["command", "too old"] == ticks - len(in_time)
    assert bridge.rejects.counts["command"] == ticks - len(in_time)
    assert bridge.counts["measurements"] == ticks and bridge.counts["missed ticks"] == 0
    # Fewer frames than ticks while the bus ticked: the count the HIL test may not expect.
    assert len([t for t, _ in written if t <= arrived[ticks - 1]]) < ticks
    times = [t for t, _ in written]
    assert max(b - a for a, b in zip(times, times[1:])) <= 0.1 + 2e-4
    assert times[-1] > arrived[ticks - 1] + 0.9  # zero force on to the end
    assert not written[-1][1].apply and bridge.tripped


def test_next_check_is_the_watchdogs_deadline() -> None:
    bridge = make_bridge(watchdog_s=0.1)
    feed(bridge, Sync(0))
    bridge.command(Command(2, 0, (1.0, 1.0)), at=5.0)
    due = bridge.next_check(5.0)
    assert 5.1 < due < 5.101
    assert bridge.watchdog(due) != []


# ------------------------------------------------------------------------- tick sources
def test_clock_ticks_come_from_the_synchronised_clock() -> None:
    wall = Clock(EPOCH + 1234 * PERIOD + 0.004)
    ticks = ClockTicks(PERIOD)
    assert ticks.latest(wall()) == 1234
    assert ticks.tick_of(1234 % 16, wall()) == 1234
    assert ticks.tick_of((1234 - 3) % 16, wall()) == 1231  # three periods in transit
    bridge = make_bridge(ticks=ticks, wall=wall)
    (m,) = feed(bridge, Odometry(2, 1234 % 16, (0.1, 0.0)), AppliedForce(2, 1234 % 16, (1, 1)))
    assert m.tick == 1234 and math.isclose(m.time_s, 12.34)
    decode(Measurement, encode(m))  # within the protocol's domains


def test_sync_ticks_follow_the_bus() -> None:
    ticks = SyncTicks()
    assert ticks.latest(0.0) is None and ticks.tick_of(0, 0.0) is None
    ticks.opened(33)
    assert ticks.tick_of(1, 0.0) == 33 and ticks.tick_of(2, 0.0) is None


def test_the_status_crosses_the_wire() -> None:
    bridge = make_bridge()
    feed(bridge, *tick_frames(0), Heartbeat(2, 0, 2, 1))
    status = bridge.status()
    assert decode(BridgeStatus, encode(status)) == status


# ------------------------------------------------------------------------- config
ROBOT = """robot = 2
n = 4
neighbours = [1, 3]
team = "t"
[zenoh]
connect = ["tcp/127.0.0.1:7447"]
"""


def test_the_config_is_the_robots_toml_with_a_can_table(tmp_path) -> None:
    from agent.node import load_agent_config

    path = tmp_path / "robot.toml"
    path.write_text(ROBOT + '[can]\nchannel = "vcan2"\nwatchdog_ms = 50\n', encoding="utf-8")
    config = load_bridge_config(path)
    assert config.can == CanSettings(channel="vcan2", watchdog_ms=50)
    assert config.node == 2 and config.robot.robot == 2
    assert config.zenoh.mode == "client" and config.zenoh.listen == ()
    assert load_agent_config(path).robot == 2  # the agent reads the same file


@pytest.mark.parametrize(
    "table, words",
    [
        ("", "can: missing"),
        ('[can]\ntime_source = "gps"', "can.time_source"),
        ("[can]\nwatchdog_ms = 1", "can.watchdog_ms"),
        ('[can]\nwatchdog_clock = "sim"', "can.watchdog_clock: expected wall or bus"),
        ('[can]\nwatchdog_clock = "bus"\ntime_source = "clock"', "bus needs the bus's Sync"),
        ("[can]\nnode = 33", "can.node"),
        ('[can]\ninterface = "socket can"', "can.interface"),
        ("[can]\nbaud = 5", "can.baud: unknown key"),
    ],
)
def test_a_bad_can_table_is_one_line_naming_the_key(tmp_path, table: str, words: str) -> None:
    path = tmp_path / "robot.toml"
    path.write_text(ROBOT + table + "\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=words) as caught:
        load_bridge_config(path)
    assert "\n" not in str(caught.value)


# ------------------------------------------------------------------------- the loop
class RecordingPort(AgentsPort):
    """The robot's side of the seam, recording what the bridge sends and reports."""

    def __init__(self) -> None:
        super().__init__([2], RejectLog(LOG, "bridge"))
        self.sent: list[Measurement] = []
        self.reports: list[BridgeStatus] = []

    def send(self, measurement: Measurement) -> None:
        self.sent.append(measurement)

    def report(self, message) -> None:
        self.reports.append(message)

    def close(self) -> None:
        pass


@contextlib.contextmanager
def bridge_on_virtual_bus(tmp_path, table: str, channel: str):
    """``heft bridge``'s loop for robot 2's ``robot.toml`` with the ``[can]`` ``table`` (on
    the python-can virtual bus ``channel``), running in a thread: yields its port and the
    driver's side of the bus. On leaving, the bridge stops (and must have); the bus stays open
    for the frames it sent as it stopped (the caller shuts it)."""
    path = tmp_path / "robot.toml"
    path.write_text(ROBOT + table, "utf-8")
    config = load_bridge_config(path)
    driver = can.Bus(interface="virtual", channel=channel)
    port = RecordingPort()
    node = BridgeNode(config, port)
    node.open()
    runner = threading.Thread(target=node.run)
    runner.start()
    try:
        yield port, driver
    finally:
        node.stop.set()
        runner.join(5)
        node._close_bus()
    assert not runner.is_alive()


def answer(port: RecordingPort, tick: int, force) -> None:
    """The agent's command for ``tick``, once the bridge has published that tick's
    measurement (within 2 s)."""
    deadline = time.monotonic() + 2.0
    while len(port.sent) <= tick and time.monotonic() < deadline:
        time.sleep(0.001)
    port.events.put((time.perf_counter(), Command(2, tick, force)))


def test_the_bridge_loop_on_a_virtual_bus(tmp_path) -> None:
    """Driver frames on a python-can virtual bus → measurements; commands → frames; the
    watchdog's zero force once commands stop; zero force again when the bridge stops."""
    table = '[can]\ninterface = "virtual"\nchannel = "t-loop"\n'
    with bridge_on_virtual_bus(tmp_path, table, "t-loop") as (port, driver):
        seen: list = []
        for tick in range(30):
            for frame in tick_frames(tick):
                driver.send(CODEC.encode(frame))
            answer(port, tick, (float(tick), 1.0))
            while (message := driver.recv(0.5)) is not None:
                seen.append(CODEC.decode(message))
                if isinstance(seen[-1], ForceCommand):
                    break
        assert [m.tick for m in port.sent] == list(range(30))
        commands = [f for f in seen if isinstance(f, ForceCommand)]
        assert [(f.counter, f.force, f.apply) for f in commands] == [
            (t % 16, (float(t), 1.0), True) for t in range(30)
        ]
        zero = driver.recv(1.0)  # nothing more from the agent: the watchdog (100 ms)
        assert zero is not None and CODEC.decode(zero).apply is False
        assert any(r.watchdog for r in port.reports if isinstance(r, BridgeStatus))
    last = None
    while (message := driver.recv(0.2)) is not None:
        last = CODEC.decode(message)
    assert last == ForceCommand(2, 29 % 16, (0.0, 0.0), False)
    driver.shutdown()


def test_on_the_bus_clock_only_ticks_without_a_command_are_a_silence(tmp_path) -> None:
    """``watchdog_clock = "bus"`` (a lockstep simulation): commands come 0.3 s of wall time
    apart, three times the 100 ms watchdog, each for the tick the bus opened: no zero force.
    Then the bus opens ticks that get no command: zero force once ten of them (100 ms at
    10 ms) have gone by since the last command's, and not before."""
    table = '[can]\ninterface = "virtual"\nchannel = "t-bus"\nwatchdog_clock = "bus"\n'
    with bridge_on_virtual_bus(tmp_path, table, "t-bus") as (port, driver):
        for tick in range(5):
            for frame in tick_frames(tick):
                driver.send(CODEC.encode(frame))
            time.sleep(0.3)
            answer(port, tick, (1.0, 0.0))
            reply = CODEC.decode(driver.recv(1.0))
            assert reply == ForceCommand(2, tick, (1.0, 0.0), True)
        assert not any(r.watchdog for r in port.reports if isinstance(r, BridgeStatus))
        zero_at = None
        for tick in range(5, 20):
            for frame in tick_frames(tick):
                driver.send(CODEC.encode(frame))
            if (message := driver.recv(0.05)) is not None:
                assert CODEC.decode(message) == ForceCommand(2, tick % 16, (0.0, 0.0), False)
                zero_at = tick if zero_at is None else zero_at
        assert zero_at in (14, 15)  # (k - 4) T > 100 ms, k = 14 as it rounds
        assert any(r.watchdog for r in port.reports if isinstance(r, BridgeStatus))
    driver.shutdown()


def test_a_bus_that_cannot_be_opened_is_one_line() -> None:
    with pytest.raises(Exception, match="CAN bus nosuch/x: cannot open it") as caught:
        open_bus(CanSettings(interface="nosuch", channel="x"))
    assert "\n" not in str(caught.value)


PROFILE_TICKS = {
    "force": tick_frames,
    "velocity": lambda tick: [
        Sync(tick),
        MotionFeedback(2, tick % 16, (0.5, -0.25)),
        ForceTorque(2, tick % 16, (10.0, -3.0)),
    ],
}
"""Each profile's frames of one tick from AGV node 2 (the velocity profile's: its base's and
its force/torque sensor's)."""


@pytest.mark.parametrize("profile", PROFILES)
def test_100000_random_frames_are_counted_by_reason_while_the_valid_traffic_flows(
    tmp_path, profile: str
) -> None:
    """The bridge's loop on a virtual bus takes 100 000 frames it must refuse (random ids,
    lengths, payloads, error and remote frames, the other profile's frames), in bursts
    between the driver's ticks: it keeps running, turns every tick into a measurement and
    every command into a frame (the velocity profile's: the admittance loop's
    ``MotionCommand``), and its counters say exactly what was sent, reason by reason."""
    codec = AgvCodec(profile)
    path = tmp_path / "robot.toml"
    table = f'[can]\ninterface = "virtual"\nchannel = "t-random"\nprofile = "{profile}"\n'
    path.write_text(ROBOT + table, "utf-8")
    node = BridgeNode(load_bridge_config(path), RecordingPort())
    driver = can.Bus(interface="virtual", channel="t-random", receive_own_messages=False)
    junk, reasons = random_frames(100_000, seed=8, codec=codec)
    assert set(reasons) == set(REASONS)  # every reason drawn
    bus_off = sum(1 for m in junk if m.is_error_frame and m.arbitration_id & CAN_ERR_BUSOFF)
    node.open()
    runner = threading.Thread(target=node.run)
    runner.start()
    ticks = 200
    try:
        deadline = time.monotonic() + 120
        for tick in range(ticks):
            for message in junk[tick * 250 : (tick + 1) * 250]:
                driver.send(message)
            for frame in PROFILE_TICKS[profile](tick):
                driver.send(codec.encode(frame))
            for message in junk[(tick + ticks) * 250 : (tick + ticks + 1) * 250]:
                driver.send(message)
            while len(node.port.sent) <= tick:  # the agent answers once it has the sample
                assert time.monotonic() < deadline and runner.is_alive()
                time.sleep(0.001)
            node.port.events.put((time.perf_counter(), Command(2, tick, (1.0, 2.0))))
        while node.bridge.counts["frames in"] < len(junk) + 3 * ticks:
            assert time.monotonic() < deadline and runner.is_alive()
            time.sleep(0.05)
        answers = []  # the commands' frames (then the watchdog's, once commands stop)
        while len([f for f in answers if driving(f)]) < ticks:
            message = driver.recv(2.0)
            assert message is not None, f"{len(answers)} frames back, then nothing"
            answers.append(codec.decode(message))
    finally:
        node.stop.set()
        runner.join(10)
        node._close_bus()
        driver.shutdown()
    bridge = node.bridge
    assert [m.tick for m in node.port.sent] == list(range(ticks))
    assert [f.counter for f in answers if driving(f)] == [t % 16 for t in range(ticks)]
    assert bridge.counts["frames in"] == len(junk) + 3 * ticks
    assert bridge.counts["bus errors"] == sum(1 for m in junk if m.is_error_frame)
    expected = {("can frame", why): n for why, n in reasons.items()}
    expected["can frame", "error frame"] -= bus_off
    expected["can frame", "bus off"] = bus_off
    assert dict(bridge.rejects.reasons) == {k: n for k, n in expected.items() if n}
    assert bridge.status().decode_errors == len(junk) - bus_off
    assert bridge.status().profile == profile
    assert bridge.counts["missed ticks"] == 0 and bridge.counts["counter jumps"] == 0


def driving(frame: ForceCommand | MotionCommand) -> bool:
    """Whether the bridge's frame carries a command (not the watchdog's zero force or STOP)."""
    return frame.apply if isinstance(frame, ForceCommand) else frame.drive


def test_a_frame_counts_from_when_it_was_on_the_bus() -> None:
    """A frame that waited 30 ms for the reader counts from its receive timestamp (the
    kernel's, on the wall clock), on the watchdog's clock; a stamp that is not on this host's
    wall clock (an adapter's own epoch, or in the future) counts from the reading."""
    before = time.monotonic()
    waited = bus_time(can.Message(timestamp=time.time() - 0.030))
    assert before - 0.032 < waited < time.monotonic() - 0.029
    for stamp in (0.0, time.time() - 2 * BUS_TIME_S, time.time() + 0.5):
        before = time.monotonic()
        assert before <= bus_time(can.Message(timestamp=stamp)) <= time.monotonic()


def test_the_log_written_aside_is_all_written_through_the_handlers_it_had() -> None:
    """Inside :func:`log_aside` a record is handed over where it is made and written by
    another thread through the root logger's handlers; every one is written, in order, by the
    end of the block, and the handlers are the root's again."""

    class Kept(logging.Handler):
        def __init__(self) -> None:
            super().__init__()
            self.lines: list[tuple[str, str]] = []

        def emit(self, record: logging.LogRecord) -> None:
            self.lines.append((threading.current_thread().name, record.getMessage()))

    root = logging.getLogger()
    kept = Kept()
    before = root.handlers[:]
    root.handlers = [kept]
    try:
        with log_aside():
            for k in range(100):
                logging.getLogger("heft.bridge").warning("line %d", k)
        assert [line for _, line in kept.lines] == [f"line {k}" for k in range(100)]
        assert threading.current_thread().name not in {name for name, _ in kept.lines}
        assert root.handlers == [kept]
    finally:
        root.handlers = before
