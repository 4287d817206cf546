"""Recordings (dashboard/recorder.py) and replays (dashboard/replay.py): a run recorded and
replayed gives the same final table; ``heft record`` over Zenoh keeps every robot's
measurements and commands, closes its file on SIGTERM and leaves it readable up to the cut
when killed with SIGKILL; replays step and pause."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from agent.platform.protocol import Command, Estimates, Keys, Measurement, Phase, encode
from agent.platform.zenoh_session import ZenohSettings, open_session
from dashboard.geometry import LoadGeometry
from dashboard.recorder import Recorder
from dashboard.replay import Recording, RecordingError, Replayer
from dashboard.state import TeamState
from tests.helpers.paths import PAPER, ROOT


@pytest.fixture(scope="module")
def paper_run():
    from simulator.inprocess import run_inprocess
    from simulator.scenario import load_scenario

    scenario = load_scenario(PAPER)
    return scenario, run_inprocess(scenario)


def record_run(path: Path, scenario, outcome, team: str = "paper") -> None:
    """The run's recorded instants as a recording, 10 ms of simulated time apart."""
    keys = Keys(team)
    start = 1_700_000_000_000_000_000
    with Recorder(path, team, LoadGeometry.from_scenario(scenario)) as recorder:
        for sample in [*outcome.history, outcome.final]:
            stamp = start + round(sample.truth.time_s * 1e9)
            recorder.write(keys.truth(), sample.truth, stamp)
            for i, est in sample.estimates.items():
                recorder.write(keys.estimate(i), est, stamp)
                recorder.write(keys.force(i), Command(i, sample.truth.tick, (1.0, 0.0)), stamp)


def test_a_replayed_recording_gives_the_runs_final_table(tmp_path: Path, paper_run) -> None:
    scenario, outcome = paper_run
    path = tmp_path / "paper.mcap"
    record_run(path, scenario, outcome)
    # The file is a proper MCAP file with a summary and JSON-schema channels.
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count > 0
        schemas = {schema.name: schema.encoding for schema in summary.schemas.values()}
        assert schemas == {
            "heft.Truth": "jsonschema",
            "heft.Estimates": "jsonschema",
            "heft.Command": "jsonschema",
        }
        assert {c.message_encoding for c in summary.channels.values()} == {"json"}
    direct = TeamState("paper", LoadGeometry.from_scenario(scenario))
    for sample in [*outcome.history, outcome.final]:
        direct.ingest(sample.truth, 0.0)
        for est in sample.estimates.values():
            direct.ingest(est, 0.0)
    recording = Recording(path)
    assert recording.header() == ("paper", LoadGeometry.from_scenario(scenario))
    replayed = TeamState("paper", recording.geometry)
    replayer = Replayer(recording, lambda r, t: replayed.ingest(r.message, t), speed=0).start()
    assert replayer.finished.wait(30)
    assert recording.cut is None and not recording.rejected
    assert replayed.final == direct.final is not None
    assert replayed.final["tick"] == outcome.final.truth.tick
    assert replayed.all_series() == direct.all_series()


def test_a_replay_steps_and_pauses(tmp_path: Path, paper_run) -> None:
    scenario, outcome = paper_run
    path = tmp_path / "paper.mcap"
    record_run(path, scenario, outcome)
    heard: list[float] = []
    replayer = Replayer(Recording(path), lambda r, t: heard.append(t), paused=True).start()
    time.sleep(0.2)
    assert heard == []  # paused from the start
    replayer.step(1.0)
    deadline = time.monotonic() + 5
    while replayer.now() < 1.0 and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(0.2)
    assert heard and max(heard) <= 1.0 and replayer.paused
    assert replayer.now() == 1.0
    count = len(heard)
    time.sleep(0.2)
    assert len(heard) == count  # stays paused after the step
    replayer.play(speed=0)
    assert replayer.finished.wait(10)
    assert max(heard) == pytest.approx(outcome.final.truth.time_s)
    with pytest.raises(ValueError):
        replayer.play(speed=-1)


def test_what_is_not_a_recording_is_refused(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="no such file|cannot read"):
        Recording(tmp_path / "missing.mcap")
    (tmp_path / "junk.mcap").write_bytes(b"not mcap at all")
    with pytest.raises(RecordingError, match="not an MCAP file"):
        Recording(tmp_path / "junk.mcap")


# ------------------------------------------------------------------------------ over Zenoh
def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Team:
    """A router in this process and a fake team publishing on it at 200 Hz: measurements,
    commands and estimates of robots 1 and 2."""

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
    """Both robots' measurements, commands and estimates, every tick in order."""
    kinds = {(type(r.message).__name__, r.key.split("/")[3]) for r in messages}
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
    recording, messages = read_all(path)
    assert recording.cut is None and len(messages) == summary.statistics.message_count
    check_stream(messages)


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
    last = max(r.message.tick for r in messages)
    # Chunks are flushed every 0.5 s: at most that (and a little scheduling) was lost.
    assert killed_at - last < 0.5 / 0.005 + 100, (killed_at, last)
    # And it replays: the dashboard's state follows it to its last estimates.
    state = TeamState(recording.team)
    replay = Replayer(Recording(path), lambda r, t: state.ingest(r.message, t), speed=0).start()
    assert replay.finished.wait(30)
    assert state.robots[1].estimates.tick >= last - 1


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
                if {"1", "2"} <= set(robots) and display.feed.rejects.total > 10:
                    break
                time.sleep(0.1)
            snapshot = display.hub.snapshot()
            assert snapshot["robots"]["2"]["tick"] > 0
            assert snapshot["robots"]["1"]["omega"] == pytest.approx(
                0.01 * snapshot["robots"]["1"]["tick"]
            )
            assert display.feed.rejects.counts["force"] > 10  # the forged payloads
            assert display.feed.failures == 0
        finally:
            display.close()
