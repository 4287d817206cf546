"""The secured router of a team: its Zenoh config, with mutual TLS and access control.

:func:`router_config` builds the router's Zenoh configuration for a team (``heft deploy
router-config``): the router listens only on ``tls`` endpoints and asks every client for a
certificate signed by the team's CA (:mod:`agent.security.certificates`); its access control denies
everything by default and lets each identity — its certificate's Common Name — do only what
its processes do (keys from :class:`agent.platform.protocol.Keys`):

============ ================================== ================================= ===========
identity     publishes                          subscribes to                     liveliness
============ ================================== ================================= ===========
``robot-i``  its robot's velocity, force,       its velocity and force, its       declares its
             share, estimate, status, log,      neighbours' shares, control       agent's and
             bridge
                                                                                  bridge's;
                                                                                  watches its
                                                                                  own agent's
                                                                                  and its
                                                                                  neighbours'
``plant``    every velocity, clock, truth,      every force, control              watches every
             load geometry, plant status                                          agent and
                                                                                  bridge
``operator`` control                            everything of the team            watches all
``dashboard`` nothing                           everything of the team            watches all
============ ================================== ================================= ===========

(``robot-i`` is robot *i*'s computer, where its agent and its AGV bridge run.) What the
router's access control checks, per message and per side (tested in
tests/integration/test_secured_network.py):

- a put must be allowed *ingress* from its publisher and *egress* to each subscriber;
- a subscriber's declaration must be allowed *ingress* from its subscriber;
- a publisher must be allowed to learn of the subscribers (``declare_subscriber``,
  *egress*, on every key of the team: subscribers to wildcards included): a client sends
  nothing for which it knows no subscriber, so without this its puts never leave it;
- a liveliness token must be allowed *ingress* from its holder (``liveliness_token``) and,
  with its disappearance, *egress* to each watcher; a watcher's subscription
  (``declare_liveliness_subscriber``) *ingress* from the watcher. Watching with history (the
  tokens already there) needs no ``liveliness_query``.
"""

from __future__ import annotations

import json
import posixpath
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from agent.platform.config import MAX_ROBOTS
from agent.platform.protocol import Keys
from agent.platform.zenoh_session import (
    DROP_WAIT_US,
    LEASE_MS,
    SEND_BUFFER_BYTES,
    TX_QUEUE_BATCHES,
    ZenohSettings,
)
from agent.security.certificates import CA_CERT, robot_identity

_EDGE = re.compile(r"^(\d{1,3})-(\d{1,3})$")


class AccessError(ValueError):
    """The team cannot be described as asked: ``str()`` is one line naming the value."""


@dataclass(frozen=True)
class Grants:
    """What one identity may do, as key expressions."""

    put: tuple[str, ...] = ()
    subscribe: tuple[str, ...] = ()
    token: tuple[str, ...] = ()
    """Liveliness tokens it may declare."""
    watch: tuple[str, ...] = ()
    """Liveliness tokens it may watch."""


# ------------------------------------------------------------------------------ the team
def parse_edges(texts: Iterable[str], robots: int) -> tuple[tuple[int, int], ...]:
    """The graph's edges from ``I-J`` texts (robots 1 to ``robots``), each once, the graph
    connected. :class:`AccessError` naming the first bad one."""
    check_robots(robots)
    edges: list[tuple[int, int]] = []
    for text in texts:
        match = _EDGE.match(text.strip())
        if not match:
            raise AccessError(f"edge {text!r}: expected I-J, two robot ids like 1-2")
        i, j = int(match[1]), int(match[2])
        for robot in (i, j):
            if not 1 <= robot <= robots:
                raise AccessError(f"edge {text!r}: robot {robot} is not one of 1..{robots}")
        if i == j:
            raise AccessError(f"edge {text!r}: a robot is not its own neighbour")
        edge = (min(i, j), max(i, j))
        if edge in edges:
            raise AccessError(f"edge {text!r}: listed twice")
        edges.append(edge)
    unreached = set(range(1, robots + 1)) - _reached(robots, edges)
    if unreached:
        raise AccessError(
            f"edges: the graph must connect every robot; robot {min(unreached)} is cut off"
            f" from robot 1 (edges: {' '.join(f'{i}-{j}' for i, j in edges) or 'none'})"
        )
    return tuple(edges)


def check_edges(edges: Iterable[Sequence[int]], robots: int) -> tuple[tuple[int, int], ...]:
    """:func:`parse_edges` for edges given as pairs of robot ids."""
    texts = []
    for edge in edges:
        if len(edge) != 2 or not all(isinstance(i, int) and not isinstance(i, bool) for i in edge):
            raise AccessError(f"edge {edge!r}: expected two robot ids")
        texts.append(f"{edge[0]}-{edge[1]}")
    return parse_edges(texts, robots)


def check_robots(robots: int) -> int:
    if isinstance(robots, bool) or not isinstance(robots, int) or not 1 <= robots <= MAX_ROBOTS:
        raise AccessError(f"robots: expected 1 to {MAX_ROBOTS}, got {robots!r}")
    return robots


def _reached(robots: int, edges: Sequence[tuple[int, int]]) -> set[int]:
    seen, todo = {1}, [1]
    while todo:
        here = todo.pop()
        for there in neighbours(here, edges):
            if there not in seen:
                seen.add(there)
                todo.append(there)
    return seen


def neighbours(robot: int, edges: Iterable[tuple[int, int]]) -> list[int]:
    """``robot``'s graph neighbours, in order."""
    return sorted({j for i, j in edges if i == robot} | {i for i, j in edges if j == robot})


def team_grants(team: str, robots: int, edges: Sequence[tuple[int, int]]) -> dict[str, Grants]:
    """Per identity (:mod:`agent.security.certificates`), what it may do in team ``team``."""
    keys = Keys(team)
    everything = f"{keys.root}/**"
    ids = range(1, check_robots(robots) + 1)
    edges = check_edges(edges, robots)
    grants: dict[str, Grants] = {}
    for i in ids:
        near = neighbours(i, edges)
        grants[robot_identity(i)] = Grants(
            # its agent, and its AGV bridge (velocity and bridge status)
            put=(
                keys.velocity(i),
                keys.force(i),
                keys.share(i),
                keys.estimate(i),
                keys.status(i),
                keys.log(i),
                keys.bridge(i),
            ),
            # the agent hears its robot's velocity, the bridge its agent's force
            subscribe=(
                keys.velocity(i),
                keys.force(i),
                *(keys.share(j) for j in near),
                keys.control(),
            ),
            token=(keys.alive(i), keys.bridge_alive(i)),
            # the bridge watches its own agent, the agent its neighbours
            watch=(keys.alive(i), *(keys.alive(j) for j in near)),
        )
    grants["plant"] = Grants(
        put=(
            *(keys.velocity(i) for i in ids),
            keys.clock(),
            keys.truth(),
            keys.geometry(),
            keys.plant_status(),
        ),
        subscribe=(*(keys.force(i) for i in ids), keys.control()),
        watch=tuple(key for i in ids for key in (keys.alive(i), keys.bridge_alive(i))),
    )
    grants["operator"] = Grants(put=(keys.control(),), subscribe=(everything,), watch=(everything,))
    grants["dashboard"] = Grants(subscribe=(everything,), watch=(everything,))
    return grants


# ------------------------------------------------------------------------------ Zenoh's ACL
def _rule(rule_id: str, messages: list[str], flow: str, key_exprs: Sequence[str]) -> dict:
    return {
        "id": rule_id,
        "messages": messages,
        "flows": [flow],
        "permission": "allow",
        "key_exprs": list(key_exprs),
    }


def access_control(team: str, robots: int, edges: Sequence[tuple[int, int]]) -> dict:
    """Zenoh's ``access_control`` block for the team: deny by default, then per identity
    (subject: its certificate's Common Name) the rules of its :class:`Grants` (see the
    module's docstring for which message and flow each needs)."""
    everything = f"{Keys(team).root}/**"
    # Every publisher: without it, a client never sends what it knows no subscriber for.
    see_subscribers = _rule("see-subscribers", ["declare_subscriber"], "egress", [everything])
    rules: list[dict] = [see_subscribers]
    subjects: list[dict] = []
    policies: list[dict] = []
    for identity, grants in team_grants(team, robots, edges).items():
        mine: list[dict] = []
        if grants.put:
            mine.append(_rule(f"{identity}-put", ["put"], "ingress", grants.put))
        if grants.subscribe:
            mine.append(
                _rule(f"{identity}-subscribe", ["declare_subscriber"], "ingress", grants.subscribe)
            )
            mine.append(_rule(f"{identity}-receive", ["put"], "egress", grants.subscribe))
        if grants.token:
            mine.append(_rule(f"{identity}-token", ["liveliness_token"], "ingress", grants.token))
        if grants.watch:
            mine.append(
                _rule(
                    f"{identity}-watch",
                    ["declare_liveliness_subscriber"],
                    "ingress",
                    grants.watch,
                )
            )
            mine.append(
                _rule(f"{identity}-watch-receive", ["liveliness_token"], "egress", grants.watch)
            )
        rules.extend(mine)
        ids = [rule["id"] for rule in mine]
        if grants.put:
            ids.insert(1, see_subscribers["id"])
        subjects.append({"id": identity, "cert_common_names": [identity]})
        policies.append({"id": identity, "rules": ids, "subjects": [identity]})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


# ------------------------------------------------------------------------------ the router
def check_listen(listen: Sequence[str]) -> tuple[str, ...]:
    """``listen`` if every endpoint is an explicit ``tls/HOST:PORT`` (and there is one)."""
    if not listen:
        raise AccessError("listen: at least one tls/HOST:PORT endpoint")
    for endpoint in listen:
        try:
            ZenohSettings.check_endpoint(endpoint, "listen")
        except ValueError as err:
            raise AccessError(str(err)) from None
        if not endpoint.startswith("tls/"):
            raise AccessError(f"listen: {endpoint}: the secured router listens on tls/HOST:PORT")
    return tuple(listen)


def router_config(
    team: str,
    robots: int,
    edges: Sequence[tuple[int, int]],
    listen: Sequence[str],
    certs: str,
) -> dict:
    """The router's Zenoh config (a dict of JSON values) for ``team``: router mode on the
    ``listen`` endpoints (``tls/HOST:PORT``), no multicast scouting, no shared memory, the
    project's lease, mutual TLS with the files the router reads from the folder ``certs``
    (``ca.pem``, ``router.pem``, ``router-key.pem``) and :func:`access_control`."""
    try:
        Keys(team)
    except ValueError as err:
        raise AccessError(f"team: {err}") from None
    listen = check_listen(listen)
    edges = check_edges(edges, robots)
    if not certs or not posixpath.isabs(certs):
        raise AccessError(f"certs: expected the absolute folder the router reads, got {certs!r}")
    return {
        "mode": "router",
        "listen": {"endpoints": list(listen)},
        "connect": {"endpoints": []},
        "scouting": {
            "multicast": {"enabled": False},
            "gossip": {
                "enabled": True,
                "multihop": False,
                "autoconnect": {"router": [], "peer": ["router", "peer"]},
            },
        },
        "transport": {
            "link": {
                "tx": {
                    "lease": LEASE_MS,
                    "keep_alive": 4,
                    "queue": {
                        "size": {"data": TX_QUEUE_BATCHES},
                        "congestion_control": {"drop": {"wait_before_drop": DROP_WAIT_US}},
                    },
                },
                "tls": {
                    "root_ca_certificate": posixpath.join(certs, CA_CERT),
                    "listen_certificate": posixpath.join(certs, "router.pem"),
                    "listen_private_key": posixpath.join(certs, "router-key.pem"),
                    "enable_mtls": True,
                    "so_sndbuf": SEND_BUFFER_BYTES,
                },
            },
            "shared_memory": {"enabled": False},
        },
        "access_control": access_control(team, robots, edges),
    }


def command_line(
    team: str, robots: int, edges: Sequence[tuple[int, int]], listen: Sequence[str], certs: str
) -> str:
    """The ``heft deploy router-config`` command that makes this config."""
    words = ["heft deploy router-config", f"--team {team}", f"--robots {robots}"]
    words.append("--edges " + " ".join(f"{i}-{j}" for i, j in edges))
    words.extend(f"--listen {endpoint}" for endpoint in listen)
    words.append(f"--certs {certs}")
    return " ".join(words)


def router_config_text(
    team: str,
    robots: int,
    edges: Sequence[tuple[int, int]],
    listen: Sequence[str],
    certs: str,
) -> str:
    """:func:`router_config` as JSON5 text (JSON, which JSON5 reads) with a comment header
    saying what it is and how it was made."""
    config = router_config(team, robots, edges, listen, certs)
    edges = check_edges(edges, robots)
    graph = " ".join(f"{i}-{j}" for i, j in edges) or "none"
    header = [
        f"Zenoh router of the Heft team {team!r} (robots 1-{robots}, graph {graph}), secured:",
        "mutual TLS (every client shows a certificate signed by the team's CA) and access",
        "control by the certificates' Common Names (robot-<i>, plant, operator, dashboard):",
        "each may publish and subscribe only what its processes need",
        "(agent/security/access_control.py).",
        "",
        "Made by (do not edit; make it again):",
        f"  {command_line(team, robots, edges, listen, certs)}",
        f"The router reads {posixpath.join(certs, '{ca,router,router-key}.pem')}",
        "(heft deploy certs). Run it with (either listens on its listen endpoints):",
        "  heft router --zenoh-config FILE",
        "or with zenohd --config FILE.",
    ]
    lines = [f"// {line}".rstrip() for line in header]
    return "\n".join(lines) + "\n" + _json(config) + "\n"


def _json(value: object, indent: str = "") -> str:
    """``value`` as JSON, two spaces per level, a list of plain values on one line where it
    fits in 100 columns (easier to read than one value per line)."""
    inner = indent + "  "
    if isinstance(value, dict) and value:
        items = [f"{inner}{json.dumps(k)}: {_json(v, inner)}" for k, v in value.items()]
        return "{\n" + ",\n".join(items) + f"\n{indent}}}"
    if isinstance(value, list) and value:
        flat = json.dumps(value)
        plain = not any(isinstance(v, (dict, list)) for v in value)
        if plain and len(inner) + len(flat) <= 100:
            return flat
        return "[\n" + ",\n".join(f"{inner}{_json(v, inner)}" for v in value) + f"\n{indent}]"
    return json.dumps(value)
