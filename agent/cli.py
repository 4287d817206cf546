"""The agent package's commands: ``heft agent`` (one robot's agent) and ``heft router`` (a
Zenoh router), processes on Zenoh that run until SIGINT, SIGTERM or SIGHUP, and ``heft
deploy`` (the files of a secured deployment: certificates, the router's config)."""

from __future__ import annotations

import argparse
import dataclasses
import logging
from pathlib import Path

from agent.platform.cli_helpers import (
    HelpFormatter,
    UsageError,
    add_zenoh_options,
    check_writable,
    setup_logging,
    write_text,
    zenoh_settings,
)
from agent.platform.config import ConfigError
from agent.platform.zenoh_session import DEFAULT_ROUTER, ZenohSettings


def cmd_agent(args: argparse.Namespace) -> int:
    """``heft agent``: run one robot's agent until told to stop."""
    from agent.node import load_agent_config, run_agent

    try:
        config = load_agent_config(args.config)
    except ConfigError as err:
        raise UsageError(str(err)) from None
    config = dataclasses.replace(config, zenoh=zenoh_settings(args, config.zenoh))
    setup_logging(args)
    return run_agent(config)


def cmd_router(args: argparse.Namespace) -> int:
    """``heft router``: run a Zenoh router until a signal. Its session says in the log what
    is in force (endpoints, TLS, access control: :func:`~agent.platform.zenoh_session.describe`)."""
    from agent.platform.process import StopSignals
    from agent.platform.zenoh_session import open_session

    base = ZenohSettings(mode="router", connect=(), listen=(DEFAULT_ROUTER,))
    settings = zenoh_settings(args, base)
    setup_logging(args)
    log = logging.getLogger("heft.router")
    stop = StopSignals().handle().event
    with open_session(settings):
        stop.wait()
    log.info("router stopped")
    return 0


def _count(text: str, option: str, low: int, high: int) -> int:
    """``text`` as an integer from ``low`` to ``high``, else a :class:`UsageError`."""
    try:
        value = int(text)
    except ValueError:
        value = None
    if value is None or not low <= value <= high:
        raise UsageError(f"{option}: expected an integer from {low} to {high}, got {text!r}")
    return value


def cmd_deploy_certs(args: argparse.Namespace) -> int:
    """``heft deploy certs``: the team's CA and certificates, or more signed by its CA."""
    from agent.platform.config import MAX_ROBOTS
    from agent.security.certificates import (
        CA_KEY,
        DEFAULT_HOSTS,
        MAX_DAYS,
        CertificateError,
        check_identity,
        make_certificates,
        team_identities,
    )

    if (args.robots is None) == (not args.identity):
        raise UsageError("give --robots N (a new team) or --identity NAME (add to its CA)")
    days = _count(args.days, "--days", 1, MAX_DAYS)
    try:
        if args.robots is not None:
            names = team_identities(_count(args.robots, "--robots", 1, MAX_ROBOTS))
        else:
            names = [check_identity(name) for name in args.identity]
        made = make_certificates(
            args.dir,
            names,
            hosts=args.host or DEFAULT_HOSTS,
            days=days,
            force=args.force,
            new_ca=args.robots is not None,
        )
    except CertificateError as err:
        raise UsageError(str(err)) from None
    what = "a new CA and " if made.new_ca else ""
    print(f"{args.dir}: made {what}certificates for {', '.join(names)}")
    for path in made.files:
        print(f"  {path}")
    print(
        f"Each host gets ca.pem and its own <identity>.pem and <identity>-key.pem; {CA_KEY}"
        " stays here (deploy/README.md)."
    )
    return 0


def cmd_deploy_router_config(args: argparse.Namespace) -> int:
    """``heft deploy router-config``: the secured router's Zenoh config for a team."""
    from agent.platform.config import MAX_ROBOTS
    from agent.security.access_control import AccessError, parse_edges, router_config_text

    robots = _count(args.robots, "--robots", 1, MAX_ROBOTS)
    try:
        edges = parse_edges(args.edges, robots)
        text = router_config_text(args.team, robots, edges, args.listen, args.certs)
    except AccessError as err:
        raise UsageError(str(err)) from None
    if args.out is None:
        print(text, end="")
        return 0
    out = Path(args.out)
    check_writable(out)
    write_text(out, text)
    return 0


def _add_deploy(commands: argparse._SubParsersAction) -> None:
    """``heft deploy certs`` and ``heft deploy router-config``."""
    deploy = commands.add_parser(
        "deploy",
        help="files of a secured deployment: certificates, router config",
        formatter_class=HelpFormatter,
        description=(
            "Make the files of a secured deployment (deploy/README.md): the team's\n"
            "certificates (mutual TLS: every process shows one signed by the team's CA) and\n"
            "the router's Zenoh config (TLS listener and access control by identity)."
        ),
        epilog="example: heft deploy certs tls --robots 4 --host 192.168.10.1\n"
        "example: heft deploy router-config --team paper --robots 4 --edges 1-2 2-3 3-4 \\\n"
        "           --listen tls/192.168.10.1:7447 --certs /etc/heft/tls --out router.json5",
    )
    sub = deploy.add_subparsers(dest="deploy_command", metavar="COMMAND", required=True)

    certs = sub.add_parser(
        "certs",
        help="the team's CA and a certificate per identity",
        formatter_class=HelpFormatter,
        description=(
            "Make the team's certificate authority (DIR/ca.pem, DIR/ca-key.pem) and, signed\n"
            "by it, a certificate and private key per identity (DIR/<identity>.pem,\n"
            "DIR/<identity>-key.pem): router, robot-1 ... robot-N, plant, operator and\n"
            "dashboard. The Common Name is the identity: the router's access control knows\n"
            "each process by it. Private keys are written with mode 0600; ca-key.pem stays\n"
            "where certificates are made, each host gets ca.pem and its own pair.\n\n"
            "Nothing is overwritten without --force (with --robots, --force makes a new CA:\n"
            "every certificate must then be installed again). --identity adds certificates\n"
            "signed by the CA already in DIR (a new robot, a second dashboard's machine).\n\n"
            "Exit status: 0 made, 2 bad arguments or a file already there (one 'heft: error:'\n"
            "line)."
        ),
        epilog="example: heft deploy certs tls --robots 4 --host 192.168.10.1 --host router.lan\n"
        "example: heft deploy certs tls --identity robot-5 --host 192.168.10.1",
    )
    certs.add_argument("dir", metavar="DIR", help="the folder to write (created, mode 0700)")
    certs.add_argument(
        "--robots", metavar="N", help="a new team of N robots: a new CA and every identity"
    )
    certs.add_argument(
        "--identity",
        action="append",
        metavar="NAME",
        help="add NAME's certificate, signed by DIR's CA (router, robot-<i>, plant, operator,"
        " dashboard); repeatable",
    )
    certs.add_argument(
        "--host",
        action="append",
        metavar="HOST",
        help="a DNS name or IP address the certificates are valid for: the router's name or"
        " address as its clients connect to it; repeatable (default: localhost and"
        " 127.0.0.1)",
    )
    certs.add_argument(
        "--days", default="825", metavar="D", help="days the certificates are valid (default: 825)"
    )
    certs.add_argument(
        "--force", action="store_true", help="replace a CA, certificates and keys already there"
    )
    certs.set_defaults(handler=cmd_deploy_certs)

    router = sub.add_parser(
        "router-config",
        help="the secured router's Zenoh config for a team",
        formatter_class=HelpFormatter,
        description=(
            "Print (or write with --out) the Zenoh router config of a team: router mode on\n"
            "tls endpoints, mutual TLS with the certificates in the folder --certs of the\n"
            "router host (ca.pem, router.pem, router-key.pem), no multicast scouting, no\n"
            "shared memory, and access control: everything denied but what each identity's\n"
            "processes do (robot-<i>: its robot's keys and its graph neighbours' shares;\n"
            "plant; operator: may stop runs; dashboard: listens).\n"
            "See agent/security/access_control.py.\n"
            "Run the router with: heft router --zenoh-config FILE (it listens on the file's\n"
            "endpoints), or zenohd --config FILE.\n\n"
            "Exit status: 0 written, 2 bad arguments (one 'heft: error:' line)."
        ),
        epilog="example: heft deploy router-config --team paper --robots 4 --edges 1-2 2-3 3-4 \\\n"
        "           --listen tls/192.168.10.1:7447 --certs /etc/heft/tls \\\n"
        "           --out /etc/heft/router.json5",
    )
    router.add_argument("--team", required=True, help="the team's name (required)")
    router.add_argument("--robots", required=True, metavar="N", help="robots 1 to N (required)")
    router.add_argument(
        "--edges",
        required=True,
        nargs="+",
        metavar="I-J",
        help="the communication graph's edges, e.g. 1-2 2-3 3-4 (required)",
    )
    router.add_argument(
        "--listen",
        required=True,
        action="append",
        metavar="ENDPOINT",
        help="where the router listens, tls/HOST:PORT; repeatable (required)",
    )
    router.add_argument(
        "--certs",
        required=True,
        metavar="DIR",
        help="the folder the router reads its certificates from at run time, e.g."
        " /etc/heft/tls (required)",
    )
    router.add_argument("--out", metavar="FILE", help="write to FILE (default: standard output)")
    router.set_defaults(handler=cmd_deploy_router_config)


def register(commands: argparse._SubParsersAction) -> None:
    """Add ``heft agent``, ``heft router`` and ``heft deploy`` (entry point of the group
    ``heft.commands``)."""
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
            "(AgentNodeConfig). --connect, --listen, --zenoh-config and --tls-* replace its\n"
            "[zenoh] table's connect, listen, config_file, root_ca, certificate and\n"
            "private_key; a Zenoh config file's endpoints, where it gives them, replace\n"
            "connect and listen.\n\n"
            "Every value of the config has a range (docs/configuration.md), checked before\n"
            "anything starts.\n\n"
            "Exit status: 0 stopped (told to, or by SIGINT/SIGTERM/SIGHUP), 2 bad config or\n"
            "arguments (one 'heft: error:' line), 3 stopped while the team was halted (a robot\n"
            "lost; restarted, the agent rejoins: the team begins again once every robot is\n"
            "back), 4 a busy port or no router within [zenoh] connect_timeout_ms (one\n"
            "'heft: error:' line; worth retrying)."
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
            "Run a Zenoh router until SIGINT/SIGTERM/SIGHUP, listening on the endpoints of\n"
            "--listen, else those of the --zenoh-config file, else tcp/127.0.0.1:7447.\n"
            "Multicast scouting is off: clients must name its endpoint. At start it logs\n"
            "what is in force: endpoints (tls or plain), mutual TLS, access control.\n"
            "Zenoh's own log joins its log at --zenoh-log's level (else RUST_LOG's, else\n"
            "info, as zenohd): at warn each refused handshake (no certificate, a foreign CA,\n"
            "plain tcp on a tls port), at info each certificate name its access control does\n"
            "not know.\n\n"
            "Exit status: 0 stopped, 2 bad arguments (one 'heft: error:' line), 4 a port that\n"
            "is busy or not on this machine (one 'heft: error:' line)."
        ),
        epilog="example: heft router --zenoh-config /etc/heft/router.json5 --zenoh-log info",
    )
    add_zenoh_options(
        router,
        connect="none, or the --zenoh-config file's",
        listen=f"the --zenoh-config file's, else {DEFAULT_ROUTER}",
        log="info",
    )
    router.set_defaults(handler=cmd_router)

    _add_deploy(commands)
