"""The secured Zenoh network's parts, without a network: the ``[zenoh]`` TLS settings and the
plain-link rule (agent/platform/zenoh_session.py), the team's certificates
(agent/security/certificates.py), the router's access control by identity and its config
(agent/security/access_control.py), and ``heft deploy``. The router and its clients on loopback
are in tests/integration/test_secured_network.py."""

from __future__ import annotations

import argparse
import dataclasses
import ipaddress
import json
import re
import stat
from pathlib import Path

import pytest

from agent.platform.cli_helpers import UsageError, add_zenoh_options, zenoh_settings
from agent.platform.config import ConfigError
from agent.platform.heft import main
from agent.platform.protocol import Keys
from agent.platform.zenoh_session import ZenohSettings, describe, zenoh_config
from agent.security.access_control import (
    AccessError,
    access_control,
    parse_edges,
    router_config,
    router_config_text,
    team_grants,
)
from agent.security.certificates import CertificateError, make_certificates, team_identities
from tests.helpers.paths import ROOT
from tests.helpers.tls import tls_files

LINE = ((1, 2), (2, 3), (3, 4))
ROUTER_JSON5 = ROOT / "deploy" / "zenoh" / "router.json5"
PAPER_ROUTER = dict(
    team="paper",
    robots=4,
    edges=LINE,
    listen=["tls/192.168.10.1:7447"],
    certs="/etc/heft/tls",
)


# ------------------------------------------------------------------------------ settings
def test_tls_settings_put_zenohs_mutual_tls_keys(certs: Path) -> None:
    client = ZenohSettings(connect=("tls/127.0.0.1:7447",), **tls_files(certs, "robot-1"))
    client.validate("zenoh")
    tls = json.loads(zenoh_config(client).get_json("transport/link/tls"))
    assert tls["root_ca_certificate"] == str(certs / "ca.pem")
    assert tls["connect_certificate"] == str(certs / "robot-1.pem")
    assert tls["connect_private_key"] == str(certs / "robot-1-key.pem")
    assert tls["enable_mtls"] is True
    assert tls["listen_certificate"] is None and tls["listen_private_key"] is None

    router = ZenohSettings(
        mode="router", connect=(), listen=("tls/127.0.0.1:7447",), **tls_files(certs, "router")
    )
    router.validate("zenoh")
    tls = json.loads(zenoh_config(router).get_json("transport/link/tls"))
    assert tls["listen_certificate"] == str(certs / "router.pem")
    assert tls["listen_private_key"] == str(certs / "router-key.pem")
    assert tls["enable_mtls"] is True and tls["connect_certificate"] is None

    plain = json.loads(zenoh_config(ZenohSettings()).get_json("transport/link/tls"))
    assert plain["root_ca_certificate"] is None and plain["enable_mtls"] is None


def test_the_three_tls_files_go_together_and_must_be_readable(certs: Path) -> None:
    files = tls_files(certs, "robot-1")
    for left_out in files:
        some = {key: value for key, value in files.items() if key != left_out}
        with pytest.raises(ConfigError, match=rf"^zenoh\.{left_out}: missing: root_ca, cert"):
            ZenohSettings(**some).validate("zenoh")

    def check(settings: ZenohSettings) -> None:
        settings.validate("zenoh")
        settings.check_private_key("zenoh.private_key")  # (once the command line had its say)

    for key in files:
        missing = {**files, key: str(certs / "nowhere.pem")}
        with pytest.raises(ConfigError, match=rf"^zenoh\.{key}: .*nowhere\.pem: cannot read"):
            check(ZenohSettings(**missing))
        folder = {**files, key: str(certs)}  # a folder cannot be read as a file
        with pytest.raises(ConfigError, match=rf"^zenoh\.{key}: .*: cannot read") as refused:
            check(ZenohSettings(**folder))
        assert "\n" not in str(refused.value)
    # The private key alone is left to the command line: systemd hands it over elsewhere.
    elsewhere = ZenohSettings(**{**files, "private_key": str(certs / "nowhere.pem")})
    elsewhere.validate("zenoh")


@pytest.mark.parametrize(
    "endpoint", ["tcp/10.0.0.1:7447", "udp/192.168.10.1:7447", "tcp/0.0.0.0:7447", "tcp/host:1"]
)
@pytest.mark.parametrize("key", ["connect", "listen"])
def test_plain_links_off_loopback_are_refused_unless_allowed(endpoint: str, key: str) -> None:
    settings = ZenohSettings(mode="peer", **{"connect": (), "listen": (), key: (endpoint,)})
    with pytest.raises(ConfigError) as refused:
        settings.validate("zenoh")
    assert str(refused.value) == (
        f"zenoh.{key}[0]: {endpoint}: plain {endpoint[:3]} to a non-loopback address: use"
        " tls/HOST:PORT with root_ca, certificate and private_key (deploy/README.md), or set"
        " allow_plain = true"
    )
    dataclasses.replace(settings, allow_plain=True).validate("zenoh")


@pytest.mark.parametrize(
    "endpoint",
    ["tcp/127.0.0.1:7447", "tcp/127.8.9.10:7447", "tcp/localhost:7447", "udp/127.0.0.1:9"],
)
def test_plain_links_on_loopback_are_fine(endpoint: str) -> None:
    ZenohSettings(connect=(endpoint,)).validate("zenoh")


def test_a_tls_endpoint_needs_the_certificates(certs: Path) -> None:
    with pytest.raises(ConfigError, match=r"^zenoh\.connect\[0\]: tls/10\.0\.0\.1:7447: a tls"):
        ZenohSettings(connect=("tls/10.0.0.1:7447",)).validate("zenoh")
    ZenohSettings(connect=("tls/10.0.0.1:7447",), **tls_files(certs, "plant")).validate("zenoh")
    # or a Zenoh config file that gives them (heft router --zenoh-config router.json5)
    ZenohSettings(
        mode="router", connect=(), listen=("tls/10.0.0.1:7447",), config_file=str(ROUTER_JSON5)
    ).validate("zenoh")


def test_a_robot_toml_takes_the_tls_settings(certs: Path) -> None:
    from agent.node import load_agent_config

    path = certs.parent / "robot-1.toml"
    files = tls_files(certs, "robot-1")
    lines = [f'{key} = "{value}"' for key, value in files.items()]
    path.write_text(
        'robot = 1\nn = 2\nneighbours = [2]\n[zenoh]\nconnect = ["tls/192.168.10.1:7447"]\n'
        + "\n".join(lines)
        + "\n",
        encoding="utf-8",
    )
    config = load_agent_config(path)
    assert config.zenoh.certificate == files["certificate"] and not config.zenoh.allow_plain


# ------------------------------------------------------------------------------ CLI options
def parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_zenoh_options(parser, connect="c", listen="l")
    return parser.parse_args(argv)


def tls_options(folder: Path, identity: str) -> list[str]:
    files = tls_files(folder, identity)
    return [
        "--tls-root-ca",
        files["root_ca"],
        "--tls-certificate",
        files["certificate"],
        "--tls-private-key",
        files["private_key"],
    ]


def test_tls_options_replace_the_table(certs: Path) -> None:
    base = ZenohSettings(connect=("tls/192.168.10.1:7447",), **tls_files(certs, "robot-1"))
    settings = zenoh_settings(parse(*tls_options(certs, "robot-2")), base)
    assert settings == dataclasses.replace(base, **tls_files(certs, "robot-2"))
    one = zenoh_settings(parse("--tls-certificate", str(certs / "plant.pem")), base)
    assert one.certificate == str(certs / "plant.pem") and one.root_ca == base.root_ca


def test_tls_options_are_checked_like_the_table(certs: Path) -> None:
    with pytest.raises(UsageError, match=r"^--tls-certificate: missing: root_ca, certificate"):
        zenoh_settings(parse("--tls-root-ca", str(certs / "ca.pem")), ZenohSettings())
    with pytest.raises(UsageError, match=r"^--tls-private-key: .*nowhere: cannot read"):
        zenoh_settings(parse("--tls-private-key", str(certs / "nowhere")), ZenohSettings())
    with pytest.raises(UsageError, match=r"^--connect: tcp/10\.0\.0\.1:7447: plain tcp to a non"):
        zenoh_settings(parse("--connect", "tcp/10.0.0.1:7447"), ZenohSettings())
    allowed = zenoh_settings(
        parse("--connect", "tcp/10.0.0.1:7447", "--allow-plain"), ZenohSettings()
    )
    assert allowed.allow_plain and allowed.connect == ("tcp/10.0.0.1:7447",)
    secured = zenoh_settings(
        parse("--connect", "tls/10.0.0.1:7447", *tls_options(certs, "plant")), ZenohSettings()
    )
    assert secured.connect == ("tls/10.0.0.1:7447",) and secured.tls
    router = zenoh_settings(
        parse("--listen", "tls/10.0.0.1:7447", "--zenoh-config", str(ROUTER_JSON5)),
        ZenohSettings(mode="router", connect=(), listen=("tcp/127.0.0.1:7447",)),
    )
    assert router.listen == ("tls/10.0.0.1:7447",)  # the router's TLS is in the file


def test_a_refused_tls_option_is_one_line(capsys, tmp_path: Path) -> None:
    code = main(["router", "--listen", "tcp/192.168.10.1:7447"])
    _, err = capsys.readouterr()
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith("heft: error: --listen: tcp/192.168.10.1:7447: plain tcp")
    assert err.rstrip().endswith("or give --allow-plain")
    code = main(["router", "--tls-root-ca", str(tmp_path / "no-ca.pem")])
    _, err = capsys.readouterr()
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith("heft: error: --tls-root-ca: ") and "no-ca.pem: cannot read" in err


# ------------------------------------------------------------------------------ certificates
def test_certificates_files_modes_names_and_signatures(certs: Path) -> None:
    from cryptography import x509
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    assert stat.S_IMODE(certs.stat().st_mode) == 0o700
    names = team_identities(4)
    robots = [f"robot-{i}" for i in range(1, 5)]
    assert names == ["router", *robots, "plant", "operator", "dashboard"]
    expected = {"ca.pem", "ca-key.pem"} | {f"{n}.pem" for n in names}
    expected |= {f"{n}-key.pem" for n in names}
    assert {p.name for p in certs.iterdir()} == expected
    ca = x509.load_pem_x509_certificate((certs / "ca.pem").read_bytes())
    assert ca.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    for path in certs.iterdir():
        mode = stat.S_IMODE(path.stat().st_mode)
        assert mode == (0o600 if path.name.endswith("-key.pem") else 0o644), path
    for name in names:
        cert = x509.load_pem_x509_certificate((certs / f"{name}.pem").read_bytes())
        cert.verify_directly_issued_by(ca)
        cn = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
        assert [a.value for a in cn] == [name]
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        assert san.get_values_for_type(x509.IPAddress) == [ipaddress.ip_address("127.0.0.1")]
        eku = cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
        assert {ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH} <= set(eku)
        assert not cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
        assert b"PRIVATE KEY" in (certs / f"{name}-key.pem").read_bytes()


def test_certificates_are_never_overwritten_without_force(tmp_path: Path) -> None:
    from cryptography import x509

    folder = tmp_path / "tls"
    make_certificates(folder, ["router", "robot-1"], hosts=["router.lan", "10.1.2.3"], days=30)
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    with pytest.raises(CertificateError, match=r"ca\.pem: a CA is already there; --force"):
        make_certificates(folder, ["router", "robot-1"])
    with pytest.raises(CertificateError, match=r"robot-1\.pem: already there; --force"):
        make_certificates(folder, ["robot-1"], new_ca=False)
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before
    # a new robot, signed by the CA already there
    made = make_certificates(folder, ["robot-2"], hosts=["10.1.2.3"], new_ca=False)
    assert not made.new_ca and sorted(p.name for p in made.files) == [
        "robot-2-key.pem",
        "robot-2.pem",
    ]
    ca = x509.load_pem_x509_certificate((folder / "ca.pem").read_bytes())
    robot2 = x509.load_pem_x509_certificate((folder / "robot-2.pem").read_bytes())
    robot2.verify_directly_issued_by(ca)
    assert (folder / "ca.pem").read_bytes() == before["ca.pem"]
    router = x509.load_pem_x509_certificate(before["router.pem"])
    san = router.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert san.get_values_for_type(x509.DNSName) == ["router.lan"]
    days = router.not_valid_after_utc - router.not_valid_before_utc
    assert 30 <= days.days <= 31
    # with force, a new CA and new keys
    make_certificates(folder, ["router", "robot-1"], force=True)
    assert (folder / "ca-key.pem").read_bytes() != before["ca-key.pem"]
    assert stat.S_IMODE((folder / "ca-key.pem").stat().st_mode) == 0o600
    with pytest.raises(CertificateError, match=r"no CA there to sign with"):
        make_certificates(tmp_path / "empty", ["robot-1"], new_ca=False)
    with pytest.raises(CertificateError, match=r"identity 'robot-0'"):
        make_certificates(tmp_path / "x", ["robot-0"])
    with pytest.raises(CertificateError, match=r"host 'not a host'"):
        make_certificates(tmp_path / "x", ["plant"], hosts=["not a host"])
    assert not (tmp_path / "x").exists()


def test_heft_deploy_certs(tmp_path: Path, capsys) -> None:
    folder = tmp_path / "tls"
    assert main(["deploy", "certs", str(folder), "--robots", "2", "--host", "127.0.0.1"]) == 0
    out, _ = capsys.readouterr()
    assert "robot-2.pem" in out and "ca-key.pem stays here" in out
    assert main(["deploy", "certs", str(folder), "--identity", "robot-3"]) == 0
    capsys.readouterr()
    refusals = [
        (["--robots", "2"], "ca.pem: a CA is already there"),
        (["--identity", "robot-3"], "robot-3.pem: already there; --force replaces it"),
        (["--identity", "robot-x"], "identity 'robot-x'"),
        (["--robots", "0"], "--robots: expected an integer from 1 to 32, got '0'"),
        (["--robots", "2", "--identity", "plant"], "give --robots N"),
        ([], "give --robots N"),
        (["--robots", "2", "--days", "0", "--force"], "--days: expected an integer from 1"),
    ]
    for argv, words in refusals:
        assert main(["deploy", "certs", str(folder), *argv]) == 2, argv
        out, err = capsys.readouterr()
        assert out == "" and err.count("\n") == 1, (argv, err)
        assert err.startswith("heft: error: ") and words in err, (argv, err)
    assert main(["deploy", "certs", str(folder), "--robots", "2", "--force"]) == 0


# ------------------------------------------------------------------------------ router config
def test_the_committed_router_config_is_the_generators() -> None:
    assert ROUTER_JSON5.read_text(encoding="utf-8") == router_config_text(**PAPER_ROUTER)


def test_the_committed_router_config_is_a_valid_zenoh_config() -> None:
    zenoh = pytest.importorskip("zenoh")
    config = zenoh.Config.from_file(str(ROUTER_JSON5))
    assert json.loads(config.get_json("mode")) == "router"
    assert json.loads(config.get_json("listen/endpoints")) == ["tls/192.168.10.1:7447"]
    assert json.loads(config.get_json("scouting/multicast/enabled")) is False
    assert json.loads(config.get_json("transport/shared_memory/enabled")) is False
    assert json.loads(config.get_json("transport/link/tx/lease")) == 2000
    tls = json.loads(config.get_json("transport/link/tls"))
    assert tls["root_ca_certificate"] == "/etc/heft/tls/ca.pem"
    assert tls["listen_certificate"] == "/etc/heft/tls/router.pem"
    assert tls["listen_private_key"] == "/etc/heft/tls/router-key.pem"
    assert tls["enable_mtls"] is True
    acl = json.loads(config.get_json("access_control"))
    assert acl["enabled"] is True and acl["default_permission"] == "deny"
    assert {s["id"] for s in acl["subjects"]} == set(team_identities(4)) - {"router"}


def test_the_grants_follow_the_graph() -> None:
    grants = team_grants("paper", 4, LINE)
    keys = Keys("paper")
    robot2 = grants["robot-2"]
    assert keys.share(1) in robot2.subscribe and keys.share(3) in robot2.subscribe
    assert keys.share(4) not in robot2.subscribe and keys.control() in robot2.subscribe
    assert set(robot2.put) == {
        keys.velocity(2),
        keys.force(2),
        keys.share(2),
        keys.estimate(2),
        keys.status(2),
        keys.log(2),
        keys.bridge(2),
    }
    assert set(robot2.token) == {keys.alive(2), keys.bridge_alive(2)}
    assert set(robot2.watch) == {keys.alive(1), keys.alive(2), keys.alive(3)}
    assert grants["operator"].put == (keys.control(),)
    assert grants["dashboard"].put == () and grants["dashboard"].subscribe == ("heft/paper/**",)
    assert keys.control() not in grants["plant"].put
    assert {keys.truth(), keys.geometry(), keys.plant_status()} <= set(grants["plant"].put)
    acl = access_control("paper", 4, LINE)
    ids = [rule["id"] for rule in acl["rules"]]
    assert len(ids) == len(set(ids))
    used = {rule for policy in acl["policies"] for rule in policy["rules"]}
    assert used == set(ids)


@pytest.mark.parametrize(
    "change, words",
    [
        ({"edges": ((1, 2), (3, 4))}, "robot 3 is cut off"),
        ({"edges": ((1, 2), (2, 1), (2, 3), (3, 4))}, "listed twice"),
        ({"edges": ((1, 5),)}, "robot 5 is not one of 1..4"),
        ({"listen": ["tcp/192.168.10.1:7447"]}, "listens on tls/HOST:PORT"),
        ({"listen": []}, "at least one tls/HOST:PORT"),
        ({"team": "a/b"}, "team: "),
        ({"certs": "tls"}, "certs: expected the absolute folder"),
        ({"robots": 0}, "robots: expected 1 to 32"),
    ],
)
def test_router_config_refuses_bad_input(change: dict, words: str) -> None:
    with pytest.raises(AccessError, match=re.escape(words)):
        router_config(**{**PAPER_ROUTER, **change})


def test_heft_deploy_router_config(tmp_path: Path, capsys) -> None:
    argv = ["deploy", "router-config", "--team", "paper", "--robots", "4", "--edges", "1-2", "2-3"]
    argv += ["3-4", "--listen", "tls/192.168.10.1:7447", "--certs", "/etc/heft/tls"]
    assert main(argv) == 0
    out, _ = capsys.readouterr()
    assert out == ROUTER_JSON5.read_text(encoding="utf-8")
    path = tmp_path / "router.json5"
    assert main([*argv, "--out", str(path)]) == 0
    assert path.read_text(encoding="utf-8") == out
    for bad, words in [
        (["--edges", "1-2", "2-x"], "edge '2-x': expected I-J"),
        (["--robots", "four"], "--robots: expected an integer"),
        (["--listen", "tls/nowhere"], "expected an explicit endpoint"),
    ]:
        assert main([*argv, *bad]) == 2, bad
        out, err = capsys.readouterr()
        assert out == "" and err.count("\n") == 1 and err.startswith("heft: error: "), err
        assert words in err, err


def test_parse_edges() -> None:
    assert parse_edges(["1-2", " 3-2 "], 3) == ((1, 2), (2, 3))
    with pytest.raises(AccessError, match="a robot is not its own neighbour"):
        parse_edges(["1-1"], 2)


def test_the_secured_routers_config_says_tls_and_access_control(certs, tmp_path) -> None:
    """What a secured router has in force, read back from its final config."""
    path = tmp_path / "router.json5"
    path.write_text(router_config_text("sec", 4, LINE, ["tls/127.0.0.1:7447"], str(certs)), "utf-8")
    router = ZenohSettings(
        mode="router", connect=(), listen=("tls/127.0.0.1:7447",), config_file=str(path)
    )
    assert describe(zenoh_config(router)) == (
        "zenoh router: listen tls/127.0.0.1:7447; mutual TLS: clients must show a certificate"
        f" signed by {certs}/ca.pem; access control on: default deny, 7 subjects;"
        " multicast scouting off"
    )
