"""The wire protocol (agent/protocol.py): every message survives encode → decode unchanged, and
whatever else arrives — short, foreign, corrupt, hostile — makes ``decode`` raise
:class:`DecodeError` and nothing else (the agents and the launcher count those and carry on).
Also the key expressions of a team."""

from __future__ import annotations

import json
import math
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.protocol import (
    WIRE_VERSION,
    Clock,
    Command,
    DecodeError,
    Estimates,
    Keys,
    Measurement,
    Share,
    Status,
    decode,
    encode,
    encode_json,
)

STRUCT_KINDS = (Measurement, Command, Share, Clock)
JSON_CLASSES = (Estimates, Status)
JSON_KINDS = ("truth", "control", "plant_status")
ALL_KINDS = (*STRUCT_KINDS, *JSON_CLASSES, *JSON_KINDS)
KIND_BYTE = {
    Measurement: 1,
    Command: 2,
    Share: 3,
    Clock: 4,
    Estimates: 5,
    Status: 6,
    "truth": 7,
    "control": 8,
    "plant_status": 9,
}
NOT_FINITE = (math.nan, math.inf, -math.inf)


def header(kind, version: int = WIRE_VERSION, magic: int = 0x48) -> bytes:
    return bytes((magic, version, KIND_BYTE[kind]))


def kind_id(kind) -> str:
    return kind if isinstance(kind, str) else kind.__name__


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
    centroid=(1.5, -2.25),
    spread=3.125,
    phase=2,
    ready=0b1011,
    switch_at=620,
)
SHARE_FLOWS = Share(
    sender=3,
    tick=2**40,
    velocity=(1e-9, -1e9),
    degree=2,
    centroid=None,
    spread=0.5,
    phase=1,
    ready=2**64 - 1,
    switch_at=-1,
    flows=((2, 0.5, -0.25, 1.0), (4, -3.0, 2.0, 0.0)),
)
CLOCK = Clock(tick=42, time_s=0.42)
ESTIMATES_EMPTY = Estimates(robot=1, tick=0, phase="excite")
ESTIMATES_FULL = Estimates(
    robot=2,
    tick=4321,
    phase="push",
    omega=0.75,
    relative_positions={1: (0.5, -1.25), 3: (-2.0, 0.0)},
    centroid_offset=(0.1, 0.2),
    spread=4.5,
    moment=12.3795,
    com_offset=(-0.3, 0.4),
    com_observer=(-0.31, 0.39),
    com_velocity=(0.0, 0.05),
    mass=5.0,
    contact_to_com=(0.2, -0.6),
    started={1: 0, 2: 150, 4: 900},
    settled={1: 140, 4: 1200},
)
ESTIMATES_PARTIAL = Estimates(
    robot=4,
    tick=10,
    phase="inertia",
    omega=None,
    relative_positions={3: (1.0, 2.0)},
    centroid_offset=None,
    spread=None,
    moment=None,
    started={1: 0},
)
STATUS = Status(
    robot=3, tick=88, phase="halted", rejected=2, decode_errors=5, late=7, lost_neighbours=(2, 4)
)
STATUS_PLAIN = Status(robot=1, tick=0, phase="excite")

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
    "status": STATUS,
    "status-plain": STATUS_PLAIN,
}


@pytest.mark.parametrize("message", MESSAGES.values(), ids=MESSAGES.keys())
def test_every_message_round_trips(message) -> None:
    payload = encode(message)
    assert payload[:3] == header(type(message))
    back = decode(type(message), payload)
    assert back == message
    assert type(back) is type(message)


def test_share_centroid_presence_survives() -> None:
    assert decode(Share, encode(SHARE_PLAIN)).centroid is None
    assert decode(Share, encode(SHARE_CENTROID)).centroid == (1.5, -2.25)
    at_origin = Share(sender=1, tick=1, velocity=(0, 0), degree=1, centroid=(0.0, 0.0))
    assert decode(Share, encode(at_origin)).centroid == (0.0, 0.0)


def test_estimates_keep_their_dict_keys_as_ints_and_pairs_as_tuples() -> None:
    back = decode(Estimates, encode(ESTIMATES_FULL))
    assert all(type(j) is int for j in back.relative_positions)
    assert all(type(v) is tuple for v in back.relative_positions.values())
    assert all(type(s) is int for s in (*back.started, *back.settled))
    assert type(back.com_offset) is tuple and type(back.contact_to_com) is tuple


def test_status_lost_neighbours_is_a_tuple() -> None:
    assert decode(Status, encode(STATUS)).lost_neighbours == (2, 4)
    # lost_neighbours may be left out of the JSON: it defaults to none lost.
    payload = header(Status) + b'{"robot":1,"tick":2,"phase":"push"}'
    assert decode(Status, payload) == Status(robot=1, tick=2, phase="push")


JSON_BODIES = {
    "truth": {
        "tick": 10,
        "time_s": 0.1,
        "com_position": [0.0, -0.138889],
        "contacts": [[-2.0, 0.4], [-1.0, -1.0]],
        "mass": 5.0,
        "ok": True,
        "note": "ünïcode ✓",
        "nothing": None,
    },
    "control": {"command": "stop"},
    "plant_status": {"lost": [2], "ticks": 6000, "latency_ms": {"p50": 0.4, "p99": 2.5}},
}


@pytest.mark.parametrize("kind", JSON_KINDS)
def test_encode_json_round_trips(kind: str) -> None:
    payload = encode_json(kind, JSON_BODIES[kind])
    assert payload[:3] == header(kind)
    assert decode(kind, payload) == JSON_BODIES[kind]
    assert decode(kind, encode_json(kind, {})) == {}


def test_encode_refuses_what_is_not_a_message() -> None:
    with pytest.raises(TypeError):
        encode({"robot": 1})
    with pytest.raises(ValueError):
        encode_json("truth", {"mass": math.nan})  # never NaN on the wire


# ----------------------------------------------------------------------------- struct round trips
finite = st.floats(allow_nan=False, allow_infinity=False)
u16 = st.integers(0, 2**16 - 1)
i64 = st.integers(-(2**63), 2**63 - 1)
pair = st.tuples(finite, finite)
shares = st.builds(
    Share,
    sender=u16,
    tick=i64,
    velocity=pair,
    degree=u16,
    centroid=st.none() | pair,
    spread=finite,
    phase=st.integers(0, 255),
    ready=st.integers(0, 2**64 - 1),
    switch_at=i64,
    flows=st.lists(st.tuples(u16, finite, finite, finite), max_size=8).map(tuple),
)
struct_messages = st.one_of(
    st.builds(Measurement, robot=u16, tick=i64, time_s=finite, velocity=pair, force=pair),
    st.builds(Command, robot=u16, tick=i64, force=pair),
    st.builds(Clock, tick=i64, time_s=finite),
    shares,
)


@settings(max_examples=200, deadline=None, database=None)
@given(struct_messages)
def test_struct_messages_round_trip_exactly(message) -> None:
    assert decode(type(message), encode(message)) == message


# ----------------------------------------------------------------------------- DecodeError
@pytest.mark.parametrize("kind", ALL_KINDS, ids=kind_id)
@pytest.mark.parametrize("payload", [b"", b"H", b"H\x01"], ids=["empty", "1-byte", "2-byte"])
def test_payloads_shorter_than_the_header(kind, payload: bytes) -> None:
    assert "shorter than the header" in str(rejects(kind, payload))


def _sample_payload(kind) -> bytes:
    if isinstance(kind, str):
        return encode_json(kind, JSON_BODIES[kind])
    return encode(
        {
            Measurement: MEASUREMENT,
            Command: COMMAND,
            Share: SHARE_FLOWS,
            Clock: CLOCK,
            Estimates: ESTIMATES_FULL,
            Status: STATUS,
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
    for unknown in (0, 10, 255):
        assert "kind" in str(rejects(kind, _sample_payload(kind)[:2] + bytes([unknown])))


STRUCT_SAMPLES = {
    "measurement": (Measurement, MEASUREMENT),
    "command": (Command, COMMAND),
    "share": (Share, SHARE_PLAIN),
    "share-flows": (Share, SHARE_FLOWS),
    "clock": (Clock, CLOCK),
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
        _with(SHARE_PLAIN, spread=bad),
        _with(SHARE_CENTROID, centroid=(0.0, bad)),
        _with(SHARE_FLOWS, flows=((2, 0.5, bad, 1.0),)),
        _with(SHARE_FLOWS, flows=((2, 0.5, 0.5, 1.0), (4, 0.0, 0.0, bad))),
    ]
    for message in corrupt:
        assert "non-finite" in str(rejects(type(message), encode(message)))


def test_share_flow_count_must_match_its_bytes() -> None:
    payload = encode(SHARE_FLOWS)  # two flows of 26 bytes each, the count in the last fixed byte
    flow = struct.calcsize("<H3d")
    fixed = len(payload) - 2 * flow
    assert payload[fixed - 1] == 2
    rejects(Share, payload[:-flow])  # one flow's bytes, count 2
    rejects(Share, payload + payload[-flow:])  # three flows' bytes, count 2
    rejects(Share, payload[: fixed - 1] + bytes([3]) + payload[fixed:])  # count 3, two flows
    rejects(Share, payload[: fixed - 1] + bytes([0]) + payload[fixed:])  # count 0, two flows
    rejects(Share, payload[: fixed - 1] + bytes([255]) + payload[fixed:])
    rejects(Share, payload[:-1])  # a flow cut short


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
JSON_DECODERS = (*JSON_CLASSES, *JSON_KINDS)


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
    body = {
        Estimates: json.loads(encode(ESTIMATES_FULL)[3:]),
        Status: json.loads(encode(STATUS)[3:]),
    }.get(kind, {"command": "stop", "mass": 5.0})
    key = {Status: "rejected", Estimates: "mass"}.get(kind, "mass")
    text = json.dumps(body).replace(f'"{key}": {json.dumps(body[key])}', f'"{key}": {number}')
    assert number in text
    rejects(kind, header(kind) + text.encode())


@pytest.mark.parametrize("kind", JSON_DECODERS, ids=kind_id)
def test_deeply_nested_json(kind) -> None:
    # 4 kB from anyone on the team's keys must not take an agent (or the launcher) down.
    depth = 5000
    rejects(kind, header(kind) + b'{"a":' + b"[" * depth + b"]" * depth + b"}")


def _estimates_body(**changes) -> dict:
    body = json.loads(encode(ESTIMATES_FULL)[3:])
    body.update(changes)
    return {k: v for k, v in body.items() if v is not _DROP}


def _status_body(**changes) -> dict:
    body = json.loads(encode(STATUS)[3:])
    body.update(changes)
    return {k: v for k, v in body.items() if v is not _DROP}


_DROP = object()


@pytest.mark.parametrize(
    "key",
    [
        "robot",
        "tick",
        "phase",
        "relative_positions",
        "started",
        "settled",
        "com_offset",
        "centroid_offset",
        "com_observer",
        "com_velocity",
        "contact_to_com",
    ],
)
def test_estimates_missing_keys(key: str) -> None:
    rejects(Estimates, header(Estimates) + json.dumps(_estimates_body(**{key: _DROP})).encode())


@pytest.mark.parametrize("key", ["robot", "tick", "phase"])
def test_status_missing_keys(key: str) -> None:
    rejects(Status, header(Status) + json.dumps(_status_body(**{key: _DROP})).encode())


ESTIMATES_WRONG_TYPES = {
    "relative_positions-list": {"relative_positions": [[0.5, -1.25]]},
    "relative_positions-key": {"relative_positions": {"one": [0.5, -1.25]}},
    "relative_positions-number": {"relative_positions": {"1": 0.5}},
    "relative_positions-string-pair": {"relative_positions": {"1": "ab"}},
    "relative_positions-triple": {"relative_positions": {"1": [1.0, 2.0, 3.0]}},
    "started-list": {"started": [0, 150]},
    "started-key": {"started": {"first": 0}},
    "started-tick-string": {"started": {"1": "zero"}},
    "com_offset-number": {"com_offset": 0.3},
    "com_offset-string": {"com_offset": "ab"},
    "com_offset-triple": {"com_offset": [0.1, 0.2, 0.3]},
    "centroid_offset-object": {"centroid_offset": {"x": 0.1, "y": 0.2}},
    "robot-string": {"robot": "two"},
    "tick-float": {"tick": 4.5},
    "phase-number": {"phase": 2},
    "omega-string": {"omega": "fast"},
    "mass-list": {"mass": [5.0]},
    "unknown-key": {"colour": "red"},
}
STATUS_WRONG_TYPES = {
    "lost_neighbours-number": {"lost_neighbours": 2},
    "lost_neighbours-string": {"lost_neighbours": "24"},
    "lost_neighbours-object": {"lost_neighbours": {"2": True}},
    "robot-string": {"robot": "three"},
    "tick-null": {"tick": None},
    "phase-number": {"phase": 4},
    "late-string": {"late": "7"},
    "unknown-key": {"colour": "red"},
}


@pytest.mark.parametrize(
    "changes", ESTIMATES_WRONG_TYPES.values(), ids=ESTIMATES_WRONG_TYPES.keys()
)
def test_estimates_with_wrong_types(changes: dict) -> None:
    rejects(Estimates, header(Estimates) + json.dumps(_estimates_body(**changes)).encode())


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
MESSAGE_FIELDS = sorted(set(Estimates.__dataclass_fields__) | set(Status.__dataclass_fields__))
message_like = st.dictionaries(
    st.sampled_from(MESSAGE_FIELDS) | st.sampled_from(["1", "2", "x"]), json_values, max_size=16
)


def _payloads(kind) -> st.SearchStrategy[bytes]:
    """Random bytes; the right header then random bytes; for JSON kinds, the right header then
    random JSON objects shaped like the messages (every key a message field or nearly)."""
    head = header(kind)
    out = st.binary(max_size=120) | st.binary(max_size=120).map(lambda b: head + b)
    if not isinstance(kind, str) and kind in STRUCT_KINDS:
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
    expected = dict if isinstance(kind, str) else kind

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
    assert keys.robot(3, "share") == "heft/paper/robot/3/share"
    assert keys.robot(12, "velocity") == "heft/paper/robot/12/velocity"
    assert keys.robot(1, "alive") == "heft/paper/robot/1/alive"
    assert keys.plant("clock") == "heft/paper/plant/clock"
    assert keys.plant("truth") == "heft/paper/plant/truth"
    assert keys.control == "heft/paper/control"
    assert Keys("paper-1234_x").robot(2, "force") == "heft/paper-1234_x/robot/2/force"


def test_robot_zero_is_the_wildcard() -> None:
    keys = Keys("paper")
    assert keys.robot(0, "estimate") == "heft/paper/robot/*/estimate"
    assert keys.robot(0, "alive") == "heft/paper/robot/*/alive"


@pytest.mark.parametrize("robot", [1, 4, 9, 65535])
def test_robot_of_a_robot_key(robot: int) -> None:
    keys = Keys("paper")
    for topic in ("velocity", "force", "share", "estimate", "status", "alive"):
        assert Keys.robot_of(keys.robot(robot, topic)) == robot


def test_robot_of_in_a_team_named_robot() -> None:
    # Keys accepts the team name "robot"; its keys must still give their robot's id (the plant
    # reads the robot of every command and liveliness key with robot_of).
    keys = Keys("robot")
    assert Keys.robot_of(keys.robot(7, "force")) == 7
    assert Keys.robot_of(keys.robot(2, "alive")) == 2


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
