"""The deployment's files (deploy/) agree with the code and with each other, so that they cannot
drift apart unnoticed:

- every systemd unit parses, has the hardening the guide promises (no capability, read-only
  system, its own user, only the address families and system calls it needs, real-time
  scheduling for the bridge alone), runs ``/opt/heft/.venv/bin/heft`` and restarts on exactly
  the exit statuses its command's ``--help`` says are worth it (that systemd itself accepts
  them is tests/integration/test_systemd_verify.py);
- a unit that gets its private key as a systemd credential names the certificate of the same
  identity, and one that runs with a robot's config runs as the user its key is readable by;
- every ``heft ...`` command line in the units, in deploy/README.md's code blocks and in the
  files' comments names a real subcommand and only options its ``--help`` lists, and parses;
- each robot's ``[zenoh]`` table connects to the router's TLS endpoint (the one the router's
  config and unit listen on) with the team's CA and the robot's own certificate and key, and
  the rest of the file loads for the agent and the bridge (the TLS files redirected to
  placeholders: they exist only on the robots).
"""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path

import pytest

from agent.node import load_agent_config
from agent.platform.zenoh_session import TLS_FILES, file_endpoints
from tests.helpers.commands import (
    assert_options_listed,
    assert_parses,
    code_blocks,
    heft_command_lines,
    leaf,
    prose,
    shell_words,
)
from tests.helpers.paths import ROOT
from tests.helpers.tls import TLS_DIR, loadable_copy

DEPLOY = ROOT / "deploy"
GUIDE = DEPLOY / "README.md"
UNITS = sorted((DEPLOY / "systemd").glob("*.service"))
ROBOTS = {i: DEPLOY / "paper" / f"robot-{i}.toml" for i in range(1, 5)}
ROUTER_JSON5 = DEPLOY / "zenoh" / "router.json5"
HEFT = "/opt/heft/.venv/bin/heft"
UNIT_COMMANDS = {
    "heft-agent@.service": "agent",
    "heft-bridge@.service": "bridge",
    "heft-router.service": "router",
    "heft-dashboard.service": "dashboard",
}
FAMILIES = {"AF_INET", "AF_INET6", "AF_UNIX", "AF_NETLINK"}
HARDENING = {
    "NoNewPrivileges": "yes",
    "ProtectSystem": "strict",
    "ProtectHome": "yes",
    "PrivateTmp": "yes",
    "PrivateDevices": "yes",  # CAN is a network interface: the bridge needs no device node
    "ProtectKernelTunables": "yes",
    "ProtectKernelModules": "yes",
    "ProtectControlGroups": "yes",
    "LockPersonality": "yes",
    "CapabilityBoundingSet": "",  # none, the bridge's raw CAN socket included
    "SystemCallArchitectures": "native",
}


# ----------------------------------------------------------------------------- helpers
Unit = dict[str, dict[str, list[str]]]


def parse_unit(path: Path) -> Unit:
    """A unit file's sections, each key's values in order (systemd's syntax: comments, ``\\``
    continuations, repeated keys); an assertion error on a line that is none of these."""
    sections: Unit = {}
    current: dict[str, list[str]] | None = None
    pending = ""
    for number, raw in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith(("#", ";")):
            continue
        if pending:
            line, pending = f"{pending} {line}", ""
        if line.endswith("\\"):
            pending = line[:-1].rstrip()
            continue
        if line.startswith("[") and line.endswith("]"):
            current = sections.setdefault(line[1:-1], {})
            continue
        key, sep, value = line.partition("=")
        assert sep and current is not None and key.strip().isidentifier(), (
            f"{path.name}:{number}: not a key=value line in a section: {raw!r}"
        )
        current.setdefault(key.strip(), []).append(value.strip())
    assert not pending, f"{path.name}: ends in a continuation"
    return sections


def service(path: Path) -> dict[str, list[str]]:
    return parse_unit(path)["Service"]


def last(values: dict[str, list[str]], key: str) -> str | None:
    """The value systemd uses for a single-valued key (the last one given)."""
    return values[key][-1] if key in values else None


def exit_statuses(heft, command: str) -> dict[int, str]:
    """The exit statuses ``heft COMMAND --help`` documents, each with what it says of it."""
    text = leaf(heft, command.split())[1].format_help()
    assert "Exit status:" in text, f"heft {command} --help documents no exit status"
    paragraph = " ".join(text.split("Exit status:", 1)[1].split("\n\n", 1)[0].split())
    items = re.split(r"(?:^|,\s+)(?=\d+\s)", paragraph)
    statuses = {}
    for item in filter(None, items):
        number, meaning = item.split(" ", 1)
        statuses[int(number)] = meaning
    return statuses


def router_json5() -> dict:
    """deploy/zenoh/router.json5 (comment lines dropped: its JSON5 is otherwise JSON)."""
    text = "\n".join(
        line
        for line in ROUTER_JSON5.read_text(encoding="utf-8").splitlines()
        if not line.lstrip().startswith("//")
    )
    return json.loads(text)


def exec_argv(path: Path) -> list[str]:
    """The unit's ``heft`` arguments (its one ``ExecStart=``)."""
    starts = service(path)["ExecStart"]
    assert len(starts) == 1, f"{path.name}: one ExecStart= expected, got {starts}"
    words = shell_words(starts[0])
    assert words[0] == HEFT, f"{path.name}: ExecStart= runs {words[0]}, not {HEFT}"
    return words[1:]


def option(argv: list[str], name: str) -> list[str]:
    """Every value given to ``name`` in ``argv``."""
    return [argv[i + 1] for i, word in enumerate(argv[:-1]) if word == name]


# ----------------------------------------------------------------------------- the units
def test_the_units_are_the_ones_the_guide_installs() -> None:
    assert {unit.name for unit in UNITS} == set(UNIT_COMMANDS)
    guide = GUIDE.read_text(encoding="utf-8")
    for unit in UNITS:
        assert f"systemd/{unit.name}" in guide, f"deploy/README.md does not list {unit.name}"
    for name in set(re.findall(r"heft-[a-z]+@?\.service", guide)):
        assert (DEPLOY / "systemd" / name).is_file(), f"deploy/README.md names {name}"


@pytest.mark.parametrize("unit", UNITS, ids=lambda p: p.name)
def test_unit_parses_and_runs_its_heft_command(unit: Path, heft) -> None:
    sections = parse_unit(unit)
    assert set(sections) == {"Unit", "Service", "Install"}, unit.name
    assert sections["Install"]["WantedBy"] == ["multi-user.target"]
    assert "network-online.target" in sections["Unit"]["Wants"][0].split()
    assert "network-online.target" in sections["Unit"]["After"][0].split()
    for link in " ".join(sections["Unit"]["Documentation"]).split():
        assert link.startswith("file:///opt/heft/"), link
        assert (ROOT / link.removeprefix("file:///opt/heft/")).is_file(), link
    argv = exec_argv(unit)
    assert argv[0] == UNIT_COMMANDS[unit.name]
    assert_parses(heft, argv, unit.name)


@pytest.mark.parametrize("unit", UNITS, ids=lambda p: p.name)
def test_unit_is_hardened(unit: Path) -> None:
    values = service(unit)
    for key, expected in HARDENING.items():
        assert last(values, key) == expected, f"{unit.name}: {key}={last(values, key)}"
    assert values["SystemCallFilter"][0] == "@system-service", unit.name
    assert last(values, "SystemCallErrorNumber") == "EPERM", unit.name
    umask = last(values, "UMask")
    assert umask is not None and int(umask, 8) & 0o007 == 0o007, f"{unit.name}: UMask={umask}"
    if last(values, "DynamicUser") != "yes":
        assert last(values, "User") not in (None, "", "root", "0"), f"{unit.name}: runs as root"
    families = set(last(values, "RestrictAddressFamilies").split())
    bridge = unit.name == "heft-bridge@.service"
    assert families == (FAMILIES | {"AF_CAN"} if bridge else FAMILIES), unit.name
    # MemoryDenyWriteExecute= is left out on purpose, and the unit says why.
    assert last(values, "MemoryDenyWriteExecute") in (None, "no"), unit.name
    assert "MemoryDenyWriteExecute" in unit.read_text(encoding="utf-8"), unit.name


def test_only_the_bridge_may_use_real_time_scheduling() -> None:
    priorities = [
        tomllib.loads(p.read_text("utf-8"))["can"]["realtime_priority"] for p in ROBOTS.values()
    ]
    for unit in UNITS:
        values = service(unit)
        if unit.name == "heft-bridge@.service":
            assert last(values, "RestrictRealtime") in (None, "no")
            assert int(last(values, "LimitRTPRIO")) >= max(priorities)
        else:
            assert last(values, "RestrictRealtime") == "yes", unit.name
            assert "LimitRTPRIO" not in values, unit.name


@pytest.mark.parametrize("unit", UNITS, ids=lambda p: p.name)
def test_unit_restarts_on_what_its_command_says_is_worth_it(unit: Path, heft) -> None:
    values = service(unit)
    command = UNIT_COMMANDS[unit.name]
    documented = exit_statuses(heft, command)
    assert last(values, "Restart") == "on-failure", unit.name
    assert float(last(values, "RestartSec")) > 0, unit.name
    prevented = {int(s) for s in " ".join(values["RestartPreventExitStatus"]).split()}
    assert prevented <= set(documented), (unit.name, prevented, documented)
    assert 2 in prevented, f"{unit.name}: a bad config or argument (2) must not loop"
    for status, meaning in documented.items():
        if "worth retrying" in meaning:
            assert status not in prevented, f"{unit.name}: {status} is {meaning!r}"
    # A router or a robot may come up minutes after the others: never give up.
    assert parse_unit(unit)["Unit"].get("StartLimitIntervalSec") == ["0"], unit.name


def test_a_halted_agent_is_restarted_and_rejoins(heft) -> None:
    """Exit status 3 (the team halted) is no longer final: a restarted agent rejoins its team,
    which begins again, one more rejoin (deploy/README.md, "Faults")."""
    assert 3 in exit_statuses(heft, "agent")
    prevented = service(DEPLOY / "systemd" / "heft-agent@.service")["RestartPreventExitStatus"]
    assert "3" not in " ".join(prevented).split()


def test_units_with_a_credential_show_the_certificate_of_its_identity() -> None:
    subjects = {s["id"] for s in router_json5()["access_control"]["subjects"]}
    for unit in UNITS:
        values, argv = service(unit), exec_argv(unit)
        key = option(argv, "--tls-private-key")
        if not key:
            continue
        assert key == ["${CREDENTIALS_DIRECTORY}/key"], unit.name
        assert last(values, "DynamicUser") == "yes", unit.name
        source = last(values, "LoadCredential")
        assert source is not None and source.startswith(f"key:{TLS_DIR}/"), unit.name
        identity = Path(source.split(":", 1)[1]).name.removesuffix("-key.pem")
        assert option(argv, "--tls-certificate") == [f"{TLS_DIR}/{identity}.pem"], unit.name
        assert option(argv, "--tls-root-ca") == [f"{TLS_DIR}/ca.pem"], unit.name
        assert identity == "router" or identity in subjects, (unit.name, identity)


def test_agent_and_bridge_run_as_the_user_their_key_is_readable_by() -> None:
    """A robot's config names its key, which the agent and the bridge check readable when they
    load the file, before any --tls-* option: their units cannot take it as a credential
    (a dynamic user could not read the file's key), so they run as the system user heft."""
    for name in ("heft-agent@.service", "heft-bridge@.service"):
        values, argv = service(DEPLOY / "systemd" / name), exec_argv(DEPLOY / "systemd" / name)
        assert argv[1:] == ["--config", "/etc/heft/robot-%i.toml"], name
        assert last(values, "User") == "heft" and last(values, "Group") == "heft", name
        assert last(values, "DynamicUser") in (None, "no"), name
        assert "LoadCredential" not in values, name
    guide = GUIDE.read_text(encoding="utf-8")
    assert "sudo install -o root -g heft -m 640 robot-3-key.pem /etc/heft/tls/" in guide


def test_the_router_unit_listens_where_its_config_and_the_robots_say() -> None:
    argv = exec_argv(DEPLOY / "systemd" / "heft-router.service")
    config = router_json5()
    # heft router listens on the file's endpoints (agent.platform.cli_helpers.zenoh_settings)
    assert option(argv, "--zenoh-config") == ["/etc/heft/router.json5"]
    assert option(argv, "--listen") == []
    assert file_endpoints(str(ROUTER_JSON5), "router") == {
        "listen": tuple(config["listen"]["endpoints"])
    }
    assert config["transport"]["link"]["tls"]["root_ca_certificate"] == f"{TLS_DIR}/ca.pem"
    endpoints = set(config["listen"]["endpoints"])
    for i, path in ROBOTS.items():
        assert set(tomllib.loads(path.read_text("utf-8"))["zenoh"]["connect"]) <= endpoints, i
    dashboard = exec_argv(DEPLOY / "systemd" / "heft-dashboard.service")
    assert set(option(dashboard, "--connect")) <= endpoints


def test_the_dashboard_serves_on_loopback_for_the_guides_tunnel() -> None:
    values = service(DEPLOY / "systemd" / "heft-dashboard.service")
    argv = exec_argv(DEPLOY / "systemd" / "heft-dashboard.service")
    assert option(argv, "--host") == ["127.0.0.1"]
    port = option(argv, "--port")[0]
    assert f"ssh -N -L {port}:127.0.0.1:{port} operator@192.168.10.1" in GUIDE.read_text("utf-8")
    assert option(argv, "--team") == ["paper"]
    # the token's file is optional (the "-"): without it the unit still starts
    assert all(f.startswith("-") for f in values.get("EnvironmentFile", []))


# ----------------------------------------------------------------------------- command lines
def test_every_command_in_the_guides_code_blocks_is_real(heft) -> None:
    commands = [
        argv
        for block in code_blocks(GUIDE.read_text("utf-8"))
        for argv in heft_command_lines(block)
    ]
    assert len(commands) >= 6, commands  # certs, router-config, watch, sim, ...
    named = {leaf(heft, argv)[0] for argv in commands}
    assert {"deploy certs", "deploy router-config", "watch", "sim"} <= named, named
    for argv in commands:
        assert_parses(heft, argv, "deploy/README.md")


def test_every_command_in_the_guides_text_is_real(heft) -> None:
    spans = [" ".join(s.split()) for s in re.findall(r"`([^`]+)`", prose(GUIDE.read_text("utf-8")))]
    commands = [span.split()[1:] for span in spans if span.startswith("heft ")]
    assert commands
    for argv in commands:
        assert_options_listed(heft, argv, "deploy/README.md")


def test_every_command_in_the_files_comments_is_real(heft) -> None:
    """``#   heft ...`` in the robots' files and the units, ``//   heft ...`` in the router's
    config: what they tell an operator to run."""
    found = 0
    for path in [*ROBOTS.values(), *UNITS, ROUTER_JSON5]:
        for line in path.read_text(encoding="utf-8").splitlines():
            comment = re.match(r"^\s*(?:#|//)\s+(heft\s.*)$", line)
            if comment:
                for argv in heft_command_lines(comment[1]):
                    assert_parses(heft, argv, path.name)
                    found += 1
    assert found >= len(ROBOTS)


def test_guide_commands_use_the_deployed_endpoint_and_certificates(heft) -> None:
    endpoint = router_json5()["listen"]["endpoints"][0]
    for block in code_blocks(GUIDE.read_text("utf-8")):
        for argv in heft_command_lines(block):
            for connect in option(argv, "--connect") + option(argv, "--listen"):
                assert connect == endpoint, argv
            if option(argv, "--connect"):
                identity = Path(option(argv, "--tls-certificate")[0]).name.removesuffix(".pem")
                key = Path(option(argv, "--tls-private-key")[0]).name
                assert key == f"{identity}-key.pem", argv


# ----------------------------------------------------------------------------- robot configs
@pytest.mark.parametrize("robot", sorted(ROBOTS))
def test_robot_file_connects_over_tls_with_its_own_certificate(robot: int) -> None:
    zenoh = tomllib.loads(ROBOTS[robot].read_text(encoding="utf-8"))["zenoh"]
    assert zenoh["connect"] and all(e.startswith("tls/") for e in zenoh["connect"]), zenoh
    assert set(TLS_FILES) <= set(zenoh), zenoh
    assert zenoh["root_ca"] == f"{TLS_DIR}/ca.pem"
    assert zenoh["certificate"] == f"{TLS_DIR}/robot-{robot}.pem"
    assert zenoh["private_key"] == f"{TLS_DIR}/robot-{robot}-key.pem"
    assert not zenoh.get("allow_plain", False)
    assert "config_file" not in zenoh


@pytest.mark.parametrize("robot", sorted(ROBOTS))
def test_robot_file_loads_for_its_agent_and_its_bridge(robot: int, tmp_path: Path) -> None:
    from bridge.config import load_bridge_config

    copy = loadable_copy(ROBOTS[robot], tmp_path)
    agent = load_agent_config(copy)
    bridge = load_bridge_config(copy)
    assert agent.robot == robot and agent.team == "paper" and agent.clock == "realtime"
    for zenoh in (agent.zenoh, bridge.zenoh):
        assert zenoh.mode == "client" and zenoh.tls and not zenoh.allow_plain
        assert zenoh.certificate == str(tmp_path / "tls" / f"robot-{robot}.pem")
    assert bridge.robot == agent


def test_the_teams_units_and_files_name_the_same_team(heft) -> None:
    teams = {tomllib.loads(p.read_text("utf-8"))["team"] for p in ROBOTS.values()}
    assert teams == {"paper"}
    assert option(exec_argv(DEPLOY / "systemd" / "heft-dashboard.service"), "--team") == ["paper"]
    for block in code_blocks(GUIDE.read_text("utf-8")):
        for argv in heft_command_lines(block):
            assert set(option(argv, "--team")) <= teams, argv
