"""A killed recorder's file made whole (dashboard/repair.py, ``heft record --repair``): a
recorder process killed with SIGKILL leaves a file the MCAP readers refuse; repaired, it has its
summary and every message flushed before the kill, as they were. A recorder that starts repairs
what killed recorders left in its folder, and nothing else; what cannot be repaired is refused
in one line."""

from __future__ import annotations

import contextlib
import io
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from agent.platform.heft import main
from agent.platform.protocol import Clock, Keys, LoadGeometry
from dashboard.recorder import Recorder
from dashboard.repair import repair
from dashboard.replay import Recording, RecordingError
from tests.helpers.paths import ROOT

GEOMETRY = LoadGeometry(2, ((-1.0, -0.5), (1.0, -0.5), (0.0, 1.0)), ((1, 2),), 0.01)

KILLED = """
import sys, time
from agent.platform.protocol import Clock, Keys, Measurement
from dashboard.recorder import Recorder

keys = Keys("killed")
recorder = Recorder(sys.argv[1], "killed", flush_every_s=1e9)
for k in range(400):
    recorder.write(keys.clock(), Clock(k, k * 0.01), 10**18 + k)
    sample = Measurement(1, k, k * 0.01, (0.1, 0.0), (1.0, 0.0))
    recorder.write(keys.velocity(1), sample, 10**18 + k)
recorder.flush()
print(recorder.messages, flush=True)
for k in range(400, 500):  # in memory only: a chunk is flushed by time or size, neither is due
    recorder.write(keys.clock(), Clock(k, k * 0.01), 10**18 + k)
print(recorder.messages, flush=True)
time.sleep(120)
"""


def heft(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


def read(path: Path) -> list[tuple[str, int, int, bytes]]:
    """Every message of a complete file: topic, log_time, publish_time, data."""
    with open(path, "rb") as stream:
        return [
            (channel.topic, m.log_time, m.publish_time, m.data)
            for _, channel, m in make_reader(stream).iter_messages(log_time_order=False)
        ]


def summary_count(path: Path) -> int:
    with open(path, "rb") as stream:
        return make_reader(stream).get_summary().statistics.message_count


def test_a_recorder_killed_with_sigkill_is_repaired_with_every_message_it_flushed(
    tmp_path: Path,
) -> None:
    path = tmp_path / "killed.mcap"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    process = subprocess.Popen(
        [sys.executable, "-c", KILLED, str(path)], stdout=subprocess.PIPE, text=True, env=env
    )
    try:
        flushed = int(process.stdout.readline())
        written = int(process.stdout.readline())
    finally:
        process.kill()
        process.wait(timeout=30)
        process.stdout.close()
    assert process.returncode == -signal.SIGKILL and (flushed, written) == (800, 900)
    with open(path, "rb") as stream, pytest.raises(Exception):  # noqa: B017, PT011
        make_reader(stream).get_summary()  # what the MCAP tools see: no footer
    cut = Recording(path)
    before = [(r.key, r.log_time_ns, r.time_ns, r.message) for r in cut.messages()]
    assert cut.cut is not None and len(before) == flushed

    code, out, err = heft("record", "--repair", str(path))
    assert code == 0 and err == ""
    assert out.startswith(f"{path}: repaired, {flushed} messages kept (cut at byte ")

    assert summary_count(path) == flushed == len(read(path))
    again = Recording(path)
    assert [(r.key, r.log_time_ns, r.time_ns, r.message) for r in again.messages()] == before
    assert again.cut is None and again.header() == "killed"
    if shutil.which("mcap"):  # the MCAP command-line tool, where it is installed
        for command in (["doctor"], ["info"]):
            ran = subprocess.run(["mcap", *command, str(path)], capture_output=True, timeout=60)
            assert ran.returncode == 0, ran.stderr


def cut_copy(recorder: Recorder, to: Path) -> None:
    """What ``recorder``'s file would be if its process were killed now."""
    recorder.flush()
    shutil.copyfile(recorder.path, to)


def write_some(recorder: Recorder, ticks: range) -> None:
    keys = Keys(recorder.team)
    recorder.write(keys.geometry(), GEOMETRY, 1)
    for k in ticks:
        recorder.write(keys.clock(), Clock(k, k * 0.01), 2 + k)


def test_a_complete_recording_is_left_as_it_is(tmp_path: Path) -> None:
    path = tmp_path / "whole.mcap"
    with Recorder(path, "whole") as recorder:
        write_some(recorder, range(50))
    data = path.read_bytes()
    code, out, _ = heft("record", "--repair", str(path))
    assert code == 0 and out == f"{path}: complete (51 messages), nothing to repair\n"
    assert path.read_bytes() == data


def test_a_recorder_repairs_what_killed_recorders_left_in_its_folder(tmp_path: Path) -> None:
    """A heft recording cut and held by no one is repaired when the next recorder starts there;
    a cut file of another program's, one a recorder is writing, and one elsewhere are not."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    with Recorder(tmp_path / "first.mcap", "left") as recorder:
        write_some(recorder, range(30))
        cut_copy(recorder, tmp_path / "left.mcap")
        cut_copy(recorder, elsewhere / "left.mcap")
    with open(tmp_path / "other.mcap", "wb") as stream:
        writer = Writer(stream)
        writer.start(library="another program")
        schema = writer.register_schema("s", "jsonschema", b"{}")
        writer.add_message(writer.register_channel("t", "json", schema), 1, b"{}", 1)
        writer.flush()
    foreign = (tmp_path / "other.mcap").read_bytes()
    live = Recorder(tmp_path / "live.mcap", "live")
    try:
        write_some(live, range(10))
        live.flush()
        live_bytes = (tmp_path / "live.mcap").read_bytes()
        with Recorder(tmp_path / "next.mcap", "next"):
            pass
        assert summary_count(tmp_path / "left.mcap") == 31
        assert (tmp_path / "other.mcap").read_bytes() == foreign
        assert (tmp_path / "live.mcap").read_bytes() == live_bytes
        with open(elsewhere / "left.mcap", "rb") as stream, pytest.raises(Exception):  # noqa: B017, PT011
            make_reader(stream).get_summary()
        with pytest.raises(RecordingError, match="a recorder is writing it"):
            repair(tmp_path / "live.mcap")
        with pytest.raises(BlockingIOError, match="another recorder is writing it"):
            Recorder(tmp_path / "live.mcap", "again")
    finally:
        live.close()
    assert summary_count(tmp_path / "live.mcap") == 11


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--repair", "{tmp}/missing.mcap"], "--repair: {tmp}/missing.mcap: no such file"),
        (["--repair", "{tmp}/junk.mcap"], "--repair: {tmp}/junk.mcap: not an MCAP file"),
        (["--repair", "{tmp}/junk.mcap", "--team", "t"], "--team does not apply"),
        (["--repair", "{tmp}/junk.mcap", "-o", "x.mcap", "--duration", "3"], "-o, --duration do"),
        (["--team", "t"], "-o/--output: needed to record (or give --repair FILE)"),
        (["-o", "{tmp}/x.mcap"], "--team: needed to record (or give --repair FILE)"),
    ],
)
def test_what_cannot_be_repaired_is_refused_in_one_line(
    tmp_path: Path, argv: list[str], message: str
) -> None:
    (tmp_path / "junk.mcap").write_bytes(b"not an MCAP file at all")
    code, out, err = heft("record", *(a.format(tmp=tmp_path) for a in argv))
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert err.startswith("heft: error: ") and message.format(tmp=tmp_path) in err
