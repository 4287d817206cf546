"""The bridge's benchmark, a subcommand of ``heft bench`` (entry point of the group
``heft.bench``)::

    heft bench can [--channel NAME] [--seconds S] [--period-ms MS]
                   [--profile force|velocity] [--stiffness N_PER_M]

Building the parser imports nothing heavy (no python-can, cantools or Zenoh): the handler
imports what it runs.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

from agent.platform.cli_helpers import PROG, HelpFormatter, UsageError


def register(benchmarks: argparse._SubParsersAction) -> None:
    """Add ``heft bench can`` (entry point of the group ``heft.bench``)."""
    parser = benchmarks.add_parser(
        "can",
        help="one AGV bridge on vcan: round trip, rate or force tracking, CPU",
        formatter_class=HelpFormatter,
        description=(
            "The AGV bridge's benchmark on a vcan interface (run it in heft vcan -- heft bench\n"
            "can): a router, one heft bridge and an agent that answers at once; round trip CAN\n"
            "-> bridge -> Zenoh -> agent -> Zenoh -> bridge -> CAN p50/p99 by kernel\n"
            "timestamps, the fastest rate forwarded without loss, the bridge's CPU share.\n\n"
            "--profile velocity: the bridge speaks the velocity profile and closes its\n"
            "admittance loop against a simulated base pushing a load through a compliant\n"
            "contact with a force/torque sensor in it (--stiffness), played in lockstep by this\n"
            "process, while the agent pushes (5 N, 1 s each way); it reports the force\n"
            "tracking error (RMS and p95 as a fraction of the commanded force), the round trip\n"
            "and the CPU shares.\n\n"
            "Goals: the round trip's p99 below 5 ms; velocity: the force tracking's p95 at\n"
            "most 5 % of the commanded force.\n\n"
            "Exit status: 0 every goal met, 1 one not met or the benchmark could not measure,\n"
            "2 bad arguments or no such vcan interface, 130 interrupted."
        ),
        epilog=(
            "examples:\n"
            "  heft vcan -- heft bench can --seconds 60\n"
            "  heft vcan -- heft bench can --profile velocity --stiffness 10000"
        ),
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
    parser.add_argument(
        "--profile",
        choices=("force", "velocity"),
        default="force",
        help="the AGV protocol's profile the bridge speaks (default: force)",
    )
    parser.add_argument(
        "--stiffness",
        type=float,
        metavar="N_PER_M",
        help="velocity: the contact's stiffness, 1000 to 10000 N/m (default: 3000)",
    )
    parser.set_defaults(handler=cmd_can)


def cmd_can(args: argparse.Namespace) -> int:
    """``heft bench can``: the AGV bridge's round trip, forwarding rate (force profile) or
    force tracking (velocity profile) and CPU on vcan."""
    from agent.platform.config import Bound, ConfigError
    from bridge.bench.can import (
        GOALS,
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
    if args.stiffness is not None:
        if args.profile != "velocity":
            raise UsageError("--stiffness: only with --profile velocity")
        Bound(1000, 10_000, "N/m").check("--stiffness", args.stiffness)
    problem = vcan_problem(channel)
    if problem is not None:
        raise UsageError(
            f"bench can needs the vcan interface {channel} ({problem}); run it as:"
            " heft vcan -- heft bench can"
        )
    if args.profile == "velocity":
        return _velocity(channel, seconds, period_ms / 1000, args.stiffness)
    settings = CanBenchSettings(channel=channel, seconds=seconds, period_s=period_ms / 1000)
    return _measure(run_can_benchmark, settings, format_can_report, GOALS, figures)


def _measure(run, settings, text, goals, figures) -> int:
    """Run the benchmark ``run`` with ``settings``, print its report (``text``) and the goals'
    verdicts; the exit status (1 if it could not measure)."""
    from agent.platform.goals import conclude
    from bridge.bench.can import BenchError

    try:
        report = run(settings)
    except BenchError as err:
        print(f"{PROG}: error: {err}", file=sys.stderr)
        return 1
    print(text(report))
    return conclude(goals, figures(report))


def _velocity(channel: str, seconds: float, period_s: float, stiffness: float | None) -> int:
    """``heft bench can --profile velocity`` (its options checked)."""
    from bridge.bench.velocity import (
        GOALS,
        VelocityBenchSettings,
        figures,
        format_velocity_report,
        run_velocity_benchmark,
    )

    settings = VelocityBenchSettings(channel, seconds, period_s)
    if stiffness is not None:
        settings = dataclasses.replace(settings, stiffness=stiffness)
    return _measure(run_velocity_benchmark, settings, format_velocity_report, GOALS, figures)
