"""A run's folder (simulator/run_folder.py): its own, named with the launcher's pid, removed
when the run ends however it ends; the folders of launchers that are gone (killed with SIGKILL)
removed as the next run starts, and nothing else. A killed ``heft run`` is in
tests/integration/test_supervision.py."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from simulator.run_folder import run_folder, sweep


def dead_pid() -> int:
    """The id of a process that has ended."""
    process = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        capture_output=True,
        text=True,
        check=True,
    )
    return int(process.stdout)


def test_a_run_has_its_own_folder_until_it_ends(tmp_path: Path) -> None:
    with run_folder(tmp_path) as folder:
        assert folder.parent == tmp_path and folder.is_dir()
        assert folder.name.startswith(f"heft-run-{os.getpid()}-")
        (folder / "scenario.toml").write_text("x", encoding="utf-8")
    assert not folder.exists()
    with pytest.raises(KeyboardInterrupt), run_folder(tmp_path) as folder:
        raise KeyboardInterrupt
    assert not folder.exists()


def test_the_folders_of_gone_launchers_are_removed_as_a_run_starts(tmp_path: Path) -> None:
    gone = tmp_path / f"heft-run-{dead_pid()}-abc"
    (gone / "sub").mkdir(parents=True)
    (gone / "sub" / "robot-1.toml").write_text("x", encoding="utf-8")
    alive = tmp_path / f"heft-run-{os.getppid()}-def"
    alive.mkdir()
    kept = [alive]
    for name in ("heft-run-abcdefgh", "other-1-x", f"heft-run-{dead_pid()}"):
        (tmp_path / name).mkdir()
        kept.append(tmp_path / name)
    not_a_folder = tmp_path / f"heft-run-{dead_pid()}-file"
    not_a_folder.write_text("x", encoding="utf-8")
    elsewhere = tmp_path / "elsewhere"
    (elsewhere / "inside").mkdir(parents=True)
    link = tmp_path / f"heft-run-{dead_pid()}-link"
    link.symlink_to(elsewhere)
    with run_folder(tmp_path) as folder:
        assert not gone.exists()
        assert all(path.is_dir() for path in kept) and not_a_folder.is_file()
        assert link.is_symlink() and (elsewhere / "inside").is_dir()
        assert sweep(tmp_path) == []  # its own folder too: its launcher is alive
        assert folder.is_dir()
