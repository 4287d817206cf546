"""The secured Zenoh network on loopback: mutual TLS with the team's certificates and the router's
access control by identity (agent/security/certificates.py, agent/security/access_control.py).

The tests run a router on ``tls/127.0.0.1:PORT`` with the config ``heft deploy router-config``
makes, and clients of each identity; every refusal is shown by a subscriber that hears nothing
while, in the same window, an allowed message on the same path is heard. The settings, the
certificates and the router's config without a network are in
tests/unit/agent/test_security.py."""

from __future__ import annotations

import dataclasses
import json
import logging
import threading
import time
from pathlib import Path

import pytest

from agent.platform.children import free_port
from agent.platform.protocol import Control, Keys, encode
from agent.platform.zenoh_session import (
    SessionError,
    ZenohSettings,
    open_session,
    zenoh_config,
)
from agent.security.access_control import router_config_text
from agent.security.certificates import make_certificates
from tests.helpers.tls import tls_files

TEAM = "sec"
LINE = ((1, 2), (2, 3), (3, 4))
KEYS = Keys(TEAM)


# ------------------------------------------------------------------------------ on the network
class Heard:
    """What a subscriber (or a liveliness watcher) heard: keys, kinds and payloads."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.items: list[tuple[str, object, bytes]] = []

    def __call__(self, sample) -> None:
        with self.lock:
            self.items.append((str(sample.key_expr), sample.kind, sample.payload.to_bytes()))

    def keys(self) -> list[str]:
        with self.lock:
            return [key for key, _, _ in self.items]

    def payloads(self) -> set[bytes]:
        with self.lock:
            return {payload for _, _, payload in self.items}


class Network:
    """A router with the team's access control on tls/127.0.0.1 and clients by identity."""

    def __init__(self, certs: Path, folder: Path):
        self.certs = certs
        self.endpoint = f"tls/127.0.0.1:{free_port()}"
        path = folder / "router.json5"
        text = router_config_text(TEAM, 4, LINE, [self.endpoint], str(certs))
        path.write_text(text, encoding="utf-8")
        # as `heft router --listen ENDPOINT --zenoh-config router.json5` opens it
        self.router = open_session(
            ZenohSettings(mode="router", connect=(), listen=(self.endpoint,), config_file=str(path))
        )
        self.sessions: dict[str, object] = {}

    def settings(self, identity: str, certs: Path | None = None) -> ZenohSettings:
        return ZenohSettings(
            connect=(self.endpoint,),
            connect_timeout_ms=1000,
            **tls_files(certs or self.certs, identity),
        )

    def session(self, identity: str, process: str = ""):
        """A session of ``identity`` (one per ``process``: a session hears its own puts
        without the router, so a forger must not be the listener)."""
        name = f"{identity}/{process}"
        if name not in self.sessions:
            self.sessions[name] = open_session(self.settings(identity))
        return self.sessions[name]

    def listen(self, identity: str, key: str) -> Heard:
        heard = Heard()
        self.session(identity).declare_subscriber(key, heard)
        return heard

    def watch(self, identity: str, key: str) -> Heard:
        heard = Heard()
        self.session(identity).liveliness().declare_subscriber(key, heard, history=True)
        return heard

    def close(self) -> None:
        for session in self.sessions.values():
            session.close()
        self.router.close()


@pytest.fixture(scope="module")
def network(certs: Path, tmp_path_factory):
    net = Network(certs, tmp_path_factory.mktemp("router"))
    yield net
    net.close()


def exchange(net: Network, allowed, refused, heard_allowed, settle: float = 0.3) -> None:
    """Put ``allowed`` and ``refused`` (lists of (identity, key, payload)), from sessions other
    than the listeners', again and again until every ``heard_allowed`` heard its first; then
    once more, and wait ``settle`` s. The caller checks what each heard."""
    deadline = time.monotonic() + 10.0
    while not all(heard.keys() for heard in heard_allowed):
        assert time.monotonic() < deadline, "allowed messages never arrived"
        for identity, key, payload in (*refused, *allowed):
            net.session(identity, "sender").put(key, payload)
        time.sleep(0.05)
    for identity, key, payload in (*refused, *allowed):
        net.session(identity, "sender").put(key, payload)
    time.sleep(settle)


@pytest.mark.slow
def test_the_right_certificate_connects_and_a_force_reaches_the_plant(network: Network) -> None:
    plant = network.listen("plant", KEYS.force(1))
    velocity = network.listen("robot-1", KEYS.velocity(1))
    exchange(
        network,
        [("robot-1", KEYS.force(1), b"f"), ("plant", KEYS.velocity(1), b"v")],
        [],
        [plant, velocity],
        settle=0.1,
    )
    assert set(plant.keys()) == {KEYS.force(1)}
    assert set(velocity.keys()) == {KEYS.velocity(1)}


@pytest.mark.slow
def test_robot_2_cannot_speak_for_robot_3(network: Network) -> None:
    """robot-2's identity puts robot 3's force and share and a stop: the plant, robot 3's
    neighbours and the agents hear none of it, while robot 3's own are heard."""
    plant = network.listen("plant", KEYS.force(3))
    neighbours = [network.listen(f"robot-{j}", KEYS.share(3)) for j in (2, 4)]
    control = [network.listen(f"robot-{i}", KEYS.control()) for i in (1, 3)]
    forged = [
        ("robot-2", KEYS.force(3), b"forged"),
        ("robot-2", KEYS.share(3), b"forged"),
        ("robot-2", KEYS.control(), encode(Control("stop"))),
    ]
    real = [("robot-3", KEYS.force(3), b"real"), ("robot-3", KEYS.share(3), b"real")]
    exchange(network, real, forged, [plant, *neighbours])
    for heard in (plant, *neighbours):
        assert heard.payloads() == {b"real"}
    assert [heard.keys() for heard in control] == [[], []]


@pytest.mark.slow
def test_only_the_operator_stops_the_team(network: Network) -> None:
    """A stop from anyone but the operator reaches no one; the operator's reaches every agent
    and the plant."""
    agents = [network.listen(f"robot-{i}", KEYS.control()) for i in (1, 2, 3, 4)]
    plant = network.listen("plant", KEYS.control())
    stop = encode(Control("stop"))
    refused = [
        (who, KEYS.control(), f"stop from {who}".encode())
        for who in ("plant", "dashboard", "robot-3")
    ]
    exchange(network, [("operator", KEYS.control(), stop)], refused, [*agents, plant])
    for heard in (*agents, plant):
        assert heard.payloads() == {stop}


@pytest.mark.slow
def test_nobody_hears_what_is_not_for_them(network: Network) -> None:
    """robot-3 is not robot 1's neighbour: it cannot subscribe to robot 1's share; the
    dashboard hears everything, and puts nothing."""
    neighbour = network.listen("robot-2", KEYS.share(1))
    everything = network.listen("dashboard", f"{KEYS.root}/**")
    stranger = network.listen("robot-3", KEYS.share(1))
    wildcard = network.listen("robot-3", f"{KEYS.root}/**")
    truth = network.listen("robot-1", KEYS.truth())
    exchange(
        network,
        [("robot-1", KEYS.share(1), b"s"), ("plant", KEYS.truth(), b"t")],
        [("dashboard", KEYS.estimate(1), b"forged")],
        [neighbour, everything],
    )
    assert stranger.keys() == [] and truth.keys() == []
    assert set(wildcard.keys()) <= {KEYS.control()}  # what robot-3 may hear (none put here)
    assert KEYS.estimate(1) not in everything.keys()
    assert {KEYS.share(1), KEYS.truth()} <= set(everything.keys())


@pytest.mark.slow
def test_liveliness_goes_only_where_it_may(network: Network) -> None:
    """The plant and robot 1's neighbour see its agent's token come and go; a robot that is
    not its neighbour does not; robot-2 cannot declare robot 3's token."""
    plant = network.watch("plant", KEYS.alive(1))
    network.session("plant").liveliness().declare_subscriber(
        KEYS.bridge_alive(1), plant, history=True
    )
    network.session("plant").liveliness().declare_subscriber(KEYS.alive(3), plant, history=True)
    neighbour = network.watch("robot-2", KEYS.alive(1))
    stranger = network.watch("robot-4", KEYS.alive(1))
    forger = open_session(network.settings("robot-2"))
    robot1 = open_session(network.settings("robot-1"))
    try:
        forger.liveliness().declare_token(KEYS.alive(3))
        robot1.liveliness().declare_token(KEYS.alive(1))
        robot1.liveliness().declare_token(KEYS.bridge_alive(1))
        deadline = time.monotonic() + 10
        while not (neighbour.keys() and len(plant.keys()) >= 2) and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        robot1.close()
    deadline = time.monotonic() + 10
    while len(neighbour.keys()) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.2)
    forger.close()
    assert neighbour.keys() == [KEYS.alive(1)] * 2  # appeared, then gone
    assert [str(kind) for _, kind, _ in neighbour.items] == [
        "SampleKind.PUT",
        "SampleKind.DELETE",
    ]
    assert set(plant.keys()) == {KEYS.alive(1), KEYS.bridge_alive(1)}
    assert stranger.keys() == []


@pytest.mark.slow
def test_a_client_without_the_teams_certificate_cannot_connect(
    network: Network, certs: Path, tmp_path: Path
) -> None:
    import zenoh

    other = tmp_path / "other"
    make_certificates(other, ["robot-1"], hosts=["127.0.0.1"])
    # a certificate signed by another CA (it trusts the team's CA to reach the router)
    foreign = dataclasses.replace(network.settings("robot-1", other), root_ca=str(certs / "ca.pem"))
    with pytest.raises(SessionError, match=r"^connect tls/127\.0\.0\.1:\d+: no answer"):
        open_session(foreign)
    # no certificate at all
    config = zenoh_config(ZenohSettings(connect=(network.endpoint,), connect_timeout_ms=1000))
    config.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(certs / "ca.pem")))
    with pytest.raises(zenoh.ZError):
        zenoh.open(config)
    # plain tcp to the TLS port
    plain = ZenohSettings(connect=(f"tcp/{network.endpoint[4:]}",), connect_timeout_ms=500)
    with pytest.raises(SessionError):
        open_session(plain)


@pytest.mark.slow
def test_each_session_says_it_is_on_plain_links(caplog) -> None:
    ports = [free_port(), free_port()]
    with caplog.at_level(logging.INFO, logger="heft.zenoh"):
        for port in ports:
            settings = ZenohSettings(mode="peer", connect=(), listen=(f"tcp/127.0.0.1:{port}",))
            with open_session(settings):
                pass
    assert [r.getMessage() for r in caplog.records if r.name == "heft.zenoh"] == [
        f"zenoh peer: listen tcp/127.0.0.1:{port}; plain tcp: no TLS, no certificates (for"
        " loopback runs only); access control off; multicast scouting off"
        for port in ports
    ]


@pytest.mark.slow
def test_a_tls_session_says_which_certificate_it_shows(network: Network, certs, caplog) -> None:
    with caplog.at_level(logging.INFO, logger="heft.zenoh"):
        with open_session(network.settings("dashboard")):
            pass
    [line] = [r.getMessage() for r in caplog.records if r.name == "heft.zenoh"]
    assert line == (
        f"zenoh client: connect {network.endpoint}; mutual TLS: shows {certs}/dashboard.pem,"
        f" trusts {certs}/ca.pem; access control off; multicast scouting off"
    )
    assert not any("PRIVATE KEY" in r.getMessage() for r in caplog.records)
