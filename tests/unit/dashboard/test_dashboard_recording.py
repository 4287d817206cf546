"""Recordings (dashboard/recorder.py) and replays (dashboard/replay.py) in one process: a run
recorded and replayed gives the same final table; replays step and pause; what is not a
recording is refused. ``heft record`` over Zenoh is in
tests/integration/test_recording_over_zenoh.py."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from agent.platform.evaluation import SCALAR_95
from agent.platform.protocol import Clock, Estimates, Keys, Phase
from dashboard.channels import record_bytes
from dashboard.recorder import Recorder
from dashboard.recording_file import TEAM_METADATA
from dashboard.replay import Recording, RecordingError, Replayer
from dashboard.state import TeamState
from tests.helpers.floor import FLOOR
from tests.helpers.paths import PAPER
from tests.helpers.recordings import record_run


@pytest.fixture(scope="module")
def paper_run():
    from simulator.inprocess import run_inprocess
    from simulator.scenario import load_scenario

    scenario = load_scenario(PAPER)
    return scenario, run_inprocess(scenario)


def test_a_replayed_recording_gives_the_runs_final_table(tmp_path: Path, paper_run) -> None:
    scenario, outcome = paper_run
    path = tmp_path / "paper.mcap"
    record_run(path, scenario, outcome)
    # The file is a proper MCAP file with a summary, JSON-schema channels of the messages and
    # protobuf ones of what Foxglove draws of them (which the replay skips).
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count > 0
        schemas = {schema.name: schema.encoding for schema in summary.schemas.values()}
        assert schemas == {
            "heft.LoadGeometry": "jsonschema",
            "heft.Truth": "jsonschema",
            "heft.Estimates": "jsonschema",
            "heft.Command": "jsonschema",
            "foxglove.FrameTransform": "protobuf",
            "foxglove.SceneUpdate": "protobuf",
            "foxglove.Log": "protobuf",
        }
        encodings = {c.topic: c.message_encoding for c in summary.channels.values()}
        drawn = {"heft/paper/transforms", "heft/paper/scene", "heft/paper/log"}
        assert {encodings.pop(topic) for topic in drawn} == {"protobuf"}
        assert set(encodings.values()) == {"json"}
    direct = TeamState("paper", scenario.load_geometry())
    for sample in [*outcome.history, outcome.final]:
        direct.ingest(sample.truth, 0.0)
        for est in sample.estimates.values():
            direct.ingest(est, 0.0)
    recording = Recording(path)
    assert recording.header() == "paper"
    replayed = TeamState("paper")
    replayer = Replayer(recording, lambda r, t: replayed.ingest(r.message, t), speed=0).start()
    assert replayer.finished.wait(30)
    assert recording.cut is None and not recording.rejected
    assert replayed.geometry == scenario.load_geometry()  # the outline from the recording
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


def test_a_recording_carries_the_floors_friction(tmp_path: Path) -> None:
    """The truth's floor and each robot's friction estimates with their standard deviations
    cross a recording whole; the replay charts ``τ̂_c`` and ``μ̂`` with their 95 % bands
    against the truth's ``μ m g c`` and ``μ``."""
    keys = Keys("floor")
    truth = dataclasses.replace(FLOOR, tick=200, time_s=2.0)
    est = Estimates(
        1,
        200,
        Phase.PUSH,
        friction_torque=1.47,
        friction_torque_std=0.01,
        coulomb=0.0201,
        coulomb_std=1e-4,
    )
    path = tmp_path / "floor.mcap"
    with Recorder(path, "floor") as recorder:
        recorder.write(keys.truth(), truth, 1)
        recorder.write(keys.estimate(1), est, 2)
    recording = Recording(path)
    replayed = [r.message for r in recording.messages()]
    assert replayed == [truth, est] and not recording.rejected
    state = TeamState("floor")
    for message in replayed:
        state.ingest(message, 0.0)
    series = state.all_series()
    assert series["friction_torque/1"] == [[2.0, 1.47, round(0.01 * SCALAR_95, 9)]]
    assert series["coulomb/1"] == [[2.0, 0.0201, round(1e-4 * SCALAR_95, 9)]]
    assert series["friction_torque/truth"] == [[2.0, round(truth.coulomb_torque, 9)]]
    assert series["coulomb/truth"] == [[2.0, 0.02]]


def _positions(path: Path) -> list[tuple[float, object, int, int]]:
    """Each message as a replay delivers it: the recording's clock then, the message, its
    arrival and its instant (ns)."""
    delivered = []
    replayer = Replayer(
        Recording(path),
        lambda r, t: delivered.append((t, r.message, r.time_ns, r.log_time_ns)),
        speed=0,
    ).start()
    assert replayer.finished.wait(10)
    return delivered


def test_a_replay_is_paced_by_arrival_and_reads_each_messages_instant(tmp_path: Path) -> None:
    """A lockstep run: ten ticks of the plant's clock (100 ms) arrive within 5 ms of the wall
    clock. The replay plays them as they arrived (the page as it was live); each message's own
    instant, ``time_s``, is read back as ``log_time_ns``."""
    keys = Keys("pace")
    path = tmp_path / "pace.mcap"
    start = 1_800_000_000_000_000_000
    arrivals = [start + k * 500_000 for k in range(10)]
    with Recorder(path, "pace") as recorder:
        for k, at in enumerate(arrivals):
            recorder.write(keys.clock(), Clock(k, k * 0.01), at)
    delivered = _positions(path)
    assert [m.tick for _, m, _, _ in delivered] == list(range(10))
    assert [at for _, _, at, _ in delivered] == arrivals
    assert [t for t, _, _, _ in delivered] == [(at - start) / 1e9 for at in arrivals]
    assert [log for _, _, _, log in delivered] == [round(k * 0.01 * 1e9) for k in range(10)]


def test_a_recording_stamped_with_arrivals_still_replays(tmp_path: Path) -> None:
    """Recordings made before ``log_time`` was the team's clock have the arrival in both
    stamps: they replay as they did."""
    keys = Keys("old")
    path = tmp_path / "old.mcap"
    start = 1_700_000_000_000_000_000
    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start(library="heft")
        writer.add_metadata(TEAM_METADATA, {"team": "old"})
        schema = writer.register_schema("heft.Clock", "jsonschema", b"{}")
        channel = writer.register_channel(keys.clock(), "json", schema)
        for k in range(5):
            at = start + k * 10_000_000
            writer.add_message(channel, at, record_bytes(Clock(k, k * 0.01)), at)
        writer.finish()
    delivered = _positions(path)
    assert [m for _, m, _, _ in delivered] == [Clock(k, k * 0.01) for k in range(5)]
    assert [t for t, _, _, _ in delivered] == [k * 0.01 for k in range(5)]
    assert all(at == log for _, _, at, log in delivered)
