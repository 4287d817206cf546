"""What every package's ``heft`` subcommands share: the error the user can fix, the help layout,
output files, logging, and the Zenoh options of the process commands.

A subcommand's handler raises :class:`UsageError` for bad input; :mod:`agent.platform.heft`
prints it as one ``heft: error: <message>`` line and exits with status 2.

Every command that opens a Zenoh session (``heft agent``, ``heft sim``, ``heft router``, ...)
takes the same three options, added by :func:`add_zenoh_options` and read back by
:func:`zenoh_settings`:

- ``--connect ENDPOINT`` (repeatable): the routers (or peers) to connect to,
- ``--listen ENDPOINT`` (repeatable): where to accept connections,
- ``--zenoh-config FILE``: a Zenoh JSON5 config file (e.g. TLS, access control) to start from;
  its endpoints are used where it gives them and the two options above do not, and the
  project's settings are applied on top of it (mode, multicast scouting off, shared memory
  off, lease),
- ``--zenoh-log LEVEL``: how much of Zenoh's own log joins the process's (else ``RUST_LOG``,
  else the command's default; :mod:`agent.platform.zenoh_log`),

and the mutual-TLS ones, all three or none (see :mod:`agent.security.certificates`):
``--tls-root-ca FILE``, ``--tls-certificate FILE``, ``--tls-private-key FILE``, and
``--allow-plain`` (plain ``tcp``/``udp`` to addresses other than loopback).

``--config`` is left to each command for its own file (``heft agent --config robot.toml``).
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import re
import stat
import sys
import tempfile
from pathlib import Path

from agent.platform import zenoh_log
from agent.platform.config import ConfigError
from agent.platform.zenoh_session import ZenohSettings, file_endpoints, zenoh_config

PROG = "heft"
DEVICE_FOLDERS = ("/dev/", "/proc/")
"""Outputs there are written directly, never renamed over (``--out /dev/stdout``)."""
LOG_FORMAT = "%(asctime)s %(levelname)s %(message)s"


class UsageError(Exception):
    """Bad input the user can fix: reported as ``heft: error: <message>``, exit status 2."""


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Keeps the descriptions' line breaks; a little wider help column; room for every
    subcommand's name on its line (``heft --help``)."""

    def __init__(self, prog: str) -> None:
        super().__init__(prog, max_help_position=30)

    def add_argument(self, action: argparse.Action) -> None:
        super().add_argument(action)
        if action.help is not argparse.SUPPRESS:
            # argparse sizes the column without the extra indentation subcommands get
            for subaction in self._iter_indented_subactions(action):
                length = len(self._format_action_invocation(subaction)) + self._current_indent
                self._action_max_length = max(self._action_max_length, length)


# ------------------------------------------------------------------------------ output files
def check_port(option: str, port: int) -> None:
    """A TCP port to listen on: 0 (any free one) to 65535, else a :class:`UsageError`."""
    if not 0 <= port <= 65535:
        raise UsageError(f"{option}: expected 0 to 65535, got {port}")


def check_writable(path: Path, directory: bool = False) -> None:
    """Fail before a run, not after it, when its output cannot be written. Creates the folder
    if needed, never the file: a temporary file is created in the folder and removed, so a run
    that fails leaves no empty file behind. An existing device or pipe (``/dev/stdout``) only
    has to be writable."""
    folder = path if directory else path.parent
    try:
        if not directory and path.is_dir():
            raise UsageError(f"{path}: is a folder")
        if not directory and _is_special(path):
            if not os.access(path, os.W_OK):
                raise UsageError(f"{path}: cannot write (permission denied)")
            return
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".heft-check-"):
            pass
    except OSError as err:
        raise UsageError(f"{path}: cannot write ({err.strerror or err})") from None


def write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically: a temporary file in the same folder, flushed to
    disk, then renamed over ``path`` — a reader (or a crash, or a signal) never sees half a
    file, and a failed write leaves the previous file as it was. A symbolic link is written
    through (its target is replaced); a device or pipe, or anything under ``/dev`` or ``/proc``
    (``/dev/stdout``, whatever it stands for), is written directly.
    The file gets the mode a plain ``open`` would give it (the old file's, or 0666 less the
    umask). A :class:`UsageError` on failure."""
    target = Path(os.path.realpath(path))
    try:
        if _is_special(target) or str(path).startswith(DEVICE_FOLDERS):
            with open(path, "w", encoding="utf-8") as stream:
                stream.write(text)
            return
        target.parent.mkdir(parents=True, exist_ok=True)
        try:
            mode = stat.S_IMODE(target.stat().st_mode)
        except FileNotFoundError:
            mode = 0o666 & ~_umask()
        with tempfile.NamedTemporaryFile(
            "w", encoding="utf-8", dir=target.parent, prefix=f".{target.name}.", delete=False
        ) as tmp:
            try:
                os.fchmod(tmp.fileno(), mode)
                tmp.write(text)
                tmp.flush()
                os.fsync(tmp.fileno())
            except BaseException:
                tmp.close()
                os.unlink(tmp.name)
                raise
        try:
            os.replace(tmp.name, target)
        except BaseException:
            os.unlink(tmp.name)
            raise
        _fsync_folder(target.parent)
    except OSError as err:
        raise UsageError(f"{path}: cannot write ({err.strerror or err})") from None


def _is_special(path: Path) -> bool:
    """Whether ``path`` exists and is neither a regular file nor a folder (a device, a pipe)."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def _umask() -> int:
    """This process's umask, read without changing it (Linux), else by setting it back."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _fsync_folder(folder: Path) -> None:
    """Make a rename in ``folder`` durable (where folders can be opened and synced)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


# ------------------------------------------------------------------------------ logging
def setup_logging(args: argparse.Namespace | None = None) -> None:
    """Log INFO and above to stderr, one timestamped line each (what a process command logs),
    and Zenoh's own log with it from the process's first session on, at the level of
    ``args``' ``--zenoh-log`` (:func:`add_zenoh_options`), else ``RUST_LOG``, else the
    command's default (:mod:`agent.platform.zenoh_log`)."""
    logging.basicConfig(
        level=logging.INFO, format=LOG_FORMAT, datefmt="%H:%M:%S", stream=sys.stderr
    )
    zenoh_log.request(
        getattr(args, "zenoh_log", None),
        getattr(args, "zenoh_log_default", zenoh_log.DEFAULT_LEVEL),
    )


# ------------------------------------------------------------------------------ Zenoh options
def add_zenoh_options(
    parser: argparse.ArgumentParser,
    connect: str,
    listen: str,
    config: str = "none",
    log: str = zenoh_log.DEFAULT_LEVEL,
) -> None:
    """Add ``--connect``, ``--listen``, ``--zenoh-config``, ``--zenoh-log``, the ``--tls-...``
    options and ``--allow-plain`` to ``parser`` as the group "Zenoh"; ``connect``, ``listen``
    and ``config`` say, for the help, what is used without them, ``log`` is the level of
    Zenoh's log without ``--zenoh-log`` or ``RUST_LOG``."""
    group = parser.add_argument_group(
        "Zenoh",
        "Multicast scouting is always off: every endpoint is explicit, like\n"
        "tls/192.168.10.1:7447 (tcp, udp, quic or tls). Plain tcp/udp is for loopback\n"
        "(127.0.0.1) only, unless --allow-plain: across a network use tls with the team's\n"
        "certificates (heft deploy certs; deploy/README.md).",
    )
    group.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help=f"connect to ENDPOINT; repeatable (default: {connect})",
    )
    group.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        help=f"listen on ENDPOINT; repeatable (default: {listen})",
    )
    group.add_argument(
        "--zenoh-config",
        metavar="FILE",
        help="start from this Zenoh JSON5 config file (e.g. TLS, access control); its"
        " endpoints are used unless --connect/--listen give them; the mode, scouting,"
        f" shared memory and lease are still set as above (default: {config})",
    )
    group.add_argument(
        "--zenoh-log",
        choices=zenoh_log.LEVELS,
        metavar="LEVEL",
        help="how much of Zenoh's own log joins this process's log: off, error, warn, info,"
        " debug or trace (default: the RUST_LOG environment variable, in Zenoh's filter"
        f" syntax, if set, else {log})",
    )
    parser.set_defaults(zenoh_log_default=log)
    for option, what in TLS_OPTIONS.items():
        group.add_argument(
            option,
            metavar="FILE",
            help=f"mutual TLS: {what} (PEM); the three go together",
        )
    group.add_argument(
        "--allow-plain",
        action="store_true",
        default=None,
        help="allow plain tcp/udp endpoints to addresses other than loopback: unencrypted,"
        " open to anyone on the network (default: [zenoh] allow_plain, false)",
    )


TLS_OPTIONS = {
    "--tls-root-ca": "the team's CA certificate",
    "--tls-certificate": "this process's certificate",
    "--tls-private-key": "its private key",
}
TLS_KEYS = {
    "--tls-root-ca": "root_ca",
    "--tls-certificate": "certificate",
    "--tls-private-key": "private_key",
}


def zenoh_settings(args: argparse.Namespace, base: ZenohSettings) -> ZenohSettings:
    """``base`` with the options of :func:`add_zenoh_options` applied (each replaces what
    ``base`` had), checked; a :class:`UsageError` naming the option if something is wrong."""
    changes: dict[str, object] = {}
    names: dict[str, str] = {}  # the options that gave a key, for the error messages
    allow_plain = getattr(args, "allow_plain", None)
    try:
        if allow_plain:
            changes["allow_plain"] = names["allow_plain"] = True
        plain_ok = base.allow_plain or bool(allow_plain)
        for option, key in (("--connect", "connect"), ("--listen", "listen")):
            endpoints = getattr(args, key)
            if endpoints:
                for endpoint in endpoints:
                    ZenohSettings.check_endpoint(endpoint, option)
                    if not plain_ok:
                        ZenohSettings.check_plain(endpoint, option, "give --allow-plain")
                changes[key] = tuple(endpoints)
                names[key] = option
        if args.zenoh_config is not None:
            ZenohSettings.check_config_file(args.zenoh_config, "--zenoh-config")
            changes["config_file"] = args.zenoh_config
            names["config_file"] = "--zenoh-config"
        for option, key in TLS_KEYS.items():
            path = getattr(args, option[2:].replace("-", "_"), None)
            if path is not None:
                ZenohSettings.check_config_file(path, option)
                changes[key] = path
                names[key] = option
        if any(key in names for key in TLS_KEYS.values()):
            for option, key in TLS_KEYS.items():  # a missing one: say which option
                if getattr(base, key) is None:
                    names.setdefault(key, option)
        settings = dataclasses.replace(base, **changes)
        if settings.config_file is not None:
            settings = _with_file_endpoints(settings, args, names, plain_ok)
        settings.validate("zenoh", names)
        settings.check_private_key(names.get("private_key", "zenoh.private_key"))
    except ConfigError as err:
        raise UsageError(str(err)) from None
    if settings.config_file is not None:
        _check_zenoh_file(settings, _file_option(args))
    return settings


def _file_option(args: argparse.Namespace) -> str:
    """What gave the Zenoh config file, for an error message."""
    return "--zenoh-config" if args.zenoh_config is not None else "zenoh.config_file"


def _with_file_endpoints(
    settings: ZenohSettings, args: argparse.Namespace, names: dict[str, str], plain_ok: bool
) -> ZenohSettings:
    """``settings`` with the endpoints its Zenoh config file gives (:func:`file_endpoints`)
    where no ``--connect``/``--listen`` gave them, each checked as those are; ``names`` then
    names the file's key for the error messages."""
    import zenoh

    path = settings.config_file
    try:
        given = file_endpoints(path, settings.mode)
    except zenoh.ZError as err:
        raise UsageError(
            f"{_file_option(args)}: {path}: not a valid Zenoh config ({_one_line(err)})"
        ) from None
    changes = {}
    for key, endpoints in given.items():
        if key in names:  # --connect/--listen
            continue
        where = f"{path}: {key}/endpoints"
        for endpoint in endpoints:
            ZenohSettings.check_endpoint(endpoint, where)
            if not plain_ok:
                ZenohSettings.check_plain(endpoint, where, "give --allow-plain")
        changes[key] = endpoints
        names[key] = where
    return dataclasses.replace(settings, **changes)


def _check_zenoh_file(settings: ZenohSettings, where: str) -> None:
    """Parse the settings' Zenoh config file now, so that a bad one is a usage error."""
    import zenoh

    try:
        zenoh_config(settings)
    except zenoh.ZError as err:
        raise UsageError(
            f"{where}: {settings.config_file}: not a valid Zenoh config ({_one_line(err)})"
        ) from None


def _one_line(err: Exception) -> str:
    """Zenoh's error about a config file as one line: ``LINE:COLUMN: what is wrong``."""
    text = str(err)
    schema = re.search(
        r'msg: "(.*?)", location: Some\(Location \{ line: (\d+), column: (\d+)', text
    )
    if schema:  # a key or value the schema rejects
        return f"{schema[2]}:{schema[3]}: {schema[1]}"
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    where = next((line[3:].strip() for line in lines if line.startswith("-->")), "")
    what = next((line[1:].strip() for line in lines if line.startswith("=")), " ".join(lines))
    what = what.split(" at /", 1)[0]  # Zenoh appends the Rust source location
    return f"{where}: {what}" if where else what
