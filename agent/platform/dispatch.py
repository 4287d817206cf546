"""The ``heft`` command (also ``python -m agent``): one entry point for every package's commands.

A package adds its subcommands by declaring an entry point of the group :data:`GROUP` in
``pyproject.toml``, without touching the other packages::

    [project.entry-points."heft.commands"]
    simulator = "simulator.cli:register"

The entry point names a function ``register(commands)`` that adds the package's subcommands
to ``commands`` (the ``argparse`` subparsers of ``heft``), each with
``formatter_class=HelpFormatter`` and ``set_defaults(handler=...)``
(:mod:`agent.platform.command_line`). A handler takes the parsed arguments and returns the exit
status; it raises :class:`~agent.platform.command_line.UsageError` for bad input, reported here as
one ``heft: error: ...`` line with exit status 2. ``register`` should import only what building
the parser needs, so that ``heft agent`` on a robot does not load the simulator's libraries.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from importlib import metadata

from agent.platform import zenoh_log
from agent.platform.command_line import PROG, HelpFormatter, UsageError
from agent.platform.config import ConfigError
from agent.platform.zenoh_session import SessionError

NETWORK_UNAVAILABLE = 4
"""Exit status when Zenoh cannot listen or connect (a busy port, no router in time): unlike a
bad config (2) it may pass, so service units restart on it."""

GROUP = "heft.commands"
"""The entry-point group of ``register(commands)`` functions."""


def _version() -> str:
    try:
        return metadata.version("heft-hil")
    except metadata.PackageNotFoundError:  # pragma: no cover - running from a bare checkout
        return "unknown"


def _register_commands(commands: argparse._SubParsersAction) -> None:
    """Let every installed package add its commands, in the order of the entry points' names.

    A package whose commands cannot be imported (an optional dependency missing) is left out
    with a warning, so that the other packages' commands still work.
    """
    entries = sorted(metadata.entry_points(group=GROUP), key=lambda e: e.name)
    if not entries:
        print(
            f"{PROG}: warning: no commands installed (entry points {GROUP!r});"
            " install the project: pip install -e .",
            file=sys.stderr,
        )
    for entry in entries:
        try:
            register = entry.load()
        except ImportError as err:
            print(
                f"{PROG}: warning: the {entry.name} commands are unavailable ({err})",
                file=sys.stderr,
            )
            continue
        register(commands)


def build_parser() -> argparse.ArgumentParser:
    """The ``heft`` argument parser with every installed package's subcommands."""
    parser = argparse.ArgumentParser(
        prog=PROG,
        formatter_class=HelpFormatter,
        description=(
            "Distributed estimation of an unknown load's mass, moment of inertia and centre\n"
            "of mass by a team of pushing robots (Franchi, Petitti, Rizzo, CDC 2014)."
        ),
        epilog="Run 'heft COMMAND --help' for a command's options.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    commands = parser.add_subparsers(dest="command", title="commands", metavar="COMMAND")
    _register_commands(commands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``heft``; returns the exit status. Run as the process's program (no
    ``argv``: its command line), its commands route Zenoh's log into its log
    (:func:`agent.platform.zenoh_log.enable`); called with ``argv`` (a test), they leave it
    alone."""
    if argv is None:
        zenoh_log.enable()
    parser = build_parser()
    args = parser.parse_args(argv)
    handler = getattr(args, "handler", None)
    if handler is None:
        parser.print_help(sys.stderr)
        return 2
    try:
        return handler(args)
    except SessionError as err:  # a busy port, an unreachable router: may pass, so retry
        print(f"{PROG}: error: {err}", file=sys.stderr)
        return NETWORK_UNAVAILABLE
    except (UsageError, ConfigError) as err:
        print(f"{PROG}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `heft run | head`: the reader is gone, so stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
