"""``heft record`` over Zenoh, as a process beside a team publishing on a router: it keeps every
robot's measurements and commands and the plant's load geometry, closes its file on SIGTERM and
leaves it readable up to the cut when killed with SIGKILL, and ``heft record --repair`` makes
that file whole; a lockstep run's recording is on the plant's clock (``log_time`` is
``time_s``); and the live display follows a team, draws the load the plant describes and drops
what is forged."""

from __future__ import annotations

import io
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.records import Message
from mcap.stream_reader import StreamReader

from agent.platform.protocol import (
    Clock,
    Command,
    Estimates,
    Keys,
    LoadGeometry,
    Measurement,
    Phase,
    encode,
)
from agent.platform.zenoh_session import ZenohSettings, open_session
from dashboard.replay import Recording, Replayer
from dashboard.state import TeamState
from tests.helpers.paths import PAPER, ROOT


# ------------------------------------------------------------------------------ over Zenoh
def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


GEOMETRY = LoadGeometry(2, ((-1.0, -0.5), (1.0, -0.5), (0.0, 1.0)), ((1, 2),), 0.005)
"""The load the fake team's plant describes."""


class Team:
    """A router in this process and a fake team publishing on it at 200 Hz: measurements,
    commands and estimates of robots 1 and 2, and every 20 ticks the load's geometry (as the
    plant does with each of its statuses)."""

    def __init__(self, team: str):
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.keys = Keys(team)
        self.session = open_session(
            ZenohSettings(mode="router", connect=(), listen=(self.endpoint,))
        )
        self.tick = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._publish, daemon=True)

    def _publish(self) -> None:
        keys, put = self.keys, self.session.put
        while not self._stop.is_set():
            k = self.tick
            for i in (1, 2):
                put(keys.velocity(i), encode(Measurement(i, k, k * 0.005, (0.1, 0.0), (1.0, 0.0))))
                put(keys.force(i), encode(Command(i, k, (1.0, -1.0))))
                put(keys.estimate(i), encode(Estimates(i, k, Phase.EXCITE, omega=0.01 * k)))
            put(keys.force(1), b"forged")  # counted and dropped, never recorded
            if k % 20 == 0:
                put(keys.geometry(), encode(GEOMETRY))
            self.tick = k + 1
            time.sleep(0.005)

    def __enter__(self) -> Team:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        self.session.close()


def start_recorder(path: Path, team: Team) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONUNBUFFERED="1")
    args = [sys.executable, "-m", "agent", "record", "--team", team.keys.team, "-o", str(path)]
    process = subprocess.Popen(
        [*args, "--connect", team.endpoint],
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
        env=env,
    )
    said = []
    while len(said) < 3 and not any("recording team" in line for line in said):
        said.append(process.stderr.readline())  # (after the plain link's note, if any)
    assert "recording team" in said[-1], "".join(said) + process.stderr.read()
    threading.Thread(target=process.stderr.read, daemon=True).start()  # (never blocks it)
    return process


def read_all(path: Path) -> tuple[Recording, list]:
    recording = Recording(path)
    return recording, list(recording.messages())


def check_stream(messages: list) -> None:
    """Both robots' measurements, commands and estimates, every tick in order, and the load's
    geometry."""
    geometries = [r.message for r in messages if isinstance(r.message, LoadGeometry)]
    assert geometries and set(geometries) == {GEOMETRY}
    robots = [r for r in messages if not isinstance(r.message, LoadGeometry)]
    kinds = {(type(r.message).__name__, r.key.split("/")[3]) for r in robots}
    assert kinds == {(k, i) for k in ("Measurement", "Command", "Estimates") for i in "12"}
    ticks = [r.message.tick for r in messages if isinstance(r.message, Measurement)]
    assert ticks == sorted(ticks)


@pytest.mark.slow
def test_heft_record_closes_its_file_on_sigterm(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    with Team(f"rec-{os.getpid()}") as team:
        recorder = start_recorder(path, team)
        time.sleep(1.5)
        recorder.send_signal(signal.SIGTERM)
        assert recorder.wait(timeout=15) == 0
    with open(path, "rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and summary.statistics.message_count > 100
    # Every message's record replays (what Foxglove draws of them, foxglove.* schemas, not).
    counts = summary.statistics.channel_message_counts
    records = sum(
        counts.get(channel.id, 0)
        for channel in summary.channels.values()
        if summary.schemas[channel.schema_id].name.startswith("heft.")
    )
    recording, messages = read_all(path)
    assert recording.cut is None and len(messages) == records > 100
    check_stream(messages)


def messages_before_the_cut(data: bytes) -> int:
    """The messages of every channel in a cut MCAP file, read up to the cut."""
    count, records = 0, StreamReader(io.BytesIO(data)).records
    while True:
        try:
            record = next(records)
        except StopIteration:
            return count
        except Exception:  # noqa: BLE001 - the cut: a truncated record
            return count
        count += isinstance(record, Message)


@pytest.mark.slow
def test_a_recording_killed_with_sigkill_replays_up_to_the_cut(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    with Team(f"kill-{os.getpid()}") as team:
        recorder = start_recorder(path, team)
        time.sleep(2.0)
        killed_at = team.tick
        recorder.kill()
        assert recorder.wait(timeout=15) == -signal.SIGKILL
    recording, messages = read_all(path)
    assert not recording.rejected
    check_stream(messages)
    last = max(r.message.tick for r in messages if hasattr(r.message, "tick"))
    # Chunks are flushed every 0.5 s: at most that (and a little scheduling) was lost.
    assert killed_at - last < 0.5 / 0.005 + 100, (killed_at, last)
    # And it replays: the dashboard's state follows it to its last estimates.
    state = TeamState(recording.team)
    replay = Replayer(Recording(path), lambda r, t: state.ingest(r.message, t), speed=0).start()
    assert replay.finished.wait(30)
    assert state.robots[1].estimates.tick >= last - 1
    # Repaired, the MCAP readers take it whole, with every message it held.
    cut = path.read_bytes()
    with open(path, "rb") as stream, pytest.raises(Exception):  # noqa: B017, PT011
        make_reader(stream).get_summary()
    repaired = subprocess.run(
        [sys.executable, "-m", "agent", "record", "--repair", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
    )
    assert repaired.returncode == 0, repaired.stderr
    held = messages_before_the_cut(cut)
    assert held > len(messages)  # the team's records, and what Foxglove draws of them
    assert f"repaired, {held} messages kept" in repaired.stdout
    with open(path, "rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary.statistics.message_count == held
    again, whole = read_all(path)
    assert again.cut is None and whole == messages


@pytest.mark.slow
def test_a_lockstep_runs_recording_is_on_the_plants_clock(tmp_path: Path) -> None:
    """``heft run --transport zenoh --record``: every message with a ``time_s`` has it as its
    ``log_time`` to the nanosecond, every tick-stamped one its tick's Clock's, one stamp per
    tick; ``publish_time`` is the wall clock while the run ran."""
    path = tmp_path / "lockstep.mcap"
    started = time.time_ns()
    run = subprocess.run(
        [sys.executable, "-m", "agent", "run", str(PAPER), "--transport", "zenoh", "-q"]
        + ["--record", str(path)],
        capture_output=True,
        text=True,
        timeout=300,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
    )
    ended = time.time_ns()
    assert run.returncode == 0, run.stderr
    recording, messages = read_all(path)
    assert recording.cut is None and not recording.rejected
    clock = {r.message.tick: r.log_time_ns for r in messages if isinstance(r.message, Clock)}
    timed = [r for r in messages if hasattr(r.message, "time_s")]
    ticked = [
        r
        for r in messages
        if not hasattr(r.message, "time_s") and getattr(r.message, "tick", -1) >= 0
    ]
    assert len(clock) > 500 and timed and ticked
    assert [r.log_time_ns for r in timed] == [round(r.message.time_s * 1e9) for r in timed]
    assert [r.log_time_ns for r in ticked] == [clock[r.message.tick] for r in ticked]
    ticks = {r.message.tick for r in messages if getattr(r.message, "tick", -1) >= 0}
    assert len({r.log_time_ns for r in messages}) == len(ticks)
    assert all(started <= r.time_ns <= ended for r in messages)


@pytest.mark.slow
def test_the_live_display_follows_a_team_and_drops_what_is_forged() -> None:
    from dashboard.display import Display

    with Team(f"live-{os.getpid()}") as team:
        display = Display.open(team.keys.team, port=0)
        try:
            display.watch(ZenohSettings(mode="client", connect=(team.endpoint,)))
            deadline = time.monotonic() + 20
            while time.monotonic() < deadline:
                robots = display.hub.snapshot()["robots"]
                heard = display.hub.state.geometry is not None
                if {"1", "2"} <= set(robots) and display.feed.rejects.total > 10 and heard:
                    break
                time.sleep(0.1)
            snapshot = display.hub.snapshot()
            assert snapshot["robots"]["2"]["tick"] > 0
            assert snapshot["robots"]["1"]["omega"] == pytest.approx(
                0.01 * snapshot["robots"]["1"]["tick"]
            )
            assert display.hub.state.geometry == GEOMETRY  # the outline, from the plant
            assert display.feed.rejects.counts["force"] > 10  # the forged payloads
            assert display.feed.failures == 0
        finally:
            display.close()
