"""Supervision of a run over Zenoh: whatever ends it — a signal to the launcher, a lost router,
plant or agents, a killed launcher, agents that cannot start — every process it started goes,
the verdict names the real cause within seconds, and the results file is written whole (never
empty, never half, never before the run)."""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from agent.platform.heft import main
from simulator import launcher
from simulator.run_folder import run_folder
from simulator.scenario import load_scenario
from tests.helpers.accuracy import worst_errors
from tests.helpers.paths import PAPER, ROOT
from tests.helpers.processes import agent_pid, child_pid, children_of, in_session, launch

pytestmark = pytest.mark.slow  # Zenoh sessions and processes


def _running(pids: list[int]) -> list[int]:
    """``pids`` less the zombies (exited, waiting for whoever adopted them to reap them)."""
    running = []
    for pid in pids:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z":
            running.append(pid)
    return running


def _nothing_left(sid: int, within_s: float = 5.0) -> None:
    deadline = time.monotonic() + within_s
    while _running(in_session(sid)) and time.monotonic() < deadline:
        time.sleep(0.05)
    left = {pid: _describe(pid) for pid in _running(in_session(sid))}
    assert left == {}


def _describe(pid: int) -> str:
    try:
        cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[:2]
    except OSError:
        return "gone"
    return f"{cmd} (state {state[0]}, parent {state[1]})"


class Launcher:
    """``heft run`` of the paper over Zenoh in real time, in a session of its own (its pid is
    the session's id), its stderr read as it comes."""

    def __init__(self, out: Path, *args: str):
        self.out = out
        self.process = launch("--clock", "realtime", *args, out=out)
        self.pid = self.process.pid
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.process.stderr:
            self.lines.append(line)

    def wait_for_line(self, text: str, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while not any(text in line for line in self.lines):
            assert self.process.poll() is None, "".join(self.lines)
            assert time.monotonic() < deadline, f"no {text!r} in: {''.join(self.lines)}"
            time.sleep(0.02)

    def under_way(self) -> Launcher:
        """Once the plant has been stepping for two seconds; the results file is not there."""
        self.wait_for_line("all 4 agents are up; starting")
        time.sleep(2.0)
        assert not self.out.exists()
        return self

    def finish(self, timeout: float = 30.0) -> tuple[int, str, float]:
        """Wait for it, checking meanwhile that the results file is never there half-written;
        its exit status, stderr, and the seconds it took."""
        started = time.monotonic()
        while self.process.poll() is None:
            assert time.monotonic() - started < timeout, "the launcher did not end"
            assert not self.out.exists() or json.loads(self.out.read_text(encoding="utf-8"))
            time.sleep(0.02)
        took = time.monotonic() - started
        self._reader.join(timeout=5)
        return self.process.returncode, "".join(self.lines), took

    def kill(self) -> None:
        """Whatever is left of its session (after a failed test)."""
        running = [self.pid] if self.process.poll() is None else []
        for pid in [*running, *in_session(self.pid)]:
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.process.wait(timeout=5)
        self.process.stdout.close()
        self.process.stderr.close()


@pytest.fixture()
def launched():
    """Starts launchers (``launched(out)``); kills what a failed test left of them."""
    started: list[Launcher] = []

    def start(out: Path, *args: str) -> Launcher:
        started.append(Launcher(out, *args))
        return started[-1]

    yield start
    for launcher_ in started:
        launcher_.kill()


def _results(path: Path) -> dict:
    results = json.loads(path.read_text(encoding="utf-8"))
    assert results["converged"] is False
    return results


def _verdict(err: str) -> str:
    """The launcher's last line (its own lines are not behind ``[name]``)."""
    assert "Traceback" not in err, err
    return err.strip().splitlines()[-1]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_a_signal_to_the_launcher_stops_everything_and_keeps_the_results(
    launched, tmp_path, sig
) -> None:
    out = tmp_path / "r.json"
    run = launched(out).under_way()
    os.kill(run.pid, sig)  # the launcher only, as systemd or a closed terminal would
    code, err, took = run.finish()
    assert code == 130, err
    assert took < 10
    assert _verdict(err) == (
        f"heft: interrupted: stopped by {sig.name}; the results recorded so far are kept in {out}"
    )
    results = _results(out)
    assert results["reason"] == "interrupted" and results["detail"] == f"stopped by {sig.name}"
    assert results["sim_time_s"] > 0.5 and results["robots"]["1"]["phase"] == "excite"
    _nothing_left(run.pid)


def test_a_signal_during_start_up_still_leaves_a_results_file(launched, tmp_path) -> None:
    out = tmp_path / "r.json"
    run = launched(out)
    run.wait_for_line("[router]")  # starting: the agents are not up yet
    os.kill(run.pid, signal.SIGTERM)
    code, err, took = run.finish()
    assert code == 130 and took < 10, err
    assert _verdict(err).startswith("heft: interrupted: stopped by SIGTERM; ")
    assert _results(out)["reason"] == "interrupted"
    _nothing_left(run.pid)


@pytest.mark.parametrize(
    "victim, verdict",
    [("router --listen", "router lost"), (" sim ", "plant lost")],
    ids=["router", "plant"],
)
def test_a_lost_router_or_plant_is_named_at_once(launched, tmp_path, victim, verdict) -> None:
    out = tmp_path / "r.json"
    run = launched(out).under_way()
    os.kill(child_pid(run.pid, victim), signal.SIGKILL)
    code, err, took = run.finish()
    assert code == 1, err
    assert took < 10  # not the plant's 60 s of simulated time
    what = "Zenoh router" if verdict == "router lost" else "plant"
    assert _verdict(err).startswith(
        f"heft: not converged: {verdict}: the {what} process ended (killed by SIGKILL) at t ="
    )
    results = _results(out)
    assert results["reason"] == verdict and "SIGKILL" in results["detail"]
    assert results["robots"]["1"]["phase"] == "excite"  # what was recorded is kept
    _nothing_left(run.pid)


def test_agents_that_all_die_at_once_are_named_at_once(launched, tmp_path) -> None:
    """No neighbour is left to halt the team: the launcher sees the processes go itself."""
    out = tmp_path / "r.json"
    run = launched(out).under_way()
    for robot in (1, 2, 3, 4):
        os.kill(agent_pid(run.pid, robot), signal.SIGKILL)
    code, err, took = run.finish()
    assert code == 1 and took < 10, err
    assert _verdict(err).startswith("heft: not converged: robot(s) [1, 2, 3, 4] lost: ")
    assert _results(out)["reason"] == "robot(s) [1, 2, 3, 4] lost"
    _nothing_left(run.pid)


def test_a_killed_launcher_leaves_no_orphan(launched, tmp_path) -> None:
    out = tmp_path / "r.json"
    run = launched(out).under_way()
    assert len(_running(in_session(run.pid))) == 6  # router, plant, four agents
    config = _describe(agent_pid(run.pid, 1)).split("--config ", 1)[1].split()[0]
    os.kill(run.pid, signal.SIGKILL)
    run.process.wait(timeout=10)
    _nothing_left(run.pid, within_s=5.0)  # each child was killed by the kernel
    assert not out.exists()  # nothing could be written, and nothing empty was left
    # The launcher's folder, which it had no time to remove, goes as the next run starts.
    folder = Path(config).parent
    assert folder.name.startswith(f"heft-run-{run.pid}-") and folder.is_dir()
    with run_folder(folder.parent) as next_one:
        assert not folder.exists() and next_one.is_dir()
    assert not next_one.exists()


# ------------------------------------------------------------------------------ at start
def _heft(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


def _own_lines(err: str) -> list[str]:
    """The launcher's own stderr lines (its children's are behind ``[name]``)."""
    return [line for line in err.splitlines() if not line.startswith("[")]


def test_agents_that_fail_at_start_end_the_run_at_once(tmp_path, monkeypatch) -> None:
    monkeypatch.setattr(launcher, "robot_toml", lambda *args: "robot = 'one'\n")  # invalid
    out = tmp_path / "r.json"
    started = time.monotonic()
    code, stdout, err = _heft("run", str(PAPER), "--transport", "zenoh", "--out", str(out))
    assert time.monotonic() - started < 15  # not the plant's 30 s wait for them
    assert code == 1, err
    own = _own_lines(err)
    assert "Traceback" not in "\n".join(own)
    assert own[-1].startswith("heft: not converged: agents did not come up: robot ")
    assert "agent process ended before the run started (exit status 2: " in own[-1]
    assert own[-1].endswith("agent.robot: expected an integer, got 'one')")  # its own error
    results = _results(out)
    assert results["reason"] == "agents did not come up"
    assert results["sim_time_s"] is None and results["robots"]["1"]["mass"] is None
    assert children_of(os.getpid()) == []


def test_a_plant_that_fails_at_start_is_named(tmp_path, monkeypatch) -> None:
    monkeypatch.setattr(launcher, "scenario_to_toml", lambda scenario: "name = 3\n")  # invalid
    with pytest.raises(launcher.RunFailed) as failed:
        launcher.run_zenoh(load_scenario(PAPER), log_stream=io.StringIO())
    assert failed.value.reason == "plant lost"
    assert failed.value.detail.startswith(
        "the plant process ended before it started (exit status 2: "  # and its error line
    )
    assert children_of(os.getpid()) == []


def _child(words: str, timeout: float = 30.0) -> int:
    """This process's child whose command line contains ``words``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for pid in children_of(os.getpid()):
            with contextlib.suppress(OSError):
                if words in Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode():
                    return pid
        time.sleep(0.05)
    raise AssertionError(f"no child {words!r}")


def test_a_hung_plant_is_named_stalled(monkeypatch) -> None:
    """The plant stops once its first truth has been heard (a stop before it would be a slow
    start, which waits: see the next test)."""
    monkeypatch.setattr(launcher, "STALL_S", 2.0)
    heard = threading.Event()
    handle = launcher.Collector._handle

    def hearing(self, kind, payload) -> None:
        handle(self, kind, payload)
        if self.first_truth_at is not None:
            heard.set()

    monkeypatch.setattr(launcher.Collector, "_handle", hearing)

    def hang_the_plant() -> None:
        plant = _child(" sim ")
        assert heard.wait(120.0), "no truth from the plant within 120 s"
        time.sleep(0.5)
        os.kill(plant, signal.SIGSTOP)
        stopped.append(time.monotonic())

    stopped: list[float] = []
    threading.Thread(target=hang_the_plant, daemon=True).start()
    outcome = launcher.run_zenoh(load_scenario(PAPER), clock="realtime", log_stream=io.StringIO())
    assert stopped and time.monotonic() - stopped[0] < 10  # named within 2 s, and the team gone
    assert outcome.reason == "stalled" and not outcome.converged
    assert "no new truth from the plant for 2 s" in outcome.detail
    assert children_of(os.getpid()) == []  # SIGCONT, then SIGTERM: a stopped plant goes too


def test_a_slow_start_is_not_a_stall(monkeypatch) -> None:
    """The stall clock starts with the plant's first truth: a start that takes longer than
    ``STALL_S`` (a loaded machine importing) is not a hung plant."""
    monkeypatch.setattr(launcher, "STALL_S", 2.0)

    def hold_the_plant() -> None:
        plant = _child(" sim ")
        os.kill(plant, signal.SIGSTOP)  # before its first tick: the team waits for it
        time.sleep(3.0)
        os.kill(plant, signal.SIGCONT)

    threading.Thread(target=hold_the_plant, daemon=True).start()
    outcome = launcher.run_zenoh(load_scenario(PAPER), log_stream=io.StringIO())
    assert outcome.converged, outcome.detail
    assert worst_errors(outcome)["mass"] < 1e-4


# ------------------------------------------------------------------------------ stopping
SIGNAL_TO_ANOTHER_THREAD = """
import os, signal, threading
from agent.platform.process import StopSignals

stop = StopSignals().handle().event
threading.Thread(target=threading.Event().wait, args=(60,), daemon=True).start()
signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM})  # only that thread can take it
os.kill(os.getpid(), signal.SIGTERM)
stop.wait()
print("stopped")
"""


def test_a_stop_signal_taken_by_another_thread_still_stops_the_wait() -> None:
    """The kernel hands SIGTERM to a thread other than the main one (as it may to Zenoh's or
    the log relay's): the main thread's ``stop.wait()`` still returns (with a plain
    ``threading.Event`` it waits for ever)."""
    done = _python(SIGNAL_TO_ANOTHER_THREAD)
    assert (done.returncode, done.stdout) == (0, "stopped\n"), done.stderr


def _python(script: str) -> subprocess.CompletedProcess:
    """``script`` run by a Python of its own (its signals and threads its own)."""
    return subprocess.run(
        [sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=20
    )


SIGNAL_TAKEN_BY_SIGWAIT = """
import os, signal, threading
from agent.platform.process import StopSignals

stop = StopSignals().take()
waiting = threading.Thread(target=threading.Event().wait, args=(60,), daemon=True)
waiting.start()  # a thread started after: it inherits the mask, the signal is not its
os.kill(os.getpid(), signal.SIGHUP)
stop.event.wait()
print(stop.received.name, signal.getsignal(signal.SIGHUP) is signal.SIG_DFL)
"""


def test_stop_signals_taken_by_sigwait_set_the_event_with_no_handler() -> None:
    """The AGV bridge's way: the signals blocked, taken by a thread of their own with
    ``sigwait``; SIGHUP, whose default would end the process, sets the event instead."""
    done = _python(SIGNAL_TAKEN_BY_SIGWAIT)
    assert (done.returncode, done.stdout) == (0, "SIGHUP True\n"), done.stderr
