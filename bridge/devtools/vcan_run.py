"""``heft vcan``'s processes: run a command natively where this kernel has SocketCAN, or in a
User-Mode Linux guest where it has not (the guest's init script and the parsing of its console
are in :mod:`bridge.devtools.vcan`).

Either way the command's exit status comes back as ``heft vcan``'s (128 + N if signal N
killed it), its output is passed through as it comes, and SIGINT, SIGTERM or SIGHUP stop it:
natively SIGTERM and SIGHUP are passed on to the command (SIGINT from a terminal reaches it
directly); a guest is killed at once with all its host processes (UML runs in a session of
its own, so nothing of it outlives ``heft vcan``). ``heft vcan`` then exits with 128 + N.
"""

from __future__ import annotations

import os
import secrets
import selectors
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from contextlib import suppress
from pathlib import Path

from agent.platform.cli_helpers import PROG, UsageError
from agent.platform.process import STOP_SIGNALS, StopSignals
from bridge.devtools.vcan import (
    ENABLE_HELP,
    GUEST_TOOLS,
    MODULES_ROOT,
    SYSTEM_PATH,
    ConsoleScanner,
    EndFilter,
    existing_interfaces,
    exit_status,
    failure_message,
    guest_environment,
    init_script,
    interface_names,
    missing_modules,
    socketcan_available,
    uml_arguments,
)

TIMED_OUT = 124
"""Exit status when ``--timeout`` stopped the command (as coreutils' ``timeout``)."""
GUEST_FAILED = 125
"""Exit status when the guest died without reporting the command's exit status."""
UML_BINARIES = ("linux.uml", "linux")


def _say(message: str) -> None:
    print(f"{PROG}: {message}", file=sys.stderr, flush=True)


def run(
    command: Sequence[str],
    count: int,
    memory: int,
    timeout: float | None = None,
    force_uml: bool = False,
) -> int:
    """Run ``command`` where vcan0 ... vcan{count-1} exist; its exit status."""
    if not force_uml and socketcan_available():
        return run_native(command, count, timeout)
    binary = find_uml()
    if binary is None:
        if force_uml:
            raise UsageError(
                "--uml: User-Mode Linux is not installed (apt-get install user-mode-linux kmod)"
            )
        raise UsageError(
            f"no vcan here: this kernel has no SocketCAN and User-Mode Linux is not installed"
            f" ({ENABLE_HELP})"
        )
    return run_uml(binary, command, count, memory, timeout)


def check(force_uml: bool = False) -> int:
    """``heft vcan --check``: one line saying whether and how vcan interfaces can be had here;
    0 if they can, 2 if not."""
    if not force_uml and socketcan_available():
        print("vcan: natively (this kernel has SocketCAN; creating interfaces needs root)")
        return 0
    binary = find_uml()
    if binary is None:
        print(f"vcan: not available here ({ENABLE_HELP})")
        return 2
    try:
        _modules_dir(binary)
    except UsageError as err:
        print(f"vcan: not available here: {err}")
        return 2
    print(f"vcan: in a User-Mode Linux guest ({binary})")
    return 0


# ------------------------------------------------------------------------------ natively
def run_native(command: Sequence[str], count: int, timeout: float | None) -> int:
    """Create the missing interfaces (root needed), run ``command``, delete those created."""
    names = interface_names(count)
    present = set(existing_interfaces(names))
    missing = [name for name in names if name not in present]
    if missing and os.geteuid() != 0:
        raise UsageError(
            f"{', '.join(missing)} missing, and creating them needs root: run"
            f" sudo deploy/vcan-setup.sh {count} (or heft vcan as root)"
        )
    created: list[str] = []
    try:
        for name in missing:
            _ip("link", "add", "dev", name, "type", "vcan")
            created.append(name)
            _ip("link", "set", name, "up")
        return _run_child(command, timeout)
    finally:
        for name in reversed(created):
            subprocess.run(["ip", "link", "delete", name], capture_output=True, check=False)


def _ip(*args: str) -> None:
    try:
        done = subprocess.run(["ip", *args], capture_output=True, text=True, check=False)
    except FileNotFoundError:
        raise UsageError("'ip' not found: apt-get install iproute2") from None
    if done.returncode != 0:
        why = (done.stderr.strip().splitlines() or ["failed"])[-1]
        hint = "; is the vcan module there? sudo modprobe vcan" if "type" in why else ""
        raise UsageError(f"ip {' '.join(args)}: {why}{hint}")


def _run_child(command: Sequence[str], timeout: float | None) -> int:
    """``command`` with this process's stdin, stdout and stderr; its exit status."""
    with StopSignals().handle() as stop:
        try:
            child = subprocess.Popen(list(command))  # a signal meanwhile: raised at the wait
        except FileNotFoundError:
            _say(f"vcan: {command[0]}: command not found")
            return 127
        except PermissionError:
            _say(f"vcan: {command[0]}: permission denied")
            return 126
        try:
            with stop.raising():
                return exit_status(child.wait(timeout))
        except subprocess.TimeoutExpired:
            _say(f"error: the command did not finish within {timeout:g} s; stopped it")
            _end(child, signal.SIGTERM)
            return TIMED_OUT
        except KeyboardInterrupt:
            signum = stop.received or signal.SIGINT
            if signum != signal.SIGINT:  # a terminal's Ctrl-C has reached it already
                with suppress(ProcessLookupError):
                    child.send_signal(signum)
            _end(child, None)
            return 128 + signum


def _end(child: subprocess.Popen, signum: int | None, grace: float = 10.0) -> None:
    if signum is not None:
        with suppress(ProcessLookupError):
            child.send_signal(signum)
    try:
        child.wait(grace)
    except subprocess.TimeoutExpired:
        child.kill()
        child.wait()


# ------------------------------------------------------------------------ User-Mode Linux
def find_uml() -> str | None:
    """Debian's User-Mode Linux kernel, if installed."""
    for name in UML_BINARIES:
        path = shutil.which(name, path=f"{os.environ.get('PATH', '')}:{SYSTEM_PATH}")
        if path:
            return path
    return None


def _modules_dir(binary: str) -> Path:
    """The UML kernel's modules folder, checked to hold the CAN modules; :class:`UsageError`
    naming what is missing."""
    try:
        done = subprocess.run(
            [binary, "--version"], capture_output=True, text=True, timeout=30, check=False
        )
        version = done.stdout.strip().splitlines()[-1] if done.stdout.strip() else ""
    except (OSError, subprocess.TimeoutExpired):
        version = ""
    if not version:
        raise UsageError(f"{binary} --version gave no kernel version; is it User-Mode Linux?")
    folder = MODULES_ROOT / version
    missing = missing_modules(folder)
    if missing:
        raise UsageError(
            f"User-Mode Linux {version} has no {missing[0]} under {folder}"
            " (apt-get install --reinstall user-mode-linux)"
        )
    for tool in GUEST_TOOLS:
        if not shutil.which(tool, path=SYSTEM_PATH):
            package = {"modprobe": "kmod", "ip": "iproute2"}.get(tool, "coreutils")
            raise UsageError(f"the guest needs '{tool}': apt-get install {package}")
    return folder


def _venv() -> str | None:
    if sys.prefix != sys.base_prefix:
        return sys.prefix
    return os.environ.get("VIRTUAL_ENV")


def run_uml(
    binary: str, command: Sequence[str], count: int, memory: int, timeout: float | None
) -> int:
    """Boot a guest that runs ``command``; pass its output through; its exit status."""
    modules = _modules_dir(binary)
    nonce = secrets.token_hex(8)
    folder = tempfile.mkdtemp(prefix="heft-vcan-")
    pipes: list[int] = []
    guest: subprocess.Popen | None = None
    try:
        os.chmod(folder, 0o755)
        script = Path(folder, "init.sh")
        env = guest_environment(os.environ, _venv())
        script.write_text(
            init_script(command, os.getcwd(), env, count, nonce, modules.parent),
            encoding="utf-8",
        )
        script.chmod(0o755)
        out_r, out_w = os.pipe()
        err_r, err_w = os.pipe()
        pipes += [out_r, out_w, err_r, err_w]
        with StopSignals().handle() as stop:
            try:
                with stop.raising():
                    # A signal between the start and `guest = ...` would leave the guest
                    # running.
                    signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
                    try:
                        guest = subprocess.Popen(
                            uml_arguments(binary, str(script), memory, folder, out_w, err_w),
                            stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT,
                            pass_fds=(out_w, err_w),
                            cwd=folder,
                            start_new_session=True,
                            preexec_fn=_unblock_signals,
                        )
                    finally:
                        _unblock_signals()
                    for fd in (out_w, err_w):
                        os.close(fd)
                        pipes.remove(fd)
                    return _relay(guest, out_r, err_r, nonce, memory, timeout)
            except KeyboardInterrupt:
                signum = stop.received or signal.SIGINT
                _kill_group(guest)
                _say(f"vcan: stopped by {signum.name}; the guest was killed")
                return 128 + signum
    finally:
        _kill_group(guest)
        for fd in pipes:
            with suppress(OSError):
                os.close(fd)
        shutil.rmtree(folder, ignore_errors=True)


def _unblock_signals() -> None:
    signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)


def _kill_group(guest: subprocess.Popen | None) -> None:
    """Kill the guest's every host process (its session's process group) and reap it."""
    if guest is None:
        return
    with suppress(ProcessLookupError, PermissionError):
        os.killpg(guest.pid, signal.SIGKILL)
    with suppress(subprocess.TimeoutExpired):
        guest.wait(10)


def _relay(
    guest: subprocess.Popen,
    out_r: int,
    err_r: int,
    nonce: str,
    memory: int,
    timeout: float | None,
) -> int:
    """Pass the command's output through as it comes; read the console; the exit status."""
    console = ConsoleScanner(nonce)
    streams = {
        out_r: (EndFilter(nonce), sys.stdout.buffer),
        err_r: (EndFilter(nonce), sys.stderr.buffer),
    }
    assert guest.stdout is not None
    console_fd = guest.stdout.fileno()
    deadline = None if timeout is None else time.monotonic() + timeout
    with selectors.DefaultSelector() as selector:
        for fd in (console_fd, out_r, err_r):
            selector.register(fd, selectors.EVENT_READ)
        while selector.get_map():
            wait = None if deadline is None else deadline - time.monotonic()
            if wait is not None and wait <= 0:
                _kill_group(guest)
                _say(f"error: the command did not finish within {timeout:g} s; stopped it")
                return TIMED_OUT
            for key, _ in selector.select(wait):
                data = os.read(key.fd, 1 << 16)
                if not data:
                    selector.unregister(key.fd)
                    if key.fd in streams:
                        _write(streams[key.fd][1], streams[key.fd][0].close())
                elif key.fd == console_fd:
                    console.feed(data)
                else:
                    end, sink = streams[key.fd]
                    _write(sink, end.feed(data))
    guest.wait()
    report = console.report()
    if report.status is None:
        _say("error: " + failure_message(report, memory))
        for line in report.tail:
            print(f"  | {line}", file=sys.stderr)
        return GUEST_FAILED
    if not all(end.ended for end, _ in streams.values()):
        _say("warning: the command's output from the guest may be incomplete")
    return report.status


def _write(sink, data: bytes) -> None:
    if not data:
        return
    with suppress(BrokenPipeError, ValueError):
        sink.write(data)
        sink.flush()
