"""The AGV CAN protocol on its own: ``bridge/agv.dbc`` is the file ``bridge/dbc.py`` declares,
every frame kind round-trips through :class:`bridge.codec.AgvCodec` at the DBC's resolution,
the signals sit where the DBC says, and every reject reason is produced by a crafted frame.
(cantools' own command reading the DBC: tests/integration/test_dbc_with_cantools.py.)"""

from __future__ import annotations

import math

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bridge.codec import (
    REASONS,
    AgvCodec,
    AppliedForce,
    ForceCommand,
    ForceTorque,
    FrameError,
    Heartbeat,
    MotionCommand,
    MotionFeedback,
    Odometry,
    Sync,
    checksum,
    clamp_command_velocity,
    clamp_force,
)
from bridge.dbc import (
    APPLIED_FORCE_BASE,
    DBC_PATHS,
    DRIVER_MODES,
    FAULT_BITS,
    FORCE_COMMAND_BASE,
    FORCE_RESOLUTION,
    FORCE_TORQUE_BASE,
    HEARTBEAT_BASE,
    MAX_COMMAND_SPEED,
    MAX_FORCE,
    MAX_SPEED,
    MOTION_COMMAND_BASE,
    MOTION_FEEDBACK_BASE,
    ODOMETRY_BASE,
    SPEED_RESOLUTION,
    SYNC_ID,
    build,
)

CODEC = AgvCodec()
NODES = (1, 17, 32)
COUNTERS = range(16)
HALF_SPEED = SPEED_RESOLUTION / 2 * (1 + 1e-9)
"""Half a velocity step, with room for the float rounding of ``raw * scale`` only."""
HALF_FORCE = FORCE_RESOLUTION / 2 * (1 + 1e-9)


def round_trip(frame):
    msg = CODEC.encode(frame)
    assert msg.dlc == 8 and len(msg.data) == 8
    assert not msg.is_extended_id and not msg.is_remote_frame and not msg.is_error_frame
    return msg, CODEC.decode(msg)


def with_checksum(frame_id: int, data: bytes | bytearray) -> bytes:
    """``data`` (8 bytes) with byte 7 replaced by the checksum the protocol expects."""
    data = bytearray(data)
    data[7] = checksum(frame_id, data)
    return bytes(data)


def data_frame(frame_id: int, data: bytes, **kwargs) -> can.Message:
    return can.Message(
        arbitration_id=frame_id, is_extended_id=False, dlc=len(data), data=data, **kwargs
    )


def reason_of(msg: can.Message) -> str:
    with pytest.raises(FrameError) as caught:
        CODEC.decode(msg)
    assert caught.value.reason in REASONS
    return caught.value.reason


# ------------------------------------------------------------------------------ the DBC file
def test_the_committed_dbc_is_what_dbc_py_builds() -> None:
    # Bytes, not text: cantools writes CRLF line ends, which text mode would translate.
    for profile, path in DBC_PATHS.items():
        assert path.read_bytes().decode("ascii") == build(profile).as_dbc_string(), (
            f"{path.name} is out of date: run python -m bridge.dbc"
        )


# ------------------------------------------------------------------------------ round trips
@pytest.mark.parametrize("node", NODES)
def test_every_per_node_frame_round_trips_for_every_counter(node: int) -> None:
    velocity = (1.234567, -0.000042)
    force = (123.4567, -0.0042)
    for counter in COUNTERS:
        msg, back = round_trip(Odometry(node, counter, velocity))
        assert msg.arbitration_id == ODOMETRY_BASE + node
        assert type(back) is Odometry and (back.node, back.counter) == (node, counter)
        assert back.velocity == pytest.approx(velocity, abs=HALF_SPEED)

        msg, back = round_trip(ForceCommand(node, counter, force))
        assert msg.arbitration_id == FORCE_COMMAND_BASE + node
        assert type(back) is ForceCommand and (back.node, back.counter) == (node, counter)
        assert back.apply is True
        assert back.force == pytest.approx(force, abs=HALF_FORCE)

        msg, back = round_trip(AppliedForce(node, counter, force))
        assert msg.arbitration_id == APPLIED_FORCE_BASE + node
        assert type(back) is AppliedForce and (back.node, back.counter) == (node, counter)
        assert back.force == pytest.approx(force, abs=HALF_FORCE)

        mode = counter % len(DRIVER_MODES)
        faults = (1 << (counter % len(FAULT_BITS))) | (1 if counter >= 8 else 0)
        msg, back = round_trip(Heartbeat(node, counter, mode, faults))
        assert msg.arbitration_id == HEARTBEAT_BASE + node
        assert back == Heartbeat(node, counter, mode, faults)


@pytest.mark.parametrize("node", NODES)
@pytest.mark.parametrize("counter", (0, 7, 15))
def test_a_zero_mode_command_decodes_to_no_force(node: int, counter: int) -> None:
    msg, back = round_trip(ForceCommand(node, counter, (321.0, -123.0), apply=False))
    assert back == ForceCommand(node, counter, (0.0, 0.0), apply=False)
    assert msg.data[6] & 0x0F == 0  # Mode ZERO
    assert msg.data[:6] == bytes(6)  # and no force on the wire either


def test_sync_round_trips_its_tick_and_counts_modulo_16() -> None:
    for tick in [*range(40), 2**31, 2**32 - 1]:
        msg, back = round_trip(Sync(tick))
        assert msg.arbitration_id == SYNC_ID
        assert back == Sync(tick) and back.counter == tick % 16
        assert msg.data[6] >> 4 == tick % 16
    # The Tick field is 32 bits: a later tick is sent modulo 2^32.
    assert round_trip(Sync(2**32 + 5))[1] == Sync(5)


@pytest.mark.parametrize("node", NODES)
@pytest.mark.parametrize("sign", (1.0, -1.0))
def test_the_extremes_of_each_range_round_trip(node: int, sign: float) -> None:
    speed, force = sign * MAX_SPEED, sign * MAX_FORCE
    _, back = round_trip(Odometry(node, 15, (speed, -speed)))
    assert back.velocity == pytest.approx((speed, -speed), abs=HALF_SPEED)
    for kind in (ForceCommand, AppliedForce):
        _, back = round_trip(kind(node, 15, (force, -force)))
        assert back.force == pytest.approx((force, -force), abs=HALF_FORCE)
    # One step inside the extreme is still one step inside, not rounded onto it.
    inside = speed - sign * SPEED_RESOLUTION
    _, back = round_trip(Odometry(node, 0, (inside, 0.0)))
    assert back.velocity[0] == pytest.approx(inside, abs=HALF_SPEED)
    assert back.velocity[0] != speed


def test_the_signals_sit_where_the_dbc_says() -> None:
    """Packs frames by hand from the documented layout (little-endian, two's complement)."""

    def packed(fields: list[tuple[int, int, int]], frame_id: int) -> bytes:
        word = 0
        for start, length, raw in fields:
            word |= (raw & ((1 << length) - 1)) << start
        return with_checksum(frame_id, word.to_bytes(8, "little"))

    odometry = CODEC.encode(Odometry(5, 9, (1234567e-6, -7654321e-6)))
    assert bytes(odometry.data) == packed([(0, 25, 1234567), (25, 25, -7654321), (52, 4, 9)], 0x185)

    command = CODEC.encode(ForceCommand(32, 3, (-4999999e-4, 1e-4)))
    assert bytes(command.data) == packed(
        [(0, 24, -4999999), (24, 24, 1), (48, 4, 1), (52, 4, 3)], 0x220
    )

    applied = CODEC.encode(AppliedForce(2, 14, (0.0, -1e-4)))
    assert bytes(applied.data) == packed([(0, 24, 0), (24, 24, -1), (52, 4, 14)], 0x282)

    heartbeat = CODEC.encode(Heartbeat(7, 11, 4, 0b100001))
    assert bytes(heartbeat.data) == packed([(0, 4, 4), (8, 8, 0b100001), (52, 4, 11)], 0x707)

    sync = CODEC.encode(Sync(0xDEADBEEF))
    assert bytes(sync.data) == packed([(0, 32, 0xDEADBEEF), (52, 4, 0xF)], 0x080)


def test_the_checksum_is_crc8_sae_j1850_over_the_id_and_bytes_0_to_6() -> None:
    # The id's two bytes little-endian ("12") then bytes 0-6 ("3456789"): CRC-8/SAE-J1850's
    # published check value for "123456789" is 0x4B. Byte 7 is not covered.
    frame_id = int.from_bytes(b"12", "little")
    assert checksum(frame_id, b"3456789") == 0x4B
    assert checksum(frame_id, b"3456789\xff") == 0x4B


# ------------------------------------------------------------------------------ quantisation
speeds = st.floats(min_value=-MAX_SPEED, max_value=MAX_SPEED, allow_nan=False)
forces = st.floats(min_value=-MAX_FORCE, max_value=MAX_FORCE, allow_nan=False)


@settings(max_examples=200, deadline=None, database=None)
@given(vx=speeds, vy=speeds, node=st.sampled_from(NODES), counter=st.integers(0, 15))
def test_velocities_cross_the_bus_quantised(vx: float, vy: float, node: int, counter: int):
    quantised = CODEC.quantize_velocity((vx, vy))
    assert abs(quantised[0] - vx) <= HALF_SPEED and abs(quantised[1] - vy) <= HALF_SPEED
    _, back = round_trip(Odometry(node, counter, (vx, vy)))
    assert back.velocity == quantised  # exactly what a receiver decodes
    assert CODEC.quantize_velocity(quantised) == quantised


@settings(max_examples=200, deadline=None, database=None)
@given(fx=forces, fy=forces, node=st.sampled_from(NODES), counter=st.integers(0, 15))
def test_forces_cross_the_bus_quantised(fx: float, fy: float, node: int, counter: int):
    quantised = CODEC.quantize_force((fx, fy))
    assert abs(quantised[0] - fx) <= HALF_FORCE and abs(quantised[1] - fy) <= HALF_FORCE
    for kind in (ForceCommand, AppliedForce):
        _, back = round_trip(kind(node, counter, (fx, fy)))
        assert back.force == quantised
    assert CODEC.quantize_force(quantised) == quantised


# ------------------------------------------------------------------------------ refused input
def valid(frame) -> can.Message:
    return CODEC.encode(frame)


def set_nibble(msg: can.Message, byte: int, high: bool, value: int) -> bytes:
    """``msg``'s data with one nibble replaced and the checksum made right again."""
    data = bytearray(msg.data)
    data[byte] = (data[byte] & 0x0F) | (value << 4) if high else (data[byte] & 0xF0) | value
    return with_checksum(msg.arbitration_id, data)


def out_of_range_velocity() -> bytes:
    raw = round(MAX_SPEED * 1.03 / SPEED_RESOLUTION)  # fits 25 bits, beyond the DBC's ±16 m/s
    assert raw < 2**24
    return with_checksum(0x181, (raw & (2**25 - 1)).to_bytes(8, "little"))


ODO = valid(Odometry(1, 4, (0.5, -0.25)))
CMD = valid(ForceCommand(17, 2, (10.0, -10.0)))
BEAT = valid(Heartbeat(32, 1, 2))
SYNC = valid(Sync(21))

CRAFTED = {
    "error frame": can.Message(arbitration_id=0x181, is_error_frame=True, dlc=8, data=ODO.data),
    "remote frame": can.Message(arbitration_id=0x181, is_remote_frame=True, dlc=8),
    "extended id": can.Message(arbitration_id=0x181, is_extended_id=True, dlc=8, data=ODO.data),
    "unknown id 0x123": data_frame(0x123, with_checksum(0x123, ODO.data)),
    "unknown id node 0": data_frame(0x180, with_checksum(0x180, ODO.data)),
    "unknown id node 33": data_frame(0x221, with_checksum(0x221, CMD.data)),
    "wrong length dlc 7": data_frame(0x181, bytes(ODO.data[:7])),
    "wrong length dlc 0": data_frame(0x181, b""),
    "checksum": data_frame(0x181, bytes([ODO.data[0] ^ 0x01]) + bytes(ODO.data[1:])),
    "out of range command mode": data_frame(0x211, set_nibble(CMD, 6, False, 5)),
    "out of range driver mode": data_frame(0x720, set_nibble(BEAT, 0, False, 9)),
    "out of range sync counter": data_frame(SYNC_ID, set_nibble(SYNC, 6, True, 6)),
    "out of range velocity": data_frame(0x181, out_of_range_velocity()),
    "wrong profile": AgvCodec("velocity").encode(MotionCommand(1, 3, (0.5, -0.5))),
}


@pytest.mark.parametrize("case", sorted(CRAFTED))
def test_a_crafted_frame_is_rejected_with_its_reason(case: str) -> None:
    expected = next(reason for reason in REASONS if case.startswith(reason))
    assert reason_of(CRAFTED[case]) == expected


def test_the_crafted_frames_produce_every_reason() -> None:
    produced = {reason_of(msg) for msg in CRAFTED.values()}
    assert produced == set(REASONS)


def test_the_crafted_frames_are_valid_but_for_their_one_defect() -> None:
    """Guards the cases above: the frames they were made from decode."""
    assert CODEC.decode(ODO) == Odometry(1, 4, (0.5, -0.25))
    assert CODEC.decode(CMD) == ForceCommand(17, 2, (10.0, -10.0))
    assert CODEC.decode(BEAT) == Heartbeat(32, 1, 2)
    assert CODEC.decode(SYNC) == Sync(21)
    # Re-checksummed but unchanged, a frame still decodes: the checksum helper is the codec's.
    assert CODEC.decode(data_frame(0x211, set_nibble(CMD, 6, False, 1))) == CODEC.decode(CMD)


@pytest.mark.parametrize("frame", [ODO, CMD, BEAT, SYNC], ids=["odo", "cmd", "beat", "sync"])
def test_any_single_flipped_bit_fails_the_checksum(frame: can.Message) -> None:
    for bit in range(64):
        data = bytearray(frame.data)
        data[bit // 8] ^= 1 << (bit % 8)
        assert reason_of(data_frame(frame.arbitration_id, bytes(data))) == "checksum", bit


@pytest.mark.parametrize("node", (1, 17))
def test_a_frame_sent_on_another_nodes_id_fails_the_checksum(node: int) -> None:
    for frame in (
        Odometry(node, 3, (0.1, 0.2)),
        ForceCommand(node, 3, (1.0, 2.0)),
        ForceCommand(node, 3, (0.0, 0.0), apply=False),
        AppliedForce(node, 3, (1.0, 2.0)),
        Heartbeat(node, 3, 1),
    ):
        msg = CODEC.encode(frame)
        moved = data_frame(msg.arbitration_id + 1, bytes(msg.data))
        assert reason_of(moved) == "checksum", frame


@pytest.mark.parametrize("node", (0, 33, -1))
@pytest.mark.parametrize(
    "frame",
    [
        lambda n: Odometry(n, 0, (0.0, 0.0)),
        lambda n: ForceCommand(n, 0, (0.0, 0.0)),
        lambda n: AppliedForce(n, 0, (0.0, 0.0)),
        lambda n: Heartbeat(n, 0, 1),
    ],
    ids=["odometry", "command", "applied", "heartbeat"],
)
def test_encode_refuses_node_ids_outside_1_to_32(node: int, frame) -> None:
    with pytest.raises(ValueError, match="node id"):
        CODEC.encode(frame(node))


@pytest.mark.parametrize(
    "frame",
    [
        Odometry(1, 0, (MAX_SPEED * 1.5, 0.0)),
        Odometry(1, 0, (0.0, -MAX_SPEED * 1.5)),
        ForceCommand(1, 0, (MAX_FORCE * 1.5, 0.0)),
        AppliedForce(1, 0, (0.0, -MAX_FORCE * 1.5)),
        Odometry(1, 16, (0.0, 0.0)),
        Heartbeat(1, 0, 1, faults=256),
        Heartbeat(1, 0, 7),
    ],
    ids=["vx", "vy", "command fx", "applied fy", "counter 16", "faults 256", "mode 7"],
)
def test_encode_refuses_values_outside_the_dbc(frame) -> None:
    """What the encoder refuses, the decoder would reject: no valid-looking invalid frame."""
    with pytest.raises(ValueError):
        CODEC.encode(frame)


def test_clamp_force_clamps_to_the_range_and_reports_it() -> None:
    assert clamp_force((100.0, -200.0)) == ((100.0, -200.0), False)
    assert clamp_force((MAX_FORCE, -MAX_FORCE)) == ((MAX_FORCE, -MAX_FORCE), False)
    assert clamp_force((750.0, -10.0)) == ((MAX_FORCE, -10.0), True)
    assert clamp_force((1.0, -1e9)) == ((1.0, -MAX_FORCE), True)
    assert clamp_force((-600.0, 600.0)) == ((-MAX_FORCE, MAX_FORCE), True)
    force, clamped = clamp_force((2 * MAX_FORCE, -3 * MAX_FORCE))
    assert clamped
    assert CODEC.decode(CODEC.encode(ForceCommand(1, 0, force))).force == (MAX_FORCE, -MAX_FORCE)


@pytest.mark.parametrize(
    "frame",
    [
        Odometry(1, 0, (math.nan, 0.0)),
        Odometry(1, 0, (0.0, math.nan)),
        ForceCommand(1, 0, (math.nan, 0.0)),
        AppliedForce(1, 0, (0.0, math.nan)),
        # clamp_force leaves NaN to the caller; it does not turn it into a number.
        ForceCommand(1, 0, clamp_force((math.nan, 1.0))[0]),
        Odometry(1, 0, (math.inf, 0.0)),
        AppliedForce(1, 0, (0.0, -math.inf)),
    ],
    ids=["odometry vx", "odometry vy", "command fx", "applied fy", "clamped nan", "inf", "-inf"],
)
def test_encode_refuses_non_finite_values(frame) -> None:
    with pytest.raises(ValueError, match="not a finite number"):
        CODEC.encode(frame)


# ------------------------------------------------------------------------------ velocity profile
VELOCITY = AgvCodec("velocity")


def velocity_round_trip(frame):
    msg = VELOCITY.encode(frame)
    assert msg.dlc == 8 and not msg.is_extended_id
    return msg, VELOCITY.decode(msg)


@pytest.mark.parametrize("node", NODES)
def test_every_velocity_frame_round_trips_for_every_counter(node: int) -> None:
    velocity = (1.234567, -0.000042)
    force = (123.4567, -0.0042)
    for counter in COUNTERS:
        msg, back = velocity_round_trip(MotionCommand(node, counter, velocity))
        assert msg.arbitration_id == MOTION_COMMAND_BASE + node
        assert type(back) is MotionCommand and (back.node, back.counter) == (node, counter)
        assert back.drive is True
        assert back.velocity == pytest.approx(velocity, abs=HALF_SPEED)

        msg, back = velocity_round_trip(MotionFeedback(node, counter, velocity))
        assert msg.arbitration_id == MOTION_FEEDBACK_BASE + node
        assert type(back) is MotionFeedback and (back.node, back.counter) == (node, counter)
        assert back.velocity == pytest.approx(velocity, abs=HALF_SPEED)

        status = counter % 4  # none, OVERRANGE, FAULT, both
        msg, back = velocity_round_trip(ForceTorque(node, counter, force, status))
        assert msg.arbitration_id == FORCE_TORQUE_BASE + node
        assert type(back) is ForceTorque and (back.node, back.counter) == (node, counter)
        assert back.status == status
        assert back.force == pytest.approx(force, abs=HALF_FORCE)


@pytest.mark.parametrize("node", NODES)
@pytest.mark.parametrize("counter", (0, 7, 15))
def test_a_stop_decodes_to_standstill(node: int, counter: int) -> None:
    msg, back = velocity_round_trip(MotionCommand(node, counter, (3.0, -2.0), drive=False))
    assert back == MotionCommand(node, counter, (0.0, 0.0), drive=False)
    assert msg.data[6] & 0x0F == 0  # Mode STOP
    assert msg.data[:6] == bytes(6)  # and no velocity on the wire either


@pytest.mark.parametrize("node", NODES)
@pytest.mark.parametrize("sign", (1.0, -1.0))
def test_the_extremes_of_each_velocity_range_round_trip(node: int, sign: float) -> None:
    command, speed, force = sign * MAX_COMMAND_SPEED, sign * MAX_SPEED, sign * MAX_FORCE
    _, back = velocity_round_trip(MotionCommand(node, 15, (command, -command)))
    assert back.velocity == pytest.approx((command, -command), abs=HALF_SPEED)
    _, back = velocity_round_trip(MotionFeedback(node, 15, (speed, -speed)))
    assert back.velocity == pytest.approx((speed, -speed), abs=HALF_SPEED)
    _, back = velocity_round_trip(ForceTorque(node, 15, (force, -force), 0b11))
    assert back.force == pytest.approx((force, -force), abs=HALF_FORCE)
    inside = command - sign * SPEED_RESOLUTION
    _, back = velocity_round_trip(MotionCommand(node, 0, (inside, 0.0)))
    assert back.velocity[0] == pytest.approx(inside, abs=HALF_SPEED) and back.velocity[0] != command
    with pytest.raises(ValueError):
        VELOCITY.encode(MotionCommand(node, 0, (command * 1.01, 0.0)))


@pytest.mark.parametrize(
    "profile, frame",
    [
        ("force", MotionCommand(1, 3, (0.5, -0.5))),
        ("force", MotionFeedback(2, 4, (0.5, -0.5))),
        ("force", ForceTorque(3, 5, (1.0, 2.0))),
        ("velocity", Odometry(1, 3, (0.5, -0.5))),
        ("velocity", ForceCommand(2, 4, (1.0, 2.0))),
        ("velocity", AppliedForce(3, 5, (1.0, 2.0))),
    ],
    ids=lambda v: v if isinstance(v, str) else type(v).__name__,
)
def test_the_other_profiles_frames_are_refused_as_wrong_profile(profile: str, frame) -> None:
    own, other = AgvCodec(profile), AgvCodec("velocity" if profile == "force" else "force")
    msg = other.encode(frame)
    assert other.decode(msg) == frame  # a valid frame, of the other profile
    with pytest.raises(FrameError) as caught:
        own.decode(msg)
    assert caught.value.reason == "wrong profile"


@pytest.mark.parametrize("profile", ["force", "velocity"])
def test_both_profiles_share_sync_and_heartbeat(profile: str) -> None:
    codec = AgvCodec(profile)
    for frame in (Sync(1234), Heartbeat(5, 3, 2, 1)):
        assert codec.decode(codec.encode(frame)) == frame


def test_clamp_command_velocity_clamps_to_the_dbc_and_reports_it() -> None:
    assert clamp_command_velocity((1.0, -2.0)) == ((1.0, -2.0), False)
    top = MAX_COMMAND_SPEED
    assert clamp_command_velocity((9.0, -2.0)) == ((top, -2.0), True)
    assert clamp_command_velocity((-1e9, 1e9)) == ((-top, top), True)
    velocity, clamped = clamp_command_velocity((20.0, -20.0))
    assert clamped and VELOCITY.quantize_command_velocity(velocity) == (top, -top)
