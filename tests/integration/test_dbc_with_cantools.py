"""``bridge/agv.dbc`` as another tool reads it: ``cantools dump``, run as a process, lists every
frame the protocol declares."""

from __future__ import annotations

import re
import subprocess
import sys

from bridge.dbc import DBC_PATH, MAX_NODE


def test_cantools_dump_reads_the_dbc_and_lists_every_frame() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "cantools", "dump", str(DBC_PATH)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    names = re.findall(r"^\s*Name:\s+(\S+)\s*$", done.stdout, flags=re.MULTILINE)
    for name in ("Sync", "Odometry_1", "ForceCommand_32", "Heartbeat_7"):
        assert name in names
    kinds = ("Odometry", "ForceCommand", "AppliedForce", "Heartbeat")
    expected = {"Sync"} | {f"{kind}_{n}" for kind in kinds for n in range(1, MAX_NODE + 1)}
    assert len(names) == len(expected) and set(names) == expected
