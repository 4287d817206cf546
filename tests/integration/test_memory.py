"""Bounded memory: a long run keeps every process's resident memory flat — histories, latency
statistics and the collector's buffers are ring buffers or strided, never lists that grow with
the run. The lockstep equivalent of a long real-time session: the paper's scenario with
settling made impossible, so the team never finishes and runs to ``run.max_time_s``. The
launcher's history fills its :data:`~simulator.history.CAPACITY` of 2000 samples (about 6 kB each:
the truth and four robots' estimates) at 20 a second, in 100 s; from then on it keeps as many,
strided. So memory is compared after that, at 120 s and 240 s simulated. The launcher runs in a
process of its own, as ``heft run`` does, not in the test's: the test's process holds the memory
of every test run before it, and its allocator's growth is not the launcher's."""

from __future__ import annotations

import dataclasses
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from simulator.launcher import run_zenoh
from simulator.scenario import load_scenario
from tests.helpers.paths import PAPER, ROOT

MIB = 1 << 20
SIMULATED_S = 240.0
EARLY_S = 120.0
GROWTH_LIMIT = 3 * MIB


def _rss(pid: int) -> int | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def _processes() -> dict[str, int]:
    """This process and its children (router, plant, agents), by their command line."""
    found = {"launcher": os.getpid()}
    me = str(os.getpid())
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            cmd = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if stat[1] == me:
            words = cmd.split()
            name = words[3] if len(words) > 3 else cmd
            if name == "agent":
                name = Path(words[-1]).stem  # robot-<i>
            found[name] = int(entry.name)
    return found


def _long_run() -> None:
    """``python -m tests.integration.test_memory``, the launcher's process: the long run, with
    every process's RSS sampled every ``EARLY_S`` of simulated time; prints ``{"samples":
    {time: {process: RSS}}, "converged": …, "sim_time_s": …}`` as JSON."""
    paper = load_scenario(PAPER)
    scenario = dataclasses.replace(
        paper,
        agent=dataclasses.replace(paper.agent, settle_tolerance=1e-8, settle_window_s=60.0),
        run=dataclasses.replace(paper.run, max_time_s=SIMULATED_S),
    )
    samples: dict[float, dict[str, int | None]] = {}

    def progress(time_s: float, phases: str) -> None:
        samples[time_s] = {name: _rss(pid) for name, pid in _processes().items()}

    outcome = run_zenoh(
        scenario, progress=progress, progress_every_s=EARLY_S, log_stream=io.StringIO()
    )
    said = {"samples": samples, "converged": outcome.converged, "sim_time_s": outcome.sim_time_s}
    print(json.dumps(said))


@pytest.mark.slow
def test_a_long_run_keeps_every_process_memory_flat() -> None:
    run = subprocess.run(
        [sys.executable, "-m", "tests.integration.test_memory"],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
    )
    assert run.returncode == 0, run.stderr
    said = json.loads(run.stdout.strip().splitlines()[-1])
    assert not said["converged"] and said["sim_time_s"] >= SIMULATED_S - 1
    samples = {float(t): rss for t, rss in said["samples"].items()}
    times = sorted(samples)
    early, late = samples[times[0]], samples[times[-1]]
    assert times[0] < 2 * EARLY_S and times[-1] >= SIMULATED_S - EARLY_S
    assert set(early) >= {"launcher", "router", "sim", "robot-1", "robot-4"}, early
    report = {
        name: (early[name] // MIB, late[name] // MIB)
        for name in early
        if early[name] is not None and late.get(name) is not None
    }
    print("RSS MiB at", times[0], "s and", times[-1], "s simulated:", report)
    for name, before in early.items():
        after = late.get(name)
        if before is not None and after is not None:
            assert after - before < GROWTH_LIMIT, (name, report)


if __name__ == "__main__":
    _long_run()
