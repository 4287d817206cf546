"""``heft dashboard --foxglove`` as a process beside a team publishing on a router: it prints the
URL to give Foxglove, and a minimal Foxglove WebSocket client connected there (through the
dashboard's port, with its token) receives every robot's estimates at the team's rate (every
tick, in order, as published) and nothing that was forged; SIGTERM ends it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading

import pytest

from agent.platform.protocol import Command, Estimates, LoadGeometry, Measurement
from dashboard import channels
from tests.helpers.foxglove_ws import FoxgloveClient
from tests.helpers.paths import ROOT
from tests.integration.test_recording_over_zenoh import GEOMETRY, Team

TOKEN = "s3cret"


def start_dashboard(team: Team) -> tuple[subprocess.Popen, str]:
    """``heft dashboard --foxglove`` on a free port; the process and the URL it prints for
    Foxglove."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONUNBUFFERED="1")
    args = [sys.executable, "-m", "agent", "dashboard", "--team", team.keys.team, "--foxglove"]
    process = subprocess.Popen(
        [*args, "--port", "0", "--token", TOKEN, "--connect", team.endpoint],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        env=env,
    )
    said = [process.stdout.readline(), process.stdout.readline()]
    assert said[0].startswith("dashboard: http://127.0.0.1:"), said
    assert said[1].startswith("foxglove: ws://127.0.0.1:"), said
    assert said[1].rstrip().endswith(f"/foxglove?token={TOKEN}"), said
    threading.Thread(target=process.stdout.read, daemon=True).start()
    return process, said[1].split(" ", 1)[1].strip()


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
