"""The dashboard package's commands::

    heft dashboard [--team T [--foxglove]] [--connect ENDPOINT] [--host H] [--port P]
                   [--token TOKEN] [--replay FILE [--speed X] [--paused]]
    heft record --team T -o FILE [--duration S] [Zenoh options]
    heft record --repair FILE

Both run until SIGINT, SIGTERM or SIGHUP (exit status 0); bad input is one ``heft: error:``
line and exit status 2; a busy port or an unreachable router is exit status 4.

The load's outline and the graph come from the plant
(:class:`~agent.platform.protocol.LoadGeometry`), live or recorded; ``--scenario``, which once
gave them, is refused with a line that says so.

Building the parser imports nothing of FastAPI, uvicorn or MCAP: the handlers do.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
from pathlib import Path

from agent.platform.cli_helpers import (
    HelpFormatter,
    UsageError,
    add_zenoh_options,
    check_port,
    check_writable,
    setup_logging,
    zenoh_settings,
)
from agent.platform.zenoh_session import DEFAULT_ROUTER, ZenohSettings
from dashboard.display import DEFAULT_PORT

TOKEN_ENV = "HEFT_DASHBOARD_TOKEN"
MAX_SPEED = 1000.0
LOG = logging.getLogger("heft.dashboard")


def _keys(team: str | None, option: str = "--team"):
    from agent.platform.protocol import Keys

    if team is None:
        return None
    try:
        return Keys(team)
    except ValueError as err:
        raise UsageError(f"{option}: {err}") from None


def _no_scenario(args: argparse.Namespace) -> None:
    """``--scenario`` is no longer taken: say where the outline comes from now."""
    if args.scenario is not None:
        raise UsageError(
            "--scenario: no longer needed: the plant (heft sim, heft run) publishes the load's"
            " outline and the graph, and a recording keeps them"
        )


def _speed(value: str) -> float:
    """``--speed``: a factor in [0.01, 1000], or ``max`` (0: as fast as possible)."""
    if value == "max":
        return 0.0
    try:
        speed = float(value)
    except ValueError:
        raise UsageError(f"--speed: expected a number or 'max', got {value!r}") from None
    if not (math.isfinite(speed) and 0.01 <= speed <= MAX_SPEED):
        raise UsageError(f"--speed: expected a factor in [0.01, 1000] or 'max', got {value}")
    return speed


# ------------------------------------------------------------------------------ heft dashboard
def cmd_dashboard(args: argparse.Namespace) -> int:
    """``heft dashboard``: serve the page for a live team or a recording until a signal."""
    from agent.platform.process import StopSignals
    from dashboard.display import Display
    from dashboard.server import ServeError, is_loopback

    token = args.token or os.environ.get(TOKEN_ENV) or None
    if not is_loopback(args.host) and token is None:
        raise UsageError(
            f"--host {args.host}: listening beyond this machine needs a token (--token or"
            f" {TOKEN_ENV})"
        )
    check_port("--port", args.port)
    _no_scenario(args)
    if args.replay is None and args.team is None:
        raise UsageError("--team: needed to watch a live team (or give --replay FILE)")
    speed = 1.0
    if args.replay is not None:
        from dashboard.replay import Recording, RecordingError

        if args.team is not None or args.connect:
            raise UsageError("--replay plays a recording: --team and --connect do not apply")
        if args.foxglove:
            raise UsageError(
                "--foxglove serves a live team: open the recording itself in Foxglove (it holds"
                " the same topics)"
            )
        if args.speed is not None:
            speed = _speed(args.speed)
        if not Path(args.replay).is_file():
            raise UsageError(f"--replay: {args.replay}: no such file")
        try:
            Recording(args.replay).header()
        except RecordingError as err:
            raise UsageError(f"--replay: {err}") from None
    elif args.speed is not None or args.paused:
        raise UsageError("--speed and --paused need --replay FILE")
    keys = _keys(args.team)
    settings = None
    if args.replay is None:
        settings = zenoh_settings(args, ZenohSettings(mode="client", connect=(DEFAULT_ROUTER,)))
    setup_logging(args)
    try:
        display = Display.open(
            team=None if keys is None else keys.team,
            host=args.host,
            port=args.port,
            token=token,
            foxglove=args.foxglove,
        )
    except ServeError as err:
        raise _network_error(str(err)) from None
    stop = StopSignals().handle().event
    try:
        if args.replay is not None:
            display.hub.replay(Path(args.replay), speed=speed, paused=args.paused)
        else:
            display.watch(settings)
        print(f"dashboard: {display.url}", flush=True)
        if display.foxglove_url is not None:
            print(f"foxglove: {display.foxglove_url}", flush=True)
        stop.wait()
    finally:
        display.close()
    return 0


def _network_error(message: str) -> Exception:
    """A busy port: exit status 4, as an unreachable router is."""
    from agent.platform.zenoh_session import SessionError

    return SessionError(message)


# ------------------------------------------------------------------------------ heft record
def cmd_record(args: argparse.Namespace) -> int:
    """``heft record``: write a team's traffic to MCAP until a signal or ``--duration``; or,
    with ``--repair``, make a cut recording whole."""
    from agent.platform.process import StopSignals
    from dashboard.display import TeamRecording

    if args.repair is not None:
        return _repair(args)
    for option, value in (("--team", args.team), ("-o/--output", args.output)):
        if value is None:
            raise UsageError(f"{option}: needed to record (or give --repair FILE)")
    keys = _keys(args.team)
    output = Path(args.output)
    check_writable(output)
    if args.duration is not None and not (0 < args.duration <= 7 * 24 * 3600):
        raise UsageError(f"--duration: expected (0, 604800] s, got {args.duration:g}")
    _no_scenario(args)
    settings = zenoh_settings(args, ZenohSettings(mode="client", connect=(DEFAULT_ROUTER,)))
    setup_logging(args)
    stop = StopSignals().handle().event
    try:
        recording = TeamRecording.open(output, keys.team, settings)
    except BlockingIOError as err:
        raise UsageError(f"-o: {err}") from None
    LOG.info("recording team %r to %s", keys.team, output)
    try:
        stop.wait(args.duration)
    finally:
        recording.close()
    LOG.info("recorded %d messages to %s", recording.recorder.messages, output)
    return 0


def _repair(args: argparse.Namespace) -> int:
    """``heft record --repair FILE``: rewrite a cut recording into a complete one."""
    from dashboard.repair import repair
    from dashboard.replay import RecordingError

    options = (("--team", args.team), ("-o", args.output), ("--duration", args.duration))
    given = [option for option, value in options if value is not None]
    if args.connect:
        given.append("--connect")
    if given:
        apply = "does not apply" if len(given) == 1 else "do not apply"
        raise UsageError(f"--repair rewrites a file: {', '.join(given)} {apply}")
    if not Path(args.repair).is_file():
        raise UsageError(f"--repair: {args.repair}: no such file")
    try:
        done = repair(args.repair)
    except RecordingError as err:
        raise UsageError(f"--repair: {err}") from None
    messages = f"{done.messages} message{'' if done.messages == 1 else 's'}"
    if done.cut is None:
        print(f"{done.path}: complete ({messages}), nothing to repair")
    else:
        print(f"{done.path}: repaired, {messages} kept ({done.cut})")
    return 0


# ------------------------------------------------------------------------------ the parsers
def register(commands: argparse._SubParsersAction) -> None:
    """Add ``heft dashboard`` and ``heft record`` (entry point of the group
    ``heft.commands``)."""
    _add_dashboard(commands)
    _add_record(commands)


def _add_dashboard(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser(
        "dashboard",
        help="a web page of the team's estimates converging, live or replayed",
        formatter_class=HelpFormatter,
        description=(
            "Serve a web page that shows a team live over Zenoh, or a recording replayed:\n"
            "every robot's m and J against the truth, the edges' |z_ij|, each robot's distance\n"
            "to the COM (each with the 95 % band the robot publishes), the rotation rate, the\n"
            "phase timeline, the communication graph's health, a top view of the load (its\n"
            "outline as the plant publishes it), alarms and the final table (with the 95 %\n"
            "intervals).\n"
            "Prints 'dashboard: URL' once serving.\n\n"
            "With --foxglove it also serves the team live to Foxglove, over the Foxglove\n"
            "WebSocket protocol (the Foxglove SDK's server): the same topics as a recording\n"
            "(heft record), at the team's rate. It prints 'foxglove: ws://HOST:PORT/foxglove':\n"
            "in Foxglove, open a connection, choose 'Foxglove WebSocket' and give that URL.\n\n"
            "It listens on 127.0.0.1 unless told otherwise; any other address needs a token,\n"
            f"given with --token or ${TOKEN_ENV}, on every request (header\n"
            "'Authorization: Bearer TOKEN', or ?token=TOKEN in the URL), Foxglove's\n"
            "connection too. The page and Foxglove's connection are plain HTTP and ws://:\n"
            "off this machine, prefer an SSH tunnel.\n\n"
            "Exit status: 0 stopped by SIGINT/SIGTERM/SIGHUP, 2 bad arguments, 4 the port is\n"
            "busy or the router does not answer."
        ),
        epilog=(
            "examples:\n"
            "  heft dashboard --team paper --connect tcp/127.0.0.1:7447\n"
            "  heft dashboard --replay run.mcap --speed 10\n"
            "  heft dashboard --team paper --host 0.0.0.0 --token s3cret\n"
            "  heft dashboard --team paper --foxglove"
        ),
    )
    parser.add_argument("--team", help="the team to watch live (required without --replay)")
    parser.add_argument(
        "--foxglove",
        action="store_true",
        help="also serve the team live to Foxglove on ws://HOST:PORT/foxglove (printed), behind"
        " the same token",
    )
    parser.add_argument(
        "--host", default="127.0.0.1", help="address to listen on (default: 127.0.0.1)"
    )
    parser.add_argument(
        "--port",
        type=int,
        default=DEFAULT_PORT,
        help=f"port to listen on, 0 for any free one (default: {DEFAULT_PORT})",
    )
    parser.add_argument(
        "--token", help=f"required from every client (default: ${TOKEN_ENV}, else none)"
    )
    parser.add_argument("--scenario", help=argparse.SUPPRESS)  # refused: see _no_scenario
    parser.add_argument(
        "--replay", metavar="FILE", help="replay this MCAP recording instead of a live team"
    )
    parser.add_argument(
        "--speed",
        metavar="X",
        help="with --replay: recorded seconds per second, 0.01 to 1000, or max (default: 1)",
    )
    parser.add_argument(
        "--paused",
        action="store_true",
        help="with --replay: start paused, to step through it from the page",
    )
    add_zenoh_options(parser, connect=DEFAULT_ROUTER, listen="none")
    parser.set_defaults(handler=cmd_dashboard)


def _add_record(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser(
        "record",
        help="record a team's Zenoh traffic to an MCAP file",
        formatter_class=HelpFormatter,
        description=(
            "Record every message of a team (measurements, commands, shares, estimates,\n"
            "statuses, the plant's truth and clock, bridges' status) to an MCAP file with\n"
            "JSON-schema channels: it opens in Foxglove and PlotJuggler with named fields and\n"
            "replays with heft dashboard --replay. Each message's log_time is its own instant\n"
            "on the team's clock (the plant's simulated time: in lockstep it equals the\n"
            "time_s of every message that has one), its publish_time the wall clock when it\n"
            "was recorded. Beside them, in Foxglove's own schemas, what its 3D and log panels\n"
            "draw: the load's frame, its scene and the team's log (deploy/foxglove/\n"
            "heft-layout.json, or python -m dashboard.layout --recording FILE, lays them out).\n\n"
            "SIGINT, SIGTERM or SIGHUP close the file properly. Chunks are flushed every\n"
            "0.5 s, so a recorder that is killed leaves a file readable up to then (heft\n"
            "dashboard --replay reads it); the MCAP tools want it whole: --repair FILE\n"
            "rewrites it with every message it holds, and a recorder that starts repairs\n"
            "those that killed recorders left in its folder.\n\n"
            "Exit status: 0 stopped (or repaired), 2 bad arguments or file, 4 the router\n"
            "does not answer."
        ),
        epilog=(
            "examples:\n"
            "  heft record --team paper -o run.mcap --connect tcp/127.0.0.1:7447\n"
            "  heft record --repair run.mcap"
        ),
    )
    parser.add_argument("--team", help="the team to record (required to record)")
    parser.add_argument(
        "-o", "--output", metavar="FILE", help="the MCAP file to write (required to record)"
    )
    parser.add_argument(
        "--repair",
        metavar="FILE",
        help="rewrite FILE, a recording cut short (its recorder killed), into a complete one"
        " with every message it holds, and exit",
    )
    parser.add_argument("--scenario", help=argparse.SUPPRESS)  # refused: see _no_scenario
    parser.add_argument(
        "--duration", type=float, metavar="S", help="stop after S seconds (default: at a signal)"
    )
    add_zenoh_options(parser, connect=DEFAULT_ROUTER, listen="none")
    parser.set_defaults(handler=cmd_record)
