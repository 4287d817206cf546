"""The ``heft`` command (also ``python -m agent``): one entry point for every package's commands.

A package adds its subcommands by declaring an entry point of the group :data:`GROUP` in
``pyproject.toml``, without touching the other packages::

    [project.entry-points."heft.commands"]
    simulator = "simulator.cli:register"

The entry point names a function ``register(commands)`` that adds the package's subcommands
to ``commands`` (the ``argparse`` subparsers of ``heft``), each with
``formatter_class=HelpFormatter`` and ``set_defaults(handler=...)``
(:mod:`agent.platform.cli_helpers`). A handler takes the parsed arguments and returns the exit
status; it raises :class:`~agent.platform.cli_helpers.UsageError` for bad input, reported here as
one ``heft: error: ...`` line with exit status 2. ``register`` should import only what building
the parser needs, so that ``heft agent`` on a robot does not load the simulator's libraries.

The benchmarks are subcommands of ``heft bench``, registered alike by each package that owns
some, in the group :data:`BENCH_GROUP`, from its ``bench`` sub-package::

    [project.entry-points."heft.bench"]
    simulator = "simulator.bench.cli:register"

``register(benchmarks)`` adds them to ``benchmarks`` (the subparsers of ``heft bench``). A
benchmark's handler returns 0 when every goal it checks is met, 1 when one is not
(:mod:`agent.platform.goals`).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from importlib import metadata

from agent.platform import zenoh_log
from agent.platform.cli_helpers import PROG, HelpFormatter, UsageError
from agent.platform.config import ConfigError
from agent.platform.zenoh_session import SessionError

NETWORK_UNAVAILABLE = 4
"""Exit status when Zenoh cannot listen or connect (a busy port, no router in time): unlike a
bad config (2) it may pass, so service units restart on it."""

GROUP = "heft.commands"
"""The entry-point group of ``register(commands)`` functions."""
BENCH_GROUP = "heft.bench"
"""The entry-point group of ``register(benchmarks)`` functions (``heft bench``'s)."""


def _version() -> str:
    try:
        return metadata.version("heft-hil")
    except metadata.PackageNotFoundError:  # pragma: no cover - running from a bare checkout
        return "unknown"


class _Subcommand(argparse.ArgumentParser):
    """The parser of a subcommand (``heft run``, ``heft bench noise``): an argument it does not
    know is its own error, said with its own usage (``heft bench noise: error: unrecognized
    arguments: --plot x``), not left to ``heft``'s, which cannot say whose option it is not."""

    def parse_known_args(self, args=None, namespace=None):
        namespace, extras = super().parse_known_args(args, namespace)
        if extras:
            self.error(f"unrecognized arguments: {' '.join(extras)}")
        return namespace, extras


def _register(group: str, what: str, subparsers: argparse._SubParsersAction) -> None:
    """Let every installed package add its subcommands of ``group`` (``what`` they are, in
    messages) to ``subparsers``, in the order of the entry points' names.

    A package whose subcommands cannot be imported (an optional dependency missing) is left
    out with a warning, so that the other packages' still work.
    """
    entries = sorted(metadata.entry_points(group=group), key=lambda e: e.name)
    if not entries:
        print(
            f"{PROG}: warning: no {what} installed (entry points {group!r});"
            " install the project: pip install -e .",
            file=sys.stderr,
        )
    for entry in entries:
        try:
            register = entry.load()
        except ImportError as err:
            print(
                f"{PROG}: warning: the {entry.name} {what} are unavailable ({err})",
                file=sys.stderr,
            )
            continue
        register(subparsers)


def _add_bench(commands: argparse._SubParsersAction) -> None:
    """``heft bench``: every installed package's benchmarks (:data:`BENCH_GROUP`) as its
    subcommands; without one, its help and exit status 2."""
    parser = commands.add_parser(
        "bench",
        help="the benchmarks: accuracy, noise, speed, CAN bridge, dashboard",
        formatter_class=HelpFormatter,
        description=(
            "Run one benchmark and print its report. A benchmark that checks goals prints,\n"
            "last, each goal's measured figure and whether it was met.\n\n"
            "Exit status: 0 every goal met (or the benchmark checks none), 1 a goal not met\n"
            "or the benchmark could not measure, 2 bad arguments, 130 interrupted."
        ),
        epilog="Run 'heft bench BENCHMARK --help' for a benchmark's options.",
    )
    benchmarks = parser.add_subparsers(dest="benchmark", title="benchmarks", metavar="BENCHMARK")
    _register(BENCH_GROUP, "benchmarks", benchmarks)

    def no_benchmark(args: argparse.Namespace) -> int:
        parser.print_help(sys.stderr)
        return 2

    parser.set_defaults(handler=no_benchmark)


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
    commands = parser.add_subparsers(
        dest="command", title="commands", metavar="COMMAND", parser_class=_Subcommand
    )
    _register(GROUP, "commands", commands)
    _add_bench(commands)
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
