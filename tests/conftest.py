"""What several test modules share (no test module imports another): the repository's root,
the paper's scenario file and the accuracy check of a run against the ground truth."""

from __future__ import annotations

import collections
import math
import os
import subprocess
import sys
import time
import tomllib
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from simulator.inprocess import RunOutcome

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "simulator" / "scenarios" / "paper.toml"


class FakeFifo:
    """A subscription of a fake Zenoh session declared with a handler (as the launcher's
    collector declares its own with ``zenoh.handlers.FifoChannel``): call it with a sample
    to queue it, :meth:`try_recv` to take one (None when empty)."""

    def __init__(self, undeclare=lambda: None) -> None:
        self.samples: collections.deque = collections.deque()
        self.undeclare = undeclare

    def __call__(self, sample) -> None:
        self.samples.append(sample)

    def try_recv(self):
        return self.samples.popleft() if self.samples else None


def worst_errors(outcome: RunOutcome) -> dict[str, float]:
    """The largest error over robots of each estimate, against truth at the same instant."""
    truth = outcome.final.truth
    worst = {"mass": 0.0, "moment": 0.0, "contact_to_com": 0.0, "relative": 0.0}
    for i, est in outcome.final.estimates.items():
        assert est.mass is not None and est.moment is not None, f"robot {i} has no m or J"
        assert est.contact_to_com is not None, f"robot {i} has no contact_to_com"
        worst["mass"] = max(worst["mass"], abs(est.mass - truth.mass) / truth.mass)
        worst["moment"] = max(worst["moment"], abs(est.moment - truth.moment) / truth.moment)
        err = math.dist(est.contact_to_com, truth.contact_to_com[i - 1])
        worst["contact_to_com"] = max(worst["contact_to_com"], err)
        pi = truth.contacts[i - 1]
        for j, z in est.relative_positions.items():
            pj = truth.contacts[j - 1]
            err = math.dist(z, (pi[0] - pj[0], pi[1] - pj[1]))
            worst["relative"] = max(worst["relative"], err)
    return worst


ESTIMATED = (
    "omega",
    "spread",
    "moment",
    "mass",
    "centroid_offset",
    "com_offset",
    "com_observer",
    "com_velocity",
    "contact_to_com",
)


def assert_same_estimates(a: RunOutcome, b: RunOutcome, tol: float = 1e-9) -> None:
    """Every robot's every estimate at the same final instant, to ``tol`` (relative)."""
    assert a.ticks == b.ticks and a.sim_time_s == b.sim_time_s
    assert a.final.estimates.keys() == b.final.estimates.keys()
    for i, x in a.final.estimates.items():
        y = b.final.estimates[i]
        assert (x.tick, x.phase, x.phase_since) == (y.tick, y.phase, y.phase_since)
        for name in ESTIMATED:
            u, v = getattr(x, name), getattr(y, name)
            assert (u is None) == (v is None), name
            if u is not None:
                u, v = (u, v) if isinstance(u, tuple) else ((u,), (v,))
                assert math.dist(u, v) <= tol * max(1.0, math.hypot(*u)), (i, name, u, v)
        assert x.relative_positions.keys() == y.relative_positions.keys()
        for j, z in x.relative_positions.items():
            assert math.dist(z, y.relative_positions[j]) <= tol * max(1.0, math.hypot(*z))
        assert (x.started, x.settled) == (y.started, y.settled)


def assert_within(outcome: RunOutcome, rel: float, metres: float) -> None:
    """The run converged within 60 s simulated, every robot's m and J within ``rel`` and its
    offsets within ``metres`` of the truth, and the load stayed on the scenario's floor."""
    from simulator.results import floor_check

    assert outcome.converged, f"not converged in {outcome.sim_time_s:.1f} s"
    floor = floor_check(outcome)
    assert floor["within"], floor
    assert outcome.sim_time_s < 60.0
    worst = worst_errors(outcome)
    assert worst["mass"] <= rel, worst
    assert worst["moment"] <= rel, worst
    assert worst["contact_to_com"] <= metres, worst
    assert worst["relative"] <= metres, worst
    assert len(outcome.final.estimates[1].relative_positions) > 0


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


VCAN_HELP = (
    "no vcan here: run `make hil` (heft vcan -- pytest -m hil); to enable: sudo modprobe vcan"
    " (or deploy/vcan-setup.sh), or apt-get install user-mode-linux kmod"
)


@pytest.fixture(scope="session")
def vcan() -> None:
    """For hardware-in-the-loop tests: vcan1... exist (inside ``heft vcan``, or a kernel that
    has them); otherwise a skip saying how to get them, or a failure where CI requires them
    (``HEFT_REQUIRE_VCAN=1``)."""
    if os.environ.get("HEFT_VCAN") == "1" or Path("/sys/class/net/vcan1").exists():
        return
    if os.environ.get("HEFT_REQUIRE_VCAN") == "1":
        pytest.fail(f"vcan unavailable but HEFT_REQUIRE_VCAN=1: {VCAN_HELP}")
    pytest.skip(VCAN_HELP)


TLS_DIR = "/etc/heft/tls"
"""Where the deployed configs (deploy/paper) name the team's certificates."""


def loadable_copy(path: Path, folder: Path) -> Path:
    """``path`` with its TLS files moved to placeholders in ``folder`` (they exist on the
    robots only; the agent checks only that they are readable when it loads the file)."""
    tls = folder / "tls"
    tls.mkdir(exist_ok=True)
    from agent.platform.zenoh_session import TLS_FILES

    text = path.read_text(encoding="utf-8")
    for key in TLS_FILES:
        name = Path(tomllib.loads(text)["zenoh"][key]).name
        (tls / name).write_text("placeholder\n", encoding="utf-8")
    copy = folder / path.name
    copy.write_text(text.replace(f'"{TLS_DIR}/', f'"{tls}/'), encoding="utf-8")
    return copy
