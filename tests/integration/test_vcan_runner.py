"""``heft vcan`` for real (marked slow, each boots a User-Mode Linux guest in ~3-5 s where this
kernel has no CAN): exit status and output passed through, vcan1 there, a CAN frame crossing
processes on it, ``--check`` and a bad ``--memory``; and a stop signal passed on to the command
it runs natively."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from agent.platform.process import STOP_SIGNALS
from bridge.devtools import vcan_run
from tests.helpers.paths import ROOT


# ------------------------------------------------------------------------------- real runs
def _heft(*args: str, timeout: float = 120.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "agent", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )


@pytest.fixture(scope="module")
def vcan_here() -> str:
    """``heft vcan --check``'s line if vcan can be had here; else a skip (a failure where
    ``HEFT_REQUIRE_VCAN=1``)."""
    done = _heft("vcan", "--check", timeout=60)
    line = (done.stdout.strip() or done.stderr.strip()).replace("\n", " ")
    if done.returncode != 0:
        if os.environ.get("HEFT_REQUIRE_VCAN") == "1":
            pytest.fail(f"vcan unavailable but HEFT_REQUIRE_VCAN=1: {line}")
        pytest.skip(f"no vcan here (heft vcan --check: {line})")
    return line


@pytest.mark.slow
def test_check_says_how_in_one_line(vcan_here: str) -> None:
    done = _heft("vcan", "--check", timeout=60)
    assert done.returncode == 0
    assert done.stdout.count("\n") == 1 and done.stdout.startswith("vcan: ")
    assert "natively" in done.stdout or "User-Mode Linux" in done.stdout
    assert done.stderr == ""


@pytest.mark.slow
def test_a_bad_memory_is_one_error_line() -> None:
    done = _heft("vcan", "--memory", "lots", "--", "true", timeout=60)
    assert done.returncode == 2
    assert done.stdout == ""
    assert done.stderr.startswith("heft: error: --memory")
    assert done.stderr.count("\n") == 1
    assert "Traceback" not in done.stderr


@pytest.mark.slow
def test_exit_status_and_output_pass_through(vcan_here: str) -> None:
    shell = "echo out; echo err >&2; exit 3"
    done = _heft("vcan", "--count", "2", "--timeout", "60", "--", "sh", "-c", shell)
    assert (done.returncode, done.stdout, done.stderr) == (3, "out\n", "err\n")


@pytest.mark.slow
def test_vcan1_is_there(vcan_here: str) -> None:
    done = _heft("vcan", "--count", "2", "--timeout", "60", "--", "ip", "link", "show", "vcan1")
    assert done.returncode == 0, done.stderr
    assert "vcan1" in done.stdout


SENDER = """
import subprocess, sys
import can

RECEIVER = '''
import can
with can.Bus(interface="socketcan", channel="vcan1") as bus:
    print("ready", flush=True)
    msg = bus.recv(timeout=30)
    print("nothing" if msg is None else f"{msg.arbitration_id:x} {msg.data.hex()}", flush=True)
'''
rx = subprocess.Popen([sys.executable, "-c", RECEIVER], stdout=subprocess.PIPE, text=True)
assert rx.stdout.readline().strip() == "ready"
with can.Bus(interface="socketcan", channel="vcan1") as bus:
    bus.send(can.Message(arbitration_id=0x123, data=bytes([1, 2, 3]), is_extended_id=False))
print("received", rx.stdout.readline().strip(), flush=True)
sys.exit(rx.wait(30))
"""


@pytest.mark.slow
def test_a_frame_crosses_processes_on_vcan1(vcan_here: str, tmp_path: Path) -> None:
    script = tmp_path / "send.py"
    script.write_text(textwrap.dedent(SENDER))
    done = _heft("vcan", "--count", "2", "--timeout", "90", "--", sys.executable, str(script))
    assert done.returncode == 0, done.stderr
    assert done.stdout == "received 123 010203\n", done.stderr


def test_a_stop_signal_is_passed_on_to_the_command_and_is_the_exit_status(tmp_path) -> None:
    """Natively (the command run where vcan already is), SIGTERM to ``heft vcan`` reaches the
    command, and ``heft vcan`` answers 128 + 15 once it has ended; its handlers are put back."""
    ready, heard = tmp_path / "ready", tmp_path / "heard"
    script = f"trap 'echo TERM > {heard}; kill $!; exit 0' TERM; touch {ready}; sleep 60 & wait"
    main = threading.main_thread().ident

    def stop_once_it_runs() -> None:
        while not ready.exists():
            time.sleep(0.01)
        signal.pthread_kill(main, signal.SIGTERM)  # where heft vcan waits for the command

    before = [signal.getsignal(sig) for sig in STOP_SIGNALS]
    threading.Thread(target=stop_once_it_runs, daemon=True).start()
    assert vcan_run._run_child(["sh", "-c", script], None) == 128 + signal.SIGTERM
    assert heard.read_text() == "TERM\n"
    assert [signal.getsignal(sig) for sig in STOP_SIGNALS] == before
