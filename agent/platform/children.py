"""Child processes the way every launcher of the project starts and stops them.

A :class:`Child` copies each line its process writes (stdout and stderr) to a stream behind
``[name]``, asks the kernel for :data:`DEATH_SIGNAL` when the process that started it dies
(Linux ``PR_SET_PDEATHSIG``: a killed launcher leaves no orphan), and stops with SIGTERM, then
SIGKILL after a grace (:func:`stop_all` stops several together). ``heft run`` starts its
router, plant, bridges and agents this way; so do the AGV bridge's rig and benchmark.
"""

from __future__ import annotations

import ctypes
import logging
import os
import signal
import socket
import subprocess
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TextIO

PR_SET_PDEATHSIG = 1
STOP_GRACE_S = 5.0
"""How long the processes asked to stop (SIGTERM) have to exit before SIGKILL."""
DEATH_SIGNAL = signal.SIGKILL
"""What every child gets from the kernel when the launcher dies (``PR_SET_PDEATHSIG``).

Not SIGTERM, measured: the kernel sends the parent-death signal again each time the child is
handed to another of the dying launcher's threads, so a child gets a burst of them; the
processes' handler as it was then (``Event.set`` in a signal handler; see
:class:`agent.platform.process.StopSignals` now) was not re-entrant and deadlocked when one
arrived while it ran (about 1 launcher kill in 25 left an agent or the plant behind), and
``heft router`` sometimes never woke from its wait. The launcher is gone and nothing is
recorded: there is nothing for a child to save."""
RECENT_LINES = 50
"""Lines of a child's output kept for :meth:`Child.wait_for_line`."""
LOG = logging.getLogger("heft.children")


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


_prctl = None


def _die_with_parent(death_signal: int = DEATH_SIGNAL) -> Callable[[], None] | None:
    """A ``preexec_fn`` by which the child, before it runs, asks for ``death_signal`` when the
    launcher dies, however it dies (Linux ``PR_SET_PDEATHSIG``), so that a killed launcher
    leaves no orphan; None where there is no ``prctl``.

    ``prctl`` is looked up here, in the launcher: between ``fork`` and ``exec`` the child only
    calls it (no ``dlopen``, whose locks another thread may hold). A launcher that died before
    the child's ``prctl`` is caught by comparing the parent's pid. The signal follows the
    *thread* that started the child: start children from a thread that outlives them."""
    global _prctl
    if _prctl is None:
        try:
            _prctl = ctypes.CDLL(None, use_errno=True).prctl
        except (OSError, AttributeError):  # not Linux
            return None
    prctl, parent, sig = _prctl, os.getpid(), int(death_signal)

    def preexec() -> None:
        prctl(PR_SET_PDEATHSIG, sig)
        if os.getppid() != parent:  # the launcher is already gone
            os._exit(1)

    return preexec


def cpu_seconds(pid: int) -> float | None:
    """User + system CPU seconds process ``pid`` has used so far (Linux ``/proc``), or None if
    it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def describe_exit(code: int) -> str:
    """A process's exit as words: ``exit status 2``, ``killed by SIGKILL``."""
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit status {code}"


class Child:
    """A child process whose output lines are copied to ``stream`` behind ``[name]``; it gets
    ``death_signal`` if the launcher dies."""

    def __init__(
        self,
        name: str,
        args: list[str],
        stream: TextIO,
        env: dict[str, str],
        death_signal: int = DEATH_SIGNAL,
    ):
        self.name = name
        self.last_line = ""
        self._recent: deque[str] = deque(maxlen=RECENT_LINES)
        self._said = threading.Condition()
        self.process = subprocess.Popen(
            args,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            text=True,
            bufsize=1,
            env=env,
            preexec_fn=_die_with_parent(death_signal),
        )
        self._thread = threading.Thread(target=self._copy, args=(stream,), daemon=True)
        self._thread.start()

    def _copy(self, stream: TextIO) -> None:
        try:
            for line in self.process.stdout:
                if line.strip():
                    self.last_line = line.strip()
                    with self._said:
                        self._recent.append(self.last_line)
                        self._said.notify_all()
                stream.write(f"[{self.name}] {line}")
                stream.flush()
        except (OSError, ValueError):  # the launcher's stream is closed: the lines are lost
            pass
        with self._said:
            self._said.notify_all()

    def wait_for_line(self, line: str, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for the process to write ``line`` (a whole line, stripped);
        False if it did not (it ended, or the time ran out)."""
        deadline = time.monotonic() + timeout_s
        with self._said:
            while line not in self._recent:
                left = deadline - time.monotonic()
                if left <= 0 or not self._thread.is_alive():
                    return line in self._recent
                self._said.wait(min(left, 0.5))
        return True

    def last_words(self) -> str:
        """The last line an exited process wrote (e.g. its ``heft: error: ...``), or ``""``."""
        self._thread.join(timeout=1.0)  # the rest of its output, up to the end of the pipe
        return self.last_line.removeprefix("heft: error: ")

    def ended(self, code: int) -> str:
        """``exit status 2: <its last line>``, for a verdict."""
        said = self.last_words()
        return f"{describe_exit(code)}: {said}" if said else describe_exit(code)

    def cpu_seconds(self) -> float | None:
        """User + system CPU time the process has used so far (Linux ``/proc``)."""
        return cpu_seconds(self.process.pid)

    def terminate(self) -> None:
        """SIGTERM (after SIGCONT: a stopped process cannot exit), if it still runs."""
        if self.process.poll() is None:
            try:
                self.process.send_signal(signal.SIGCONT)
                self.process.send_signal(signal.SIGTERM)
            except ProcessLookupError:
                pass

    def stop(self, grace_s: float = STOP_GRACE_S) -> None:
        """SIGTERM, up to ``grace_s`` to exit, then SIGKILL."""
        stop_all([self], grace_s)


def wait_all(children: Sequence[Child], timeout_s: float) -> bool:
    """Wait up to ``timeout_s`` for every one of ``children`` to exit; True if they did."""
    deadline = time.monotonic() + timeout_s
    for child in children:
        try:
            child.process.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            return False
    return True


def stop_all(children: Sequence[Child], grace_s: float = STOP_GRACE_S) -> None:
    """Stop ``children`` together: SIGTERM to every one still running, up to ``grace_s`` for
    all of them to exit, then SIGKILL to the rest (a hung process cannot hold the run up)."""
    for child in children:
        child.terminate()
    if not wait_all(children, grace_s):
        for child in children:
            if child.process.poll() is None:
                LOG.warning("%s did not stop within %.0f s: killed", child.name, grace_s)
                child.process.kill()
        wait_all(children, grace_s)
    for child in children:
        child._thread.join(timeout=1.0)
