"""The bridge package's commands: ``heft bridge`` (one robot's AGV bridge, CAN ↔ Zenoh) and
``heft vcan`` (run a command where virtual CAN interfaces exist).

Building the parser imports nothing heavy (no python-can, cantools or Zenoh): the handlers
import what they run.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

from agent.platform.cli_helpers import (
    PROG,
    HelpFormatter,
    UsageError,
    add_zenoh_options,
    setup_logging,
    zenoh_settings,
)
from agent.platform.config import ConfigError
from bridge.devtools.vcan import DEFAULT_COUNT, DEFAULT_MEMORY


def register(commands: argparse._SubParsersAction) -> None:
    """Add the bridge package's commands (entry point of the group ``heft.commands``)."""
    _add_bridge(commands)
    _add_vcan(commands)


# ---------------------------------------------------------------------------------- bridge
def cmd_bridge(args: argparse.Namespace) -> int:
    """``heft bridge``: run one robot's AGV bridge until a signal."""
    from agent.platform.heft import NETWORK_UNAVAILABLE
    from bridge.config import load_bridge_config
    from bridge.node import BusUnavailable, run_bridge

    try:
        config = load_bridge_config(args.config)
        changes = {
            key: value
            for key, value in (("channel", args.channel), ("interface", args.interface))
            if value is not None
        }
        if changes:
            can = dataclasses.replace(config.can, **changes)
            can.validate("can")
            config = dataclasses.replace(config, can=can)
    except ConfigError as err:
        raise UsageError(str(err)) from None
    if args.listen:
        raise UsageError("--listen: a bridge never listens (it is a client of its router)")
    robot = dataclasses.replace(config.robot, zenoh=zenoh_settings(args, config.robot.zenoh))
    config = dataclasses.replace(config, robot=robot)
    setup_logging(args)
    try:
        return run_bridge(config)
    except BusUnavailable as err:  # like an unreachable router: worth retrying
        print(f"{PROG}: error: {err}", file=sys.stderr)
        return NETWORK_UNAVAILABLE


def _add_bridge(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser(
        "bridge",
        help="one robot's AGV bridge: its CAN bus <-> its agent over Zenoh",
        formatter_class=HelpFormatter,
        description=(
            "Run one robot's AGV bridge: it reads each tick's velocity and force frames from\n"
            "the robot's CAN bus, publishes them as the robot's measurement on Zenoh, and\n"
            "turns the agent's force commands into command frames. Its agent cannot tell it\n"
            "from the simulated plant. Two profiles ([can] profile):\n"
            "  force     a driver that takes force commands (bridge/agv.dbc): Odometry and\n"
            "            AppliedForce in, ForceCommand out;\n"
            "  velocity  a base that takes velocity commands, with a force/torque sensor at\n"
            "            its contact (bridge/agv-velocity.dbc): MotionFeedback and ForceTorque\n"
            "            in, MotionCommand out; the bridge tares the sensor and closes an\n"
            "            admittance loop ([can.admittance]) from the force to the velocity.\n"
            "No valid command for [can] watchdog_ms: it commands zero force (velocity: STOP)\n"
            "until commands return; velocity: a sensor silent or faulty that long, STOP too.\n"
            "Bad frames are counted and logged, never fatal; a bus that fails is reopened.\n"
            "It publishes its counters (BridgeStatus) four times a second.\n\n"
            "The config is the robot's robot.toml (as heft agent reads it) with a [can]\n"
            "table; the bridge is a Zenoh client of its [zenoh] connect endpoints.\n\n"
            "Exit status: 0 stopped by SIGINT/SIGTERM/SIGHUP, 2 bad config or arguments\n"
            "(one 'heft: error:' line), 4 the bus cannot be opened, or no router within\n"
            "[zenoh] connect_timeout_ms (one 'heft: error:' line; worth retrying)."
        ),
        epilog=(
            "example [can] table (the rest of robot.toml as for heft agent):\n"
            "  [can]\n"
            '  interface = "socketcan"   # python-can interface (virtual: in one process)\n'
            '  channel = "can0"\n'
            "  bitrate = 1000000         # bit/s\n"
            "  node = 1                  # CAN node id (default: the robot's id)\n"
            "  watchdog_ms = 100\n"
            '  time_source = "sync"      # or "clock" (chrony/PTP-synchronised host clock)\n'
            '  profile = "force"         # or "velocity"\n'
            "  [can.admittance]          # velocity profile only (see docs/can-bridge.md)\n"
            "  mass = 100.0              # kg, the virtual mass\n"
            "  damping = 1000.0          # N s/m\n\n"
            "example: heft bridge --config robot-1.toml --channel vcan1"
        ),
    )
    parser.add_argument(
        "--config", required=True, metavar="FILE", help="the robot's robot.toml with [can]"
    )
    parser.add_argument("--channel", help="replaces [can] channel (e.g. vcan1)")
    parser.add_argument("--interface", help="replaces [can] interface (e.g. socketcan)")
    add_zenoh_options(
        parser,
        connect="robot.toml's [zenoh] connect",
        listen="none (a bridge never listens)",
        config="robot.toml's [zenoh] config_file, if any",
    )
    parser.set_defaults(handler=cmd_bridge)


# ---------------------------------------------------------------------------------- vcan
def cmd_vcan(args: argparse.Namespace) -> int:
    """``heft vcan``: run the command where vcan0 ... vcan{N-1} exist; its exit status."""
    from bridge.devtools import vcan
    from bridge.devtools.vcan_run import check, run

    if args.check:
        if args.command:
            raise UsageError("vcan: --check runs no command")
        return check(force_uml=args.uml)
    command = list(args.command)
    if command[:1] == ["--"]:
        command = command[1:]
    if not command:
        raise UsageError("vcan: no command given: heft vcan [OPTIONS] -- CMD [ARGS...]")
    try:
        count = vcan.check_count(args.count)
        memory = vcan.parse_memory(args.memory)
    except ValueError as err:
        raise UsageError(str(err)) from None
    if args.timeout is not None and args.timeout <= 0:
        raise UsageError(f"--timeout: expected a positive number of seconds, got {args.timeout}")
    return run(command, count, memory, args.timeout, force_uml=args.uml)


def _add_vcan(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser(
        "vcan",
        help="run a command where virtual CAN interfaces vcan0.. exist",
        formatter_class=HelpFormatter,
        description=(
            "Run CMD where the network interfaces vcan0 ... vcan{N-1} exist (robots 1..8 use\n"
            "vcan1 ... vcan8; vcan0 is spare), for the hardware-in-the-loop tests.\n\n"
            "On a kernel with SocketCAN the missing interfaces are created (as root), CMD\n"
            "runs here, and the interfaces created are deleted afterwards. On a kernel\n"
            "without it, CMD runs in a User-Mode Linux guest (Debian's user-mode-linux and\n"
            "kmod): a Linux kernel booted as a process, with this machine's files as its\n"
            "root, in this folder and environment (plus HEFT_VCAN=1). There CMD has one\n"
            "CPU, stdin /dev/null, only the loopback network (IPv4 and IPv6), and its\n"
            "stdout and stderr come back here as it prints them; --memory sets the guest's.\n\n"
            "Exit status: CMD's own (128 + N if signal N killed it), 2 no vcan possible here\n"
            "or bad arguments (one 'heft: error:' line), 124 --timeout stopped CMD, 125 the\n"
            "guest died without CMD's status, 128 + N heft vcan was stopped by signal N."
        ),
        epilog=(
            "examples:\n"
            "  heft vcan -- python -m pytest -q -m hil\n"
            "  heft vcan --count 3 -- candump vcan1\n\n"
            "to have vcan interfaces without heft vcan: sudo deploy/vcan-setup.sh 9"
        ),
    )
    parser.add_argument(
        "--count",
        type=int,
        default=DEFAULT_COUNT,
        metavar="N",
        help=f"interfaces vcan0 ... vcan{{N-1}} (default: {DEFAULT_COUNT})",
    )
    parser.add_argument(
        "--memory",
        default=DEFAULT_MEMORY,
        metavar="SIZE",
        help=f"the guest's memory, e.g. 512M, 4G (default: {DEFAULT_MEMORY})",
    )
    parser.add_argument(
        "--timeout",
        type=float,
        metavar="SECONDS",
        help="stop CMD after this long (exit status 124)",
    )
    parser.add_argument(
        "--check",
        action="store_true",
        help="only say whether (and how) vcan is available here: exit status 0 or 2",
    )
    parser.add_argument(
        "--uml",
        action="store_true",
        help="use the User-Mode Linux guest even if this kernel has SocketCAN",
    )
    parser.add_argument("command", nargs=argparse.REMAINDER, metavar="-- CMD [ARGS...]")
    parser.set_defaults(handler=cmd_vcan)
