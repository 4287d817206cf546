"""The wire protocol (agent/platform/protocol.py): every message survives encode → decode unchanged,
and whatever else arrives — short, foreign, corrupt, hostile — makes ``decode`` raise
:class:`DecodeError` and nothing else (the agents and the launcher count those and carry on).
Also the key expressions of a team."""

from __future__ import annotations

import json
import math
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.platform.protocol import (
    AGV_PROFILES,
    DOMAINS,
    KINDS,
    LOG_LEVELS,
    MAX_LOG_TEXT,
    WIRE_VERSION,
    Barrier,
    BridgeStatus,
    Clock,
    Command,
    Control,
    DecodeError,
    Estimates,
    Keys,
    LoadGeometry,
    LogLine,
    Measurement,
    Phase,
    PlantStatus,
    Share,
    Status,
    Truth,
    decode,
    encode,
    log_text,
)
from agent.platform.team import ConsensusState, flow_width

STRUCT_KINDS = (Measurement, Command, Share, Clock, Estimates)
JSON_CLASSES = (Status, Truth, Control, PlantStatus, BridgeStatus, LoadGeometry, LogLine)
ALL_KINDS = (*STRUCT_KINDS, *JSON_CLASSES)
KIND_BYTE = {
    Measurement: 1,
    Command: 2,
    Share: 3,
    Clock: 4,
    Estimates: 5,
    Status: 6,
    Truth: 7,
    Control: 8,
    PlantStatus: 9,
    BridgeStatus: 10,
    LoadGeometry: 11,
    LogLine: 12,
}
NOT_FINITE = (math.nan, math.inf, -math.inf)


def header(kind, version: int = WIRE_VERSION, magic: int = 0x48) -> bytes:
    return bytes((magic, version, KIND_BYTE[kind]))


def kind_id(kind) -> str:
    return kind.__name__


def rejects(kind, payload: bytes) -> DecodeError:
    """``decode(kind, payload)`` must raise DecodeError — not return, not raise anything else."""
    try:
        message = decode(kind, payload)
    except DecodeError as err:
        return err
    except Exception as err:  # noqa: BLE001 - the point of the check
        pytest.fail(
            f"decode({kind_id(kind)}, {payload[:60]!r}) raised {type(err).__name__}: {err}"
            " instead of DecodeError"
        )
    pytest.fail(f"decode({kind_id(kind)}, {payload[:60]!r}) accepted it: {message!r}")


# ----------------------------------------------------------------------------- messages
MEASUREMENT = Measurement(robot=3, tick=1234, time_s=12.34, velocity=(0.25, -1.5), force=(2.0, 0))
COMMAND = Command(robot=4, tick=99, force=(-9.5, 3.25))
SHARE_PLAIN = Share(sender=2, tick=7, velocity=(0.1, 0.2), degree=2)
SHARE_CENTROID = Share(
    sender=1,
    tick=500,
    velocity=(-0.5, 0.75),
    degree=1,
    barrier=Barrier(phase=Phase.PUSH, ready=0b1011, switch_at=620, levels=(7, 254)),
    consensus=ConsensusState(centroid_offset=(1.5, -2.25), mean_square_offset=3.125),
)
SHARE_FLOWS = Share(
    sender=3,
    tick=2**40,
    velocity=(1e-9, -100.0),
    degree=2,
    barrier=Barrier(phase=Phase.INERTIA, ready=2**64 - 1, switch_at=-1),
    consensus=ConsensusState(
        mean_square_offset=0.5,
        mean_gain=1.02,
        mean_gain_offset=(0.04, -0.01),
        mean_gain_square_offset=2.5,
    ),
    flows=(
        (
            2,
            0.5,
            -0.25,
            1.0,
            0.02,
            0.1,
            -0.2,
            0.3,
            4.0,
            20.0,
            6.4,
            10.2,
            1.5,
            3.0,
            0.5,
            0.1,
            -0.2,
            1e-6,
        ),
        (
            4,
            -3.0,
            2.0,
            0.0,
            -0.01,
            0.0,
            0.0,
            1e-3,
            0.0,
            -1.0,
            0.0,
            0.0,
            -0.25,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
        ),
    ),
)
CLOCK = Clock(tick=42, time_s=0.42)
ESTIMATES_EMPTY = Estimates(robot=1, tick=0, phase=Phase.EXCITE)
ESTIMATES_FULL = Estimates(
    robot=2,
    tick=4321,
    phase=Phase.PUSH,
    phase_since=4000,
    omega=0.75,
    relative_positions={1: (0.5, -1.25), 3: (-2.0, 0.0)},
    centroid_offset=(0.1, 0.2),
    w=4.5,
    moment=12.3795,
    com_offset=(-0.3, 0.4),
    com_observer=(-0.31, 0.39),
    com_velocity=(0.0, 0.05),
    mass=5.0,
    contact_to_com=(0.2, -0.6),
    started={1: 0, 2: 150, 4: 900},
    settled={1: 140, 4: 1200},
)
ESTIMATES_UNCERTAIN = Estimates(
    robot=3,
    tick=900,
    phase=Phase.DONE,
    phase_since=880,
    relative_positions={2: (0.5, -1.25), 4: (-2.0, 0.0)},
    mass=5.01,
    moment=12.4,
    contact_to_com=(0.2, -0.6),
    mass_std=0.02,
    moment_std=0.05,
    contact_to_com_cov=(4e-6, -1e-6, 9e-6),
    relative_positions_cov={2: (1e-6, 0.0, 2e-6), 4: (3e-6, 1e-6, 1e-6)},
    drive_gain=1.021,
    drive_gain_std=0.008,
)
ESTIMATES_PARTIAL = Estimates(
    robot=4,
    tick=10,
    phase=Phase.INERTIA,
    omega=None,
    relative_positions={3: (1.0, 2.0)},
    centroid_offset=None,
    w=None,
    moment=None,
    started={1: 0},
)
STATUS = Status(
    robot=3,
    tick=88,
    phase=Phase.HALTED,
    rejected=2,
    decode_errors=5,
    late=7,
    lost_neighbours=(2, 4),
)
STATUS_PLAIN = Status(robot=1, tick=0, phase=Phase.EXCITE)
TRUTH = Truth(
    tick=10,
    time_s=0.1,
    com_position=(0.0, -0.138889),
    angle=0.25,
    com_velocity=(0.5, -0.125),
    omega=-0.75,
    contacts=((-2.0, 0.4), (-1.0, -1.0)),
    contact_velocities=((0.1, 0.2), (0.3, 0.4)),
    contact_to_com=((2.0, -0.538889), (1.0, 0.861111)),
    mass=5.0,
    moment=12.3795,
    largest_travel=0.25,
    largest_speed=0.75,
    largest_omega=1.0,
    ground_coulomb=0.02,
    ground_static=0.03,
    ground_viscous=0.5,
    friction_radius=1.2,
    viscous_radius2=1.6,
    friction_force=(-0.9, 0.3),
    friction_torque=0.4,
)
CONTROL = Control("stop")
PLANT_STATUS = PlantStatus(tick=6000, time_s=60.0, clock="realtime", lost=(2,), latency_ms_p50=0.4)
BRIDGE_STATUS = BridgeStatus(robot=2, tick=77, watchdog=True, watchdog_trips=1, frames_in=154)
BRIDGE_STATUS_VELOCITY = BridgeStatus(
    robot=3,
    tick=78,
    profile="velocity",
    force_error_rms=0.125,
    force_error_p95=0.5,
    sensor_stale=True,
    sensor_stale_trips=2,
)
GEOMETRY = LoadGeometry(
    n=3,
    outline=((-1.5, -0.5), (1.5, -0.5), (0.25, 1.0)),
    edges=((1, 2), (2, 3)),
    period_s=0.01,
    end_tick=1200,
)
LOG_LINE = LogLine(robot=2, tick=4321, level="warning", text="robot 2: lost neighbour 3; halting")
LOG_LINE_FIRST = LogLine(robot=1, tick=-1, level="info", text="robot 1: up\n\t(é, ±, →)")

MESSAGES = {
    "measurement": MEASUREMENT,
    "command": COMMAND,
    "share": SHARE_PLAIN,
    "share-centroid": SHARE_CENTROID,
    "share-flows": SHARE_FLOWS,
    "clock": CLOCK,
    "estimates-empty": ESTIMATES_EMPTY,
    "estimates-full": ESTIMATES_FULL,
    "estimates-partial": ESTIMATES_PARTIAL,
    "estimates-uncertain": ESTIMATES_UNCERTAIN,
    "status": STATUS,
    "status-plain": STATUS_PLAIN,
    "truth": TRUTH,
    "control": CONTROL,
    "plant-status": PLANT_STATUS,
    "load-geometry": GEOMETRY,
    "bridge-status": BRIDGE_STATUS,
    "bridge-status-velocity": BRIDGE_STATUS_VELOCITY,
    "log-line": LOG_LINE,
    "log-line-first": LOG_LINE_FIRST,
}


@pytest.mark.parametrize("message", MESSAGES.values(), ids=MESSAGES.keys())
def test_every_message_round_trips(message) -> None:
    payload = encode(message)
    assert payload[:3] == header(type(message))
    back = decode(type(message), payload)
    assert back == message
    assert type(back) is type(message)


def test_a_shares_team_state_survives() -> None:
    assert decode(Share, encode(SHARE_PLAIN)).consensus == ConsensusState()
    assert decode(Share, encode(SHARE_CENTROID)).consensus.centroid_offset == (1.5, -2.25)
    assert decode(Share, encode(SHARE_FLOWS)).consensus.mean_gain_offset == (0.04, -0.01)


def test_estimates_keep_their_dict_keys_as_ints_and_pairs_as_tuples() -> None:
    back = decode(Estimates, encode(ESTIMATES_FULL))
    assert all(type(j) is int for j in back.relative_positions)
    assert all(type(v) is tuple for v in back.relative_positions.values())
    assert all(type(s) is int for s in (*back.started, *back.settled))
    assert type(back.com_offset) is tuple and type(back.contact_to_com) is tuple


def test_status_lost_neighbours_is_a_tuple() -> None:
    assert decode(Status, encode(STATUS)).lost_neighbours == (2, 4)
    # Every field is on the wire: a message with one left out is not this version's.
    payload = header(Status) + b'{"robot":1,"tick":2,"phase":"push"}'
    assert "keys" in str(rejects(Status, payload))


def test_phases_travel_by_name_in_json_and_by_number_in_shares() -> None:
    assert json.loads(encode(STATUS)[3:])["phase"] == "halted"
    assert decode(Share, encode(SHARE_CENTROID)).barrier.phase is Phase.PUSH


@pytest.mark.parametrize("phase", [5, 6, 200, 255])
def test_a_share_with_no_such_phase_is_refused(phase: int) -> None:
    payload = bytearray(encode(SHARE_CENTROID))
    at = 3 + struct.calcsize("<Hq2dHq")  # the phase byte: after sender, tick, velocity, ...
    assert payload[at] == Phase.PUSH
    payload[at] = phase
    assert "phase" in str(rejects(Share, bytes(payload)))


def test_truth_keeps_its_pairs_as_tuples() -> None:
    back = decode(Truth, encode(TRUTH))
    assert type(back.contacts) is tuple and all(type(p) is tuple for p in back.contacts)
    assert back.centroid_offsets == TRUTH.centroid_offsets


def test_control_accepts_only_known_commands() -> None:
    assert "command" in str(rejects(Control, header(Control) + b'{"command":"launch"}'))


def test_encode_refuses_what_is_not_a_message() -> None:
    with pytest.raises(TypeError):
        encode({"robot": 1})
    with pytest.raises(ValueError):
        encode(_with(TRUTH, mass=math.nan))  # never NaN on the wire


def test_every_message_class_has_a_kind_and_a_key() -> None:
    assert KINDS == KIND_BYTE
    keys = Keys("paper")
    for message in MESSAGES.values():
        assert keys.of(message).startswith("heft/paper/")


# ----------------------------------------------------------------------------- struct round trips
finite = st.floats(allow_nan=False, allow_infinity=False)
u16 = st.integers(0, 2**16 - 1)
i64 = st.integers(-(2**63), 2**63 - 1)
pair = st.tuples(finite, finite)


def _messages(ids, ticks, numbers, small) -> st.SearchStrategy:
    """Struct messages built from these field strategies (``small``: counts and phases)."""
    pairs = st.tuples(numbers, numbers)
    shares = st.builds(
        Share,
        sender=ids,
        tick=ticks,
        velocity=pairs,
        degree=small,
        instant=ticks,
        barrier=st.builds(
            Barrier,
            phase=st.sampled_from(Phase),
            ready=st.integers(0, 2**64 - 1),
            switch_at=ticks,
            load_changes=st.integers(0, 10_000),
            rejoins=st.integers(0, 10_000),
            levels=st.tuples(st.integers(0, 255), st.integers(0, 255)),
        ),
        consensus=st.builds(
            ConsensusState,
            centroid_offset=pairs,
            mean_square_offset=numbers,
            mean_gain=st.floats(-100.0, 100.0),
            mean_gain_offset=pairs,
            mean_gain_square_offset=numbers,
            mean_mass_information=numbers,
            mean_weighted_mass=numbers,
            mean_weighted_log_mass=numbers,
            mean_weighted_square_log_mass=numbers,
            mean_spin_torque=numbers,
            mean_kick_level=numbers,
            mean_com_weight=st.floats(0.0, 1.0),
            mean_weighted_com=pairs,
            rotation=st.floats(-math.pi, math.pi),
            rotation_weight=st.floats(0.0, 1e8),
            mean_turn_variance=st.floats(0.0, 100.0),
        ),
        flows=st.lists(st.tuples(ids, *[numbers] * flow_width()), max_size=8).map(tuple),
    )
    maybe = lambda strategy: st.none() | strategy  # noqa: E731
    # (xx, ρ √(xx yy), yy): a covariance whenever xx, yy ≥ 0; anything, from anything.
    covariances = st.tuples(numbers, numbers, st.floats(-1.0, 1.0)).map(
        lambda t: (t[0], t[2] * math.sqrt(abs(t[0])) * math.sqrt(abs(t[1])), t[1])
    )
    estimates = st.builds(
        Estimates,
        robot=ids,
        tick=ticks,
        phase=st.sampled_from(Phase),
        phase_since=ticks,
        omega=maybe(numbers),
        relative_positions=st.dictionaries(ids, pairs, max_size=6),
        centroid_offset=maybe(pairs),
        w=maybe(numbers),
        moment=maybe(numbers),
        com_offset=maybe(pairs),
        com_observer=maybe(pairs),
        com_velocity=maybe(pairs),
        mass=maybe(numbers),
        contact_to_com=maybe(pairs),
        started=st.dictionaries(small, ticks, max_size=7),
        settled=st.dictionaries(small, ticks, max_size=7),
        mass_std=maybe(numbers),
        moment_std=maybe(numbers),
        contact_to_com_cov=maybe(covariances),
        relative_positions_cov=st.dictionaries(ids, covariances, max_size=6),
        drive_gain=maybe(st.floats(0.0, 100.0)),
        drive_gain_std=maybe(numbers),
        load_changes=st.integers(0, 10_000),
        change_score=maybe(st.floats(0.0, 1e6)),
        rejoins=st.integers(0, 10_000),
    )
    return st.one_of(
        st.builds(Measurement, robot=ids, tick=ticks, time_s=numbers, velocity=pairs, force=pairs),
        st.builds(Command, robot=ids, tick=ticks, force=pairs),
        st.builds(Clock, tick=ticks, time_s=numbers),
        shares,
        estimates,
    )


in_domain = _messages(
    st.integers(1, 2**16 - 1), st.integers(0, 2**40), st.floats(0, 300), st.integers(8, 255)
).filter(
    lambda m: (
        (not isinstance(m, Share) or -1 <= m.instant < m.tick)
        and (not isinstance(m, Estimates) or not (m.started or m.settled))
    )
)
anything_on_the_wire = _messages(u16, i64, finite, st.integers(0, 255))


@settings(max_examples=200, deadline=None, database=None)
@given(in_domain)
def test_struct_messages_round_trip_exactly(message) -> None:
    assert decode(type(message), encode(message)) == message


@settings(max_examples=500, deadline=None, database=None)
@given(anything_on_the_wire)
def test_well_encoded_messages_out_of_their_domain_are_refused(message) -> None:
    """Every id, tick and value the wire format can carry: decode gives the message back only
    when each field is within its domain, and otherwise names the field."""
    try:
        payload = encode(message)
    except struct.error:
        return  # not even encodable (a negative id, a tick past 64 bits)
    try:
        DOMAINS[type(message)](message)
    except DecodeError as expected:
        assert str(rejects(type(message), payload)) == str(expected)
    else:
        assert decode(type(message), payload) == message


DOMAIN_CASES = {
    "robot 0": Measurement(0, 1, 0.01, (0.0, 0.0), (0.0, 0.0)),
    "tick past the domain": Command(1, 2**62, (10.0, 0.0)),
    "negative tick": Command(1, -5, (10.0, 0.0)),
    "force of 1e6 N": Command(1, 5, (1e6, 0.0)),
    "velocity of 1 km/s": Measurement(1, 1, 0.01, (1000.0, 0.0), (0.0, 0.0)),
    "share degree 0": Share(sender=2, tick=3, velocity=(0.0, 0.0), degree=0),
    "share instant not before its tick": Share(2, 3, (0.0, 0.0), 1, instant=3),
    "share switch below -1": Share(2, 3, (0.0, 0.0), 1, barrier=Barrier(switch_at=-7)),
    "share mean gain of 1000": Share(
        2, 3, (0.0, 0.0), 1, consensus=ConsensusState(mean_gain=1000.0)
    ),
    "estimates with a negative drive gain": Estimates(1, 3, Phase.DONE, drive_gain=-1.0),
    "estimates with a negative gain std": Estimates(1, 3, Phase.DONE, drive_gain_std=-0.1),
    "share with more flows than neighbours": Share(
        2, 3, (0.0, 0.0), 1, flows=((1, *[0.0] * flow_width()), (3, *[0.0] * flow_width()))
    ),
    "share centroid 1e5 m away": Share(
        2, 3, (0.0, 0.0), 1, consensus=ConsensusState(centroid_offset=(1e5, 0.0))
    ),
}


@pytest.mark.parametrize("message", DOMAIN_CASES.values(), ids=DOMAIN_CASES.keys())
def test_values_out_of_their_domain_are_refused(message) -> None:
    rejects(type(message), encode(message))


NOT_UNCERTAINTIES = {
    "negative mass std": dict(mass_std=-0.1),
    "negative moment std": dict(moment_std=-1e-9),
    "negative variance": dict(contact_to_com_cov=(-1e-6, 0.0, 1e-6)),
    "correlation above one": dict(contact_to_com_cov=(1e-6, 2e-6, 1e-6)),
    "an edge's negative variance": dict(relative_positions_cov={2: (1e-6, 0.0, -1e-6)}),
    "a covariance of robot 0": dict(relative_positions_cov={0: (1e-6, 0.0, 1e-6)}),
}


@pytest.mark.parametrize("changes", NOT_UNCERTAINTIES.values(), ids=NOT_UNCERTAINTIES.keys())
def test_uncertainties_out_of_their_domain_are_refused(changes: dict) -> None:
    assert "estimates" in str(rejects(Estimates, encode(_with(ESTIMATES_UNCERTAIN, **changes))))


def test_json_messages_are_checked_too() -> None:
    assert "robot" in str(rejects(Status, encode(_with(STATUS, robot=0))))
    assert "step" in str(rejects(Estimates, encode(_with(ESTIMATES_FULL, started={9: 1}))))
    assert "clock" in str(rejects(PlantStatus, encode(_with(PLANT_STATUS, clock="sundial"))))
    assert "positive" in str(rejects(Truth, encode(_with(TRUTH, mass=-5.0))))
    assert "largest_speed" in str(rejects(Truth, encode(_with(TRUTH, largest_speed=-0.1))))
    velocity = BRIDGE_STATUS_VELOCITY
    assert "profile" in str(rejects(BridgeStatus, encode(_with(velocity, profile="torque"))))
    error = rejects(BridgeStatus, encode(_with(velocity, force_error_p95=-0.1)))
    assert "force_error_p95" in str(error)
    error = rejects(BridgeStatus, encode(_with(velocity, sensor_stale_trips=-1)))
    assert "sensor_stale_trips" in str(error)


NOT_LOG_LINES = {
    "robot 0": dict(robot=0),
    "a tick below -1": dict(tick=-2),
    "a tick past the domain": dict(tick=2**41),
    "no such level": dict(level="debug"),
    "a level in capitals": dict(level="WARNING"),
    "a text too long": dict(text="x" * (MAX_LOG_TEXT + 1)),
    "an escape sequence": dict(text="robot 2: \x1b[2J cleared"),
    "a carriage return": dict(text="robot 2: ok\rforged"),
    "a NUL": dict(text="robot 2\x00"),
    "a C1 control": dict(text="robot 2: \x9b2J"),
}


@pytest.mark.parametrize("changes", NOT_LOG_LINES.values(), ids=NOT_LOG_LINES.keys())
def test_a_log_line_out_of_its_domain_is_refused(changes: dict) -> None:
    assert "log_line" in str(rejects(LogLine, encode(_with(LOG_LINE, **changes))))


def test_a_log_line_with_a_lone_surrogate_is_refused() -> None:
    """No UTF-8 for it: the wire's JSON refuses it, and the domain check (a recording's JSON
    reader takes it) too."""
    line = _with(LOG_LINE, text="robot 2: \ud800")
    rejects(LogLine, encode(line))
    with pytest.raises(DecodeError, match="log_line.text"):
        DOMAINS[LogLine](line)


LOG_LINE_WRONG_TYPES = {
    "text-number": {"text": 5},
    "text-list": {"text": ["a"]},
    "text-null": {"text": None},
    "level-number": {"level": 20},
    "tick-string": {"tick": "7"},
    "robot-float": {"robot": 2.5},
    "unknown-key": {"colour": "red"},
    "no text": {"text": None, "drop": "text"},
}


@pytest.mark.parametrize("changes", LOG_LINE_WRONG_TYPES.values(), ids=LOG_LINE_WRONG_TYPES.keys())
def test_a_log_line_with_wrong_types_is_refused(changes: dict) -> None:
    body = json.loads(encode(LOG_LINE)[3:]) | changes
    body.pop(body.pop("drop", None), None)
    rejects(LogLine, header(LogLine) + json.dumps(body).encode())


def test_log_text_makes_any_text_a_log_lines() -> None:
    assert log_text("robot 1: fine\n\tindented") == "robot 1: fine\n\tindented"
    assert log_text("a\x1b[31mred\x00\r\x7f\ud800") == "a?[31mred????"
    long = log_text("é" * (MAX_LOG_TEXT + 50))
    assert len(long) == MAX_LOG_TEXT and long.endswith("…")
    for text in ("\x1b" * 5000, "x" * MAX_LOG_TEXT, "\ud800\udc00", "".join(map(chr, range(256)))):
        line = LogLine(1, 0, "info", log_text(text))
        assert decode(LogLine, encode(line)) == line
    assert set(LOG_LEVELS) == {"info", "warning", "error", "critical"}


def test_the_bridges_profiles_are_the_dbcs() -> None:
    from bridge.dbc import PROFILES

    assert AGV_PROFILES == PROFILES


NOT_GROUNDS = {
    "a negative coulomb": dict(ground_coulomb=-0.01),
    "a static below the coulomb": dict(ground_static=0.01),
    "a negative viscous": dict(ground_viscous=-0.5),
    "a negative friction radius": dict(friction_radius=-1.0),
    "a mean radius above its root mean square": dict(friction_radius=1.3),
}


@pytest.mark.parametrize("changes", NOT_GROUNDS.values(), ids=NOT_GROUNDS.keys())
def test_a_truths_ground_out_of_its_domain_is_refused(changes: dict) -> None:
    assert "truth" in str(rejects(Truth, encode(_with(TRUTH, **changes))))


def test_a_truth_without_its_ground_is_refused() -> None:
    """Every field is on the wire: a truth of wire version 8 (no ground) does not decode as one
    of today's, even under today's header."""
    body = json.loads(bytes(encode(TRUTH))[3:])
    del body["friction_torque"]
    assert "keys" in str(rejects(Truth, header(Truth) + json.dumps(body).encode()))


NOT_GEOMETRIES = {
    "one robot": dict(n=1),
    "more robots than a team has": dict(n=33),
    "two vertices": dict(outline=((0.0, 0.0), (1.0, 0.0))),
    "a vertex far away": dict(outline=((0.0, 0.0), (1.0, 0.0), (0.0, 1e4))),
    "an edge to robot 4 of 3": dict(edges=((1, 2), (3, 4))),
    "an edge backwards": dict(edges=((2, 1),)),
    "an edge twice": dict(edges=((1, 2), (1, 2))),
    "a period of a second and more": dict(period_s=1.5),
    "a negative end": dict(end_tick=-1),
}


@pytest.mark.parametrize("changes", NOT_GEOMETRIES.values(), ids=NOT_GEOMETRIES.keys())
def test_a_load_geometry_out_of_its_domain_is_refused(changes: dict) -> None:
    assert "load_geometry" in str(rejects(LoadGeometry, encode(_with(GEOMETRY, **changes))))


def test_a_load_geometry_places_its_outline_at_the_truths_pose() -> None:
    square = LoadGeometry(2, ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0)), ((1, 2),), 0.01)
    turned = square.world_outline((10.0, 20.0), math.pi / 2)
    flat = [v for vertex in turned for v in vertex]
    assert flat == pytest.approx([10.0, 21.0, 9.0, 20.0, 10.0, 19.0])


# ----------------------------------------------------------------------------- DecodeError
@pytest.mark.parametrize("kind", ALL_KINDS, ids=kind_id)
@pytest.mark.parametrize("payload", [b"", b"H", b"H\x01"], ids=["empty", "1-byte", "2-byte"])
def test_payloads_shorter_than_the_header(kind, payload: bytes) -> None:
    assert "shorter than the header" in str(rejects(kind, payload))


def _sample_payload(kind) -> bytes:
    return encode(
        {
            Measurement: MEASUREMENT,
            Command: COMMAND,
            Share: SHARE_FLOWS,
            Clock: CLOCK,
            Estimates: ESTIMATES_FULL,
            Status: STATUS,
            Truth: TRUTH,
            Control: CONTROL,
            PlantStatus: PLANT_STATUS,
            BridgeStatus: BRIDGE_STATUS,
            LoadGeometry: GEOMETRY,
            LogLine: LOG_LINE,
        }[kind]
    )


@pytest.mark.parametrize("kind", ALL_KINDS, ids=kind_id)
def test_bad_magic(kind) -> None:
    payload = _sample_payload(kind)
    for magic in (0x00, 0x47, 0x68, 0xFF):
        assert "magic" in str(rejects(kind, bytes([magic]) + payload[1:]))


@pytest.mark.parametrize("kind", ALL_KINDS, ids=kind_id)
def test_another_wire_version(kind) -> None:
    payload = _sample_payload(kind)
    for version in (0, WIRE_VERSION + 1, 255):
        err = rejects(kind, payload[:1] + bytes([version]) + payload[2:])
        assert "version" in str(err)


@pytest.mark.parametrize("kind", ALL_KINDS, ids=kind_id)
def test_every_other_kind_is_refused(kind) -> None:
    for other in ALL_KINDS:
        if other != kind:
            assert "kind" in str(rejects(kind, _sample_payload(other)))
    for unknown in (0, max(KIND_BYTE.values()) + 1, 255):
        assert "kind" in str(rejects(kind, _sample_payload(kind)[:2] + bytes([unknown])))


STRUCT_SAMPLES = {
    "measurement": (Measurement, MEASUREMENT),
    "command": (Command, COMMAND),
    "share": (Share, SHARE_PLAIN),
    "share-flows": (Share, SHARE_FLOWS),
    "clock": (Clock, CLOCK),
    "estimates-empty": (Estimates, ESTIMATES_EMPTY),
    "estimates-full": (Estimates, ESTIMATES_FULL),
    "estimates-partial": (Estimates, ESTIMATES_PARTIAL),
    "estimates-uncertain": (Estimates, ESTIMATES_UNCERTAIN),
}


@pytest.mark.parametrize("kind, message", STRUCT_SAMPLES.values(), ids=STRUCT_SAMPLES.keys())
def test_truncated_struct_bodies(kind, message) -> None:
    payload = encode(message)
    for end in range(3, len(payload)):
        rejects(kind, payload[:end])


@pytest.mark.parametrize("kind, message", STRUCT_SAMPLES.values(), ids=STRUCT_SAMPLES.keys())
def test_over_long_struct_bodies(kind, message) -> None:
    payload = encode(message)
    for extra in (b"\x00", b"\x00" * 7, b"\xff" * 33, payload[3:]):
        rejects(kind, payload + extra)


def _with(message, **changes):
    fields = {k: getattr(message, k) for k in message.__dataclass_fields__}
    return type(message)(**{**fields, **changes})


@pytest.mark.parametrize("bad", NOT_FINITE, ids=["nan", "inf", "-inf"])
def test_non_finite_numbers_in_struct_messages(bad: float) -> None:
    corrupt = [
        _with(MEASUREMENT, time_s=bad),
        _with(MEASUREMENT, velocity=(0.0, bad)),
        _with(MEASUREMENT, force=(bad, 0.0)),
        _with(COMMAND, force=(1.0, bad)),
        _with(CLOCK, time_s=bad),
        _with(SHARE_PLAIN, velocity=(bad, 0.0)),
        _with(SHARE_PLAIN, consensus=ConsensusState(mean_square_offset=bad)),
        _with(SHARE_CENTROID, consensus=ConsensusState(centroid_offset=(0.0, bad))),
        _with(SHARE_FLOWS, flows=((2, 0.5, bad, *[0.0] * (flow_width() - 2)),)),
        _with(
            SHARE_FLOWS, flows=((2, *[0.5] * flow_width()), (4, *[0.0] * (flow_width() - 1), bad))
        ),
        _with(SHARE_FLOWS, consensus=ConsensusState(mean_gain=bad)),
        _with(SHARE_FLOWS, consensus=ConsensusState(mean_gain_offset=(0.0, bad))),
        _with(ESTIMATES_FULL, mass=bad),
        _with(ESTIMATES_FULL, contact_to_com=(0.0, bad)),
        _with(ESTIMATES_PARTIAL, omega=bad),
        _with(ESTIMATES_FULL, relative_positions={1: (0.5, -1.25), 3: (bad, 0.0)}),
        _with(ESTIMATES_UNCERTAIN, mass_std=bad),
        _with(ESTIMATES_UNCERTAIN, contact_to_com_cov=(1e-6, bad, 1e-6)),
        _with(ESTIMATES_UNCERTAIN, relative_positions_cov={2: (1e-6, 0.0, bad)}),
    ]
    for message in corrupt:
        assert "non-finite" in str(rejects(type(message), encode(message)))


def test_share_flow_count_must_match_its_bytes() -> None:
    payload = encode(
        SHARE_FLOWS
    )  # two flows of 2 + 8 flow_width() bytes each, the count in the last fixed byte
    flow = struct.calcsize(f"<H{flow_width()}d")
    fixed = len(payload) - 2 * flow
    assert payload[fixed - 1] == 2
    rejects(Share, payload[:-flow])  # one flow's bytes, count 2
    rejects(Share, payload + payload[-flow:])  # three flows' bytes, count 2
    rejects(Share, payload[: fixed - 1] + bytes([3]) + payload[fixed:])  # count 3, two flows
    rejects(Share, payload[: fixed - 1] + bytes([0]) + payload[fixed:])  # count 0, two flows
    rejects(Share, payload[: fixed - 1] + bytes([255]) + payload[fixed:])
    rejects(Share, payload[:-1])  # a flow cut short


ESTIMATES_FIXED = struct.Struct("<HqBqIBBBBHH")
"""robot, tick, phase, phase_since, presence bits, neighbours, covariances, started, settled,
load changes, rejoins."""


def _estimates_fixed(message: Estimates, **changes) -> bytes:
    """``message``'s payload with fields of its fixed part replaced."""
    payload = encode(message)
    values = dict(
        zip(
            (
                "robot",
                "tick",
                "phase",
                "phase_since",
                "present",
                "neighbours",
                "covariances",
                "started",
                "settled",
                "load_changes",
                "rejoins",
            ),
            ESTIMATES_FIXED.unpack_from(payload, 3),
            strict=True,
        )
    )
    values.update(changes)
    return (
        payload[:3] + ESTIMATES_FIXED.pack(*values.values()) + payload[3 + ESTIMATES_FIXED.size :]
    )


def test_estimates_carry_only_the_values_they_have() -> None:
    empty, full = encode(ESTIMATES_EMPTY), encode(ESTIMATES_FULL)
    assert len(empty) == 3 + ESTIMATES_FIXED.size
    assert ESTIMATES_FIXED.unpack_from(full, 3)[4] == 0b1_1111_1111  # nine optional values
    assert len(full) == 3 + ESTIMATES_FIXED.size + 14 * 8 + 2 * 18 + 5 * 9


@pytest.mark.parametrize("phase", [len(Phase), 200, 255])
def test_estimates_with_no_such_phase_are_refused(phase: int) -> None:
    assert "phase" in str(rejects(Estimates, _estimates_fixed(ESTIMATES_FULL, phase=phase)))


@pytest.mark.parametrize("present", [1 << 20, 0xFFFFFFFF])
def test_estimates_presence_bits_past_the_fields_are_refused(present: int) -> None:
    assert "presence" in str(rejects(Estimates, _estimates_fixed(ESTIMATES_EMPTY, present=present)))


ESTIMATES_MISCOUNTED = {
    "a value not declared": (ESTIMATES_FULL, dict(present=0b1_1111_1110)),
    "no values declared": (ESTIMATES_FULL, dict(present=0)),
    "a value declared, not sent": (ESTIMATES_EMPTY, dict(present=1)),
    "a neighbour more": (ESTIMATES_FULL, dict(neighbours=3)),
    "a neighbour fewer": (ESTIMATES_FULL, dict(neighbours=1)),
    "255 neighbours": (ESTIMATES_FULL, dict(neighbours=255)),
    "a step more": (ESTIMATES_FULL, dict(started=4)),
    "a settled step fewer": (ESTIMATES_FULL, dict(settled=1)),
    "a covariance more": (ESTIMATES_UNCERTAIN, dict(covariances=3)),
    "a covariance fewer": (ESTIMATES_UNCERTAIN, dict(covariances=1)),
}


@pytest.mark.parametrize(
    "message, changes", ESTIMATES_MISCOUNTED.values(), ids=ESTIMATES_MISCOUNTED.keys()
)
def test_estimates_counts_must_match_their_bytes(message: Estimates, changes: dict) -> None:
    assert "bytes" in str(rejects(Estimates, _estimates_fixed(message, **changes)))


def test_estimates_with_a_neighbour_or_a_step_twice_are_refused() -> None:
    twice = bytearray(encode(ESTIMATES_FULL))
    neighbours = 3 + ESTIMATES_FIXED.size + 14 * 8
    twice[neighbours + 18 : neighbours + 20] = twice[neighbours : neighbours + 2]  # 1 and 1
    assert "repeated" in str(rejects(Estimates, bytes(twice)))
    twice = bytearray(encode(ESTIMATES_FULL))
    steps = neighbours + 2 * 18
    twice[steps + 9] = twice[steps]  # started {1, 1, 4}
    assert "repeated" in str(rejects(Estimates, bytes(twice)))


NOT_JSON = {
    "invalid-utf8": b'{"command": "st\xc3\x28p"}',
    "latin1": '{"command": "café"}'.encode("latin-1"),
    "lone-ff": b"\xff",
    "truncated": b'{"command": "stop"',
    "garbage": b"stop",
    "empty-body": b"",
    "single-quotes": b"{'command': 'stop'}",
    "trailing": b'{"command": "stop"} x',
}
NOT_OBJECT = {
    "list": b'["stop"]',
    "string": b'"stop"',
    "number": b"8",
    "null": b"null",
    "true": b"true",
}
JSON_DECODERS = JSON_CLASSES


@pytest.mark.parametrize("kind", JSON_DECODERS, ids=kind_id)
@pytest.mark.parametrize("body", NOT_JSON.values(), ids=NOT_JSON.keys())
def test_bodies_that_are_not_json(kind, body: bytes) -> None:
    assert "not JSON" in str(rejects(kind, header(kind) + body))


@pytest.mark.parametrize("kind", JSON_DECODERS, ids=kind_id)
@pytest.mark.parametrize("body", NOT_OBJECT.values(), ids=NOT_OBJECT.keys())
def test_json_that_is_not_an_object(kind, body: bytes) -> None:
    assert "JSON object" in str(rejects(kind, header(kind) + body))


@pytest.mark.parametrize("kind", JSON_DECODERS, ids=kind_id)
@pytest.mark.parametrize("number", ["NaN", "Infinity", "-Infinity"])
def test_non_finite_numbers_in_json_messages(kind, number: str) -> None:
    # encode/encode_json never write these (allow_nan=False), so no valid message has one.
    body = json.loads(_sample_payload(kind)[3:]) | ({"mass": 5.0} if kind is Control else {})
    key = {
        Status: "rejected",
        PlantStatus: "time_s",
        BridgeStatus: "frames_in",
        LoadGeometry: "period_s",
        LogLine: "tick",
    }.get(kind, "mass")
    text = json.dumps(body).replace(f'"{key}": {json.dumps(body[key])}', f'"{key}": {number}')
    assert number in text
    rejects(kind, header(kind) + text.encode())


@pytest.mark.parametrize("kind", JSON_DECODERS, ids=kind_id)
def test_deeply_nested_json(kind) -> None:
    # 4 kB from anyone on the team's keys must not take an agent (or the launcher) down.
    depth = 5000
    rejects(kind, header(kind) + b'{"a":' + b"[" * depth + b"]" * depth + b"}")


def _status_body(**changes) -> dict:
    body = json.loads(encode(STATUS)[3:])
    body.update(changes)
    return {k: v for k, v in body.items() if v is not _DROP}


_DROP = object()


@pytest.mark.parametrize("key", ["robot", "tick", "phase"])
def test_status_missing_keys(key: str) -> None:
    rejects(Status, header(Status) + json.dumps(_status_body(**{key: _DROP})).encode())


STATUS_WRONG_TYPES = {
    "lost_neighbours-number": {"lost_neighbours": 2},
    "lost_neighbours-string": {"lost_neighbours": "24"},
    "lost_neighbours-object": {"lost_neighbours": {"2": True}},
    "robot-string": {"robot": "three"},
    "tick-null": {"tick": None},
    "phase-number": {"phase": 4},
    "phase-unknown": {"phase": "flying"},
    "late-string": {"late": "7"},
    "unknown-key": {"colour": "red"},
}


@pytest.mark.parametrize("changes", STATUS_WRONG_TYPES.values(), ids=STATUS_WRONG_TYPES.keys())
def test_status_with_wrong_types(changes: dict) -> None:
    rejects(Status, header(Status) + json.dumps(_status_body(**changes)).encode())


# ----------------------------------------------------------------------------- fuzzing
json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**70), 2**70) | finite | st.text(max_size=8),
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=4), inner, max_size=4)
    ),
    max_leaves=12,
)
MESSAGE_FIELDS = sorted({f for kind in JSON_CLASSES for f in kind.__dataclass_fields__})
message_like = st.dictionaries(
    st.sampled_from(MESSAGE_FIELDS) | st.sampled_from(["1", "2", "x"]), json_values, max_size=16
)


def _payloads(kind) -> st.SearchStrategy[bytes]:
    """Random bytes; the right header then random bytes; for JSON kinds, the right header then
    random JSON objects shaped like the messages (every key a message field or nearly)."""
    head = header(kind)
    out = st.binary(max_size=120) | st.binary(max_size=120).map(lambda b: head + b)
    if kind in STRUCT_KINDS:
        good = _sample_payload(kind)
        flips = st.lists(st.tuples(st.integers(3, len(good) - 1), st.integers(0, 255)), max_size=4)
        out |= flips.map(lambda fs: _flipped(good, fs))
        out |= st.integers(3, len(good)).map(lambda end: good[:end])
    else:
        out |= message_like.map(lambda d: head + json.dumps(d).encode())
        out |= st.binary(max_size=40).map(lambda b: _sample_payload(kind) + b)
    return out


def _flipped(payload: bytes, flips: list[tuple[int, int]]) -> bytes:
    data = bytearray(payload)
    for index, value in flips:
        data[index] = value
    return bytes(data)


@pytest.mark.parametrize("kind", ALL_KINDS, ids=kind_id)
def test_fuzz_decode_returns_a_message_or_raises_decode_error(kind) -> None:
    expected = kind

    @settings(max_examples=200, deadline=None, database=None)
    @given(_payloads(kind))
    def check(payload: bytes) -> None:
        try:
            message = decode(kind, payload)
        except DecodeError:
            return
        assert type(message) is expected

    check()


# ----------------------------------------------------------------------------- keys
def test_key_shapes() -> None:
    keys = Keys("paper")
    assert keys.team == "paper" and keys.root == "heft/paper"
    assert keys.share(3) == "heft/paper/robot/3/share"
    assert keys.velocity(12) == "heft/paper/robot/12/velocity"
    assert keys.alive(1) == "heft/paper/robot/1/alive"
    assert keys.bridge(4) == "heft/paper/robot/4/bridge"
    assert keys.clock() == "heft/paper/plant/clock"
    assert keys.truth() == "heft/paper/plant/truth"
    assert keys.plant_status() == "heft/paper/plant/status"
    assert keys.geometry() == "heft/paper/plant/geometry"
    assert keys.control() == "heft/paper/control"
    assert keys.log(2) == "heft/paper/robot/2/log"
    assert Keys("paper-1234_x").force(2) == "heft/paper-1234_x/robot/2/force"


def test_the_wildcards_are_methods_of_their_own() -> None:
    keys = Keys("paper")
    assert keys.all_estimates() == "heft/paper/robot/*/estimate"
    assert keys.all_statuses() == "heft/paper/robot/*/status"
    assert keys.all_forces() == "heft/paper/robot/*/force"
    assert keys.all_bridges() == "heft/paper/robot/*/bridge"
    assert keys.all_alive() == "heft/paper/robot/*/alive"
    assert keys.all_logs() == "heft/paper/robot/*/log"


@pytest.mark.parametrize("robot", [0, -1, True, 1.0, "1"])
def test_a_robot_key_needs_a_robot_id(robot) -> None:
    with pytest.raises(ValueError, match="robot ids"):
        Keys("paper").share(robot)


ROBOT_TOPICS = ("velocity", "force", "share", "estimate", "status", "bridge", "log", "alive")


@pytest.mark.parametrize("robot", [1, 4, 9, 65535])
def test_robot_of_a_robot_key(robot: int) -> None:
    keys = Keys("paper")
    for topic in ROBOT_TOPICS:
        assert Keys.robot_of(getattr(keys, topic)(robot)) == robot


def test_robot_of_in_a_team_named_robot() -> None:
    # Keys accepts the team name "robot"; its keys must still give their robot's id.
    keys = Keys("robot")
    assert Keys.robot_of(keys.force(7)) == 7
    assert Keys.robot_of(keys.alive(2)) == 2


@pytest.mark.parametrize(
    "key",
    [
        "",
        "heft/paper/plant/clock",
        "heft/paper/control",
        "heft/paper/robot",
        "heft/paper/robot/",
        "heft/paper/robot/*/share",
        "heft/paper/robot/two/share",
        "heft/paper/robot/1.5/share",
        "heft/paper/robots/1/share",
    ],
)
def test_robot_of_a_key_without_a_robot_id(key: str) -> None:
    with pytest.raises(DecodeError):
        Keys.robot_of(key)


@pytest.mark.parametrize(
    "team", ["", "a/b", "/", "team*", "**", "$x", "what?", "#1", "paper/robot/1"]
)
def test_bad_team_names_are_refused(team: str) -> None:
    with pytest.raises(ValueError, match="team name"):
        Keys(team)
