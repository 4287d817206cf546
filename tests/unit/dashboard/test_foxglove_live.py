"""The team live in Foxglove (dashboard/foxglove_live.py, dashboard/relay.py): a minimal Foxglove
WebSocket client, connected through the dashboard's ``/foxglove`` route to a dashboard fed by
a fake feed, receives on every topic what a recording of the same messages holds (same
channels, schemas, log times and bytes); the route wants the page's token and passes the
subprotocol through; and the agents' log lines as Foxglove log messages."""

from __future__ import annotations

import pytest
from mcap.reader import make_reader
from websockets.exceptions import InvalidStatus

from agent.platform.protocol import (
    Clock,
    Command,
    Estimates,
    Keys,
    LoadGeometry,
    LogLine,
    Measurement,
    Phase,
    Status,
    Truth,
)
from dashboard import channels
from dashboard.display import Display
from dashboard.log_entries import log_entry, timestamp
from dashboard.recorder import Recorder
from dashboard.topics import Topics
from tests.helpers.foxglove import decoder
from tests.helpers.foxglove_ws import SUBPROTOCOL, FoxgloveClient, wait_until

TEAM = "live"
KEYS = Keys(TEAM)
TOKEN = "s3cret"
GEOMETRY = LoadGeometry(2, ((-1.0, -0.5), (1.0, -0.5), (0.0, 1.0)), ((1, 2),), 0.01)
START_NS = 1_700_000_000_000_000_000


def team_messages(k: int) -> list:
    """What a team of two says at tick ``k``."""
    truth = Truth(
        k, k * 0.01, (0.1 * k, 0.0), 0.01 * k, (0.1, 0), 0.5, ((0, 0), (1, 1)), ((0, 0),) * 2,
        ((1, 1),) * 2, 5, 12,
    )  # fmt: skip
    return [
        Clock(k, k * 0.01),
        truth,
        GEOMETRY,
        *(Measurement(i, k, k * 0.01, (0.1, 0.0), (1.0, -0.5 * i)) for i in (1, 2)),
        *(Command(i, k, (1.0, -0.5 * i)) for i in (1, 2)),
        *(Estimates(i, k, Phase.EXCITE, omega=0.01 * k + i) for i in (1, 2)),
        Status(2, k, Phase.EXCITE, late=k),
        LogLine(1, k, "warning", f"robot 1: tick {k}: a warning"),
    ]


def batch(k: int) -> list[tuple]:
    """The feed's batch of tick ``k``: ``(key, message, arrival (s), arrival (ns))``."""
    stamp = START_NS + k * 10_000_000
    return [(KEYS.of(m), m, 0.0, stamp + j) for j, m in enumerate(team_messages(k))]


def recorded(path, after_ns: int = 0) -> tuple[dict, list[tuple[str, int, bytes]]]:
    """A recording's channels by topic (encoding, schema name, encoding and data) and its
    messages received at ``after_ns`` or later (topic, log time, bytes)."""
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        out, topics = [], {}
        for schema, channel, message in reader.iter_messages():
            topics[channel.topic] = (
                channel.message_encoding,
                schema.name,
                schema.encoding,
                schema.data,
            )
            if message.publish_time >= after_ns:
                out.append((channel.topic, message.log_time, message.data))
    return topics, out


@pytest.fixture
def display():
    display = Display.open(TEAM, port=0, token=TOKEN, foxglove=True)
    try:
        yield display
    finally:
        display.close()


def test_foxglove_receives_what_the_recording_holds(display, tmp_path) -> None:
    live = display.foxglove
    page = display.server.url
    assert display.foxglove_url == f"{page.replace('http', 'ws', 1)}foxglove?token={TOKEN}"
    first, then = batch(0), [*batch(1), *batch(2), *batch(3)]
    live.ingest_batch(first)  # the topics appear with their first messages
    with FoxgloveClient(display.foxglove_url) as client:
        assert client.ws.subprotocol == SUBPROTOCOL
        assert client.server_info["name"] == f"heft {TEAM}"
        advertised = client.advertised(set(live.channels))
        client.subscribe(advertised.values())
        wait_until(lambda: all(c.has_sinks() for c in live.channels.values()), "subscribed")
        live.ingest_batch(then)
        path = tmp_path / "run.mcap"
        with Recorder(path, TEAM) as recorder:
            for key, message, _, stamp in [*first, *then]:
                recorder.write(key, message, stamp)
        topics, expected = recorded(path, after_ns=then[0][3])
        received = client.receive(len(expected))

    # Every topic of the recording, with its schema; every message, stamped the same.
    assert set(advertised) == set(topics)
    for topic, (encoding, schema_name, schema_encoding, schema) in topics.items():
        channel = advertised[topic]
        assert (channel.encoding, channel.schema_name, channel.schema_encoding) == (
            encoding,
            schema_name,
            schema_encoding,
        )
        assert channel.schema == schema, topic
    assert sorted((r.topic, r.log_time_ns, r.data) for r in received) == sorted(expected)
    drawn = {c.schema_name for c in advertised.values() if c.schema_encoding == "protobuf"}
    assert drawn == {"foxglove.SceneUpdate", "foxglove.FrameTransform", "foxglove.Log"}

    # And what arrives is what the team said.
    kinds = {KEYS.of(m): type(m) for m in team_messages(0)}
    heard = [
        (r.topic, channels.from_record(kinds[r.topic], r.data))
        for r in received
        if advertised[r.topic].schema_name.startswith("heft.")
    ]
    said = [(key, message) for key, message, _, _ in then]
    assert sorted(heard, key=repr) == sorted(said, key=repr)


def test_the_foxglove_route_wants_the_token_and_a_subprotocol(display) -> None:
    base = display.foxglove_url.split("?")[0]
    for url in (base, f"{base}?token=wrong"):
        with pytest.raises(InvalidStatus) as refused:
            FoxgloveClient(url)
        assert refused.value.response.status_code == 403, url
    headers = {"Authorization": f"Bearer {TOKEN}"}
    with FoxgloveClient(base, additional_headers=headers) as client:
        assert client.ws.subprotocol == SUBPROTOCOL
    # The SDK's server speaks only its own subprotocol: a client without it is refused.
    with pytest.raises(InvalidStatus) as refused:
        FoxgloveClient(display.foxglove_url, subprotocols=())
    assert refused.value.response.status_code == 403


def test_a_client_is_disconnected_when_the_dashboard_closes() -> None:
    display = Display.open(TEAM, port=0, foxglove=True)
    try:
        client = FoxgloveClient(display.foxglove_url)
    finally:
        display.close()
    from websockets.exceptions import ConnectionClosed

    with pytest.raises(ConnectionClosed):
        while True:
            client.ws.recv(timeout=20)


def test_a_display_opened_before_its_team_is_known_serves_it_once_named() -> None:
    display = Display.open(None, port=0, foxglove=True)  # heft demo's: its run names the team
    try:
        live = display.foxglove
        live.ingest_batch(batch(0))
        assert live.channels == {} and live.messages == 0  # no team: nothing to name them after
        sinks = display.follow(TEAM)
        assert sinks == [display.hub.ingest_batch, live.ingest_batch]
        assert display.hub.team == display.hub.state.team == TEAM
        live.ingest_batch(batch(1))
        assert {KEYS.truth(), f"heft/{TEAM}/scene", f"heft/{TEAM}/transforms"} <= set(live.channels)
        assert live.messages > len(batch(1))
        display.follow(TEAM)  # the same team again: nothing changes
        with pytest.raises(ValueError, match="not 'other'"):
            display.follow("other")
    finally:
        display.close()


def test_without_foxglove_there_is_no_foxglove_route() -> None:
    display = Display.open(TEAM, port=0)
    try:
        assert display.foxglove is None and display.foxglove_url is None
        with pytest.raises(InvalidStatus):
            FoxgloveClient(f"{display.url.replace('http', 'ws', 1)}foxglove")
    finally:
        display.close()


@pytest.mark.parametrize(
    ("level", "foxglove_level"),
    [("info", "INFO"), ("warning", "WARNING"), ("error", "ERROR"), ("critical", "FATAL")],
)
def test_a_log_line_is_a_foxglove_log_message(level: str, foxglove_level: str) -> None:
    line = LogLine(3, 120, level, "robot 3: tick 120: phase inertia\n\tand more")
    entry = log_entry(line, timestamp(1_700_000_001_250_000_007))
    schema = entry.get_schema()
    assert (schema.name, schema.encoding) == ("foxglove.Log", "protobuf")
    log = decoder(schema.name, schema.data).FromString(entry.encode())
    assert (log.timestamp.seconds, log.timestamp.nanos) == (1_700_000_001, 250_000_007)
    assert log.message == line.text and log.name == "robot 3"
    assert (
        log.DESCRIPTOR.fields_by_name["level"].enum_type.values_by_number[log.level].name
        == foxglove_level
    )


def test_an_agents_log_line_is_recorded_and_on_the_teams_log() -> None:
    keys = Keys("paper")
    topics = Topics("paper")
    topics.of(keys.clock(), Clock(40, 0.4), START_NS)
    line = LogLine(2, 40, "warning", "robot 2: neighbour 3 lost")
    record, log = topics.of(keys.log(2), line, START_NS + 1)
    assert (record.topic, record.schema.name) == (keys.log(2), "heft.LogLine")
    assert (log.topic, log.schema.name) == ("heft/paper/log", "foxglove.Log")
    assert record.log_time_ns == log.log_time_ns == 400_000_000  # tick 40 on the plant's clock
    entry = decoder(log.schema.name, log.schema.data).FromString(log.data)
    assert (entry.message, entry.name, entry.timestamp.nanos) == (line.text, "robot 2", 4e8)
