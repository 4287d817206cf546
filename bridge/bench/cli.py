"""The bridge's benchmark, a subcommand of ``heft bench`` (entry point of the group
``heft.bench``)::

    heft bench can [--channel NAME] [--seconds S] [--period-ms MS]

Building the parser imports nothing heavy (no python-can, cantools or Zenoh): the handler
imports what it runs.
"""

from __future__ import annotations

import argparse
import sys

from agent.platform.cli_helpers import PROG, HelpFormatter, UsageError


def register(benchmarks: argparse._SubParsersAction) -> None:
    """Add ``heft bench can`` (entry point of the group ``heft.bench``)."""
    parser = benchmarks.add_parser(
        "can",
        help="one AGV bridge on vcan: round trip, forwarding rate, CPU",
        formatter_class=HelpFormatter,
        description=(
            "The AGV bridge's benchmark on a vcan interface (run it in heft vcan -- heft bench\n"
            "can): a router, one heft bridge and an agent that answers at once; round trip CAN\n"
            "-> bridge -> Zenoh -> agent -> Zenoh -> bridge -> CAN p50/p99 by kernel\n"
            "timestamps, the fastest rate forwarded without loss, the bridge's CPU share.\n\n"
            "Goal: the round trip's p99 below 5 ms.\n\n"
            "Exit status: 0 every goal met, 1 one not met or the benchmark could not measure,\n"
            "2 bad arguments or no such vcan interface, 130 interrupted."
        ),
        epilog="example: heft vcan -- heft bench can --seconds 60",
    )
    parser.add_argument("--channel", metavar="NAME", help="the vcan interface (default: vcan8)")
    parser.add_argument(
        "--seconds",
        type=float,
        metavar="S",
        help="length of the round-trip phase, 1 to 3600 (default: 20)",
    )
    parser.add_argument(
        "--period-ms",
        type=float,
        metavar="MS",
        help="the tick period of the round-trip phase, 1 to 100 (default: 10)",
    )
    parser.set_defaults(handler=cmd_can)


def cmd_can(args: argparse.Namespace) -> int:
    """``heft bench can``: the AGV bridge's round trip, forwarding rate and CPU on vcan."""
    from agent.platform.config import Bound, ConfigError
    from agent.platform.goals import conclude
    from bridge.bench.can import (
        GOALS,
        BenchError,
        CanBenchSettings,
        figures,
        format_can_report,
        run_can_benchmark,
        vcan_problem,
    )
    from bridge.config import CanSettings

    default = CanBenchSettings()
    channel = args.channel or default.channel
    try:
        CanSettings(channel=channel).validate("--channel")
    except ConfigError as err:
        raise UsageError(str(err).replace("--channel.channel", "--channel")) from None
    seconds = default.seconds if args.seconds is None else args.seconds
    period_ms = 1000 * default.period_s if args.period_ms is None else args.period_ms
    Bound(1, 3600, "s").check("--seconds", seconds)
    Bound(1, 100, "ms").check("--period-ms", period_ms)
    problem = vcan_problem(channel)
    if problem is not None:
        raise UsageError(
            f"bench can needs the vcan interface {channel} ({problem}); run it as:"
            " heft vcan -- heft bench can"
        )
    settings = CanBenchSettings(channel=channel, seconds=seconds, period_s=period_ms / 1000)
    try:
        report = run_can_benchmark(settings)
    except BenchError as err:
        print(f"{PROG}: error: {err}", file=sys.stderr)
        return 1
    print(format_can_report(report))
    return conclude(GOALS, figures(report))
