"""The agent package's commands: ``heft agent`` (one robot's agent) and ``heft router`` (a
Zenoh router). Both are processes on Zenoh that run until SIGINT, SIGTERM or SIGHUP."""

from __future__ import annotations

import argparse
import dataclasses
import logging

from agent.command_line import (
    HelpFormatter,
    UsageError,
    add_zenoh_options,
    setup_logging,
    zenoh_settings,
)
from agent.config import ConfigError
from agent.zenoh_session import DEFAULT_ROUTER, ZenohSettings


def cmd_agent(args: argparse.Namespace) -> int:
    """``heft agent``: run one robot's agent until told to stop."""
    from agent.node import load_agent_config, run_agent

    try:
        config = load_agent_config(args.config)
    except ConfigError as err:
        raise UsageError(str(err)) from None
    config = dataclasses.replace(config, zenoh=zenoh_settings(args, config.zenoh))
    setup_logging()
    return run_agent(config)


def cmd_router(args: argparse.Namespace) -> int:
    """``heft router``: run a Zenoh router until a signal."""
    from agent.process import stop_on_signals
    from agent.zenoh_session import open_session

    base = ZenohSettings(mode="router", connect=(), listen=(DEFAULT_ROUTER,))
    settings = zenoh_settings(args, base)
    setup_logging()
    log = logging.getLogger("heft.router")
    stop = stop_on_signals()
    with open_session(settings):
        log.info("router listening on %s", ", ".join(settings.listen))
        if settings.connect:
            log.info("router connecting to %s", ", ".join(settings.connect))
        stop.wait()
    log.info("router stopped")
    return 0


def register(commands: argparse._SubParsersAction) -> None:
    """Add ``heft agent`` and ``heft router`` (entry point of the group ``heft.commands``)."""
    agent = commands.add_parser(
        "agent",
        help="one robot's agent, as a process on Zenoh",
        formatter_class=HelpFormatter,
        description=(
            "Run one robot's agent: it receives its robot's measurements and its graph\n"
            "neighbours' messages over Zenoh and publishes force commands, its messages and\n"
            "its estimates, until told to stop (or SIGINT/SIGTERM/SIGHUP). The config file\n"
            "gives the robot's id, n, its neighbours, the team, the clock, the Zenoh\n"
            "endpoints, link faults to inject and the tuning; see agent/node.py\n"
            "(AgentNodeConfig). --connect, --listen and --zenoh-config replace its [zenoh]\n"
            "table's connect, listen and config_file.\n\n"
            "Every value of the config has a range (README: Limits), checked before anything\n"
            "starts.\n\n"
            "Exit status: 0 stopped (told to, or by SIGINT/SIGTERM/SIGHUP), 2 bad config or\n"
            "arguments (one 'heft: error:' line), 3 the team halted because a robot was lost\n"
            "(restart every agent of the team together), 4 a busy port or no router within\n"
            "[zenoh] connect_timeout_ms (one 'heft: error:' line; worth retrying)."
        ),
        epilog='example robot.toml:\n  robot = 1\n  n = 4\n  neighbours = [2]\n  team = "paper"\n'
        '  clock = "realtime"\n  [zenoh]\n  connect = ["tcp/127.0.0.1:7447"]\n\n'
        "example: heft agent --config robot-1.toml --connect tcp/192.168.10.1:7447",
    )
    agent.add_argument(
        "--config", required=True, metavar="FILE", help="the robot's robot.toml (required)"
    )
    add_zenoh_options(
        agent,
        connect="robot.toml's [zenoh] connect",
        listen="robot.toml's [zenoh] listen",
        config="robot.toml's [zenoh] config_file, if any",
    )
    agent.set_defaults(handler=cmd_agent)

    router = commands.add_parser(
        "router",
        help="a Zenoh router (no separate binary needed)",
        formatter_class=HelpFormatter,
        description=(
            "Run a Zenoh router on the given endpoints until SIGINT/SIGTERM/SIGHUP.\n"
            "Multicast scouting is off: clients must name its endpoint.\n\n"
            "Exit status: 0 stopped, 2 bad arguments, or a port that is busy or not on this\n"
            "machine (one 'heft: error:' line)."
        ),
        epilog="example: heft router --listen tcp/192.168.10.1:7447",
    )
    add_zenoh_options(router, connect="none", listen=DEFAULT_ROUTER)
    router.set_defaults(handler=cmd_router)
