"""A live Foxglove connection to a team, as Foxglove makes it: a minimal Foxglove WebSocket client
connected to the URL printed for Foxglove, through the dashboard's port.

- ``heft dashboard --foxglove`` as a process beside a team publishing on a router (with its
  token): the client receives every robot's estimates at the team's rate (every tick, in order,
  as published) and nothing that was forged; SIGTERM ends it.
- ``heft demo --foxglove``, the paper's team running in real time: the client receives the scene
  (``foxglove.SceneUpdate`` and ``foxglove.FrameTransform``, decoded with protobuf) where the
  truth it receives too puts the load, its contacts and the robots' forces and estimates, and
  every robot's estimates at the team's rate (as many per robot as the ticks elapsed say, in
  order); SIGTERM interrupts the run."""

from __future__ import annotations

import dataclasses
import math
import os
import signal
import statistics
import subprocess
import sys
import threading
from collections import defaultdict
from pathlib import Path

import pytest

from agent.node import AgentNodeConfig
from agent.platform.protocol import Command, Estimates, Keys, LoadGeometry, Measurement, Truth
from dashboard import channels
from dashboard.scene import SceneTopics
from simulator.scenario import load_scenario
from tests.helpers.foxglove import close, decoder, in_world, turn
from tests.helpers.foxglove_ws import FoxgloveClient
from tests.helpers.paths import PAPER, ROOT
from tests.integration.test_recording_over_zenoh import GEOMETRY, Team

TOKEN = "s3cret"


def start_heft(*args: str, stderr=subprocess.DEVNULL) -> subprocess.Popen:
    """``heft ARGS`` as a process, its standard output read line by line."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONUNBUFFERED="1")
    return subprocess.Popen(
        [sys.executable, "-m", "agent", *args],
        stdout=subprocess.PIPE,
        stderr=stderr,
        text=True,
        env=env,
    )


def foxglove_url(process: subprocess.Popen, query: str = "") -> str:
    """The URL ``process`` prints for Foxglove, after its dashboard's (``query`` after it);
    the rest of its output is read on and dropped."""
    said = [process.stdout.readline(), process.stdout.readline()]
    assert said[0].startswith("dashboard: http://127.0.0.1:"), said
    assert said[1].startswith("foxglove: ws://127.0.0.1:"), said
    assert said[1].rstrip().endswith(f"/foxglove{query}"), said
    threading.Thread(target=process.stdout.read, daemon=True).start()
    return said[1].split(" ", 1)[1].strip()


def start_dashboard(team: Team) -> tuple[subprocess.Popen, str]:
    """``heft dashboard --foxglove`` on a free port; the process and the URL it prints for
    Foxglove."""
    process = start_heft(
        *("dashboard", "--team", team.keys.team, "--foxglove", "--port", "0"),
        *("--token", TOKEN, "--connect", team.endpoint),
    )
    return process, foxglove_url(process, f"?token={TOKEN}")


@pytest.mark.slow
def test_foxglove_follows_a_live_team_through_the_dashboard() -> None:
    with Team(f"fox-{os.getpid()}") as team:
        process, url = start_dashboard(team)
        try:
            keys = team.keys
            kinds = {keys.geometry(): LoadGeometry}
            for i in (1, 2):
                kinds |= {
                    keys.velocity(i): Measurement,
                    keys.force(i): Command,
                    keys.estimate(i): Estimates,
                }
            with FoxgloveClient(url) as client:
                advertised = client.advertised(set(kinds))
                client.subscribe(advertised[topic] for topic in kinds)
                received = client.receive(2000)
        finally:
            process.send_signal(signal.SIGTERM)
            assert process.wait(timeout=20) == 0

    heard = [(r.topic, channels.from_record(kinds[r.topic], r.data)) for r in received]
    assert {topic for topic, _ in heard} == set(kinds)
    assert {m for topic, m in heard if topic == keys.geometry()} == {GEOMETRY}
    for i in (1, 2):
        estimates = [m for topic, m in heard if topic == keys.estimate(i)]
        ticks = [m.tick for m in estimates]
        # Every tick the team published since the subscription, in order: the team's rate.
        assert len(ticks) > 100 and ticks == list(range(ticks[0], ticks[0] + len(ticks)))
        assert all(m.omega == 0.01 * m.tick for m in estimates)
        forces = [m for topic, m in heard if topic == keys.force(i)]
        assert forces and all(m == Command(i, m.tick, (1.0, -1.0)) for m in forces)


# ------------------------------------------------------------------------------ heft demo
TICKS = 300
"""How much of the demo's run the client takes: about 3 s of the team's time."""
MESSAGES = 7 * TICKS
"""What the client takes of it: per tick a truth, its frame and 4 commands, a robot's estimates
every 5 ticks (:data:`REPORT_EVERY`), a scene every 5 or 6."""
REPORT_EVERY = {f.name: f for f in dataclasses.fields(AgentNodeConfig)}["report_every"].default
"""The demo's agents publish their estimates every this many ticks (the default)."""
EDGE_TICKS = 25
"""How far the stretch of ticks a robot's estimates received cover may differ from the truths'
at either end: the agents and the plant publish a little apart, by more or less from one
instant to another."""


def decoded(advertised, topic: str):
    """The protobuf class of ``topic``'s messages, from the schema advertised with it."""
    channel = advertised[topic]
    assert (channel.encoding, channel.schema_encoding) == ("protobuf", "protobuf")
    return decoder(channel.schema_name, channel.schema)


def check_scene(update, frame, truth: Truth, outline, commands, estimates) -> None:
    """The scene ``update`` drawn where ``truth`` puts the load (its frame ``frame``), with each
    robot's newest command (``commands``) and estimates (``estimates``) received before it."""
    entities = {e.id: e for e in update.entities}
    expected = {"load", "com"}
    for i in range(1, len(truth.contacts) + 1):
        expected.add(f"contact/{i}")
        if math.hypot(*commands[i].force) > 0.0:
            expected.add(f"force/{i}")
        if estimates[i].contact_to_com is not None:
            expected.add(f"com_estimate/{i}")
        if estimates[i].relative_positions or estimates[i].centroid_offset is not None:
            expected.add(f"geometry/{i}")
    assert set(entities) == expected
    lines = entities["load"].lines[0]
    drawn = [in_world(frame, lines.pose, p.x, p.y) for p in lines.points]
    assert len(drawn) == len(outline) and all(map(close, drawn, outline))
    assert close(in_world(frame, entities["com"].spheres[0].pose), truth.com_position)
    for i, contact in enumerate(truth.contacts, start=1):
        assert close(in_world(frame, entities[f"contact/{i}"].spheres[0].pose), contact)
        if f"force/{i}" in entities:
            arrow = entities[f"force/{i}"].arrows[0]
            assert close(in_world(frame, arrow.pose), contact)
            heading = turn(frame.rotation) + turn(arrow.pose.orientation)
            force = commands[i].force
            assert abs(math.remainder(heading - math.atan2(force[1], force[0]), math.tau)) < 1e-9
        est = estimates[i]
        if f"geometry/{i}" in entities:  # its neighbours' contacts where it puts them
            placed = [in_world(frame, s.pose) for s in entities[f"geometry/{i}"].spheres]
            wanted = [
                (contact[0] - z[0], contact[1] - z[1])
                for _, z in sorted(est.relative_positions.items())
            ]
            assert len(placed) == len(wanted) and all(map(close, placed, wanted))
        if f"com_estimate/{i}" in entities:  # later in the run: the COM where it puts it
            ring = entities[f"com_estimate/{i}"].lines[0]
            points = [in_world(frame, ring.pose, p.x, p.y) for p in ring.points]
            centre = tuple(sum(c) / len(points) for c in zip(*points))
            offset = est.contact_to_com
            assert close(centre, (contact[0] + offset[0], contact[1] + offset[1]))


@pytest.mark.slow
def test_foxglove_follows_heft_demo_live(tmp_path: Path) -> None:
    scenario = load_scenario(PAPER)
    robots = range(1, scenario.n + 1)
    with (tmp_path / "stderr.txt").open("w") as stderr:  # kept by pytest, to read on a failure
        process = start_heft(
            *("demo", "--foxglove", "--dashboard-port", "0", "--no-wait", "-q"),
            *("--record", str(tmp_path / "demo.mcap")),
            stderr=stderr,
        )
    try:
        url = foxglove_url(process)
        keys = Keys("paper")  # the launcher names the team after its scenario
        drawn = SceneTopics(keys.team)
        kinds = {keys.truth(): Truth}
        kinds |= {keys.force(i): Command for i in robots}
        kinds |= {keys.estimate(i): Estimates for i in robots}
        with FoxgloveClient(url) as client:
            advertised = client.advertised({*kinds, drawn.scene, drawn.transforms})
            client.subscribe(advertised[t] for t in (*kinds, drawn.scene, drawn.transforms))
            received = client.receive(MESSAGES)
    finally:
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=60) == 130  # interrupted: the run is stopped

    scene_of, frame_of = decoded(advertised, drawn.scene), decoded(advertised, drawn.transforms)
    truths: list[Truth] = []
    commands: dict[int, Command] = {}
    estimates: dict[int, list[Estimates]] = defaultdict(list)
    frame = None
    scenes = 0
    for before, got in zip([None, *received], received):
        if got.topic in kinds:
            message = channels.from_record(kinds[got.topic], got.data)
            if isinstance(message, Truth):
                truths.append(message)
            elif isinstance(message, Command):
                assert keys.force(message.robot) == got.topic
                commands[message.robot] = message
            else:
                assert keys.estimate(message.robot) == got.topic
                estimates[message.robot].append(message)
        elif got.topic == drawn.transforms:
            # Each truth's frame right after it, stamped with it: world -> load at its pose.
            if before is None:
                continue  # its truth came before the subscription
            assert before.topic == keys.truth()
            truth, frame = truths[-1], frame_of.FromString(got.data)
            assert (frame.parent_frame_id, frame.child_frame_id) == ("world", "load")
            assert close((frame.translation.x, frame.translation.y), truth.com_position)
            assert abs(math.remainder(turn(frame.rotation) - truth.angle, math.tau)) < 1e-9
            assert frame.timestamp.seconds * 10**9 + frame.timestamp.nanos == got.log_time_ns
        elif got.topic == drawn.scene:
            # The scene right after a frame, as of the messages before it.
            assert before is not None and before.topic == drawn.transforms
            if set(commands) == set(estimates) == set(robots):
                truth = truths[-1]
                outline = scenario.load_geometry().world_outline(truth.com_position, truth.angle)
                newest = {i: estimates[i][-1] for i in robots}
                check_scene(scene_of.FromString(got.data), frame, truth, outline, commands, newest)
                scenes += 1

    # The truth every tick, in order, and with it the scene (one every 0.05 s of the messages'
    # time: every 5 or 6 ticks, at least one every 20).
    ticks = [t.tick for t in truths]
    assert ticks == list(range(ticks[0], ticks[0] + len(ticks)))
    assert len(ticks) >= 0.8 * TICKS and scenes >= len(ticks) // 20
    # Every robot's estimates at the team's rate, in order, as many as the ticks that passed:
    # sent at every REPORT_EVERY-th tick, each of the instant the robot could estimate up to,
    # which lags that tick by as long as its neighbours' shares took to arrive. In real time that
    # lag varies: a neighbour held 100 ms by a busy machine makes one step between reports 0 or
    # 2 * REPORT_EVERY more, and the one after it makes up for it. So the instants never go
    # back, most steps are REPORT_EVERY, and their count follows the ticks.
    for i in robots:
        mine = [e.tick for e in estimates[i]]
        gaps = [b - a for a, b in zip(mine, mine[1:])]
        odd = [(n, gap) for n, gap in enumerate(gaps) if gap != REPORT_EVERY]
        assert all(gap >= 0 for gap in gaps), (i, odd, mine)
        assert statistics.median(gaps) == REPORT_EVERY, (i, odd, mine)
        assert abs(len(mine) * REPORT_EVERY - len(ticks)) <= 2 * EDGE_TICKS, (i, mine, ticks)
