"""Zenoh's own log in the process's log, the endpoints of a Zenoh config file, and what a
session says is in force (agent/platform/zenoh_log.py, agent/platform/zenoh_session.py,
agent/platform/cli_helpers.py).

The router tests run ``heft router`` as a process, on ``tls/127.0.0.1:PORT`` with the config
``heft deploy router-config`` makes, and read its log (standard error) as an operator's journal
would: it listens where the file says and nowhere else, says so, and Zenoh's lines about the
clients it refuses are in it, at the level chosen.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import re
import signal
import subprocess
import sys
import threading
import time
from datetime import UTC, datetime
from pathlib import Path

import pytest

from agent.platform import zenoh_log
from agent.platform.children import free_port
from agent.platform.cli_helpers import UsageError, add_zenoh_options, zenoh_settings
from agent.platform.zenoh_session import (
    DEFAULT_ROUTER,
    SessionError,
    ZenohSettings,
    describe,
    file_endpoints,
    open_session,
    zenoh_config,
)
from agent.security.access_control import router_config_text
from agent.security.certificates import make_certificates, team_identities
from tests.helpers.paths import ROOT

TEAM = "logs"
LINE = ((1, 2), (2, 3), (3, 4))

# Lines eclipse-zenoh 1.10.2 wrote to standard output for a router, as they were (colours
# included: NO_COLOR was not set).
NO_CERTIFICATE = (
    "\x1b[2m2026-11-25T14:00:26.471523Z\x1b[0m \x1b[33m WARN\x1b[0m acc-0 ThreadId(05)"
    " \x1b[2mzenoh_link_tls::unicast\x1b[0m\x1b[2m:\x1b[0m peer sent no certificates. Hint:"
    " increase the system open file limit.\n"
)
UNKNOWN_SUBJECT = (
    "2026-11-25T14:03:52.616165Z  INFO acc-0 ThreadId(05) rt{zid=a16b4610}:"
    " zenoh::net::routing::interceptor::access_control: 4923a4ed7c4c403bb33270aa91f5c108 did"
    " not match any configured ACL subject. Default permission `Deny` will be applied on all"
    " messages"
)
MAIN_THREAD = "2026-11-25T13:56:04.524402Z  INFO ThreadId(01) zenoh::net::runtime: Using ZID: 79"
SPANS = (
    "2026-11-25T14:03:53.711234Z DEBUG  rx-1 ThreadId(09) demux{zid=a16b src=south:0:client/f0:2}"
    ":send_push{expr=heft/sec/robot/1/force}: zenoh::net::routing::hat::router::pubsub: return=[]"
)


def utc(text: str) -> float:
    return datetime.fromisoformat(text).replace(tzinfo=UTC).timestamp()


# ------------------------------------------------------------------------------ Zenoh's lines
def test_zenohs_lines_become_records_of_their_level_and_target() -> None:
    event = zenoh_log.parse(NO_CERTIFICATE)
    assert event is not None
    assert event.level == logging.WARNING
    assert event.target == "zenoh_link_tls::unicast"
    assert event.logger == "zenoh.zenoh_link_tls.unicast"
    assert event.message == (
        "zenoh_link_tls::unicast: peer sent no certificates. Hint: increase the system open file"
        " limit."
    )
    assert event.created == pytest.approx(utc("2026-11-25T14:00:26.471523"), abs=1e-6)

    subject = zenoh_log.parse(UNKNOWN_SUBJECT)
    assert subject.level == logging.INFO
    assert subject.target == "zenoh::net::routing::interceptor::access_control"
    assert subject.message.startswith("rt{zid=a16b4610}: zenoh::net::routing::interceptor")
    assert "did not match any configured ACL subject" in subject.message

    main = zenoh_log.parse(MAIN_THREAD)
    assert main.target == "zenoh::net::runtime"
    assert main.message == "zenoh::net::runtime: Using ZID: 79"
    spans = zenoh_log.parse(SPANS)
    assert spans.level == logging.DEBUG
    assert spans.target == "zenoh::net::routing::hat::router::pubsub"
    trace = zenoh_log.parse(MAIN_THREAD.replace(" INFO", "TRACE"))
    assert trace.level == zenoh_log.TRACE == 5
    bare = zenoh_log.parse(MAIN_THREAD.replace("ThreadId(01) ", ""))  # without thread ids
    assert (bare.target, bare.message) == (main.target, main.message)


@pytest.mark.parametrize(
    "line",
    ["", "hello\n", "heft: error: x\n", "14:00:26 WARNING zenoh: x\n", "2026-11-25T14:00Z x\n"],
)
def test_other_lines_are_not_zenohs(line: str) -> None:
    assert zenoh_log.parse(line) is None


def test_the_level_is_the_options_else_rust_log_else_the_commands() -> None:
    assert zenoh_log.choose("debug", "info", env={"RUST_LOG": "trace"}) == zenoh_log.Choice(
        "warn,zenoh=debug", "--zenoh-log debug"
    )
    assert zenoh_log.choose(None, "info", env={"RUST_LOG": " zenoh=trace "}) == zenoh_log.Choice(
        "zenoh=trace", "RUST_LOG"
    )
    assert zenoh_log.choose(None, "info", env={"RUST_LOG": ""}) == zenoh_log.Choice(
        "warn,zenoh=info", "default"
    )
    assert str(zenoh_log.choose(None, env={})) == "warn (default)"
    assert [zenoh_log.rust_filter(level) for level in zenoh_log.LEVELS] == [
        "off",
        "error",
        "warn",
        "warn,zenoh=info",
        "warn,zenoh=debug",
        "warn,zenoh=trace",
    ]
    assert zenoh_log.choose("off", env={}).off
    with pytest.raises(ValueError):
        zenoh_log.rust_filter("verbose")


@pytest.mark.slow
def test_a_library_caller_routes_nothing(capsys) -> None:
    """A command called with its arguments (as tests do), not run as the process's program,
    and a session opened as a library leave Zenoh's log and standard output alone (here:
    pytest's own capture of descriptor 1)."""
    from agent.platform.heft import main

    before = os.fstat(1)
    listen = f"tcp/127.0.0.1:{free_port()}"
    with open_session(ZenohSettings(mode="peer", connect=(), listen=(listen,))):
        assert main(["router", "--listen", listen]) == 4  # its port is taken: no router
    after = os.fstat(1)
    assert (after.st_dev, after.st_ino) == (before.st_dev, before.st_ino)
    assert zenoh_log.in_force() is None
    assert capsys.readouterr().err.strip().endswith("address already in use")


ZENOH_COMMANDS = {
    "agent": "warn",
    "bridge": "warn",
    "sim": "warn",
    "dashboard": "warn",
    "record": "warn",
    "watch": "warn",
    "router": "info",
}


@pytest.mark.parametrize("command", ZENOH_COMMANDS)
def test_every_process_command_takes_the_zenoh_log_level(command: str) -> None:
    from agent.platform.heft import build_parser

    parser = build_parser()
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    sub = commands.choices[command]
    text = " ".join(sub.format_help().split())
    assert "--zenoh-log LEVEL" in text
    assert f"in Zenoh's filter syntax, if set, else {ZENOH_COMMANDS[command]})" in text
    assert sub.get_default("zenoh_log_default") == ZENOH_COMMANDS[command]


# ------------------------------------------------------------------------------ endpoints
def parse_zenoh_options(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_zenoh_options(parser, connect="c", listen="l")
    return parser.parse_args(argv)


ROUTER_BASE = ZenohSettings(mode="router", connect=(), listen=(DEFAULT_ROUTER,))


@pytest.fixture(scope="module")
def certs(tmp_path_factory) -> Path:
    """The team's certificates, valid for 127.0.0.1, and one of an identity its access control
    does not know (robot 5 of a team of 4) signed by its CA."""
    folder = tmp_path_factory.mktemp("pki") / "tls"
    make_certificates(folder, team_identities(4), hosts=["127.0.0.1"])
    make_certificates(folder, ["robot-5"], hosts=["127.0.0.1"], new_ca=False)
    return folder


def secured_router(folder: Path, certs: Path, endpoint: str) -> Path:
    path = folder / "router.json5"
    path.write_text(router_config_text(TEAM, 4, LINE, [endpoint], str(certs)), "utf-8")
    return path


def test_the_routers_endpoints_come_from_its_file(certs: Path, tmp_path: Path) -> None:
    path = secured_router(tmp_path, certs, "tls/127.0.0.1:7450")
    assert file_endpoints(str(path), "router") == {"listen": ("tls/127.0.0.1:7450",)}
    settings = zenoh_settings(parse_zenoh_options("--zenoh-config", str(path)), ROUTER_BASE)
    assert settings.listen == ("tls/127.0.0.1:7450",) and settings.connect == ()
    assert json_of(zenoh_config(settings), "listen/endpoints") == ["tls/127.0.0.1:7450"]
    # --listen replaces them
    given = parse_zenoh_options("--zenoh-config", str(path), "--listen", "tls/127.0.0.1:7451")
    assert zenoh_settings(given, ROUTER_BASE).listen == ("tls/127.0.0.1:7451",)


def json_of(config, key: str):
    import json

    return json.loads(config.get_json(key))


def test_a_files_endpoints_by_mode_and_its_defaults(tmp_path: Path) -> None:
    path = tmp_path / "zenoh.json5"
    path.write_text(
        '{ connect: { endpoints: { client: ["tcp/127.0.0.1:7001"], peer: [] } },\n'
        '  listen: { endpoints: { router: ["tcp/127.0.0.1:7002"] } } }\n',
        "utf-8",
    )
    assert file_endpoints(str(path), "client") == {"connect": ("tcp/127.0.0.1:7001",)}
    assert file_endpoints(str(path), "router") == {"listen": ("tcp/127.0.0.1:7002",)}
    assert file_endpoints(str(path), "peer") == {}
    empty = tmp_path / "empty.json5"
    empty.write_text("{ mode: 'peer' }\n", "utf-8")  # Zenoh's default endpoints: none given
    assert file_endpoints(str(empty), "router") == {}
    settings = zenoh_settings(parse_zenoh_options("--zenoh-config", str(empty)), ROUTER_BASE)
    assert settings.listen == (DEFAULT_ROUTER,)


def test_a_files_endpoints_replace_the_tables(tmp_path: Path) -> None:
    """robot.toml's ``[zenoh] connect`` gives way to its Zenoh file's; ``--connect`` to
    neither."""
    from agent.node import load_agent_config

    path = tmp_path / "client.json5"
    path.write_text('{ connect: { endpoints: ["tcp/127.0.0.1:7003"] } }\n', "utf-8")
    robot = tmp_path / "robot.toml"
    robot.write_text(
        'robot = 1\nn = 2\nneighbours = [2]\n[zenoh]\nconnect = ["tcp/127.0.0.1:7010"]\n'
        f'config_file = "{path}"\n',
        "utf-8",
    )
    base = load_agent_config(robot).zenoh
    assert base.connect == ("tcp/127.0.0.1:7010",)
    settings = zenoh_settings(parse_zenoh_options(), base)
    assert settings.connect == ("tcp/127.0.0.1:7003",) and settings.listen == ()
    given = parse_zenoh_options("--connect", "tcp/127.0.0.1:7004")
    assert zenoh_settings(given, base).connect == ("tcp/127.0.0.1:7004",)


def test_a_files_endpoints_are_checked_as_the_options_are(tmp_path: Path) -> None:
    path = tmp_path / "far.json5"
    path.write_text('{ listen: { endpoints: ["tcp/10.0.0.1:7447"] } }\n', "utf-8")
    with pytest.raises(UsageError, match=rf"^{re.escape(str(path))}: listen/endpoints: tcp/10"):
        zenoh_settings(parse_zenoh_options("--zenoh-config", str(path)), ROUTER_BASE)
    allowed = parse_zenoh_options("--zenoh-config", str(path), "--allow-plain")
    assert zenoh_settings(allowed, ROUTER_BASE).listen == ("tcp/10.0.0.1:7447",)
    vague = tmp_path / "vague.json5"
    vague.write_text('{ listen: { endpoints: ["tcp/127.0.0.1"] } }\n', "utf-8")
    with pytest.raises(UsageError, match=r"listen/endpoints: expected an explicit endpoint"):
        zenoh_settings(parse_zenoh_options("--zenoh-config", str(vague)), ROUTER_BASE)


def test_what_is_in_force_is_read_from_the_final_config(tmp_path: Path) -> None:
    """The file turns multicast scouting on and access control on: the session's settings
    turn scouting off again, and the line says what the final config has."""
    path = tmp_path / "zenoh.json5"
    path.write_text(
        "{ scouting: { multicast: { enabled: true } },\n"
        '  access_control: { enabled: true, default_permission: "allow" } }\n',
        "utf-8",
    )
    settings = ZenohSettings(
        mode="router", connect=(), listen=("tcp/127.0.0.1:7005",), config_file=str(path)
    )
    assert describe(zenoh_config(settings)) == (
        "zenoh router: listen tcp/127.0.0.1:7005; plain tcp: no TLS, no certificates (for"
        " loopback runs only); access control on: default allow, 0 subjects; multicast"
        " scouting off"
    )
    far = ZenohSettings(connect=("tcp/10.0.0.1:7447",), allow_plain=True)
    assert "plain tcp: no TLS, no certificates (anyone on the network can join)" in describe(
        zenoh_config(far)
    )


# ------------------------------------------------------------------------------ heft router
class Router:
    """``heft router ARGS`` as a process; its standard error read line by line."""

    def __init__(self, *args: str, env: dict[str, str] | None = None):
        self.process = subprocess.Popen(
            [sys.executable, "-m", "agent", "router", *args],
            cwd=ROOT,
            env={**os.environ, **(env or {})},
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.lines: list[str] = []
        self.out = ""
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self._out = threading.Thread(target=self._read_out, daemon=True)
        self._out.start()

    def _read(self) -> None:
        for line in self.process.stderr:
            self.lines.append(line.rstrip("\n"))

    def _read_out(self) -> None:
        self.out = self.process.stdout.read()

    def wait_for(self, pattern: str, timeout_s: float = 30.0) -> str:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for line in list(self.lines):
                if re.search(pattern, line):
                    return line
            if self.process.poll() is not None and not self._reader.is_alive():
                break
            time.sleep(0.05)
        raise AssertionError(f"no line matching {pattern!r}:\n" + "\n".join(self.lines))

    def stop(self) -> list[str]:
        """SIGTERM; every line it wrote, once it has exited (status 0)."""
        self.process.send_signal(signal.SIGTERM)
        assert self.process.wait(timeout=20) == 0, "\n".join(self.lines)
        self._reader.join(5)
        self._out.join(5)
        return self.lines

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()


def listening_ports(pid: int) -> set[int]:
    """The TCP ports process ``pid`` listens on (its sockets in /proc/net/tcp{,6})."""
    inodes = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    ports = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        with open(table, encoding="ascii") as lines:
            for line in lines.readlines()[1:]:
                fields = line.split()
                if fields[3] == "0A" and fields[9] in inodes:  # LISTEN
                    ports.add(int(fields[1].rsplit(":", 1)[1], 16))
    return ports


def client(certs: Path, endpoint: str, identity: str | None) -> ZenohSettings:
    tls = {}
    if identity is not None:
        tls = {
            "root_ca": str(certs / "ca.pem"),
            "certificate": str(certs / f"{identity}.pem"),
            "private_key": str(certs / f"{identity}-key.pem"),
        }
    return ZenohSettings(connect=(endpoint,), connect_timeout_ms=400, **tls)


def refused(settings: ZenohSettings) -> None:
    with pytest.raises(SessionError):
        open_session(settings)


@pytest.mark.slow
def test_a_router_listens_on_its_files_endpoint_and_logs_whom_it_refuses(
    certs: Path, tmp_path: Path
) -> None:
    """``heft router --zenoh-config FILE``: on the file's TLS endpoint alone (not on 7447), its
    first line says TLS and access control, and at its default level (info, as zenohd) Zenoh's
    lines on a plain client, a client without a certificate and an unknown identity are in its
    log, in the log's format; its standard output stays empty."""
    port = free_port()
    endpoint = f"tls/127.0.0.1:{port}"
    router = Router("--zenoh-config", str(secured_router(tmp_path, certs, endpoint)))
    try:
        line = router.wait_for(r"INFO zenoh router: ")
        assert line.split(" INFO ", 1)[1] == (
            f"zenoh router: listen {endpoint}; mutual TLS: clients must show a certificate"
            f" signed by {certs}/ca.pem; access control on: default deny, 7 subjects;"
            " multicast scouting off; zenoh log warn,zenoh=info (default)"
        )
        assert listening_ports(router.process.pid) == {port}
        with open_session(client(certs, endpoint, "robot-1")):  # it is there
            pass
        refused(client(certs, f"tcp/127.0.0.1:{port}", None))  # plain tcp on the TLS port
        router.wait_for(r"^\d\d:\d\d:\d\d WARNING zenoh_link_tls::unicast: received corrupt")
        no_certificate = client(certs, endpoint, None)
        no_certificate = dataclasses.replace(
            no_certificate, config_file=str(ca_only(tmp_path, certs))
        )
        refused(no_certificate)
        router.wait_for(r"WARNING zenoh_link_tls::unicast: peer sent no certificates")
        with open_session(client(certs, endpoint, "robot-5")):  # signed, but no subject
            pass
        router.wait_for(r"INFO zenoh::net::routing::interceptor::access_control: \w+ did not")
        lines = router.stop()
    finally:
        router.kill()
    assert lines[-1].endswith("INFO router stopped")
    assert router.out == ""


def ca_only(folder: Path, certs: Path) -> Path:
    """A client's Zenoh config that trusts the team's CA but has no certificate of its own."""
    path = folder / "ca-only.json5"
    ca = certs / "ca.pem"
    path.write_text(f'{{ transport: {{ link: {{ tls: {{ root_ca_certificate: "{ca}" }} }} }} }}\n')
    return path


@pytest.mark.slow
@pytest.mark.parametrize(
    ("option", "env", "in_force", "logged"),
    [
        (["--zenoh-log", "error"], {"RUST_LOG": "debug"}, "error (--zenoh-log error)", False),
        ([], {"RUST_LOG": "warn"}, "warn (RUST_LOG)", True),
    ],
    ids=["option-error", "rust-log-warn"],
)
def test_the_chosen_level_decides(option, env, in_force, logged, certs, tmp_path) -> None:
    """A plain client on the TLS port, refused: Zenoh's warning is in the router's log at
    ``warn`` (chosen by RUST_LOG), not at ``error`` (by --zenoh-log, over RUST_LOG); the
    unknown identity's info line is in neither."""
    port = free_port()
    endpoint = f"tls/127.0.0.1:{port}"
    path = secured_router(tmp_path, certs, endpoint)
    router = Router("--zenoh-config", str(path), *option, env=env)
    try:
        line = router.wait_for(r"INFO zenoh router: ")
        assert line.endswith(f"; zenoh log {in_force}")
        refused(client(certs, f"tcp/127.0.0.1:{port}", None))
        with open_session(client(certs, endpoint, "robot-5")):
            pass
        lines = router.stop()  # what Zenoh wrote is in the log by the time it has exited
    finally:
        router.kill()
    warnings = [line for line in lines if " WARNING zenoh_link_tls::unicast: " in line]
    assert bool(warnings) == logged, "\n".join(lines)
    assert not any("did not match any configured ACL subject" in line for line in lines)
    assert not any(" DEBUG " in line for line in lines)
