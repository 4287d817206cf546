"""The recordings' record format (dashboard/channels.py): every message kind's JSON schema is
read by Foxglove's own JSON-schema parser (the npm package @foxglove/studio-base, run in node)
with every field named, is a valid Draft 2020-12 schema that every record validates against;
random messages of every kind come back equal from their records; a PlotJuggler-style
flattening of a record finds every field and every number; and a recording of format 1 (before
the metadata named a format) still replays."""

from __future__ import annotations

import dataclasses
import enum
import json
import math
import typing
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from jsonschema import Draft202012Validator
from mcap.reader import make_reader
from mcap.writer import Writer

from agent.platform.protocol import (
    AGV_PROFILES,
    CLOCKS,
    CONTROL_COMMANDS,
    LOG_LEVELS,
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
    log_text,
)
from agent.platform.team import TEAM_QUANTITIES, ConsensusState, flow_width
from dashboard import channels
from dashboard.channels import MESSAGE_KINDS
from dashboard.recorder import TEAM_METADATA, Recorder
from dashboard.replay import Recording, RecordingError
from tests.helpers.foxglove import NODE, foxglove_parse

# ------------------------------------------------------------------------------ messages
ids = st.integers(1, 32)
ticks = st.integers(0, 2**40)
amounts = st.floats(0.0, 1e3)
numbers = st.floats(-1e3, 1e3)
vectors = st.tuples(st.floats(-100.0, 100.0), st.floats(-100.0, 100.0))
counts = st.integers(0, 10_000)
phases = st.sampled_from(Phase)
maybe = lambda strategy: st.none() | strategy  # noqa: E731
# (xx, ρ √(xx yy), yy) with xx, yy ≥ 0 and |ρ| ≤ 1: a covariance.
covariances = st.tuples(amounts, amounts, st.floats(-1.0, 1.0)).map(
    lambda t: (t[0], t[2] * math.sqrt(t[0]) * math.sqrt(t[1]), t[1])
)
consensus = st.builds(
    ConsensusState,
    **{q.name: st.floats(-1.0, 1.0) if q.shape == 1 else vectors for q in TEAM_QUANTITIES},
)


def _truths(n: int) -> st.SearchStrategy:
    contacts = st.tuples(*[vectors] * n)
    return st.builds(
        Truth,
        tick=ticks,
        time_s=amounts,
        com_position=vectors,
        angle=numbers,
        com_velocity=vectors,
        omega=numbers,
        contacts=contacts,
        contact_velocities=contacts,
        contact_to_com=contacts,
        mass=st.floats(1e-3, 1e3),
        moment=st.floats(1e-3, 1e3),
        largest_travel=amounts,
        largest_speed=amounts,
        largest_omega=amounts,
        ground_coulomb=st.floats(0.0, 1.0),
        ground_static=st.floats(0.0, 1.0),
        ground_viscous=amounts,
        friction_radius=st.floats(0.0, 10.0),
        viscous_radius2=st.floats(0.0, 10.0),
        friction_force=vectors,
        friction_torque=numbers,
    ).map(  # μ_s ≥ μ and c² ≤ ρ²
        lambda t: dataclasses.replace(
            t,
            ground_static=t.ground_coulomb + t.ground_static,
            viscous_radius2=t.friction_radius**2 + t.viscous_radius2,
        )
    )


def _geometries(n: int) -> st.SearchStrategy:
    pairs = [(i, j) for i in range(1, n + 1) for j in range(i + 1, n + 1)]
    return st.builds(
        LoadGeometry,
        n=st.just(n),
        outline=st.lists(vectors, min_size=3, max_size=12).map(tuple),
        edges=st.lists(st.sampled_from(pairs), unique=True, max_size=len(pairs)).map(tuple),
        period_s=st.floats(1e-4, 1.0),
        end_tick=ticks,
    )


MESSAGES = st.one_of(
    st.builds(Measurement, robot=ids, tick=ticks, time_s=amounts, velocity=vectors, force=vectors),
    st.builds(Command, robot=ids, tick=ticks, force=vectors),
    st.builds(
        Share,
        sender=ids,
        tick=st.integers(1001, 2**40),
        velocity=vectors,
        degree=st.integers(8, 32),
        instant=st.integers(-1, 1000),
        barrier=st.builds(
            Barrier,
            phase=phases,
            ready=st.integers(0, 2**32 - 1),
            switch_at=st.integers(-1, 2**40),
            load_changes=counts,
            rejoins=counts,
            levels=st.tuples(st.integers(0, 255), st.integers(0, 255)),
        ),
        consensus=consensus,
        flows=st.lists(st.tuples(ids, *[numbers] * flow_width()), max_size=8).map(tuple),
    ),
    st.builds(Clock, tick=ticks, time_s=amounts),
    st.builds(
        Estimates,
        robot=ids,
        tick=st.integers(-1, 2**40),
        phase=phases,
        phase_since=ticks,
        omega=maybe(numbers),
        relative_positions=st.dictionaries(ids, vectors, max_size=6),
        centroid_offset=maybe(vectors),
        w=maybe(amounts),
        moment=maybe(numbers),
        com_offset=maybe(vectors),
        com_observer=maybe(vectors),
        com_velocity=maybe(vectors),
        mass=maybe(numbers),
        contact_to_com=maybe(vectors),
        started=st.dictionaries(st.integers(1, 7), ticks, max_size=7),
        settled=st.dictionaries(st.integers(1, 7), ticks, max_size=7),
        mass_std=maybe(amounts),
        moment_std=maybe(amounts),
        contact_to_com_cov=maybe(covariances),
        relative_positions_cov=st.dictionaries(ids, covariances, max_size=6),
        drive_gain=maybe(st.floats(0.0, 100.0)),
        drive_gain_std=maybe(amounts),
        load_changes=counts,
        change_score=maybe(amounts),
        rejoins=counts,
        friction_torque=maybe(numbers),
        friction_torque_std=maybe(amounts),
        coulomb=maybe(numbers),
        coulomb_std=maybe(amounts),
        stuck_torque=maybe(amounts),
    ),
    st.builds(
        Status,
        robot=ids,
        tick=st.integers(-1, 2**40),
        phase=phases,
        rejected=counts,
        decode_errors=counts,
        late=counts,
        lost_neighbours=st.lists(ids, max_size=6).map(tuple),
        rejoins=counts,
    ),
    st.integers(1, 8).flatmap(_truths),
    st.builds(Control, command=st.sampled_from(CONTROL_COMMANDS)),
    st.builds(
        PlantStatus,
        tick=ticks,
        time_s=amounts,
        clock=st.sampled_from(CLOCKS),
        late_commands=counts,
        missing_commands=counts,
        overruns=counts,
        resent=counts,
        decode_errors=counts,
        lost=st.lists(ids, max_size=6).map(tuple),
        latency_ms_p50=maybe(amounts),
        latency_ms_p99=maybe(amounts),
        latency_ms_mean=maybe(amounts),
        latency_samples=counts,
    ),
    st.builds(
        BridgeStatus,
        robot=ids,
        tick=st.integers(-1, 2**40),
        watchdog=st.booleans(),
        **{  # every counter: the integer fields but the ids, the tick and the driver's
            f.name: counts
            for f in dataclasses.fields(BridgeStatus)
            if f.type == "int" and f.name not in ("robot", "tick", "driver_mode", "driver_faults")
        },
        driver_mode=st.integers(-1, 15),
        driver_faults=st.integers(0, 255),
        profile=st.sampled_from(AGV_PROFILES),
        force_error_rms=amounts,
        force_error_p95=amounts,
        sensor_stale=st.booleans(),
    ),
    st.integers(2, 8).flatmap(_geometries),
    st.builds(
        LogLine,
        robot=ids,
        tick=st.integers(-1, 2**40),
        level=st.sampled_from(LOG_LEVELS),
        text=st.text(max_size=300).map(log_text),
    ),
)
"""Random messages of every kind, each within its domain."""

FULL = [
    Measurement(2, 7, 0.07, (0.1, -0.2), (1.0, 2.0)),
    Command(2, 7, (1.5, -0.5)),
    Share(
        2,
        7,
        (0.1, 0.2),
        2,
        6,
        Barrier(Phase.INERTIA, 3, 9, 1, 2, levels=(3, 5)),
        ConsensusState(centroid_offset=(1.0, 2.0), mean_square_offset=3.0),
        ((1, *[0.5] * flow_width()), (3, *[-0.25] * flow_width())),
    ),
    Clock(7, 0.07),
    Estimates(
        2,
        7,
        Phase.PUSH,
        phase_since=5,
        omega=0.4,
        relative_positions={1: (1.0, 2.0), 3: (0.5, 0.5)},
        centroid_offset=(0.5, 0.5),
        w=2.0,
        moment=12.0,
        com_offset=(0.1, 0.2),
        com_observer=(0.1, 0.3),
        com_velocity=(0.0, 0.1),
        mass=5.0,
        contact_to_com=(0.2, -0.6),
        started={1: 0, 2: 3},
        settled={1: 2},
        mass_std=0.02,
        moment_std=0.05,
        contact_to_com_cov=(4e-6, -1e-6, 9e-6),
        relative_positions_cov={1: (1e-6, 0.0, 2e-6)},
        drive_gain=1.02,
        drive_gain_std=0.008,
        load_changes=1,
        change_score=0.5,
        rejoins=2,
        friction_torque=1.47,
        friction_torque_std=0.01,
        coulomb=0.02,
        coulomb_std=1e-4,
        stuck_torque=3.0,
    ),
    Status(2, 7, Phase.DONE, 1, 2, 3, (4,), 1),
    Truth(
        7,
        0.07,
        (1.0, 2.0),
        0.3,
        (0.0, 1.0),
        0.4,
        ((0.0, 0.0), (1.0, 1.0)),
        ((0.0, 0.0), (0.1, 0.0)),
        ((1.0, 1.0), (0.0, 1.0)),
        5.0,
        12.0,
        *(0.1, 0.2, 0.3, 0.02, 0.03, 0.5, 1.2, 1.6, (-0.9, 0.3), 0.4),
    ),
    Control("stop"),
    LogLine(2, 7, "warning", "robot 2: lost neighbour 3; halting the team"),
    PlantStatus(7, 0.07, "realtime", 1, 2, 3, 4, 5, (3,), 1.5, 2.5, 1.6, 10),
    BridgeStatus(2, 7, True, *range(1, 13), 3, 4, "velocity", 0.1, 0.5, True, 2, 3, 4),
    LoadGeometry(3, ((-1.0, -1.0), (1.0, -1.0), (0.0, 1.0)), ((1, 2), (2, 3)), 0.01, 300),
]
"""A message of every kind with every optional field given and every collection filled."""


# ------------------------------------------------------------------------------ fields
def _is_record(tp) -> bool:
    return dataclasses.is_dataclass(tp) or (isinstance(tp, type) and hasattr(tp, "_fields"))


def field_chains(tp, prefix: tuple[str, ...] = ()) -> set[tuple[str, ...]]:
    """Every field of dataclass (or named tuple) ``tp`` as a chain of names, a nested
    dataclass's fields within it (``("barrier", "levels")``)."""
    hints = typing.get_type_hints(tp)
    names = [f.name for f in dataclasses.fields(tp)] if dataclasses.is_dataclass(tp) else tp._fields
    chains = set()
    for name in names:
        hint = hints[name]
        chains |= field_chains(hint, (*prefix, name)) if _is_record(hint) else {(*prefix, name)}
    return chains


def flatten(value, path: str = "") -> dict[str, object]:
    """A record as PlotJuggler's JSON parser lays it out: a nested object's field as
    ``a/b``, an array's item as ``a[0]``, each leaf a number, a string or a boolean."""
    if isinstance(value, dict):
        out = {}
        for key, item in value.items():
            out |= flatten(item, f"{path}/{key}" if path else key)
        return out
    if isinstance(value, list):
        out = {}
        for i, item in enumerate(value):
            out |= flatten(item, f"{path}[{i}]")
        return out
    assert isinstance(value, (int, float, str, bool)), f"{path}: {value!r} is not a leaf"
    return {path: value}


def scalars(value) -> int:
    """How many numbers, strings and booleans ``value`` (a message or a part of one) holds: a
    map's keys count with its values."""
    if dataclasses.is_dataclass(value):
        return sum(scalars(getattr(value, f.name)) for f in dataclasses.fields(value))
    if isinstance(value, dict):
        return len(value) + sum(scalars(v) for v in value.values())
    if isinstance(value, (tuple, list)):
        return sum(scalars(v) for v in value)
    return 0 if value is None else 1


def chains_of(paths) -> set[tuple[str, ...]]:
    """The names along each flattened path, the array indices left out."""
    out = set()
    for path in paths:
        names = tuple(part.split("[")[0] for part in path.split("/"))
        out |= {names[:i] for i in range(1, len(names) + 1)}
    return out


# ------------------------------------------------------------------------------ Foxglove
def foxglove_chains(datatypes: dict, name: str, prefix: tuple[str, ...] = ()) -> set[tuple]:
    """Every field Foxglove's message definition of ``name`` names, nested types within."""
    out = set()
    for field in datatypes[name]:
        chain = (*prefix, field["name"])
        out.add(chain)
        if field.get("isComplex"):
            out |= foxglove_chains(datatypes, field["type"], chain)
    return out


@pytest.mark.skipif(NODE is None, reason="node is not installed: Foxglove's parser runs in it")
def test_foxglove_reads_every_kinds_schema_with_every_field_named() -> None:
    schemas = {f"heft.{kind.__name__}": channels.json_schema(kind) for kind in MESSAGE_KINDS}
    nullable = {"type": "object", "properties": {"omega": {"type": ["number", "null"]}}}
    results = foxglove_parse({**schemas, "nullable": nullable})
    # The parser is Foxglove's, strict as in Foxglove: a nullable union is refused.
    assert not results.pop("nullable")["ok"]
    refused = {name: r["error"] for name, r in results.items() if not r["ok"]}
    assert not refused, f"{len(results) - len(refused)} of {len(results)} kinds read: {refused}"
    for kind in MESSAGE_KINDS:
        name = f"heft.{kind.__name__}"
        named = foxglove_chains(results[name]["datatypes"], name)
        missing = field_chains(kind) - named
        assert not missing, f"{name}: Foxglove names no {sorted(missing)}"


# ------------------------------------------------------------------------------ format 2
def test_every_kinds_schema_is_draft_2020_12_within_foxglove_s_json_schema() -> None:
    def walk(schema: dict, where: str) -> None:
        assert isinstance(schema.get("type"), str), f"{where}: a type union or none"
        assert schema["type"] != "null", where
        if schema["type"] == "object":
            assert "properties" in schema, f"{where}: an object without properties (a map)"
            for name, field in schema["properties"].items():
                walk(field, f"{where}.{name}")
        elif schema["type"] == "array":
            assert schema["items"]["type"] != "array", f"{where}: an array of arrays"
            walk(schema["items"], f"{where}[]")

    for kind in MESSAGE_KINDS:
        schema = channels.json_schema(kind)
        Draft202012Validator.check_schema(schema)
        walk(schema, kind.__name__)


@settings(max_examples=400, deadline=None, database=None)
@given(MESSAGES)
def test_random_messages_come_back_from_their_records_and_validate(message) -> None:
    kind = type(message)
    data = channels.record_bytes(message)
    assert channels.from_record(kind, data) == message
    record = json.loads(data)
    Draft202012Validator(channels.json_schema(kind)).validate(record)
    # PlotJuggler finds every number of the message, each at a path of its own.
    assert len(flatten(record)) == scalars(message)


def test_a_flattened_record_finds_every_field_of_every_dataclass() -> None:
    assert {type(m) for m in FULL} == set(MESSAGE_KINDS)
    for message in FULL:
        record = channels.to_record(message)
        Draft202012Validator(channels.json_schema(type(message))).validate(record)
        paths = flatten(record)
        missing = field_chains(type(message)) - chains_of(paths)
        assert not missing, f"{type(message).__name__}: no path for {sorted(missing)}"
        assert len(paths) == scalars(message)
    share = channels.to_record(FULL[2])
    assert flatten(share)["barrier/levels/force"] == 5
    assert flatten(share)["flows[1]/outflows/centroid_offset/y"] == -0.25
    assert flatten(share)["flows[1]/neighbour"] == 3
    estimates = flatten(channels.to_record(FULL[4]))
    assert estimates["relative_positions[1]/key"] == 3
    assert estimates["relative_positions[1]/value/x"] == 0.5
    assert estimates["contact_to_com_cov/xy"] == -1e-6
    assert flatten(channels.to_record(FULL[-1]))["edges[1]/i"] == 2


def test_what_is_not_estimated_is_absent_not_null() -> None:
    record = channels.to_record(Estimates(1, 0, Phase.EXCITE, omega=0.5))
    assert record["omega"] == 0.5 and "mass" not in record and "centroid_offset" not in record
    assert record["relative_positions"] == [] and record["phase"] == "excite"


def _records_to_refuse() -> dict[str, tuple[type, dict, bool]]:
    """A valid record made wrong in one way: what the schema also refuses (True) or only the
    reader (False: a map's key given twice)."""
    estimates = channels.to_record(FULL[4])
    share = channels.to_record(FULL[2])
    geometry = channels.to_record(FULL[-1])

    def changed(record: dict, **fields) -> dict:
        return {**record, **fields}

    flow = share["flows"][0]
    return {
        "null": (Estimates, changed(estimates, mass=None), True),
        "unknown field": (Estimates, changed(estimates, mood=1.0), True),
        "required field missing": (
            Estimates,
            {k: v for k, v in estimates.items() if k != "phase_since"},
            True,
        ),
        "vector as an array (format 1)": (
            Estimates,
            changed(estimates, com_offset=[1.0, 2.0]),
            True,
        ),
        "vector without y": (Estimates, changed(estimates, com_offset={"x": 1.0}), True),
        "map as an object (format 1)": (Estimates, changed(estimates, started={"1": 0}), True),
        "map key a string": (
            Estimates,
            changed(estimates, started=[{"key": "1", "value": 0}]),
            True,
        ),
        "map key negative": (
            Estimates,
            changed(estimates, started=[{"key": -1, "value": 0}]),
            True,
        ),
        "map key twice": (
            Estimates,
            changed(estimates, settled=[{"key": 1, "value": 0}, {"key": 1, "value": 5}]),
            False,
        ),
        "phase unknown": (Estimates, changed(estimates, phase="resting"), True),
        "flow neighbour a number": (
            Share,
            changed(share, flows=[{**flow, "neighbour": 1.5}]),
            True,
        ),
        "flow outflow missing": (
            Share,
            changed(share, flows=[{**flow, "outflows": {"mean_gain": 1.0}}]),
            True,
        ),
        "edge as an array (format 1)": (LoadGeometry, changed(geometry, edges=[[1, 2]]), True),
        "not an object": (Command, [], True),
    }


@pytest.mark.parametrize("case", list(_records_to_refuse()))
def test_a_record_that_is_not_its_kinds_is_refused_by_the_reader_and_the_schema(case) -> None:
    kind, record, schema_refuses = _records_to_refuse()[case]
    with pytest.raises(DecodeError, match=kind.__name__):
        channels.from_record(kind, json.dumps(record).encode())
    errors = list(Draft202012Validator(channels.json_schema(kind)).iter_errors(record))
    assert bool(errors) == schema_refuses


# ------------------------------------------------------------------------------ format 1
def format1_value(value):
    """A value as recordings of format 1 held it: the protocol's JSON form (pairs as arrays,
    None as null, integer map keys as strings), a named tuple by its fields."""
    if isinstance(value, enum.Enum):
        return value.name.lower()
    if dataclasses.is_dataclass(value):
        return {f.name: format1_value(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, tuple) and hasattr(value, "_asdict"):
        return {k: format1_value(v) for k, v in value._asdict().items()}
    if isinstance(value, dict):
        return {str(k): format1_value(v) for k, v in value.items()}
    if isinstance(value, (tuple, list)):
        return [format1_value(v) for v in value]
    return value


def write_format1(path: Path, team: str, messages: list) -> None:
    """A recording as the recorder wrote them before record format 2: the team's metadata
    names no format."""
    keys = Keys(team)
    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start(profile="", library="heft")
        writer.add_metadata(TEAM_METADATA, {"team": team})
        channel_of: dict[str, int] = {}
        for stamp, message in enumerate(messages, start=1):
            key = keys.of(message)
            if key not in channel_of:
                name = f"heft.{type(message).__name__}"
                schema = writer.register_schema(name, "jsonschema", b"{}")
                channel_of[key] = writer.register_channel(key, "json", schema)
            data = json.dumps(format1_value(message)).encode()
            writer.add_message(channel_of[key], log_time=stamp, data=data, publish_time=stamp)
        writer.finish()


def test_a_recording_of_format_1_still_replays(tmp_path: Path) -> None:
    path = tmp_path / "format1.mcap"
    unknown = [Estimates(1, 0, Phase.EXCITE), PlantStatus(1, 0.01, "lockstep")]  # nulls
    write_format1(path, "old", [*FULL, *unknown])
    recording = Recording(path)
    assert recording.header() == "old" and recording.record_format == "1"
    assert [r.message for r in recording.messages()] == [*FULL, *unknown]
    assert not recording.rejected
    # Its records are not of format 2: read as such, each kind with a pair or a map is refused.
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        refused = set()
        for schema, _, message in reader.iter_messages():
            kind = next(k for k in MESSAGE_KINDS if f"heft.{k.__name__}" == schema.name)
            try:
                channels.from_record(kind, message.data, "2")
            except DecodeError:
                refused.add(kind)
    assert {Measurement, Command, Share, Estimates, Truth, LoadGeometry} <= refused


def test_a_recording_names_its_record_format(tmp_path: Path) -> None:
    path = tmp_path / "format2.mcap"
    with Recorder(path, "new") as recorder:
        for stamp, message in enumerate(FULL, start=1):
            recorder.write(Keys("new").of(message), message, stamp)
    recording = Recording(path)
    assert recording.header() == "new" and recording.record_format == channels.RECORD_FORMAT
    assert [r.message for r in recording.messages()] == FULL
    assert not recording.rejected


def test_a_recording_of_an_unknown_format_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "future.mcap"
    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start(profile="", library="heft")
        writer.add_metadata(TEAM_METADATA, {"team": "t", "format": "3"})
        writer.finish()
    with pytest.raises(RecordingError, match="record format '3', this program reads 1, 2"):
        Recording(path).header()


# ------------------------------------------------------------------------------ bad records
json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers()
    | st.just(10**400)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=6),
    lambda children: (
        st.lists(children, max_size=3)
        | st.dictionaries(st.sampled_from(["x", "y", "key", "value", "z"]), children, max_size=3)
    ),
    max_leaves=6,
)


@st.composite
def damaged_records(draw) -> tuple[type, object]:
    """A record of :data:`FULL` with one value somewhere in it replaced by any JSON value."""
    message = draw(st.sampled_from(FULL))
    record = channels.to_record(message)
    parent, key = None, None
    node = record
    while isinstance(node, (dict, list)) and node and draw(st.integers(0, 5)):
        parent = node
        key = draw(st.sampled_from(sorted(node) if isinstance(node, dict) else range(len(node))))
        node = node[key]
    if parent is None:
        return type(message), draw(json_values)
    parent[key] = draw(json_values)
    return type(message), record


@settings(max_examples=600, deadline=None, database=None)
@given(damaged_records())
def test_a_damaged_record_is_refused_in_one_line_or_read_as_its_schema_allows(case) -> None:
    kind, record = case
    try:
        message = channels.from_record(kind, json.dumps(record).encode())
    except DecodeError as err:
        assert "\n" not in str(err)
        return
    # What the reader takes, the schema takes too, and it is the record of what was read.
    Draft202012Validator(channels.json_schema(kind)).validate(record)
    assert channels.from_record(kind, channels.record_bytes(message)) == message
