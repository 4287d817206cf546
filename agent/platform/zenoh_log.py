"""Zenoh's own log in the process's log.

Zenoh logs through Rust's ``tracing``, and eclipse-zenoh 1.x (1.10.2 here) has one way to turn
that on: ``zenoh.init_log_from_env_or(FILTER)`` (or ``try_init_log_from_env()``), which writes
every event, formatted (ANSI colours unless ``NO_COLOR`` is set), to file descriptor 1 — the
process's standard output, where a command's results go — and nothing of it to Python's
``logging``. Without it Zenoh says nothing at all: a refused TLS handshake or a certificate
name the router's access control does not know left no trace.

So :func:`start` puts a pipe on descriptor 1 before it turns Zenoh's log on, gives Python's
``sys.stdout`` the real standard output back, and a thread reads the pipe: each line of
Zenoh's, like::

    2026-11-25T14:00:26.471523Z  WARN acc-0 ThreadId(05) zenoh_link_tls::unicast: peer sent
    no certificates. Hint: increase the system open file limit.

becomes a record of the logger ``zenoh.<target>`` (``zenoh.zenoh_link_tls.unicast``) at its
level (TRACE is level 5), stamped with Zenoh's time, whose message is the line from the
target on (spans included); any other line written to descriptor 1 (by code still holding the
old ``sys.stdout``) is copied to the real standard output unchanged. At exit the pipe is
emptied into the log before the process ends.

Which of Zenoh's events (:func:`choose`): the level given by ``--zenoh-log LEVEL``, else the
``RUST_LOG`` environment variable (Zenoh's filter syntax, e.g. ``warn,zenoh::net=debug``),
else the command's default (:data:`DEFAULT_LEVEL`; ``info`` for ``heft router``, as
``zenohd``). A level applies to Zenoh's own crates (targets ``zenoh*``); the libraries under
them log warnings and errors only. ``off`` leaves Zenoh silent and standard output alone.
Measured with eclipse-zenoh 1.10.2: a router logs each refused handshake (no certificate, a
foreign CA, plain TCP on its TLS port) at ``warn``, a certificate that matches no subject of
its access control at ``info``.

Only a process whose own program is the ``heft`` command (:func:`enable`, by
:func:`agent.platform.heft.main` run from the command line) and whose command asked for it
(:func:`request`, by :func:`agent.platform.cli_helpers.setup_logging`) routes Zenoh's log,
from its first session on (:func:`agent.platform.zenoh_session.open_session` calls
:func:`start`): the standard output of a process that calls commands or opens sessions as a
library (a test's) is left alone, and so is that of a command that never opens Zenoh. Rust's
``tracing`` takes its subscriber once per process: the first choice stands.
"""

from __future__ import annotations

import atexit
import fcntl
import logging
import os
import re
import sys
import threading
from dataclasses import dataclass
from datetime import datetime

LEVELS = ("off", "error", "warn", "info", "debug", "trace")
"""The levels ``--zenoh-log`` takes, as Zenoh (Rust's ``tracing``) names them."""
DEFAULT_LEVEL = "warn"
"""What a process logs of Zenoh's without ``--zenoh-log`` or ``RUST_LOG``: its warnings and
errors (a refused handshake, a link lost)."""
TRACE = 5
"""The Python level of Zenoh's TRACE events (below DEBUG)."""
PYTHON_LEVELS = {
    "ERROR": logging.ERROR,
    "WARN": logging.WARNING,
    "INFO": logging.INFO,
    "DEBUG": logging.DEBUG,
    "TRACE": TRACE,
}
PIPE_BYTES = 1 << 20
"""The pipe's buffer (Linux's default limit for a process): a Zenoh thread that logs waits
only once this much is waiting for the log, e.g. at ``trace`` on a loaded machine."""
JOIN_S = 2.0
"""How long the exit waits for the last of Zenoh's lines to reach the log."""

_EVENT = re.compile(
    r"^(?P<time>\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(?:\.\d+)?Z)\s+"
    r"(?P<level>TRACE|DEBUG|INFO|WARN|ERROR)\s+"
    r"(?:(?:\S+\s+)?ThreadId\(\d+\)\s+)?"  # the thread's name, if any, and id
    r"(?P<message>.*)$"
)
_TARGET = re.compile(r"(?<![\w:])([A-Za-z_]\w*(?:::\w+)+): ")  # a module path
_CRATE = re.compile(r"([A-Za-z_]\w*): ")  # a crate's root
_ANSI = re.compile(r"\x1b\[[0-9;]*m")


@dataclass(frozen=True)
class Choice:
    """What of Zenoh's log a process asked for."""

    filter: str
    """Rust ``tracing``'s filter (``RUST_LOG`` syntax), e.g. ``warn,zenoh=info``."""
    source: str
    """Where it came from, for the log: ``--zenoh-log info``, ``RUST_LOG``, ``default``."""

    @property
    def off(self) -> bool:
        return self.filter.strip().lower() == "off"

    def __str__(self) -> str:
        return f"{self.filter} ({self.source})"


def rust_filter(level: str) -> str:
    """``tracing``'s filter for ``level`` (one of :data:`LEVELS`): the level for Zenoh's own
    crates (their targets begin with ``zenoh``), at most ``warn`` for the libraries under
    them."""
    if level not in LEVELS:
        raise ValueError(f"expected one of {', '.join(LEVELS)}, got {level!r}")
    if LEVELS.index(level) <= LEVELS.index("warn"):
        return level
    return f"warn,zenoh={level}"


def choose(level: str | None, default: str = DEFAULT_LEVEL, env: dict | None = None) -> Choice:
    """The filter in force: ``level`` (``--zenoh-log``) if given, else ``RUST_LOG`` if set
    (in ``env``, by default the process's environment), else ``default``."""
    env = os.environ if env is None else env
    if level is not None:
        return Choice(rust_filter(level), f"--zenoh-log {level}")
    if env.get("RUST_LOG", "").strip():
        return Choice(env["RUST_LOG"].strip(), "RUST_LOG")
    return Choice(rust_filter(default), "default")


@dataclass(frozen=True)
class Event:
    """One of Zenoh's log lines, parsed."""

    created: float
    """Seconds since the epoch (Zenoh's UTC timestamp)."""
    level: int
    """The Python level."""
    target: str
    """The Rust module that logged it, e.g. ``zenoh_link_tls::unicast``."""
    message: str
    """The line from its spans and target on."""

    @property
    def logger(self) -> str:
        """The Python logger's name: ``zenoh.`` and the target's path with dots."""
        return "zenoh." + self.target.replace("::", ".")


def parse(line: str) -> Event | None:
    """The event ``line`` of Zenoh's ``tracing`` output (colours or not) is, or None if it is
    not one."""
    match = _EVENT.match(_ANSI.sub("", line).rstrip("\r\n"))
    if match is None:
        return None
    message = match["message"]
    target = _TARGET.search(message) or _CRATE.match(message)
    created = datetime.fromisoformat(match["time"].replace("Z", "+00:00")).timestamp()
    return Event(
        created=created,
        level=PYTHON_LEVELS[match["level"]],
        target=target[1] if target else "zenoh",
        message=message,
    )


class _Relay(threading.Thread):
    """Reads the pipe on descriptor 1: Zenoh's lines to the log, the rest to ``out``."""

    def __init__(self, pipe: int, out: int | None):
        super().__init__(name="zenoh-log", daemon=True)
        self.pipe = pipe
        self.out = out
        self.loggers: dict[str, logging.Logger] = {}

    def run(self) -> None:
        pending = b""
        while True:
            try:
                chunk = os.read(self.pipe, 65536)
            except InterruptedError:  # pragma: no cover - retried by Python itself
                continue
            except OSError:
                break
            if not chunk:
                break
            pending += chunk
            *lines, pending = pending.split(b"\n")
            for line in lines:
                self.handle(line + b"\n")
        if pending:
            self.handle(pending)
        os.close(self.pipe)

    def handle(self, line: bytes) -> None:
        event = parse(line.decode("utf-8", "replace"))
        if event is None:
            self.copy(line)
            return
        logger = self.loggers.get(event.logger)
        if logger is None:
            logger = self.loggers[event.logger] = logging.getLogger(event.logger)
        if not logger.isEnabledFor(event.level):
            return
        record = logger.makeRecord(logger.name, event.level, "zenoh", 0, event.message, None, None)
        record.created = event.created
        record.msecs = (event.created - int(event.created)) * 1000
        try:
            logger.handle(record)
        except Exception:  # pragma: no cover - a handler's failure must not stop the relay
            self.copy(line)

    def copy(self, line: bytes) -> None:
        if self.out is None:
            return
        try:
            os.write(self.out, line)
        except OSError:  # the reader of standard output is gone: the line is lost
            pass


_enabled = False
_requested: Choice | None = None
_started: Choice | None = None
_relay: _Relay | None = None
_real_stdout: int | None = None
_lock = threading.Lock()


def enable() -> None:
    """This process is the ``heft`` command: its standard output is its own, and its command
    may route Zenoh's log (:func:`request`)."""
    global _enabled
    _enabled = True


def request(level: str | None, default: str = DEFAULT_LEVEL) -> Choice | None:
    """Route Zenoh's log into this process's log from its first session on, with the filter
    :func:`choose` picks, once :func:`enable` was called; returns the choice that stands (None:
    not enabled)."""
    global _requested
    if not _enabled:
        return None
    choice = choose(level, default)
    with _lock:
        if _requested is None:
            _requested = choice
    return _requested


def in_force() -> Choice | None:
    """What of Zenoh's log this process routes, ``off`` included (None: it was not asked)."""
    if _started is None and _requested is not None and _requested.off:
        return _requested
    return _started


def start() -> Choice | None:
    """Turn Zenoh's log on as :func:`request`-ed, once per process (nothing if it was not
    requested, or ``off``); returns :func:`in_force`."""
    global _started
    with _lock:
        if _requested is None or _started is not None or _requested.off:
            return _started
        _route_stdout()
        _init_zenoh(_requested)
        _started = _requested
        logging.addLevelName(TRACE, "TRACE")
        # Rust's filter decides what comes: let all of it through to the handlers
        logging.getLogger("zenoh").setLevel(TRACE)
    atexit.register(stop)
    return _started


def _route_stdout() -> None:
    """The pipe on descriptor 1, read by the relay; ``sys.stdout`` on the real one."""
    global _relay, _real_stdout
    stdout = sys.stdout
    if stdout is not None:
        try:
            stdout.flush()
        except (OSError, ValueError):
            pass
    try:
        real = os.dup(1)
    except OSError:  # no standard output at all
        real = None
    read, write = os.pipe()
    try:
        fcntl.fcntl(write, fcntl.F_SETPIPE_SZ, PIPE_BYTES)
    except (OSError, AttributeError):  # not Linux, or above the system's limit
        pass
    os.dup2(write, 1)
    os.close(write)
    _real_stdout = real
    if real is not None and stdout is not None and _writes_to_fd_1(stdout):
        sys.stdout = _reopen(stdout, real)
    _relay = _Relay(read, real)
    _relay.start()


def _writes_to_fd_1(stream) -> bool:
    try:
        return stream.fileno() == 1
    except (OSError, ValueError, AttributeError):
        return False


def _reopen(stream, fd: int):
    """A text stream on ``fd`` that writes as ``stream`` did (encoding, buffering)."""
    line_buffering = getattr(stream, "line_buffering", False)
    reopened = open(  # noqa: SIM115 - it replaces sys.stdout for the process's lifetime
        fd,
        "w",
        encoding=getattr(stream, "encoding", None) or "utf-8",
        errors=getattr(stream, "errors", None) or "strict",
        buffering=1 if line_buffering else -1,
        closefd=False,
    )
    if getattr(stream, "write_through", False):
        reopened.reconfigure(write_through=True)
    return reopened


def _init_zenoh(choice: Choice) -> None:
    """Zenoh's ``tracing`` subscriber with ``choice``'s filter and no colours. Both are read
    from the environment when it is made; the environment is put back after."""
    import zenoh

    saved = {key: os.environ.get(key) for key in ("RUST_LOG", "NO_COLOR")}
    os.environ["RUST_LOG"] = choice.filter
    os.environ["NO_COLOR"] = "1"
    try:
        # RUST_LOG that Zenoh cannot parse: the default's filter instead
        zenoh.init_log_from_env_or(rust_filter(DEFAULT_LEVEL))
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def stop() -> None:
    """Give descriptor 1 back to the real standard output and wait (up to :data:`JOIN_S`)
    for the relay to log what the pipe still holds (at exit)."""
    global _relay
    relay = _relay
    if relay is None:
        return
    _relay = None
    try:
        sys.stdout.flush()
    except (OSError, ValueError, AttributeError):
        pass
    if _real_stdout is not None:
        os.dup2(_real_stdout, 1)  # closes the pipe's last writer: the relay reads to its end
    else:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
        os.close(devnull)
    relay.join(JOIN_S)
