"""A run over Zenoh as ``heft run`` in a session of its own, and the processes it started,
found through ``/proc``."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

from tests.helpers.paths import PAPER, ROOT


def processes(field: int, value: int) -> list[int]:
    """Processes whose ``/proc/<pid>/stat`` field (after the command: 1 = parent, 3 = session)
    is ``value``, other than ``value`` itself."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and int(entry.name) != value:
            try:
                stat = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(stat[field]) == value:
                found.append(int(entry.name))
    return found


def children_of(pid: int) -> list[int]:
    return processes(1, pid)


def in_session(sid: int) -> list[int]:
    return processes(3, sid)


def launch(*args: str, out: Path) -> subprocess.Popen:
    """``heft run`` of the paper over Zenoh in a session of its own (its pid is the sid)."""
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "agent",
            "run",
            str(PAPER),
            "--transport",
            "zenoh",
            "--out",
            str(out),
            *args,
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )


def child_pid(sid: int, words: str, timeout: float = 20.0) -> int:
    """The process of session ``sid`` whose command line contains ``words``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for pid in in_session(sid):
            try:
                cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
            except OSError:
                continue
            if words in cmd:
                return pid
        time.sleep(0.1)
    raise AssertionError(f"no process {words!r} in session {sid}")


def agent_pid(sid: int, robot: int, timeout: float = 20.0) -> int:
    """Robot ``robot``'s agent process, started by the launcher of session ``sid``."""
    return child_pid(sid, f"robot-{robot}.toml", timeout)


def wait_for(process: subprocess.Popen, timeout: float = 60.0) -> tuple[int, str]:
    _, err = process.communicate(timeout=timeout)
    return process.returncode, err
