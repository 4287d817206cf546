"""The folder where a run over Zenoh keeps its processes' files (the scenario, each robot's
config), and the sweep of those that killed runs left behind.

Each run has its own, ``heft-run-<pid>-<random>`` in the system's temporary folder
(``$TMPDIR``, else ``/tmp``), ``<pid>`` the launcher's process id. The launcher removes it when
the run ends, whatever ends it, but a launcher killed with SIGKILL cannot (its processes die
with it: :mod:`agent.platform.children`). So every run, as it starts, first removes the folders
of this user's runs whose launcher is no longer alive.
"""

from __future__ import annotations

import os
import re
import shutil
import stat
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

PREFIX = "heft-run-"
_NAME = re.compile(rf"{PREFIX}(\d+)-")


@contextmanager
def run_folder(parent: Path | None = None) -> Iterator[Path]:
    """A new folder for this run in ``parent`` (the temporary folder by default), after
    :func:`sweep`; removed with its files on exit."""
    parent = Path(tempfile.gettempdir()) if parent is None else parent
    sweep(parent)
    folder = Path(tempfile.mkdtemp(prefix=f"{PREFIX}{os.getpid()}-", dir=parent))
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def sweep(parent: Path) -> list[Path]:
    """Remove the run folders in ``parent`` that this user's dead launchers left; which."""
    removed = []
    uid = os.getuid()
    for folder in parent.glob(f"{PREFIX}*"):
        found = _NAME.match(folder.name)
        if found is None or _alive(int(found.group(1))):
            continue
        try:
            status = folder.lstat()
        except OSError:
            continue
        if not stat.S_ISDIR(status.st_mode) or status.st_uid != uid:
            continue
        shutil.rmtree(folder, ignore_errors=True)
        removed.append(folder)
    return removed


def _alive(pid: int) -> bool:
    """Whether process ``pid`` exists (another user's too)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):  # another user's; not a process id at all
        return True
    return True
