"""The command-line side of the processes on Zenoh: ``heft agent``, ``heft sim``,
``heft router`` and ``heft demo``."""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading

from agent.config import ConfigError
from agent.protocol import CLOCKS

LOG_FORMAT = "%(asctime)s %(levelname)s %(message)s"


def _logging() -> None:
    logging.basicConfig(
        level=logging.INFO, format=LOG_FORMAT, datefmt="%H:%M:%S", stream=sys.stderr
    )


def _stop_on_signals() -> threading.Event:
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    return stop


def cmd_agent(args: argparse.Namespace) -> int:
    from agent.node import load_agent_config, run_agent
    from heft.cli import UsageError

    try:
        config = load_agent_config(args.config)
    except ConfigError as err:
        raise UsageError(str(err)) from None
    _logging()
    return run_agent(config)


def cmd_sim(args: argparse.Namespace) -> int:
    from agent.zenoh_session import DEFAULT_ROUTER, ZenohSettings
    from heft.cli import UsageError, _load
    from simulator.node import run_plant

    scenario = _load(args.scenario)
    try:
        settings = ZenohSettings(mode="client", connect=tuple(args.connect or [DEFAULT_ROUTER]))
        settings.validate("--connect")
    except ConfigError as err:
        raise UsageError(str(err)) from None
    _logging()
    return run_plant(
        scenario,
        args.team or scenario.name,
        args.clock,
        settings,
        _stop_on_signals(),
        args.start_timeout,
    )


def cmd_router(args: argparse.Namespace) -> int:
    from agent.zenoh_session import DEFAULT_ROUTER, ZenohSettings, open_session
    from heft.cli import UsageError

    try:
        listen = tuple(args.listen or [DEFAULT_ROUTER])
        settings = ZenohSettings(mode="router", connect=(), listen=listen)
        settings.validate("--listen")
    except ConfigError as err:
        raise UsageError(str(err)) from None
    _logging()
    stop = _stop_on_signals()
    with open_session(settings):
        logging.getLogger("heft.router").info("router listening on %s", ", ".join(listen))
        stop.wait()
    logging.getLogger("heft.router").info("router stopped")
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    from heft.benchmark import PAPER_SCENARIO
    from heft.cli import cmd_run

    args.scenario = str(PAPER_SCENARIO)
    args.transport = "zenoh"
    args.clock = "realtime"
    args.drop = 0.0
    args.delay_ms = 0.0
    return cmd_run(args)


def add_commands(commands: argparse._SubParsersAction, formatter, add_output_options) -> None:
    from agent.zenoh_session import DEFAULT_ROUTER

    agent = commands.add_parser(
        "agent",
        help="one robot's agent, as a process on Zenoh",
        formatter_class=formatter,
        description=(
            "Run one robot's agent: it receives its robot's measurements and its graph\n"
            "neighbours' messages over Zenoh and publishes force commands, its messages and\n"
            "its estimates, until told to stop (or SIGINT/SIGTERM). The config file gives the\n"
            "robot's id, n, its neighbours, the team, the clock, the Zenoh endpoints, link\n"
            "faults to inject and the tuning; see agent/node.py (AgentNodeConfig)."
        ),
        epilog='example robot.toml:\n  robot = 1\n  n = 4\n  neighbours = [2]\n  team = "paper"\n'
        '  clock = "realtime"\n  [zenoh]\n  connect = ["tcp/127.0.0.1:7447"]',
    )
    agent.add_argument("--config", required=True, metavar="FILE", help="robot.toml")
    agent.set_defaults(handler=cmd_agent)

    sim = commands.add_parser(
        "sim",
        help="the simulated load and robots, as a process on Zenoh",
        formatter_class=formatter,
        description=(
            "Run the pymunk plant of SCENARIO as a process: it publishes each robot's\n"
            "measurements, applies each robot's force commands and publishes the truth. It\n"
            "starts once every robot's agent is up."
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
        "--connect",
        action="append",
        metavar="ENDPOINT",
        default=None,
        help=f"router endpoint (default: {DEFAULT_ROUTER})",
    )
    sim.add_argument(
        "--start-timeout",
        type=float,
        default=30.0,
        metavar="S",
        help="give up if the agents are not all up after S seconds (default: 30)",
    )
    sim.set_defaults(handler=cmd_sim)

    router = commands.add_parser(
        "router",
        help="a Zenoh router (no separate binary needed)",
        formatter_class=formatter,
        description="Run a Zenoh router on the given endpoints until SIGINT/SIGTERM.\n"
        "Multicast scouting is off: clients must name its endpoint.",
    )
    router.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        default=None,
        help=f"endpoint to listen on (default: {DEFAULT_ROUTER})",
    )
    router.set_defaults(handler=cmd_router)

    demo = commands.add_parser(
        "demo",
        help="the paper's scenario, one process per robot over Zenoh, in real time",
        formatter_class=formatter,
        description=(
            "Run the paper's Sec. VI scenario as it would run on robots: a Zenoh router, the\n"
            "plant and four agent processes on 127.0.0.1, stepping on the wall clock. Prints\n"
            "the table of estimates against truth at the end."
        ),
    )
    add_output_options(demo)
    demo.set_defaults(handler=cmd_demo)
