"""What is deployed on robots (deploy/), how an agent's ``robot.toml`` is checked, and the
process subcommands' bad input and help: all in one process, without a Zenoh network.

- deploy/paper/robot-<i>.toml load, agree with each other and with the paper's scenario, and are
  what the launcher would write for the team "paper" on the wall clock;
- ``load_agent_config`` turns every mistake into a one-line :class:`ConfigError` naming the file
  and the key;
- deploy/zenoh/router.json5 is the router ``heft router`` runs, secured (TLS only, no multicast;
  its access control is tested in tests/integration/test_secured_network.py);
- ``heft agent|sim|router|run`` exit 2 with one ``heft: error:`` line on bad input, and
  ``--help`` describes each command;
- the Zenoh options every process command shares (``--connect``, ``--listen``,
  ``--zenoh-config``) replace what they name and nothing else, and a Zenoh config file is the
  base the project's settings are applied on.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import re
import tomllib
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.algorithm.tuning import AgentTuning
from agent.node import AgentNodeConfig, load_agent_config
from agent.platform.cli_helpers import UsageError, add_zenoh_options, zenoh_settings
from agent.platform.config import ConfigError, from_table, toml_value
from agent.platform.faults import FaultSettings
from agent.platform.heft import main
from agent.platform.protocol import CLOCKS
from agent.platform.zenoh_session import DEFAULT_ROUTER, ZenohSettings, zenoh_config
from bridge.admittance import AdmittanceSettings
from bridge.config import CanSettings, can_table
from simulator.can_drivers import CanLink
from simulator.launcher import can_settings, robot_toml
from simulator.scenario import load_scenario
from tests.helpers.paths import PAPER, ROOT
from tests.helpers.tls import loadable_copy

DEPLOY = ROOT / "deploy"
ROBOT_FILES = {i: DEPLOY / "paper" / f"robot-{i}.toml" for i in range(1, 5)}
ROUTER_JSON5 = DEPLOY / "zenoh" / "router.json5"


@pytest.fixture(scope="module")
def paper():
    return load_scenario(PAPER)


@pytest.fixture(scope="module")
def loadable(tmp_path_factory) -> dict[int, Path]:
    """The deployed robot files, their TLS files (on the robots only) swapped for
    placeholders."""
    folder = tmp_path_factory.mktemp("deployed")
    return {i: loadable_copy(path, folder) for i, path in ROBOT_FILES.items()}


@pytest.fixture(scope="module")
def deployed(loadable) -> dict[int, AgentNodeConfig]:
    return {i: load_agent_config(path) for i, path in loadable.items()}


# ----------------------------------------------------------------------------- deploy/paper
def test_the_four_robot_files_are_there() -> None:
    assert sorted(p.name for p in (DEPLOY / "paper").glob("robot-*.toml")) == [
        f"robot-{i}.toml" for i in range(1, 5)
    ]


@pytest.mark.parametrize("robot", sorted(ROBOT_FILES))
def test_robot_file_loads_as_documented(robot: int, deployed) -> None:
    config = deployed[robot]
    assert config.robot == robot
    assert config.n == 4
    assert config.team == "paper"
    assert config.clock == "realtime"
    assert config.period_s == 0.01
    assert config.zenoh.mode == "client"
    assert config.zenoh.connect == ("tls/192.168.10.1:7447",)  # the router, over mutual TLS
    assert config.zenoh.listen == ()
    assert config.zenoh.certificate.endswith(f"/robot-{robot}.pem") and not config.zenoh.allow_plain
    assert config.faults == FaultSettings()  # no injected faults on robots
    assert config.tuning == AgentTuning()  # the defaults: the robust estimators, for real robots


@pytest.mark.parametrize("robot", sorted(ROBOT_FILES))
def test_robot_file_is_also_its_bridges_config(robot: int, deployed, loadable) -> None:
    """The robot's AGV bridge reads the same file: its bus, node id, 100 ms watchdog, Sync
    ticks and real-time priority; the agent part is the agent's."""
    from bridge.config import CanSettings, load_bridge_config

    config = load_bridge_config(loadable[robot])
    assert config.robot == deployed[robot]
    assert config.can == CanSettings(
        interface="socketcan", channel="can0", watchdog_ms=100, realtime_priority=50
    )
    assert config.node == robot


def test_robot_files_share_the_team_settings(deployed) -> None:
    def team_part(c: AgentNodeConfig) -> AgentNodeConfig:
        zenoh = dataclasses.replace(c.zenoh, certificate=None, private_key=None)  # its own
        return dataclasses.replace(c, robot=1, neighbours=(2,), zenoh=zenoh)

    assert len({team_part(c) for c in deployed.values()}) == 1


def test_neighbours_are_symmetric_and_match_the_paper_graph(deployed, paper) -> None:
    for i, config in deployed.items():
        for j in config.neighbours:
            assert i in deployed[j].neighbours, f"robot {i} lists {j}, but {j} does not list {i}"
    edges = {tuple(sorted((i, j))) for i, c in deployed.items() for j in c.neighbours}
    assert edges == {tuple(sorted(e)) for e in paper.edges} == {(1, 2), (2, 3), (3, 4)}
    for i, config in deployed.items():
        assert tuple(sorted(config.neighbours)) == paper.neighbours(i)
    assert deployed[1].n == paper.n and deployed[1].period_s == paper.period_s


@pytest.mark.parametrize("robot", sorted(ROBOT_FILES))
def test_robot_file_is_what_the_launcher_writes_for_the_paper_team(robot, deployed, paper) -> None:
    # The robots run the default estimators, made for real sensors and drives, where the
    # paper's scenario runs the paper's, the reference: its load and team with the defaults.
    team = dataclasses.replace(paper, agent=AgentTuning())
    generated = load_config_text(
        robot_toml(robot, team, "paper", "realtime", DEFAULT_ROUTER, FaultSettings())
    )  # (but for the [zenoh] table: the robots' is secured, the launcher's on loopback)
    assert dataclasses.replace(deployed[robot], zenoh=generated.zenoh) == generated


@pytest.mark.parametrize("robot", sorted(ROBOT_FILES))
def test_robot_file_explains_every_key(robot: int) -> None:
    lines = ROBOT_FILES[robot].read_text(encoding="utf-8").splitlines()
    data = tomllib.loads("\n".join(lines))
    assert "tuning" not in data and "faults" not in data  # defaults: left out
    previous = ""
    for line in lines:
        if re.match(r"^[a-z_]+\s*=", line) or line.startswith("["):
            assert previous.startswith("#"), f"no comment above {line!r}"
        if line.strip():
            previous = line
    text = "\n".join(lines)
    connect = text.index("connect =")
    assert "router host" in text[text.rindex("\n\n", 0, connect) : connect]


# ----------------------------------------------------------------------------- robot.toml errors
BASE = {
    "robot": 2,
    "n": 4,
    "neighbours": [1, 3],
    "team": "paper",
    "period_s": 0.01,
    "clock": "realtime",
}


def toml_text(top: dict, **tables: dict) -> str:
    """TOML for simple values (JSON's numbers, strings, booleans and lists are TOML too)."""
    lines = [f"{k} = {json.dumps(v)}" for k, v in top.items()]
    for name, table in tables.items():
        lines += ["", f"[{name}]"] + [f"{k} = {json.dumps(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


def load_config_text(text: str) -> AgentNodeConfig:
    return from_table(AgentNodeConfig, tomllib.loads(text), "agent")


def config_error(path: Path) -> str:
    with pytest.raises(ConfigError) as caught:
        load_agent_config(path)
    message = str(caught.value)
    assert "\n" not in message, message
    assert message.startswith(f"{path}: "), message
    return message


def test_a_valid_minimal_file_loads(tmp_path: Path) -> None:
    path = tmp_path / "robot.toml"
    path.write_text(toml_text(BASE), encoding="utf-8")
    config = load_agent_config(path)
    assert config.robot == 2 and config.neighbours == (1, 3)
    assert config.zenoh == ZenohSettings() and config.zenoh.connect == (DEFAULT_ROUTER,)


def test_missing_file(tmp_path: Path) -> None:
    message = config_error(tmp_path / "robot-9.toml")
    assert "cannot read" in message


@pytest.mark.parametrize(
    "text",
    ["robot = = 2\n", "robot = 2\nrobot = 3\n", "[zenoh\nmode = 'client'\n", 'team = "paper\n'],
    ids=["double-equals", "repeated-key", "unclosed-table", "unclosed-string"],
)
def test_invalid_toml(tmp_path: Path, text: str) -> None:
    path = tmp_path / "robot.toml"
    path.write_text(text, encoding="utf-8")
    assert "not valid TOML" in config_error(path)


def test_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "robot.toml"
    path.write_bytes(b'team = "caf\xe9"\n')
    assert "not valid TOML" in config_error(path)


CASES = {
    "unknown-top-level-key": (toml_text({**BASE, "colour": "red"}), "agent.colour"),
    "unknown-zenoh-key": (toml_text(BASE, zenoh={"router": DEFAULT_ROUTER}), "agent.zenoh.router"),
    "unknown-table": (toml_text(BASE, network={"mode": "client"}), "agent.network"),
    "missing-robot": (toml_text({k: v for k, v in BASE.items() if k != "robot"}), "agent.robot"),
    "missing-neighbours": (
        toml_text({k: v for k, v in BASE.items() if k != "neighbours"}),
        "agent.neighbours",
    ),
    "robot-0": (toml_text({**BASE, "robot": 0, "neighbours": [1]}), "agent.robot"),
    "robot-above-n": (toml_text({**BASE, "robot": 5, "neighbours": [4]}), "agent.robot"),
    "robot-not-an-integer": (toml_text({**BASE, "robot": "two"}), "agent.robot"),
    "robot-float": (toml_text({**BASE, "robot": 2.0}), "agent.robot"),
    "n-1": (toml_text({**BASE, "n": 1, "robot": 1, "neighbours": [2]}), "agent.n"),
    "neighbour-itself": (toml_text({**BASE, "neighbours": [1, 2]}), "agent.neighbours"),
    "neighbour-0": (toml_text({**BASE, "neighbours": [0, 3]}), "agent.neighbours"),
    "neighbour-above-n": (toml_text({**BASE, "neighbours": [3, 5]}), "agent.neighbours"),
    "neighbour-repeated": (toml_text({**BASE, "neighbours": [1, 1]}), "agent.neighbours"),
    "no-neighbours": (toml_text({**BASE, "neighbours": []}), "agent.neighbours"),
    "neighbours-not-a-list": (toml_text({**BASE, "neighbours": 1}), "agent.neighbours"),
    "neighbour-string": (toml_text({**BASE, "neighbours": [1, "3"]}), "agent.neighbours[1]"),
    "clock-fast": (toml_text({**BASE, "clock": "fast"}), "agent.clock"),
    "team-with-slash": (toml_text({**BASE, "team": "pa/per"}), "agent.team"),
    "team-empty": (toml_text({**BASE, "team": ""}), "agent.team"),
    "period-zero": (toml_text({**BASE, "period_s": 0}), "period_s"),
    "endpoint-without-protocol": (
        toml_text(BASE, zenoh={"connect": ["127.0.0.1:7447"]}),
        "agent.zenoh.connect[0]",
    ),
    "endpoint-without-port": (
        toml_text(BASE, zenoh={"connect": [DEFAULT_ROUTER, "tcp/127.0.0.1"]}),
        "agent.zenoh.connect[1]",
    ),
    "endpoint-bad-protocol": (
        toml_text(BASE, zenoh={"connect": ["http/127.0.0.1:7447"]}),
        "agent.zenoh.connect[0]",
    ),
    "endpoint-not-a-list": (
        toml_text(BASE, zenoh={"connect": DEFAULT_ROUTER}),
        "agent.zenoh.connect",
    ),
    "client-without-router": (toml_text(BASE, zenoh={"connect": []}), "agent.zenoh.connect"),
    "router-without-listen": (
        toml_text(BASE, zenoh={"mode": "router", "connect": []}),
        "agent.zenoh.listen",
    ),
    "zenoh-mode-unknown": (toml_text(BASE, zenoh={"mode": "broker"}), "agent.zenoh.mode"),
    "lease-too-short": (toml_text(BASE, zenoh={"lease_ms": 10}), "lease_ms"),
    "zenoh-config-file-missing": (
        toml_text(BASE, zenoh={"config_file": "/nonexistent/zenoh.json5"}),
        "agent.zenoh.config_file",
    ),
    "faults-drop-1.5": (toml_text(BASE, faults={"drop": 1.5}), "agent.faults.drop"),
    "faults-drop-1": (toml_text(BASE, faults={"drop": 1.0}), "agent.faults.drop"),
    "faults-drop-negative": (toml_text(BASE, faults={"drop": -0.1}), "agent.faults.drop"),
    "faults-negative-delay": (
        toml_text(BASE, faults={"delay_s": -0.01}),
        "agent.faults.delay_s",
    ),
    "tuning-unknown": (toml_text(BASE, tuning={"max_speed": 1.0}), "agent.tuning.max_speed"),
    "tuning-negative": (toml_text(BASE, tuning={"max_force": -1.0}), "agent.tuning.max_force"),
    "tuning-kick-above-max": (
        toml_text(BASE, tuning={"max_force": 1.0, "kick_force": 2.0}),
        "agent.tuning.kick_force",
    ),
}


@pytest.mark.parametrize("text, key", CASES.values(), ids=CASES.keys())
def test_bad_config_names_the_file_and_the_key(tmp_path: Path, text: str, key: str) -> None:
    path = tmp_path / "robot.toml"
    path.write_text(text, encoding="utf-8")
    message = config_error(path)
    assert re.search(rf"(^|\W){re.escape(key)}(\W|$)", message), message


def test_lockstep_and_realtime_are_the_clocks(tmp_path: Path) -> None:
    assert CLOCKS == ("lockstep", "realtime")
    for clock in CLOCKS:
        assert load_config_text(toml_text({**BASE, "clock": clock})).clock == clock


# ----------------------------------------------------------------------------- launcher round trip
@pytest.mark.parametrize("robot", [1, 2, 3, 4])
def test_launcher_robot_toml_round_trips(robot: int, paper) -> None:
    router = "tcp/127.0.0.1:40123"
    faults = FaultSettings()
    text = robot_toml(robot, paper, "paper-4242", "lockstep", router, faults)
    config = from_table(AgentNodeConfig, tomllib.loads(text), "agent")
    assert config == AgentNodeConfig(
        robot=robot,
        n=4,
        neighbours=paper.neighbours(robot),
        team="paper-4242",
        period_s=0.01,
        seed=paper.run.seed,
        clock="lockstep",
        zenoh=ZenohSettings(mode="client", connect=(router,)),
        faults=FaultSettings(),
        tuning=paper.agent,
    )
    assert config.neighbours == {1: (2,), 2: (1, 3), 3: (2, 4), 4: (3,)}[robot]
    assert config.tuning == paper.agent != AgentTuning()  # the scenario's: the paper's estimators


@given(st.text(st.characters(exclude_categories=("Cs",))))
def test_a_toml_string_reads_back_as_written(text: str) -> None:
    assert tomllib.loads(f"x = {toml_value(text)}") == {"x": text}


def test_the_launchers_can_table_reads_back_whatever_the_names() -> None:
    settings = can_settings(3, CanLink(interface="socketcan", channel='can\\"{robot}'), 50)
    assert settings.channel == 'can\\"3' and settings.node == 3 and settings.watchdog_ms == 50
    assert settings.watchdog_clock == "wall"
    lockstep = can_settings(3, CanLink(), 200, clock="lockstep")
    assert lockstep.watchdog_clock == "bus" and lockstep.time_source == "sync"
    lockstep.validate("can")
    table = tomllib.loads(can_table(settings))["can"]
    assert from_table(CanSettings, table, "can") == settings
    loop = AdmittanceSettings(mass=2.5, damping=7.25, tare_samples=3)
    velocity = dataclasses.replace(settings, profile="velocity", admittance=loop)
    table = tomllib.loads(can_table(velocity))["can"]
    assert from_table(CanSettings, table, "can") == velocity


def test_launcher_robot_toml_carries_faults_and_tuning(paper) -> None:
    faults = FaultSettings(drop=0.1, delay_s=0.02, seed=7)
    tuned = dataclasses.replace(paper, agent=AgentTuning(max_force=12.5, push_direction=(1, 0)))
    text = robot_toml(3, tuned, 'odd "team" \\ name', "realtime", DEFAULT_ROUTER, faults)
    config = load_config_text(text)
    assert config.faults == faults
    assert config.tuning == tuned.agent
    assert config.team == 'odd "team" \\ name'


# ----------------------------------------------------------------------------- router.json5
def strip_json5(text: str) -> str:
    """The JSON of this JSON5 subset: // and /* */ comments, bare keys, trailing commas."""
    out, i, in_string = [], 0, False
    while i < len(text):
        c = text[i]
        if in_string:
            out.append(c)
            if c == "\\":
                out.append(text[i + 1])
                i += 1
            elif c == '"':
                in_string = False
        elif c == '"':
            in_string = True
            out.append(c)
        elif text.startswith("//", i):
            i = text.find("\n", i)
            i = len(text) if i < 0 else i
            continue
        elif text.startswith("/*", i):
            i = text.index("*/", i) + 2
            continue
        else:
            out.append(c)
        i += 1
    plain = "".join(out)
    plain = re.sub(r"([{,]\s*)([A-Za-z_][A-Za-z0-9_]*)\s*:", r'\1"\2":', plain)
    return re.sub(r",(\s*[}\]])", r"\1", plain)


def test_strip_json5_helper() -> None:
    text = '{\n  // c\n  a: "x//y", /* b */ b: [1, 2,],\n  c: {d: "e\\"f",},\n}\n'
    assert json.loads(strip_json5(text)) == {"a": "x//y", "b": [1, 2], "c": {"d": 'e"f'}}


@pytest.fixture(scope="module")
def router_config() -> dict:
    return json.loads(strip_json5(ROUTER_JSON5.read_text(encoding="utf-8")))


def _endpoints(node) -> list[str]:
    if isinstance(node, dict):
        return [e for k, v in node.items() for e in _endpoints(v) if k != "autoconnect"]
    if isinstance(node, list):
        return [e for v in node for e in _endpoints(v)]
    return [node] if isinstance(node, str) and "/" in node else []


def test_router_config_is_a_tls_router_without_multicast(router_config: dict) -> None:
    assert router_config["mode"] == "router"
    assert router_config["listen"]["endpoints"] == ["tls/192.168.10.1:7447"]
    assert router_config.get("connect", {}).get("endpoints", []) == []
    assert router_config["scouting"]["multicast"]["enabled"] is False
    gossip = router_config["scouting"].get("gossip", {})
    assert gossip.get("multihop", False) is False
    assert gossip.get("autoconnect", {}).get("router", []) == []  # never dials out
    assert router_config["transport"]["shared_memory"]["enabled"] is False
    endpoints = [e for e in _endpoints(router_config) if re.match(r"^[a-z]+/[^/]+:\d+$", e)]
    assert endpoints and all(e.startswith("tls/") for e in endpoints), endpoints
    assert router_config["transport"]["link"]["tls"]["enable_mtls"] is True


def test_router_config_is_what_heft_router_runs() -> None:
    zenoh = pytest.importorskip("zenoh")
    deployed = zenoh.Config.from_file(str(ROUTER_JSON5))  # zenohd's own parser and schema
    ours = zenoh_config(ZenohSettings(mode="router", connect=(), listen=(DEFAULT_ROUTER,)))
    for key in (  # its listen endpoint is on the robots' network (heft router --listen)
        "mode",
        "connect/endpoints",
        "scouting/multicast/enabled",
        "transport/shared_memory/enabled",
        "transport/link/tx/lease",
        "transport/link/tx/keep_alive",
    ):
        assert json.loads(deployed.get_json(key)) == json.loads(ours.get_json(key)), key


# ----------------------------------------------------------------------------- systemd units
def _unit(name: str) -> dict[str, list[str]]:
    values: dict[str, list[str]] = {}
    for line in (DEPLOY / "systemd" / name).read_text(encoding="utf-8").splitlines():
        if "=" in line and not line.startswith(("#", ";")):
            key, value = line.split("=", 1)
            values.setdefault(key.strip(), []).append(value.strip())
    return values


def test_agent_unit() -> None:
    unit = _unit("heft-agent@.service")
    assert unit["ExecStart"] == ["/opt/heft/.venv/bin/heft agent --config /etc/heft/robot-%i.toml"]
    assert unit["Restart"] == ["on-failure"]
    assert "network-online.target" in unit["After"][0].split()
    assert "network-online.target" in unit["Wants"][0].split()
    assert unit["User"] == ["heft"]
    assert "2" in unit["RestartPreventExitStatus"][0].split()  # a bad config does not loop


def test_router_unit() -> None:
    unit = _unit("heft-router.service")
    (start,) = unit["ExecStart"]
    assert start.startswith("/opt/heft/.venv/bin/heft router ")
    assert "--zenoh-config /etc/heft/router.json5" in start  # secured: TLS, access control
    assert unit["Restart"] == ["on-failure"]
    assert "network-online.target" in unit["After"][0].split()
    assert unit["DynamicUser"] == ["yes"]
    assert not (DEPLOY / "systemd" / "heft-sim.service").exists()


# ----------------------------------------------------------------------------- the command line
def assert_usage_error(code: int, err: str, *words: str) -> str:
    assert code == 2, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert lines and lines[-1].startswith("heft: error: "), err
    for word in words:
        assert word in lines[-1], err
    return lines[-1]


def test_agent_with_a_bad_config(tmp_path: Path, capsys) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(toml_text({**BASE, "robot": 0, "neighbours": [1]}), encoding="utf-8")
    code = main(["agent", "--config", str(path)])
    out, err = capsys.readouterr()
    assert_usage_error(code, err, str(path), "agent.robot")
    assert len(err.strip().splitlines()) == 1 and out == ""


def test_agent_with_a_missing_config(tmp_path: Path, capsys) -> None:
    code = main(["agent", "--config", str(tmp_path / "missing.toml")])
    _, err = capsys.readouterr()
    assert_usage_error(code, err, "missing.toml")
    assert len(err.strip().splitlines()) == 1


def test_agent_with_invalid_toml(tmp_path: Path, capsys) -> None:
    path = tmp_path / "bad.toml"
    path.write_text("robot = \n", encoding="utf-8")
    code = main(["agent", "--config", str(path)])
    _, err = capsys.readouterr()
    assert_usage_error(code, err, str(path), "not valid TOML")
    assert len(err.strip().splitlines()) == 1


def test_sim_with_a_missing_scenario(tmp_path: Path, capsys) -> None:
    code = main(["sim", str(tmp_path / "missing.toml")])
    _, err = capsys.readouterr()
    assert_usage_error(code, err, "missing.toml")


@pytest.mark.parametrize("endpoint", ["notanendpoint", "127.0.0.1:7447", "tcp/127.0.0.1"])
def test_sim_with_a_bad_endpoint(endpoint: str, capsys) -> None:
    code = main(["sim", str(PAPER), "--connect", endpoint])
    _, err = capsys.readouterr()
    assert_usage_error(code, err, "--connect", endpoint)


@pytest.mark.parametrize("endpoint", ["bad", "127.0.0.1:7447", "tcp/:7447"])
def test_router_with_a_bad_endpoint(endpoint: str, capsys) -> None:
    code = main(["router", "--listen", endpoint])
    _, err = capsys.readouterr()
    assert_usage_error(code, err, "--listen", endpoint)


@pytest.mark.parametrize("transport", ["inprocess", "zenoh"])
@pytest.mark.parametrize("options", [["--drop", "1.5"], ["--drop", "-0.5"], ["--delay-ms", "-1"]])
def test_run_with_bad_faults(transport: str, options: list[str], capsys) -> None:
    code = main(["run", str(PAPER), "--quiet", "--transport", transport, *options])
    out, err = capsys.readouterr()
    assert_usage_error(code, err, options[0].lstrip("-").split("-")[0])
    assert len(err.strip().splitlines()) == 1 and out == ""


@pytest.mark.parametrize("options", [["--delay-ms", "5"], ["--clock", "realtime"]])
def test_run_in_one_process_refuses_what_only_processes_do(options: list[str], capsys) -> None:
    """The wall clock and a network's delay are the processes' (``--transport zenoh``): in one
    process they would be silently ignored."""
    code = main(["run", str(PAPER), "--quiet", *options])
    out, err = capsys.readouterr()
    assert_usage_error(code, err, options[0], "--transport zenoh")
    assert len(err.strip().splitlines()) == 1 and out == ""


def test_run_with_drop_1_5_without_quiet(capsys) -> None:
    code = main(["run", str(PAPER), "--drop", "1.5"])
    _, err = capsys.readouterr()
    assert_usage_error(code, err, "--drop", "1.5")


HELP = {
    "agent": ("--config", "Run one robot's agent"),
    "sim": ("SCENARIO", "Run the pymunk plant of SCENARIO"),
    "router": ("--listen", "Run a Zenoh router"),
    "demo": ("--out", "Run the paper's Sec. VI scenario"),
}
ZENOH_COMMANDS = ("agent", "sim", "router")


@pytest.mark.parametrize("command", HELP)
def test_help(command: str, capsys) -> None:
    with pytest.raises(SystemExit) as exited:
        main([command, "--help"])
    assert exited.value.code == 0
    out, _ = capsys.readouterr()
    option, description = HELP[command]
    assert out.startswith(f"usage: heft {command}")
    assert option in out and description in out


def test_top_level_help_lists_the_process_commands(capsys) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["--help"])
    assert exited.value.code == 0
    out, _ = capsys.readouterr()
    for command in HELP:
        assert re.search(rf"^\s+{command}\s+\S", out, re.M), command


@pytest.mark.parametrize("command", ZENOH_COMMANDS)
def test_every_process_command_documents_the_zenoh_options(command: str, capsys) -> None:
    with pytest.raises(SystemExit):
        main([command, "--help"])
    out, _ = capsys.readouterr()
    for option in ("--connect ENDPOINT", "--listen ENDPOINT", "--zenoh-config FILE"):
        assert option in out, option
    assert "Multicast scouting is always off" in out


# ----------------------------------------------------------------------------- Zenoh options
ZENOH_ARGS = {
    "agent": ["agent", "--config", "ROBOT_1"],  # (see _robot_1)
    "sim": ["sim", str(PAPER)],
    "router": ["router"],
}
JSON5 = '{\n  // a comment\n  mode: "peer",\n  scouting: { multicast: { enabled: true } },\n}\n'


@pytest.fixture(autouse=True)
def _robot_1(loadable, monkeypatch) -> None:
    """``heft agent``'s config in :data:`ZENOH_ARGS`: robot 1's deployed file, loadable."""
    monkeypatch.setitem(ZENOH_ARGS, "agent", ["agent", "--config", str(loadable[1])])


def parse_zenoh_options(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_zenoh_options(parser, connect="c", listen="l")
    return parser.parse_args(argv)


@pytest.mark.parametrize("command", ZENOH_COMMANDS)
@pytest.mark.parametrize("option", ["--connect", "--listen"])
@pytest.mark.parametrize("endpoint", ["bad", "127.0.0.1:7447", "tcp/127.0.0.1"])
def test_a_bad_endpoint_names_the_option(command, option, endpoint, capsys) -> None:
    code = main([*ZENOH_ARGS[command], option, DEFAULT_ROUTER, option, endpoint])
    out, err = capsys.readouterr()
    line = assert_usage_error(code, err, option, repr(endpoint))
    assert line.startswith(f"heft: error: {option}: expected an explicit endpoint")
    assert len(err.strip().splitlines()) == 1 and out == ""


@pytest.mark.parametrize("command", ZENOH_COMMANDS)
def test_a_missing_zenoh_config_file_names_the_option(command, tmp_path: Path, capsys) -> None:
    missing = tmp_path / "missing.json5"
    code = main([*ZENOH_ARGS[command], "--zenoh-config", str(missing)])
    out, err = capsys.readouterr()
    line = assert_usage_error(code, err, "--zenoh-config", str(missing), "cannot read")
    assert line.startswith("heft: error: --zenoh-config: ")
    assert len(err.strip().splitlines()) == 1 and out == ""


@pytest.mark.parametrize("command", ZENOH_COMMANDS)
@pytest.mark.parametrize(
    "text, words",
    [("{ mode: ", ("1:9", "expected")), ("{\n  colour: 3 }", ("2:3", "unknown field", "colour"))],
    ids=["unfinished", "unknown-key"],
)
def test_an_invalid_zenoh_config_file_is_one_line(command, text, words, tmp_path, capsys) -> None:
    bad = tmp_path / "bad.json5"
    bad.write_text(text, encoding="utf-8")
    code = main([*ZENOH_ARGS[command], "--zenoh-config", str(bad)])
    _, err = capsys.readouterr()
    assert_usage_error(code, err, "--zenoh-config", str(bad), "not a valid Zenoh config", *words)
    assert len(err.strip().splitlines()) == 1


def test_a_directory_is_not_a_zenoh_config_file(tmp_path: Path) -> None:
    with pytest.raises(UsageError, match=r"^--zenoh-config: .*: cannot read"):
        zenoh_settings(parse_zenoh_options("--zenoh-config", str(tmp_path)), ZenohSettings())


def test_without_zenoh_options_the_base_settings_stay(deployed) -> None:
    base = deployed[1].zenoh
    assert zenoh_settings(parse_zenoh_options(), base) == base


def test_zenoh_options_replace_what_they_name_and_nothing_else(deployed, tmp_path) -> None:
    """``heft agent --connect ...`` overrides robot.toml's ``[zenoh] connect`` only."""
    path = tmp_path / "zenoh.json5"
    path.write_text(JSON5, encoding="utf-8")
    base = dataclasses.replace(deployed[1].zenoh, lease_ms=3000, allow_plain=True)
    args = parse_zenoh_options(
        "--connect",
        "tcp/10.0.0.1:7447",
        "--connect",
        "tcp/10.0.0.2:7447",
        "--listen",
        "tcp/0.0.0.0:7448",
        "--zenoh-config",
        str(path),
    )
    assert zenoh_settings(args, base) == dataclasses.replace(
        base,
        connect=("tcp/10.0.0.1:7447", "tcp/10.0.0.2:7447"),
        listen=("tcp/0.0.0.0:7448",),
        config_file=str(path),
    )
    connect_only = zenoh_settings(parse_zenoh_options("--connect", "tcp/10.0.0.1:7447"), base)
    assert connect_only == dataclasses.replace(base, connect=("tcp/10.0.0.1:7447",))


def test_a_zenoh_config_file_is_the_base_of_the_projects_settings(tmp_path: Path) -> None:
    pytest.importorskip("zenoh")
    path = tmp_path / "zenoh.json5"
    path.write_text(JSON5.replace("mode", "queries_default_timeout: 1234,\n  mode"), "utf-8")
    settings = ZenohSettings(mode="client", connect=(DEFAULT_ROUTER,), config_file=str(path))
    config = zenoh_config(settings)
    assert json.loads(config.get_json("queries_default_timeout")) == 1234  # the file's own
    assert json.loads(config.get_json("mode")) == "client"  # the project's, on top
    assert json.loads(config.get_json("scouting/multicast/enabled")) is False
    assert json.loads(config.get_json("connect/endpoints")) == [DEFAULT_ROUTER]


def test_a_robot_toml_can_name_a_zenoh_config_file(tmp_path: Path) -> None:
    path = tmp_path / "zenoh.json5"
    path.write_text(JSON5, encoding="utf-8")
    config = load_config_text(toml_text(BASE, zenoh={"config_file": str(path)}))
    assert config.zenoh.config_file == str(path)
