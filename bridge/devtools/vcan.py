"""Virtual CAN interfaces for ``heft vcan``: the pure parts (no processes started here).

``heft vcan -- CMD ARGS...`` runs CMD where the interfaces ``vcan0`` ... ``vcan{N-1}`` exist.
On a kernel with SocketCAN it creates the missing ones and runs CMD natively
(:mod:`bridge.devtools.vcan_run`). On a kernel without it (``socket(AF_CAN, ...)`` fails with
EAFNOSUPPORT, as on the build and CI machines) it boots Debian's User-Mode Linux: a Linux
kernel as an ordinary process, with the host's filesystem as its root (hostfs) and a generated
init script (:func:`init_script`) that loads the CAN modules, creates the interfaces, runs CMD
in the caller's folder and environment and reports CMD's exit status on the console.

The guest's channels (:func:`uml_arguments`):

- console ``con0`` (the kernel's messages and the init script's own lines): read by the host
  for the marker lines ``heft-vcan NONCE start``, ``... exit STATUS`` or ``... error MESSAGE``
  (:class:`ConsoleScanner`), shown only when the guest fails;
- ``con1``, ``con2`` (the guest's ``/dev/tty1``, ``/dev/tty2``): CMD's stdout and stderr,
  relayed from pipes by ``cat`` (a tty is slow for many small writes), each closed by the
  token ``heft-vcan NONCE end`` once everything has been written (:class:`EndFilter`).

CMD's stdin is ``/dev/null`` in the guest, its stdout and stderr are pipes, and the guest has
one CPU.
"""

from __future__ import annotations

import os
import re
import shlex
import socket
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

DEFAULT_COUNT = 9
"""vcan0 ... vcan8: robots 1..8 use vcan1 ... vcan8, vcan0 is spare."""
MAX_COUNT = 64
DEFAULT_MEMORY = "2G"
MIN_MEMORY = 128 << 20
MODULES_ROOT = Path("/usr/lib/uml/modules")
"""Debian's ``user-mode-linux`` keeps its modules in ``MODULES_ROOT/<kernel version>/``."""
CAN_MODULES = (
    "kernel/net/can/can.ko",
    "kernel/net/can/can-raw.ko",
    "kernel/drivers/net/can/dev/can-dev.ko",
    "kernel/drivers/net/can/vcan.ko",
)
"""Loaded by the guest (``modprobe``, so with what they depend on); each is needed."""
OPTIONAL_MODULES = ("kernel/net/ipv6/ipv6.ko",)
"""Loaded if present, so that listeners on ``[::]`` work in the guest as on the host."""
GUEST_TOOLS = ("modprobe", "ip", "stty", "mkfifo", "halt")
"""Host programs the guest's init script runs (from kmod, iproute2, coreutils, systemd)."""
SYSTEM_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
MARK = "heft-vcan"
END_WAIT_S = 5.0
"""How long the guest waits, after CMD exits, for CMD's output pipes to be closed by
processes CMD left behind, before it reports the status anyway."""

ENABLE_HELP = (
    "on a kernel with CAN: sudo modprobe vcan (or sudo deploy/vcan-setup.sh); on one without:"
    " apt-get install user-mode-linux kmod"
)


def interface_names(count: int) -> list[str]:
    """``["vcan0", ..., f"vcan{count - 1}"]``."""
    return [f"vcan{i}" for i in range(count)]


def check_count(count: int) -> int:
    """``count`` if it is 1 to :data:`MAX_COUNT`, else :class:`ValueError`."""
    if not 1 <= count <= MAX_COUNT:
        raise ValueError(f"--count: expected 1 to {MAX_COUNT} interfaces, got {count}")
    return count


_SIZE = re.compile(r"^(\d+)([KMG]?)$", re.I)


def parse_memory(text: str) -> int:
    """The guest's memory in bytes from ``512M``, ``2G``, ``1048576K`` or a number of bytes;
    :class:`ValueError` with a one-line message if it is not one, or below 128M."""
    match = _SIZE.match(text.strip())
    if not match:
        raise ValueError(f"--memory: expected a size like 512M or 2G, got {text!r}")
    number, unit = match.groups()
    size = int(number) << {"": 0, "K": 10, "M": 20, "G": 30}[unit.upper()]
    if size < MIN_MEMORY:
        raise ValueError(f"--memory: the guest needs at least 128M, got {text!r}")
    return size


def memory_option(size: int) -> str:
    """UML's ``mem=`` value for ``size`` bytes (in MiB, rounded up)."""
    return f"{-(-size // (1 << 20))}M"


# ------------------------------------------------------------------------- the host's kernel
def socketcan_available() -> bool:
    """Whether this kernel has SocketCAN: a raw CAN socket opens (anything but EAFNOSUPPORT,
    e.g. a permission error, counts as yes)."""
    family = getattr(socket, "AF_CAN", None)
    if family is None:  # pragma: no cover - a Python built without CAN support
        return False
    try:
        socket.socket(family, socket.SOCK_RAW, socket.CAN_RAW).close()
    except OSError as err:
        return err.errno not in (97, 93)  # EAFNOSUPPORT, EPROTONOSUPPORT
    return True


def existing_interfaces(names: Sequence[str], sys_class_net: Path = Path("/sys/class/net")):
    """Those of ``names`` that exist on this machine."""
    return [name for name in names if (sys_class_net / name).exists()]


def missing_modules(modules_dir: Path) -> list[str]:
    """The CAN modules (:data:`CAN_MODULES`) missing from the UML modules folder."""
    return [m for m in CAN_MODULES if not (modules_dir / m).is_file()]


# ------------------------------------------------------------------------------- the guest
def guest_environment(
    environ: Mapping[str, str], venv: str | None = None, extra: Mapping[str, str] | None = None
) -> dict[str, str]:
    """CMD's environment in the guest: the caller's, with the virtualenv ``venv`` (if any)
    first on ``PATH`` and in ``VIRTUAL_ENV``, the system folders on ``PATH``,
    ``PYTHONUNBUFFERED=1`` unless the caller set it (output streams out as it is printed; set
    it empty for throughput: every write is a slow system call in the guest) and
    ``HEFT_VCAN=1`` (tests can tell that they run inside), then ``extra``."""
    env = {k: v for k, v in environ.items() if k and "=" not in k and "\0" not in k + v}
    path = [p for p in env.get("PATH", "").split(os.pathsep) if p]
    if venv:
        env["VIRTUAL_ENV"] = venv
        bin_dir = os.path.join(venv, "bin")
        path = [bin_dir] + [p for p in path if p != bin_dir]
    path += [p for p in SYSTEM_PATH.split(":") if p not in path]
    env["PATH"] = os.pathsep.join(path)
    env.setdefault("HOME", "/root")
    env.setdefault("PYTHONUNBUFFERED", "1")
    env["HEFT_VCAN"] = "1"
    env.update(extra or {})
    return env


def init_script(
    command: Sequence[str],
    cwd: str,
    environ: Mapping[str, str],
    count: int,
    nonce: str,
    modules_root: Path = MODULES_ROOT,
) -> str:
    """The guest's ``/bin/sh`` init script: mount ``/proc``, ``/sys``, a tmpfs on ``/run`` and
    ``/dev/shm``; bring ``lo`` up; load the CAN modules of the running kernel; create and bring
    up ``vcan0`` ... ``vcan{count-1}``; run ``command`` in ``cwd`` with exactly ``environ``
    (``env -i``), stdin ``/dev/null``; report ``heft-vcan NONCE exit STATUS`` on the console and
    halt. Any failure before CMD runs is reported as ``heft-vcan NONCE error MESSAGE``.
    Every caller-given word is quoted (:func:`shlex.quote`)."""
    if not command:
        raise ValueError("no command")
    if not re.fullmatch(r"[0-9a-f]{8,64}", nonce):
        raise ValueError(f"nonce: expected hex digits, got {nonce!r}")
    q = shlex.quote
    env_words = " \\\n    ".join(q(f"{k}={v}") for k, v in sorted(environ.items()))
    cmd_words = " ".join(q(word) for word in command)
    required = " ".join(Path(m).stem for m in CAN_MODULES)
    optional = " ".join(Path(m).stem for m in OPTIONAL_MODULES)
    polls = int(END_WAIT_S * 10)
    return f"""#!/bin/sh
# The init of a User-Mode Linux guest, written by `heft vcan` (bridge/devtools/vcan.py): it creates
# vcan0..vcan{count - 1}, runs one command and reports its exit status on the console.
PATH={SYSTEM_PATH}
export PATH
MARK='{MARK} {nonce}'
RUN=/run/heft-vcan

stop() {{
    sync
    halt -f >/dev/null 2>&1
    echo o >/proc/sysrq-trigger
    sleep 60
}}

fail() {{
    echo "$MARK error $*"
    stop
}}

mount -t proc proc /proc || fail "cannot mount /proc"
mount -t sysfs sysfs /sys || fail "cannot mount /sys"
mount -t tmpfs -o mode=0755 tmpfs /run || fail "cannot mount a tmpfs on /run"
mkdir -p /dev/shm /dev/pts "$RUN/root/lib"
mount -t tmpfs -o mode=1777 tmpfs /dev/shm || fail "cannot mount a tmpfs on /dev/shm"
mount -t devpts devpts /dev/pts
ln -s /proc/self/fd /dev/fd
echo heft-vcan >/proc/sys/kernel/hostname

# modprobe finds the UML kernel's modules through $RUN/root/lib/modules.
ln -s {q(str(modules_root))} "$RUN/root/lib/modules"
modprobe -d "$RUN/root" -a {required} {optional} 2>/dev/null ||
    modprobe -d "$RUN/root" -a {required} || fail "cannot load the CAN modules ({required})"
i=0
while [ "$i" -lt {count} ]; do
    echo "link add dev vcan$i type vcan"
    echo "link set vcan$i up"
    i=$((i + 1))
done | ip -batch - || fail "cannot create vcan0..vcan{count - 1}"
ip link set lo up || fail "cannot bring lo up"

# CMD writes to pipes; cat relays them in large writes to tty1 (stdout) and tty2 (stderr).
mkdir -p "$RUN" && mkfifo "$RUN/out" "$RUN/err" || fail "cannot create the output pipes"
stty -F /dev/tty1 raw -echo && stty -F /dev/tty2 raw -echo || fail "cannot set up tty1, tty2"
{{ cat "$RUN/out" >/dev/tty1; : >"$RUN/out.done"; }} &
{{ cat "$RUN/err" >/dev/tty2; : >"$RUN/err.done"; }} &
cd {q(cwd)} || fail "cannot enter "{q(cwd)}

echo "$MARK start"
env -i -- \\
    {env_words} \\
    /bin/sh -c 'exec "$0" "$@"' {cmd_words} \\
    </dev/null >"$RUN/out" 2>"$RUN/err"
status=$?

# Wait (a while) for the relays: processes CMD left behind may hold the pipes open.
n=0
while [ "$n" -lt {polls} ] && ! {{ [ -e "$RUN/out.done" ] && [ -e "$RUN/err.done" ]; }}; do
    sleep 0.1
    n=$((n + 1))
done
printf '%s' "$MARK end" >/dev/tty1
printf '%s' "$MARK end" >/dev/tty2
# Setting a tty's mode waits until its output has been sent to the host.
stty -F /dev/tty1 raw
stty -F /dev/tty2 raw
sync
echo "$MARK exit $status"
stop
"""


def uml_arguments(
    binary: str, script: str, memory: int, uml_dir: str, out_fd: int, err_fd: int
) -> list[str]:
    """The command line that boots the guest: hostfs root, ``script`` as init, ``memory``
    bytes, the console on UML's stdout, ``/dev/tty1`` and ``/dev/tty2`` on the host's file
    descriptors ``out_fd`` and ``err_fd``, no other consoles or serial lines, UML's own files
    (pid, mconsole socket) in ``uml_dir``."""
    return [
        binary,
        f"mem={memory_option(memory)}",
        "rootfstype=hostfs",
        "rootflags=/",
        "rw",
        f"init={script}",
        "quiet",
        "con=null",
        "ssl=null",
        "con0=null,fd:1",
        f"con1=null,fd:{out_fd}",
        f"con2=null,fd:{err_fd}",
        f"uml_dir={uml_dir}",
    ]


# ------------------------------------------------------------------------- reading the guest
class EndFilter:
    """Passes a stream through until the token ``heft-vcan NONCE end`` and drops the token
    and anything after it. Streaming: :meth:`feed` returns what may be shown now, keeping back
    only a tail that could be the start of the token; :meth:`close` returns that tail if the
    token never came."""

    def __init__(self, nonce: str) -> None:
        self.token = f"{MARK} {nonce} end".encode()
        self.ended = False
        self._held = b""

    def feed(self, data: bytes) -> bytes:
        if self.ended:
            return b""
        data = self._held + data
        at = data.find(self.token)
        if at >= 0:
            self.ended = True
            self._held = b""
            return data[:at]
        keep = 0
        for n in range(min(len(self.token) - 1, len(data)), 0, -1):
            if data.endswith(self.token[:n]):
                keep = n
                break
        self._held = data[len(data) - keep :]
        return data[: len(data) - keep]

    def close(self) -> bytes:
        held, self._held = self._held, b""
        return b"" if self.ended else held


@dataclass
class GuestReport:
    """What the console said: ``status`` (CMD's exit status) or ``error`` (why the guest could
    not run CMD), whether CMD was ``started``, and the console's last lines."""

    status: int | None
    error: str | None
    started: bool
    tail: list[str]


class ConsoleScanner:
    """Reads the guest's console (kernel messages and the init script's lines) for the marker
    lines ``heft-vcan NONCE start|exit STATUS|error MESSAGE``, keeping the last ``keep`` other
    lines for error messages."""

    def __init__(self, nonce: str, keep: int = 20) -> None:
        self._marker = re.compile(rf"{MARK} {re.escape(nonce)} (start|exit|error)\b ?(.*)")
        self._partial = b""
        self._tail: deque[str] = deque(maxlen=keep)
        self.status: int | None = None
        self.error: str | None = None
        self.started = False

    def feed(self, data: bytes) -> None:
        lines = (self._partial + data).split(b"\n")
        self._partial = lines.pop()
        for line in lines:
            self._line(line)

    def _line(self, raw: bytes) -> None:
        line = raw.decode("utf-8", "replace").replace("\r", "").rstrip()
        match = self._marker.search(line)
        if not match:
            if line:
                self._tail.append(line)
            return
        kind, rest = match.groups()
        if kind == "start":
            self.started = True
        elif kind == "exit" and rest.strip().isdigit():
            self.status = int(rest)
        elif kind == "error":
            self.error = rest.strip() or "unknown error"

    def report(self) -> GuestReport:
        if self._partial:
            self._line(self._partial)
            self._partial = b""
        return GuestReport(self.status, self.error, self.started, list(self._tail))


def failure_message(report: GuestReport, memory: int) -> str:
    """One line saying why the guest gave no exit status (followed by nothing else: the
    console's last lines are printed after it by the caller)."""
    if report.error:
        return f"the User-Mode Linux guest could not run the command: {report.error}"
    if not report.started:
        return "the User-Mode Linux guest stopped before running the command; its console ends:"
    return (
        "the User-Mode Linux guest stopped without reporting the command's exit status (out of"
        f" memory? --memory is {memory_option(memory)}); its console ends:"
    )


def exit_status(returncode: int) -> int:
    """A shell's exit status for a ``subprocess`` return code: 128 + N for signal N."""
    return 128 - returncode if returncode < 0 else returncode
