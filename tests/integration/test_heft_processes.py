"""``heft`` as a user runs it, a process of its own: ``python -m agent`` and the installed
``heft`` script run the heft program (:mod:`agent.platform.heft`), and bad input (a bad
option, a value out of its range, a bridge config without a channel, a CAN bus that cannot be
opened) ends it at once with its exit status and one ``heft: error:`` line, never a traceback.
The same refusals in one process are in tests/unit (test_cli.py, test_input_bounds.py,
test_nodes_cli.py, test_can_drivers.py, test_noise_bench.py)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest

from tests.helpers.bad_input import scenario_file
from tests.helpers.paths import PAPER, ROOT


def test_python_dash_m_agent_is_heft() -> None:
    ran = subprocess.run(
        [sys.executable, "-m", "agent", "--version"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert ran.returncode == 0, ran.stderr
    assert ran.stdout.strip() == f"heft {metadata.version('heft-hil')}"


COMMANDS = {"run", "scenario", "bench", "agent", "sim", "router", "demo", "deploy"}


def test_the_heft_script_runs_the_dispatcher() -> None:
    script = Path(sys.executable).with_name("heft")
    if not script.exists():
        pytest.skip("the heft script is not installed next to this interpreter")
    ran = subprocess.run([str(script), "--help"], capture_output=True, text=True, timeout=60)
    assert ran.returncode == 0, ran.stderr
    for command in COMMANDS:
        assert re.search(rf"^    {command} ", ran.stdout, re.M), command


def test_a_bridge_config_is_refused_in_one_line_before_the_bus(tmp_path: Path) -> None:
    """``heft bridge`` as a process, with an empty CAN channel: exit 2 and one line on stderr
    that names the key, before any bus is opened (so no vcan is needed)."""
    path = tmp_path / "robot.toml"
    path.write_text('robot = 1\nn = 2\nneighbours = [2]\n[can]\nchannel = ""\n', "utf-8")
    done = subprocess.run(
        [sys.executable, "-m", "agent", "bridge", "--config", str(path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert "can.channel" in done.stderr


def test_sim_says_which_bus_it_cannot_open_with_status_4() -> None:
    """No such interface (or no SocketCAN in this kernel): one line, like a missing router."""
    done = subprocess.run(
        [sys.executable, "-m", "agent", "sim", str(PAPER), "--can"]
        + ["--can-channel", "heft-no-such-bus{robot}", "--connect-timeout-ms", "0"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    last = done.stderr.strip().splitlines()[-1]
    assert done.returncode == 4, done.stderr
    assert last.startswith("heft: error: CAN bus socketcan/heft-no-such-bus1 (robot 1)"), last
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize(
    "args, message",
    [
        (["accuracy", "--seeds", "3"], "heft bench accuracy: error: unrecognized arguments"),
        (["noise", "--plot", "x"], "heft bench noise: error: unrecognized arguments: --plot"),
        (["noise", "--seeds", "0"], "heft: error: --seeds"),
        (["changes", "--generated", "3"], "changes: error: unrecognized arguments: --generated"),
        (["noise", "--first-seed", "-1"], "heft: error: --first-seed"),
        (["noise", "--generated", "3", "x.toml"], "not allowed with argument --generated"),
    ],
)
def test_bench_noise_options(args: list[str], message: str) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "agent", "bench", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2, done.stderr
    assert message in done.stderr and "Traceback" not in done.stderr


@pytest.mark.parametrize("probe", ["start timeout nan", "port 99999", "memory of 1e-300 s"])
def test_as_a_process_exit_2_one_line_no_hang(tmp_path, probe) -> None:
    """The probes as a user ran them: a ``heft`` process, which ends at once."""
    argv = {
        "start timeout nan": ["sim", str(PAPER), "--start-timeout", "nan"],
        "port 99999": ["router", "--listen", "tcp/127.0.0.1:99999"],
        "memory of 1e-300 s": [
            "run",
            str(scenario_file(tmp_path, {"agent.regression_memory_s": 1e-300})),
        ],
    }[probe]
    done = subprocess.run(
        [sys.executable, "-m", "agent", *argv], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 2, done
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("heft: error: "), done.stderr
