"""The results file is never lost and never half-written: it is written atomically (a failure
or a signal mid-write leaves the previous file as it was, and no temporary behind), never
created before the run, and written whatever the verdict — with ``"converged": false``, the
reason and null estimates when nothing could be recorded. In one process; the runs over Zenoh
are in tests/integration/test_supervision.py."""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import stat
from pathlib import Path

import pytest

from agent.platform.cli_helpers import UsageError, check_writable, write_text
from agent.platform.heft import main
from simulator import cli
from simulator.results import (
    ERROR_KEYS,
    failed_results_dict,
    format_table,
    rejection_counts,
    results_dict,
)
from simulator.scenario import load_scenario
from tests.helpers.paths import PAPER


def _heft(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


def _files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


# ------------------------------------------------------------------------------ atomic writes
def test_a_write_that_fails_leaves_the_previous_file_whole(tmp_path, monkeypatch) -> None:
    path = tmp_path / "r.json"
    write_text(path, '{"first": true}\n')

    def no_space(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", no_space)
    with pytest.raises(UsageError, match="No space left"):
        write_text(path, '{"second": true}\n')
    assert path.read_text() == '{"first": true}\n'
    assert _files(tmp_path) == ["r.json"]  # no temporary left behind


def test_a_rename_that_fails_leaves_the_previous_file_whole(tmp_path, monkeypatch) -> None:
    path = tmp_path / "r.json"
    write_text(path, "old\n")

    def refuse(src, dst):
        raise OSError(18, "Invalid cross-device link")

    monkeypatch.setattr(os, "replace", refuse)
    with pytest.raises(UsageError, match="cross-device"):
        write_text(path, "new\n")
    assert path.read_text() == "old\n" and _files(tmp_path) == ["r.json"]


def test_a_signal_mid_write_leaves_the_previous_file_whole(tmp_path, monkeypatch) -> None:
    path = tmp_path / "r.json"
    write_text(path, "old\n")

    def ctrl_c(fd):  # the new text is in the temporary file, not yet renamed
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "fsync", ctrl_c)
    with pytest.raises(KeyboardInterrupt):
        write_text(path, "new and longer\n")
    assert path.read_text() == "old\n" and _files(tmp_path) == ["r.json"]


def test_a_written_file_has_the_mode_a_plain_open_gives(tmp_path) -> None:
    fresh = tmp_path / "fresh.json"
    write_text(fresh, "{}\n")
    umask = os.umask(0o022)
    os.umask(umask)
    assert stat.S_IMODE(fresh.stat().st_mode) == 0o666 & ~umask  # not the temporary's 0600
    kept = tmp_path / "kept.json"
    kept.write_text("old\n")
    kept.chmod(0o640)
    write_text(kept, "new\n")
    assert stat.S_IMODE(kept.stat().st_mode) == 0o640 and kept.read_text() == "new\n"


def test_a_link_is_written_through_and_a_device_is_not_replaced(tmp_path) -> None:
    target = tmp_path / "target.json"
    link = tmp_path / "link.json"
    link.symlink_to(target)
    write_text(link, "through\n")
    assert link.is_symlink() and target.read_text() == "through\n"
    check_writable(Path(os.devnull))
    write_text(Path(os.devnull), "{}\n")  # e.g. --out /dev/stdout: written, not renamed over
    assert stat.S_ISCHR(os.stat(os.devnull).st_mode)


def test_checking_an_output_creates_no_file(tmp_path) -> None:
    path = tmp_path / "new" / "r.json"
    check_writable(path)
    assert path.parent.is_dir() and not path.exists()
    assert list(path.parent.iterdir()) == []
    with pytest.raises(UsageError, match="is a folder"):
        check_writable(tmp_path)
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(UsageError, match="cannot write"):
        check_writable(blocker / "r.json")  # its folder would be a file


# ------------------------------------------------------------------------------ the document
def test_a_run_that_recorded_nothing_has_the_same_keys_with_nulls() -> None:
    from simulator.inprocess import run_inprocess

    scenario = load_scenario(PAPER)
    real = results_dict(run_inprocess(scenario))
    failed = failed_results_dict(scenario, "router lost", "the router process ended", 1.5)
    assert set(failed) == set(real) | {"detail"}
    assert failed["converged"] is False and failed["reason"] == "router lost"
    assert failed["detail"] == "the router process ended" and failed["sim_time_s"] is None
    assert sorted(failed["robots"]) == ["1", "2", "3", "4"]
    for robot in failed["robots"].values():
        assert set(robot) == set(real["robots"]["1"])
        assert robot["mass"] is None and robot["moment"] is None
        assert robot["contact_to_com"] is None
    assert failed["errors"] == dict.fromkeys(ERROR_KEYS) and failed["truth"] is None
    assert [p["step"] for p in failed["phases"]] == [1, 2, 3, 4, 5, 6, 7]
    json.dumps(failed, allow_nan=False)


def test_rejections_are_counted_per_robot_and_in_total() -> None:
    reported = {
        "launcher": {"Estimates": 3, "Truth": 2},
        "plant": 4,
        "robots": {
            "1": {"decode_errors": 5, "rejected": 1},
            "2": {"decode_errors": 0, "rejected": 0},
        },
    }
    counts = rejection_counts(reported)
    assert counts["total"] == 3 + 2 + 4 + 5 + 1 and counts["launcher_total"] == 5
    assert counts["robots"]["1"] == {"decode_errors": 5, "rejected": 1, "total": 6}
    assert counts["robots"]["2"]["total"] == 0
    assert rejection_counts(None) is None  # one process: nothing decoded


def test_the_table_has_a_rejections_line_only_when_there_were_some() -> None:
    import dataclasses

    from simulator.inprocess import run_inprocess

    outcome = run_inprocess(load_scenario(PAPER))
    assert "rejected" not in format_table(outcome)
    clean = {"launcher": {}, "plant": 0, "robots": {"1": {"decode_errors": 0, "rejected": 0}}}
    outcome = dataclasses.replace(outcome, transport={"rejections": clean})
    assert "rejected" not in format_table(outcome)
    dirty = {
        "launcher": {"Truth": 2},
        "plant": 1,
        "robots": {"3": {"decode_errors": 4, "rejected": 1}},
    }
    line = format_table(dataclasses.replace(outcome, transport={"rejections": dirty}))
    assert "messages rejected: 8: launcher 2 (Truth 2); plant 1; robot 3 5" in line


# ------------------------------------------------------------------------------ heft run --out
def _short_paper(tmp_path: Path, max_time_s: float) -> Path:
    text = PAPER.read_text(encoding="utf-8").replace(
        "max_time_s = 60.0", f"max_time_s = {max_time_s}"
    )
    path = tmp_path / "short.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_out_is_not_created_before_the_run(tmp_path, monkeypatch) -> None:
    from simulator import inprocess

    out = tmp_path / "r.json"
    seen = []
    real = inprocess.run_inprocess

    def run(*args, **kwargs):
        seen.append(out.exists())
        return real(*args, **kwargs)

    monkeypatch.setattr(inprocess, "run_inprocess", run)
    code, stdout, _ = _heft("run", str(PAPER), "--out", str(out), "--quiet")
    assert code == 0 and seen == [False]
    assert json.loads(out.read_text())["converged"] is True
    assert _files(tmp_path) == ["r.json"]


def test_a_run_out_of_time_writes_its_reason(tmp_path) -> None:
    out = tmp_path / "r.json"
    code, stdout, stderr = _heft("run", str(_short_paper(tmp_path, 2.0)), "--out", str(out), "-q")
    assert code == 1
    results = json.loads(out.read_text())
    assert results["converged"] is False
    assert results["reason"] == "out of simulated time (run.max_time_s = 2 s)"
    assert results["detail"] and results["sim_time_s"] >= 2.0
    last = stderr.strip().splitlines()[-1]
    assert last.startswith("heft: not converged: out of simulated time (run.max_time_s = 2 s): ")
    assert "NOT converged (out of simulated time" in stdout


@pytest.mark.parametrize(
    "sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT], ids=["SIGTERM", "SIGHUP", "SIGINT"]
)
def test_a_signal_mid_run_writes_what_was_recorded(tmp_path, monkeypatch, sig) -> None:
    """The in-process run: SIGTERM and SIGHUP stop it as Ctrl-C does, exit 130, and the results
    recorded so far are written."""

    def printer(started, stream):
        def report(tick, time_s, agents):
            if time_s > 0:
                os.kill(os.getpid(), sig)

        return report

    monkeypatch.setattr(cli, "_progress_printer", printer)
    handlers = [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)]
    out = tmp_path / "r.json"
    code, _, stderr = _heft("run", str(PAPER), "--out", str(out))
    assert code == 130, stderr
    results = json.loads(out.read_text())
    assert results["converged"] is False and results["reason"] == "interrupted"
    assert results["detail"] == f"stopped by {sig.name}"
    assert 4.0 < results["sim_time_s"] < 6.0  # at the first progress line (5 s), not done
    assert results["robots"]["1"]["mass"] is None
    assert stderr.strip().splitlines()[-1] == (
        f"heft: interrupted: stopped by {sig.name}; the results recorded so far are kept in {out}"
    )
    assert handlers == [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)]


def test_a_run_stopped_before_its_first_instant_still_writes_a_file(tmp_path, monkeypatch) -> None:
    from simulator import inprocess

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(inprocess, "run_inprocess", interrupted)
    out = tmp_path / "r.json"
    code, stdout, stderr = _heft("run", str(PAPER), "--out", str(out), "--quiet")
    assert code == 130 and "Traceback" not in stderr
    results = json.loads(out.read_text())
    assert results["converged"] is False and results["reason"] == "interrupted"
    assert results["robots"]["1"]["mass"] is None and results["sim_time_s"] is None
    assert stderr.strip().splitlines()[-1].endswith("nothing was recorded")
