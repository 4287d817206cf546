"""``heft bridge`` as a process, on python-can's ``virtual`` bus (no vcan needed): it takes
SIGTERM with its log written by a thread of its own (:func:`bridge.node.log_aside`), and
leaves with status 0 and every line of its log written, the last its counters."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

from agent.platform.children import free_port
from agent.platform.zenoh_session import ZenohSettings, open_session
from tests.helpers.paths import ROOT

UP = "bridge of robot 1 up"
LAST = "bridge of robot 1 stops:"


def test_a_bridge_leaves_on_sigterm_with_its_whole_log(tmp_path: Path) -> None:
    router = f"tcp/127.0.0.1:{free_port()}"
    config = tmp_path / "robot.toml"
    config.write_text(
        'robot = 1\nn = 2\nneighbours = [2]\nteam = "bridge-process"\n'
        f'[zenoh]\nmode = "client"\nconnect = ["{router}"]\n'
        '[can]\ninterface = "virtual"\nchannel = "heft-bridge-process"\nprofile = "velocity"\n',
        "utf-8",
    )
    with open_session(ZenohSettings(mode="router", connect=(), listen=(router,))):
        process = subprocess.Popen(
            [sys.executable, "-m", "agent", "bridge", "--config", str(config)],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
        )
        lines: list[str] = []
        watchdog = threading.Timer(60, process.kill)  # a bridge that never comes up
        watchdog.start()
        try:
            for line in process.stdout:  # up: its loop runs
                lines.append(line)
                if UP in line:
                    break
            assert any(UP in line for line in lines), "".join(lines)
            process.send_signal(signal.SIGTERM)
            rest, _ = process.communicate(timeout=60)
        finally:
            watchdog.cancel()
            if process.poll() is None:
                process.kill()
                process.communicate()
    log = "".join(lines) + rest
    assert process.returncode == 0, log
    assert LAST in log.strip().splitlines()[-1], log
    assert "Traceback" not in log
