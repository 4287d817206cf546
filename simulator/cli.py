"""The simulator package's commands::

    heft run SCENARIO [--transport inprocess|zenoh] [--out FILE] [--plot DIR] [--quiet]
    heft scenario generate SEED [-o FILE]
    heft sim SCENARIO [--team NAME] [--clock lockstep|realtime] [Zenoh options]
    heft demo [--out FILE] [--plot DIR] [--quiet]
    heft baseline RECORDING [--velocity-noise S] [--force-noise S] [--no-friction] [--out FILE]

(Its benchmarks, ``heft bench accuracy|generated|zenoh|noise|sweep|changes``, are in
:mod:`simulator.bench.cli`.)

Exit status (docs/cli.md): 0 success (``run``: every robot converged), 1 ``run`` did
not converge (the last line and the results' ``reason`` say why), 2 bad input (a one-line
``heft: error: ...`` on stderr), 130 interrupted (SIGINT, SIGTERM or SIGHUP).

Building the parser imports nothing heavy (no pymunk, numpy or matplotlib): the handlers
import what they run.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import threading
import time
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from agent.platform.cli_helpers import (
    PROG,
    HelpFormatter,
    UsageError,
    add_zenoh_options,
    check_port,
    check_writable,
    setup_logging,
    write_text,
    zenoh_settings,
)
from agent.platform.process import StopSignals
from agent.platform.protocol import CLOCKS, Phase
from agent.platform.zenoh_session import DEFAULT_ROUTER, ZenohSettings
from simulator.lockstep import INTERRUPTED
from simulator.scenario import (
    PAPER_SCENARIO,
    Scenario,
    ScenarioError,
    load_scenario,
    scenario_to_toml,
)

if TYPE_CHECKING:
    from agent.algorithm.agent import Agent
    from agent.platform.faults import FaultSettings
    from simulator.can_drivers import CanLink
    from simulator.inprocess import Progress, RunOutcome

PROGRESS_EVERY_S = 5.0
"""Simulated seconds between two progress lines of ``heft run``."""


def load_scenario_argument(path: str) -> Scenario:
    """The scenario at ``path``; a :class:`UsageError` naming the problem if it is invalid."""
    try:
        return load_scenario(path)
    except ScenarioError as err:
        raise UsageError(str(err)) from None


# ------------------------------------------------------------------------------ progress lines
def _team_phase(agents: Sequence[Agent]) -> str:
    """``'inertia'`` when every robot is in that phase, else e.g. ``'excite: 1,2; inertia: 3'``."""
    robots: dict[str, list[int]] = defaultdict(list)
    for agent in agents:
        robots[Phase(agent.phase).label].append(agent.robot)
    if len(robots) == 1:
        return next(iter(robots))
    return "; ".join(f"{name}: {','.join(map(str, ids))}" for name, ids in robots.items())


def _progress_printer(started: float, stream: TextIO) -> Progress:
    """A :data:`simulator.inprocess.Progress` callback printing one line per call to ``stream``."""

    def report(tick: int, time_s: float, agents: list[Agent]) -> None:
        if tick == 0:
            return
        wall = time.perf_counter() - started
        print(
            f"{PROG}: t = {time_s:6.1f} s simulated, phase {_team_phase(agents)},"
            f" {wall:.2f} s wall",
            file=stream,
            flush=True,
        )

    return report


# ------------------------------------------------------------------------------ heft run
EXIT_INTERRUPTED = 130
"""Ctrl-C, SIGTERM and SIGHUP alike (128 + SIGINT, as shells report an interrupted command)."""


def cmd_run(args: argparse.Namespace) -> int:
    """``heft run``: simulate a scenario; write the results JSON (whatever the verdict, and on
    SIGINT, SIGTERM or SIGHUP), print the table, write the plots, print the verdict last."""
    from simulator.results import failed_results_dict, format_table, results_dict

    # From here on a signal only asks the run to stop: over Zenoh the launcher stops its
    # processes and returns what it recorded; in one process the loop is interrupted where it
    # is (see _run). Either way the results are written.
    with StopSignals().handle() as stop:
        scenario = load_scenario_argument(args.scenario)
        if args.transport is None:  # --can alone runs the processes, as on robots
            args.transport = "zenoh" if args.can else "inprocess"
        link = _can_link(args)
        faults = _faults(args, scenario)
        out = None if args.out is None else Path(args.out)
        if out is not None:
            check_writable(out)  # never creates the file: it appears, whole, at the end
        if args.plot is not None:
            check_writable(Path(args.plot), directory=True)
        companion = _companion(args, scenario)  # the dashboard's URL is printed before the run
        started = time.perf_counter()
        if not args.quiet:
            print(f"{PROG}: running {scenario.name!r} ({scenario.n} robots)", file=sys.stderr)
        outcome: RunOutcome | None = None
        try:
            on_ready = None if companion is None else companion.on_ready
            outcome = _run(args, scenario, faults, started, stop, link, on_ready)
            reason, detail = outcome.reason, outcome.detail
            rejections = outcome.transport.get("rejections")
        except _NothingRecorded as failed:
            reason, detail, rejections = failed.reason, failed.detail, failed.rejections
        if reason == INTERRUPTED:
            detail = f"stopped by {stop.received.name if stop.received else 'KeyboardInterrupt'}"
        if outcome is not None:
            outcome.detail = detail
            document = results_dict(outcome)
        else:
            wall = time.perf_counter() - started
            document = failed_results_dict(scenario, reason, detail, wall, rejections)
        if out is not None:
            write_text(out, json.dumps(document, indent=2, allow_nan=False) + "\n")
        if outcome is not None:
            print(format_table(outcome))
        if out is not None:
            print(f"wrote results to {out}")
        if outcome is not None and args.plot is not None and reason != INTERRUPTED:
            try:
                with stop.raising():  # the plots take seconds: a signal cuts them short
                    for path in _write_plots(outcome, Path(args.plot)):
                        print(f"wrote plot {path}")
            except KeyboardInterrupt:
                reason, detail = INTERRUPTED, f"plots cut short by {stop.received.name}"
        if companion is not None:
            _after_the_run(args, companion, stop.event)
    return _say_verdict(reason, detail, out, recorded=outcome is not None)


def _companion(args: argparse.Namespace, scenario: Scenario):
    """The run's recording (over Zenoh, unless ``--no-record``) and, for ``heft demo``, its
    dashboard (with ``--foxglove``, serving the run live to Foxglove too), served from now on;
    None when there is neither."""
    dashboard = getattr(args, "dashboard", False)
    if args.dashboard_port is not None:
        check_port("--dashboard-port", args.dashboard_port)
    record = None
    if args.transport == "zenoh" and not args.no_record:
        from dashboard.companion import default_recording

        record = Path(args.record) if args.record else default_recording(scenario.name)
        check_writable(record)
    elif args.record is not None:
        raise UsageError("--record needs --transport zenoh (a run in one process sends nothing)")
    if record is None and not dashboard:
        return None
    from agent.platform.zenoh_session import SessionError
    from dashboard.companion import RunCompanion
    from dashboard.server import ServeError

    try:
        return RunCompanion.open(
            record,
            dashboard,
            port=args.dashboard_port,
            stream=sys.stdout,
            foxglove=getattr(args, "foxglove", False),
        )
    except ServeError as err:  # a busy port: exit status 4, as an unreachable router
        raise SessionError(str(err)) from None


def _after_the_run(args: argparse.Namespace, companion, stop: threading.Event) -> None:
    """Close the recording; ``heft demo`` then keeps its dashboard up until Ctrl-C (unless
    ``--no-wait``, or the run itself was interrupted)."""
    try:
        companion.run_over()
        if companion.record is not None:
            print(f"recorded the run to {companion.record}")
        if companion.display is not None and not args.no_wait and not stop.is_set():
            print(
                f"{PROG}: the dashboard stays at {companion.display.url} (replay the run"
                " there); Ctrl-C to stop",
                file=sys.stderr,
                flush=True,
            )
            companion.serve_until(stop)
    finally:
        companion.close()


def _say_verdict(reason: str, detail: str, out: Path | None, recorded: bool) -> int:
    """The verdict as the last line on stderr; the exit status (docs/cli.md: Exit status)."""
    if not reason:
        return 0
    if reason == INTERRUPTED:
        kept = "the results recorded so far are kept" if recorded else "nothing was recorded"
        where = f" in {out}" if out is not None and recorded else ""
        print(f"{PROG}: {reason}: {detail}; {kept}{where}", file=sys.stderr)
        return EXIT_INTERRUPTED
    print(f"{PROG}: not converged: {reason}: {detail}", file=sys.stderr)
    return 1


class _NothingRecorded(Exception):
    """A run that ended before recording any instant (the verdict says why)."""

    def __init__(self, reason: str, detail: str, rejections: dict | None = None):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail
        self.rejections = rejections


def _run(
    args: argparse.Namespace,
    scenario: Scenario,
    faults: FaultSettings,
    started: float,
    stop: StopSignals,
    link: CanLink | None = None,
    on_ready=None,
) -> RunOutcome:
    """The run of ``heft run``, in one process or over Zenoh (with ``link``, the robots on
    CAN behind their bridges); :class:`_NothingRecorded` when it recorded nothing. In one
    process ``link`` quantises as CAN does."""
    if args.transport == "zenoh":
        return _run_zenoh(args, scenario, faults, stop.event, link, on_ready)
    if args.transport == "watch":
        return _watch(args, scenario, stop.event)
    from simulator.inprocess import run_inprocess

    progress = None if args.quiet else _progress_printer(started, sys.stderr)
    every = max(1, round(PROGRESS_EVERY_S / scenario.period_s))
    transport = None
    if faults.active:
        from agent.platform.faults import FaultyTransport
        from agent.platform.transport import InMemoryTransport

        transport = FaultyTransport(InMemoryTransport(scenario.n, scenario.edges), faults)
    try:
        with stop.raising():
            return run_inprocess(
                scenario,
                transport=transport,
                progress=progress,
                progress_every=every,
                link="memory" if link is None else "can",
            )
    except KeyboardInterrupt:  # before its first instant: nothing to keep
        raise _NothingRecorded(INTERRUPTED, "") from None


def _faults(args: argparse.Namespace, scenario: Scenario) -> FaultSettings:
    from agent.platform.faults import FaultSettings

    if not 0.0 <= args.drop < 1.0:
        raise UsageError(f"--drop: expected a probability in [0, 1), got {args.drop:g}")
    if not 0.0 <= args.delay_ms <= 10_000.0:
        raise UsageError(f"--delay-ms: expected a number in [0, 10000], got {args.delay_ms:g}")
    if args.delay_ms and args.transport != "zenoh":
        raise UsageError("--delay-ms needs --transport zenoh (in one process time is simulated)")
    if args.transport == "inprocess" and args.clock == "realtime":
        raise UsageError(
            "--clock realtime needs --transport zenoh (in one process the robots take turns:"
            " lockstep)"
        )
    return FaultSettings(drop=args.drop, delay_s=args.delay_ms / 1000.0, seed=scenario.run.seed)


def _run_zenoh(
    args: argparse.Namespace,
    scenario: Scenario,
    faults: FaultSettings,
    stop: threading.Event,
    link: CanLink | None = None,
    on_ready=None,
) -> RunOutcome:
    """The run over Zenoh (:func:`simulator.launcher.run_zenoh`), with ``link`` over CAN
    too; it stops once ``stop`` is set. :class:`_NothingRecorded` when it recorded nothing."""
    from simulator.launcher import RunFailed, run_zenoh

    def report(time_s: float, phases: str) -> None:
        if not args.quiet:
            print(
                f"{PROG}: t = {time_s:6.1f} s simulated, phases so far: {phases}",
                file=sys.stderr,
                flush=True,
            )

    stream = sys.stderr if not args.quiet else open(os.devnull, "w")  # noqa: SIM115
    try:
        return run_zenoh(
            scenario,
            clock=args.clock,
            faults=faults,
            progress=report,
            log_stream=stream,
            stop=stop,
            can=link,
            on_ready=on_ready,
        )
    except RunFailed as failed:
        rejections = failed.transport.get("rejections")
        raise _NothingRecorded(failed.reason, failed.detail, rejections) from None
    finally:
        if stream is not sys.stderr:
            stream.close()


def _watch(args: argparse.Namespace, scenario: Scenario, stop: threading.Event) -> RunOutcome:
    """``heft watch``'s run: a team that runs elsewhere, followed
    (:func:`simulator.watch.watch_team`)."""
    from agent.platform.config import Bound
    from agent.platform.protocol import Keys
    from simulator.launcher import RunFailed
    from simulator.watch import watch_team

    Bound(0, 3600, "s").check("--rejoin-s", args.rejoin_s)
    Bound(0, 3600, "s", open_low=True).check("--start-timeout", args.start_timeout)
    team = args.team or scenario.name
    try:
        Keys(team)
    except ValueError as err:
        raise UsageError(f"--team: {err}") from None
    settings = zenoh_settings(args, ZenohSettings(mode="client", connect=(DEFAULT_ROUTER,)))
    setup_logging(args)

    def report(time_s: float, phases: str) -> None:
        if not args.quiet:
            print(
                f"{PROG}: t = {time_s:6.1f} s simulated, phases so far: {phases}",
                file=sys.stderr,
                flush=True,
            )

    try:
        return watch_team(
            scenario,
            team,
            settings,
            rejoin_s=args.rejoin_s,
            start_timeout_s=args.start_timeout,
            stop_when_done=args.stop,
            progress=report,
            stop=stop,
        )
    except RunFailed as failed:
        rejections = failed.transport.get("rejections")
        raise _NothingRecorded(failed.reason, failed.detail, rejections) from None


def _write_plots(outcome: RunOutcome, directory: Path) -> list[Path]:
    """Write the figures of ``outcome`` into ``directory``; a :class:`UsageError` on failure."""
    from simulator.plots import write_plots

    try:
        return write_plots(outcome, directory)
    except OSError as err:
        raise UsageError(f"{directory}: cannot write the plots ({err.strerror or err})") from None


# ------------------------------------------------------------------------------ heft demo
def cmd_demo(args: argparse.Namespace) -> int:
    """``heft demo``: ``heft run`` of the paper's scenario over Zenoh on the wall clock."""
    args.scenario = str(PAPER_SCENARIO)
    args.transport = "zenoh"
    args.can = False
    args.can_interface = args.can_channel = None
    args.clock = "realtime"
    args.drop = 0.0
    args.delay_ms = 0.0
    args.dashboard = True
    return cmd_run(args)


# ------------------------------------------------------------------------------ heft scenario
def cmd_generate(args: argparse.Namespace) -> int:
    """``heft scenario generate``: write the random scenario of a seed as TOML."""
    from agent.platform.config import MAX_SEED, Bound
    from simulator.generate import generate_scenario

    Bound(0, MAX_SEED).check("SEED", args.seed)
    text = scenario_to_toml(generate_scenario(args.seed))
    if args.output is None:
        sys.stdout.write(text)
    else:
        write_text(Path(args.output), text)
        print(f"wrote scenario {args.output}", file=sys.stderr)
    return 0


# ------------------------------------------------------------------------------ heft sim
def cmd_sim(args: argparse.Namespace) -> int:
    """``heft sim``: the plant of a scenario as a process on Zenoh."""
    import dataclasses

    from agent.platform.config import Bound, bounds
    from agent.platform.heft import NETWORK_UNAVAILABLE
    from agent.platform.protocol import Keys
    from simulator.can_drivers import CanBusError
    from simulator.node import run_plant

    scenario = load_scenario_argument(args.scenario)
    Bound(0, 3600, "s", open_low=True).check("--start-timeout", args.start_timeout)  # NaN too
    base = ZenohSettings(mode="client", connect=(DEFAULT_ROUTER,))
    if args.connect_timeout_ms is not None:
        timeout = bounds(ZenohSettings)["connect_timeout_ms"]
        timeout.check("--connect-timeout-ms", args.connect_timeout_ms)
        base = dataclasses.replace(base, connect_timeout_ms=args.connect_timeout_ms)
    team = args.team or scenario.name
    try:
        Keys(team)
    except ValueError as err:
        source = "--team" if args.team else f"{args.scenario}: name (the default --team)"
        raise UsageError(f"{source}: {err}") from None
    settings = zenoh_settings(args, base)
    link = _can_link(args)
    setup_logging(args)
    try:
        return run_plant(
            scenario,
            team,
            args.clock,
            settings,
            StopSignals().handle().event,
            args.start_timeout,
            link,
        )
    except CanBusError as err:  # no such bus (yet): like an unreachable router, may pass
        print(f"{PROG}: error: {err}", file=sys.stderr)
        return NETWORK_UNAVAILABLE


def _can_link(args: argparse.Namespace) -> CanLink | None:
    """The buses of ``--can`` (``--can-interface``, ``--can-channel``), or None without it."""
    if not args.can:
        for option in ("can_interface", "can_channel"):
            if getattr(args, option) is not None:
                raise UsageError(f"--{option.replace('_', '-')} needs --can")
        return None
    from agent.platform.config import ConfigError
    from simulator.can_drivers import CanLink

    given = {"interface": args.can_interface, "channel": args.can_channel}
    link = CanLink(**{key: value for key, value in given.items() if value is not None})
    try:
        link.validate("--can")
    except ConfigError as err:
        raise UsageError(str(err)) from None
    return link


def _add_can_options(parser: argparse.ArgumentParser, what: str) -> None:
    parser.add_argument("--can", action="store_true", help=what)
    parser.add_argument(
        "--can-interface",
        metavar="NAME",
        help="with --can: the python-can interface of the buses (default: socketcan; virtual"
        " only within one process)",
    )
    parser.add_argument(
        "--can-channel",
        metavar="TEMPLATE",
        help="with --can: robot i's bus, {robot} standing for i; without {robot} every robot"
        " shares one bus (default: vcan{robot})",
    )


# ------------------------------------------------------------------------------ the parsers
def register(commands: argparse._SubParsersAction) -> None:
    """Add ``heft run``, ``watch``, ``scenario``, ``sim``, ``demo`` and ``baseline`` (entry
    point of the group ``heft.commands``)."""
    _add_run(commands)
    _add_watch(commands)
    _add_scenario(commands)
    _add_sim(commands)
    _add_demo(commands)
    _add_baseline(commands)


def _add_run(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser(
        "run",
        help="simulate a scenario and print the estimates against the truth",
        formatter_class=HelpFormatter,
        description=(
            "Simulate SCENARIO: one agent per robot and a pymunk plant, until every robot has\n"
            "finished the paper's seven steps or the scenario's run.max_time_s. By default in\n"
            "this process over the in-memory transport; with --transport zenoh as separate\n"
            "processes (a Zenoh router, the plant, one agent per robot) on 127.0.0.1. Prints\n"
            "a table of every robot's estimates (m, J, contact-to-COM offset; the floor's\n"
            "friction when the robots estimate it) and their errors against the ground truth,\n"
            "when each step started and ended, and the 95 % intervals the robots published.\n\n"
            "With --can the robots are AGVs on CAN: the plant plays their drivers on one bus\n"
            "per robot and an AGV bridge per robot (heft bridge) links each to its agent;\n"
            "--can implies --transport zenoh, and --transport inprocess --can is its reference\n"
            "in one process (measurements and commands quantised as on the bus).\n\n"
            "Exit status: 0 converged, 1 not converged (out of time, or a robot was lost),\n"
            "2 bad scenario or arguments, 130 interrupted."
        ),
        epilog=(
            "examples:\n"
            "  heft run simulator/scenarios/paper.toml --out results.json --plot plots\n"
            "  heft run simulator/scenarios/paper.toml --transport zenoh --drop 0.1\n"
            "  heft run simulator/scenarios/paper.toml --can --can-channel 'vcan{robot}'"
        ),
    )
    parser.add_argument("scenario", metavar="SCENARIO", help="scenario TOML file")
    parser.add_argument(
        "--transport",
        choices=("inprocess", "zenoh"),
        help="inprocess: one process; zenoh: one process per robot (default: inprocess, or"
        " zenoh with --can)",
    )
    _add_can_options(
        parser, "the robots on CAN, each behind its AGV bridge (a heft bridge per robot)"
    )
    parser.add_argument(
        "--clock",
        choices=CLOCKS,
        default="lockstep",
        help="with zenoh: lockstep (deterministic, faster than real time) or realtime"
        " (the wall clock) (default: lockstep)",
    )
    parser.add_argument(
        "--drop",
        type=float,
        default=0.0,
        metavar="P",
        help="probability that a message between agents is lost (default: 0)",
    )
    parser.add_argument(
        "--delay-ms",
        type=float,
        default=0.0,
        metavar="MS",
        help="with zenoh: delay added to every message between agents (default: 0)",
    )
    _add_output_options(parser)
    _add_record_options(parser)
    parser.set_defaults(handler=cmd_run, dashboard=False, dashboard_port=None, no_wait=True)


def _add_watch(commands: argparse._SubParsersAction) -> None:
    from simulator.watch import REJOIN_S, START_TIMEOUT_S

    parser = commands.add_parser(
        "watch",
        help="follow a team that runs on other hosts, as heft run does",
        formatter_class=HelpFormatter,
        description=(
            "Follow a team whose router, plant (heft sim) and agents (heft agent) were started\n"
            "elsewhere, e.g. on several hosts by their units, as the operator: print progress,\n"
            "then the table of every robot's estimates against the plant's truth, as heft run\n"
            "does, and write the results JSON. A halted team is given --rejoin-s to begin\n"
            "again (its lost robots back: a link up again, an agent restarted).\n\n"
            "Exit status: 0 converged, 1 not converged (halted and not begun again, out of\n"
            "time, stalled, nothing heard), 2 bad scenario or arguments, 4 the router does not\n"
            "answer, 130 interrupted."
        ),
        epilog=(
            "example:\n"
            "  heft watch simulator/scenarios/paper.toml --team paper --stop \\\n"
            "      --connect tls/192.168.10.1:7447 --tls-root-ca /etc/heft/tls/ca.pem \\\n"
            "      --tls-certificate /etc/heft/tls/operator.pem \\\n"
            "      --tls-private-key /etc/heft/tls/operator-key.pem"
        ),
    )
    parser.add_argument("scenario", metavar="SCENARIO", help="the team's scenario TOML file")
    parser.add_argument("--team", help="the team's name (default: the scenario's name)")
    parser.add_argument(
        "--rejoin-s",
        type=float,
        default=REJOIN_S,
        metavar="S",
        help=f"how long a halted team is given to begin again, 0 to 3600 (default: {REJOIN_S:g})",
    )
    parser.add_argument(
        "--start-timeout",
        type=float,
        default=START_TIMEOUT_S,
        metavar="S",
        help="give up if nothing is heard of the plant within S seconds, in (0, 3600]"
        f" (default: {START_TIMEOUT_S:g})",
    )
    parser.add_argument(
        "--stop",
        action="store_true",
        help="once the run is over, tell every process of the team to stop (default: no)",
    )
    _add_output_options(parser)
    add_zenoh_options(parser, connect=DEFAULT_ROUTER, listen="none", config="none")
    parser.set_defaults(
        handler=cmd_run,
        transport="watch",
        can=False,
        can_interface=None,
        can_channel=None,
        drop=0.0,
        delay_ms=0.0,
        record=None,
        no_record=True,
        dashboard=False,
        dashboard_port=None,
        no_wait=True,
    )


def _add_output_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--out",
        metavar="FILE",
        help="write the results as JSON (SI units, world frame) to FILE (default: none)",
    )
    parser.add_argument(
        "--plot",
        metavar="DIR",
        help="write the paper's Figs. 4-6 as PNGs into DIR, created if needed (default: none)",
    )
    parser.add_argument(
        "-q",
        "--quiet",
        action="store_true",
        help=f"no progress lines on stderr (default: one every {PROGRESS_EVERY_S:g} simulated s)",
    )


def _add_record_options(parser: argparse.ArgumentParser) -> None:
    group = parser.add_mutually_exclusive_group()
    group.add_argument(
        "--record",
        metavar="FILE",
        help="record the run's Zenoh traffic to this MCAP file (default, over Zenoh:"
        " out/recordings/SCENARIO-DATE-TIME.mcap)",
    )
    group.add_argument("--no-record", action="store_true", help="do not record the run")


def _add_scenario(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser(
        "scenario",
        help="make scenario files",
        formatter_class=HelpFormatter,
        description="Work with scenario files.",
    )
    sub = parser.add_subparsers(dest="scenario_command", metavar="COMMAND", required=True)
    generate = sub.add_parser(
        "generate",
        help="write a random scenario for a seed",
        formatter_class=HelpFormatter,
        description=(
            "Write the random scenario of SEED as TOML: 3-8 robots, a line, ring, star or\n"
            "random graph (seed % 4), a convex or concave load (seed // 4 % 2), random mass,\n"
            "moment, COM, contacts and pose. The same seed always gives the same scenario."
        ),
        epilog="example: heft scenario generate 7 -o load7.toml && heft run load7.toml",
    )
    generate.add_argument("seed", metavar="SEED", type=int, help="integer seed, 0 to 2**63 - 1")
    generate.add_argument(
        "-o", "--output", metavar="FILE", help="write to FILE (default: standard output)"
    )
    generate.set_defaults(handler=cmd_generate)


def _add_sim(commands: argparse._SubParsersAction) -> None:
    sim = commands.add_parser(
        "sim",
        help="the simulated load and robots, as a process on Zenoh",
        formatter_class=HelpFormatter,
        description=(
            "Run the pymunk plant of SCENARIO as a process: it publishes each robot's\n"
            "measurements, applies each robot's force commands and publishes the truth. It\n"
            "starts once every robot's agent is up, and runs until the team is done or\n"
            "SIGINT/SIGTERM/SIGHUP.\n\n"
            "With --can it plays every AGV's driver on CAN instead (bridge/agv.dbc): robot i's\n"
            "Sync, Odometry, AppliedForce and Heartbeat frames on its bus, its ForceCommand\n"
            "frames from its AGV bridge (heft bridge), which talks to the agent; it then also\n"
            "waits for every robot's bridge, and takes no measurement or command over Zenoh.\n\n"
            "Exit status: 0 done or stopped, 1 the agents were not all up within\n"
            "--start-timeout, 2 bad scenario or arguments, 4 no router within\n"
            "--connect-timeout-ms, or a CAN bus that could not be opened."
        ),
        epilog=(
            "examples:\n"
            "  heft sim simulator/scenarios/paper.toml --team paper --clock realtime\n"
            "  heft sim simulator/scenarios/paper.toml --team paper --can --can-channel"
            " 'vcan{robot}'"
        ),
    )
    sim.add_argument("scenario", metavar="SCENARIO", help="scenario TOML file")
    sim.add_argument("--team", help="team name in the key expressions (default: scenario name)")
    sim.add_argument(
        "--clock",
        choices=CLOCKS,
        default="lockstep",
        help="lockstep: wait for every command; realtime: the wall clock (default: lockstep)",
    )
    sim.add_argument(
        "--start-timeout",
        type=float,
        default=30.0,
        metavar="S",
        help="give up if the agents are not all up after S seconds, in (0, 3600] (default: 30)",
    )
    _add_can_options(sim, "play the AGVs' drivers on CAN, behind one AGV bridge per robot")
    add_zenoh_options(sim, connect=DEFAULT_ROUTER, listen="none")
    sim.add_argument(
        "--connect-timeout-ms",
        type=int,
        metavar="MS",
        help="wait this long for the router at start-up, 0 to 600000 ms, then fail with exit"
        " status 4 (default: 15000)",
    )
    sim.set_defaults(handler=cmd_sim)


def _add_demo(commands: argparse._SubParsersAction) -> None:
    demo = commands.add_parser(
        "demo",
        help="the paper's scenario, one process per robot on Zenoh, real time",
        formatter_class=HelpFormatter,
        description=(
            "Run the paper's Sec. VI scenario as it would run on robots: a Zenoh router, the\n"
            "plant and four agent processes on 127.0.0.1, stepping on the wall clock. Prints\n"
            "'dashboard: URL' first: the page shows the team live; prints the table of\n"
            "estimates against truth at the end, then keeps the dashboard up (the run can be\n"
            "replayed there from its recording) until Ctrl-C, unless --no-wait.\n\n"
            "With --foxglove the dashboard also serves the run live to Foxglove, as heft\n"
            "dashboard --foxglove does: it prints 'foxglove: ws://127.0.0.1:PORT/foxglove'\n"
            "next; in Foxglove, open a connection, choose 'Foxglove WebSocket' and give that\n"
            "URL. The topics are a recording's (the scene, the frames, every message of the\n"
            "team), at the team's rate, from the run's start to its end.\n\n"
            "Exit status: 0 converged, 1 not converged, 2 bad arguments, 4 the dashboard's\n"
            "port is busy, 130 interrupted."
        ),
        epilog=(
            "examples:\n"
            "  heft demo --out results.json --plot plots\n"
            "  heft demo --foxglove --dashboard-port 0 --no-record"
        ),
    )
    _add_output_options(demo)
    _add_record_options(demo)
    demo.add_argument(
        "--dashboard-port",
        type=int,
        default=8765,
        metavar="PORT",
        help="serve the dashboard on 127.0.0.1:PORT, 0 for any free one (default: 8765)",
    )
    demo.add_argument(
        "--foxglove",
        action="store_true",
        help="also serve the run live to Foxglove on ws://127.0.0.1:PORT/foxglove (printed)",
    )
    demo.add_argument(
        "--no-wait",
        action="store_true",
        help="exit when the run ends (default: keep the dashboard up until Ctrl-C)",
    )
    demo.set_defaults(handler=cmd_demo)


def _add_baseline(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser(
        "baseline",
        help="the centralized reference: a batch fit of a recording",
        formatter_class=HelpFormatter,
        description=(
            "Fit the load's mass, moment of inertia, every contact's offset to the COM and the\n"
            "floor's friction (while the load turns, a torque tau_c against the turn and a drag\n"
            "kappa v/|omega| on the COM; while it slides without turning, F_s = mu m g against\n"
            "its motion) to all robots' recorded measurements at once (simulator/baseline.py:\n"
            "a batch least-squares fit of the rigid-body model over the longest stretch of\n"
            "ticks at which every robot was measured; the intervals where the load barely moves\n"
            "are left out), with standard deviations; print them against the recorded truth,\n"
            "when there is one. The yardstick of the distributed estimators: what one computer\n"
            "that saw everything could reach.\n\n"
            "Exit status: 0 fitted, 1 the fit did not converge, 2 bad recording or arguments."
        ),
        epilog=(
            "examples:\n"
            "  heft run simulator/scenarios/paper.toml --transport zenoh --record run.mcap\n"
            "  heft baseline run.mcap --velocity-noise 0.01 --force-noise 0.5\n\n"
            "The noise is the sensors' (their datasheets, or the scenario's [sensors]); a\n"
            "noise-free run takes 0 (the weights are then floored at 1e-6 m/s and 1e-4 N)."
        ),
    )
    parser.add_argument("recording", metavar="RECORDING", help="an MCAP recording of a run")
    parser.add_argument(
        "--velocity-noise",
        metavar="S",
        type=float,
        required=True,
        help="σ of the odometry (m/s per axis): the velocities' weight (0 if noise-free)",
    )
    parser.add_argument(
        "--force-noise",
        metavar="S",
        type=float,
        required=True,
        help="σ of the force sensing (N per axis): the forces' weight (0 if noise-free)",
    )
    parser.add_argument(
        "--no-friction",
        action="store_true",
        help="fit the rigid-body model alone, on every interval (a frictionless floor)",
    )
    parser.add_argument("--out", metavar="FILE", help="write the fit as JSON (SI units) to FILE")
    parser.set_defaults(handler=cmd_baseline)


def cmd_baseline(args: argparse.Namespace) -> int:
    from simulator.baseline import fit, read_recording, truth_friction

    for name in ("velocity_noise", "force_noise"):
        value = getattr(args, name)
        if not (0.0 <= value <= 100.0):
            flag = "--" + name.replace("_", "-")
            raise UsageError(f"{flag}: expected a number in [0, 100], got {value!r}")
    if args.out:
        check_writable(Path(args.out))
    try:
        run = read_recording(args.recording)
    except ValueError as err:
        raise UsageError(str(err)) from None
    n = run.velocities.shape[1]
    ticks = run.velocities.shape[0]
    print(
        f"baseline: {ticks} ticks of {n} robots ({ticks * run.period_s:.2f} s from tick"
        f" {run.first_tick}); fitting...",
        file=sys.stderr,
    )
    try:
        result = fit(
            run.velocities,
            run.forces,
            run.period_s,
            args.velocity_noise,
            args.force_noise,
            run.first_tick,
            friction=not args.no_friction,
        )
    except ValueError as err:
        raise UsageError(f"{args.recording}: {err}") from None
    truth = run.truth
    friction = {} if truth is None else truth_friction(truth)
    model = (
        "without friction (--no-friction)"
        if result.friction_torque is None
        else f"friction: turning in {result.turning_intervals}, sliding in"
        f" {result.sliding_intervals} of {result.ticks - 1} intervals (ε = "
        f"{result.omega_epsilon:.2g} rad/s)"
    )
    lines = [
        f"baseline of {args.recording}: {result.ticks} ticks, the load turned"
        f" {result.angle:.2f} rad; weights σ_v {result.velocity_noise:.2g} m/s, σ_f"
        f" {result.force_noise:.2g} N; {model}" + ("" if result.converged else "; NOT CONVERGED"),
        "",
        f"{'':10} {'estimate':>10} {'± (1σ)':>10} {'truth':>10} {'error':>10}",
    ]
    rows = [
        ("m [kg]", result.mass, result.mass_std, None if truth is None else truth.mass),
        ("J [kg m2]", result.moment, result.moment_std, None if truth is None else truth.moment),
    ]
    for label, key in (
        ("τ_c [N m]", "friction_torque"),
        ("κ [N/m]", "spin_drag"),
        ("F_s [N]", "sliding_friction"),
    ):
        value = getattr(result, key)
        if value is not None:
            rows.append((label, value, getattr(result, key + "_std"), friction.get(key)))
    for label, value, std, true in rows:
        if true is None:
            error = "-"
        elif true:
            error = f"{100 * abs(value - true) / true:.3f} %"
        else:  # no friction: how far from 0 in its own standard deviations
            error = f"{abs(value) / std:.2f} σ" if std else "-"
        true_text = "-" if true is None else f"{true:.5f}"
        lines.append(f"{label:10} {value:10.5f} {std:10.2g} {true_text:>10} {error:>10}")
    lines += ["", f"{'robot':>5} {'ctc x [m]':>10} {'ctc y [m]':>10} {'± mm':>8} {'err mm':>8}"]
    errors = {}
    for i, (c, std) in enumerate(zip(result.contact_to_com, result.contact_to_com_std), start=1):
        error = "-"
        if truth is not None:
            t = truth.contact_to_com[i - 1]
            errors[i] = 1000.0 * ((c[0] - t[0]) ** 2 + (c[1] - t[1]) ** 2) ** 0.5
            error = f"{errors[i]:.2f}"
        lines.append(f"{i:5} {c[0]:10.4f} {c[1]:10.4f} {1000 * std:8.2f} {error:>8}")
    lines.append("(ctc = contact_to_com = p_C - p_Ci in the world frame at the last tick fitted)")
    if result.friction_torque is not None:
        lines.append(
            "(τ_c: the floor's friction torque about the COM while the load turns; κ: its drag"
            " on the COM then, -κ v/|ω|; F_s: its friction while the load slides, μ m g)"
        )
    print("\n".join(lines))
    if args.out:
        true = None
        if truth is not None:
            true = {"tick": truth.tick, "mass": truth.mass, "moment": truth.moment}
            true["contact_to_com"] = [list(c) for c in truth.contact_to_com]
            true.update(friction)
        data = {
            "recording": str(args.recording),
            "period_s": run.period_s,
            **dataclasses.asdict(result),
            "truth": true,
        }
        text = json.dumps(_finite_or_null(data), indent=2, allow_nan=False)
        write_text(Path(args.out), text + "\n")
    if not result.converged:
        print(f"{PROG}: the fit did not converge", file=sys.stderr)
        return 1
    return 0


def _finite_or_null(value):
    """``value`` with every NaN or infinity (an undetermined standard deviation) as None,
    for JSON."""
    if isinstance(value, float):
        return value if value - value == 0.0 else None
    if isinstance(value, dict):
        return {k: _finite_or_null(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_or_null(v) for v in value]
    return value
