"""systemd itself accepts every deployed unit (``systemd-analyze verify``, offline in a root of
its own, where it is installed). What the units say is checked in
tests/unit/agent/test_deploy_files.py."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.helpers.paths import ROOT

UNITS = sorted((ROOT / "deploy" / "systemd").glob("*.service"))
HEFT = "/opt/heft/.venv/bin/heft"


def test_systemd_accepts_every_unit(tmp_path: Path) -> None:
    """``systemd-analyze verify`` (offline, in a root of its own) reports nothing about the
    units: no unknown key, no value it cannot parse."""
    analyze = shutil.which("systemd-analyze")
    if analyze is None:
        pytest.skip("no systemd-analyze here")
    version = subprocess.run([analyze, "--version"], capture_output=True, text=True).stdout
    found = re.search(r"systemd (\d+)", version)
    if found is None or int(found[1]) < 250:
        pytest.skip(f"systemd-analyze too old for verify --root: {version.strip()[:40]}")
    system = next(
        (
            p
            for p in map(Path, ("/usr/lib/systemd/system", "/lib/systemd/system"))
            if (p / "sysinit.target").exists()
        ),
        None,
    )
    if system is None:
        pytest.skip("no system units to verify against")
    root = tmp_path / "root"
    shutil.copytree(system, root / "usr" / "lib" / "systemd" / "system", symlinks=True)
    program = root / HEFT.lstrip("/")
    program.parent.mkdir(parents=True)
    program.write_text("#!/bin/sh\n", encoding="utf-8")
    program.chmod(0o755)
    installed = root / "etc" / "systemd" / "system"
    installed.mkdir(parents=True)
    for unit in UNITS:
        shutil.copy(unit, installed / unit.name)
    names = [unit.name.replace("@.", "@3.") for unit in UNITS]
    done = subprocess.run(
        [analyze, "verify", "--man=no", f"--root={root}", *names],
        capture_output=True,
        text=True,
        timeout=120,
    )
    complaints = [line for line in (done.stdout + done.stderr).splitlines() if "heft-" in line]
    assert done.returncode == 0 and not complaints, done.stdout + done.stderr
