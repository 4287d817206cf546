"""Opening Zenoh sessions the project's way.

Every session the project opens goes through :func:`open_session`: multicast scouting is off
and every endpoint is explicit (``tcp/127.0.0.1:PORT`` in demos and tests), shared memory is
off (it is not available everywhere the agents run), and a client waits for a router that is
not up yet instead of failing at once.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from agent.config import ConfigError, bounded, check_bounds
from agent.process import in_user_mode_linux

DEFAULT_ROUTER = "tcp/127.0.0.1:7447"
LEASE_MS = 2000
"""How soon the others notice that a process hung, by default: 2 s."""
EMULATED_LEASE_MS = 10_000
"""The default lease in User-Mode Linux (:func:`~agent.process.in_user_mode_linux`). There
the guest's one CPU serves every process of a run, each system call costs about 100 µs, and
keep-alives wait: with a 2 s lease the sessions of a CAN run (router, plant, four bridges,
four agents) expired and reconnected every few seconds, and the team halted; with 10 s it
ran through."""
_ENDPOINT = re.compile(r"^(tcp|udp|quic|tls)/[^:/\s]+:\d{1,5}$")


@dataclass(frozen=True)
class ZenohSettings:
    """Where a process's Zenoh session connects and listens (the ``[zenoh]`` table)."""

    mode: str = "client"
    """``client`` (through a router), ``peer`` or ``router``."""
    connect: tuple[str, ...] = (DEFAULT_ROUTER,)
    """Endpoints to connect to, each explicit: ``tcp/HOST:PORT`` (or ``udp``, ``quic``,
    ``tls``), port 1 to 65535; a client needs at least one."""
    listen: tuple[str, ...] = ()
    """Endpoints to listen on, as ``connect``; a router needs at least one."""
    lease_ms: int = bounded(
        EMULATED_LEASE_MS if in_user_mode_linux() else LEASE_MS, 100, 60_000, "ms"
    )
    """How soon the others notice this process hung (``transport/link/tx/lease``): 2 s,
    10 s in User-Mode Linux (see :data:`EMULATED_LEASE_MS`)."""
    connect_timeout_ms: int = bounded(15000, 0, 600_000, "ms")
    """How long a client waits for its router at start-up (0: it tries once); then
    :func:`open_session` fails with one line naming the endpoints."""
    config_file: str | None = None
    """A Zenoh JSON5 config file to start from (TLS, access control, ...); the settings above
    are applied on top of it, so its mode, endpoints, scouting and lease are never used."""

    def validate(self, where: str) -> None:
        if self.mode not in ("client", "peer", "router"):
            raise ConfigError(f"{where}.mode: expected client, peer or router, got {self.mode!r}")
        for key in ("connect", "listen"):
            for i, endpoint in enumerate(getattr(self, key)):
                self.check_endpoint(endpoint, f"{where}.{key}[{i}]")
        if self.mode == "client" and not self.connect:
            raise ConfigError(f"{where}.connect: a client needs at least one router endpoint")
        if self.mode == "router" and not self.listen:
            raise ConfigError(f"{where}.listen: a router needs at least one endpoint")
        check_bounds(self, where)
        if self.config_file is not None:
            self.check_config_file(self.config_file, f"{where}.config_file")

    @staticmethod
    def check_endpoint(endpoint: str, where: str) -> None:
        """:class:`ConfigError` naming ``where`` unless ``endpoint`` is explicit
        (``tcp/HOST:PORT``, or ``udp``, ``quic``, ``tls``)."""
        if not _ENDPOINT.match(endpoint) or not 1 <= int(endpoint.rsplit(":", 1)[1]) <= 65535:
            raise ConfigError(
                f"{where}: expected an explicit endpoint like tcp/127.0.0.1:7447 (port 1 to"
                f" 65535), got {endpoint!r}"
            )

    @staticmethod
    def check_config_file(path: str, where: str) -> None:
        """:class:`ConfigError` naming ``where`` unless ``path`` is a readable file."""
        try:
            with open(path, "rb"):
                pass
        except OSError as err:
            raise ConfigError(f"{where}: {path}: cannot read ({err.strerror or err})") from None


TX_QUEUE_BATCHES = 16
"""Batches in a link's queue for data-priority messages (Zenoh's maximum; its default is 2)."""
DROP_WAIT_US = 20_000
"""How long a droppable message waits for room in a full queue (Zenoh's default: 1 000)."""


def zenoh_config(settings: ZenohSettings):
    """The ``zenoh.Config`` for ``settings`` (multicast scouting always off): its
    ``config_file`` if any (``zenoh.ZError`` if that is not a valid Zenoh config), with the
    project's keys set on top."""
    import zenoh

    if settings.config_file is not None:
        config = zenoh.Config.from_file(settings.config_file)
    else:
        config = zenoh.Config()
    config.insert_json5("mode", json.dumps(settings.mode))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("connect/endpoints", json.dumps(list(settings.connect)))
    config.insert_json5("listen/endpoints", json.dumps(list(settings.listen)))
    config.insert_json5("transport/shared_memory/enabled", "false")
    config.insert_json5("transport/link/tx/lease", str(settings.lease_ms))
    config.insert_json5("transport/link/tx/keep_alive", "4")
    # What may be dropped (estimates, statuses, the truth) waits this long for room in a
    # queue this deep before it is. Zenoh's defaults (2 batches, 1 ms) leave no room for a
    # process that waits milliseconds for a CPU, as on a loaded 2-CPU machine; with these, a
    # lockstep run there ended on its in-process instant 10 times out of 10.
    config.insert_json5("transport/link/tx/queue/size/data", str(TX_QUEUE_BATCHES))
    config.insert_json5(
        "transport/link/tx/queue/congestion_control/drop/wait_before_drop", str(DROP_WAIT_US)
    )
    if settings.mode == "client":
        config.insert_json5("connect/timeout_ms", str(settings.connect_timeout_ms))
        config.insert_json5(
            "connect/retry",
            '{"period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2}',
        )
    return config


class SessionError(ConfigError):
    """Zenoh could not open the session: ``str()`` is one line naming the endpoint and why,
    e.g. ``listen tcp/127.0.0.1:7447: address already in use`` or ``connect
    tcp/127.0.0.1:7447: no answer within 15000 ms (connect_timeout_ms); is the router
    running?``."""


def open_session(settings: ZenohSettings):
    """Open a Zenoh session; close it with ``session.close()`` (or use it in ``with``).
    :class:`SessionError` if Zenoh cannot (it raises ``zenoh.ZError``: a busy or unusable
    port, no router within ``connect_timeout_ms``)."""
    import zenoh

    try:
        return zenoh.open(zenoh_config(settings))
    except zenoh.ZError as err:
        raise SessionError(session_error(str(err), settings)) from None


_LISTENER = re.compile(r"listener bound to (\w+/\S+?): \[.*?: (.+?) \(os error \d+\)", re.S)
_UNREACHABLE = re.compile(r"Unable to connect to any of \[(.*?)\]\s*(\. Timeout!|!)", re.S)


def session_error(message: str, settings: ZenohSettings) -> str:
    """Zenoh's error on opening a session as one line naming the endpoint and the cause."""
    listener = _LISTENER.search(message)
    if listener:
        endpoint, cause = listener.groups()
        return f"listen {endpoint}: {cause[:1].lower()}{cause[1:]}"
    unreachable = _UNREACHABLE.search(message)
    if unreachable:
        endpoints = re.findall(r"\w+/[^\s(),\]]+", unreachable[1]) or list(settings.connect)
        timeout = settings.connect_timeout_ms
        waited = f"within {timeout} ms (connect_timeout_ms)"
        if not timeout:
            waited = "to one try (connect_timeout_ms = 0)"
        return f"connect {', '.join(endpoints)}: no answer {waited}; is the router running?"
    where = ", ".join((*settings.listen, *settings.connect)) or "zenoh"
    return f"{where}: {_one_line(message)}"


def _one_line(message: str) -> str:
    """Zenoh's error text without its source locations and nesting."""
    message = re.sub(r"\s+at\s+\S+\.rs:\d+\.?", "", message)
    return " ".join(message.replace("[", " ").replace("]", " ").split()).rstrip(".")


def tick_publisher(session, key: str):
    """A publisher for a per-tick message (measurement, command, share): sent at once, not
    batched (``express``), and never dropped when queues fill (congestion control ``BLOCK``):
    a lockstep run waits for each of these."""
    import zenoh

    return session.declare_publisher(
        key, express=True, congestion_control=zenoh.CongestionControl.BLOCK
    )


def watch_liveliness(session, key: str, on_change: Callable[[str, bool], None]):
    """Subscribe to the liveliness tokens matching ``key`` (those already there included):
    ``on_change(token key, alive)`` when one appears or disappears (its process was killed or
    hung past its lease). Returns the subscriber (``undeclare()`` it when done)."""
    import zenoh

    return session.liveliness().declare_subscriber(
        key,
        lambda s: on_change(str(s.key_expr), s.kind == zenoh.SampleKind.PUT),
        history=True,
    )


def fifo_subscriber(session, key: str, capacity: int):
    """A subscriber to ``key`` whose samples queue in Zenoh's own FIFO of ``capacity``,
    outside Python: reception never waits for this process's interpreter (when the FIFO is
    full, the link to the router backs up). Empty it with :func:`take`."""
    import zenoh

    return session.declare_subscriber(key, zenoh.handlers.FifoChannel(capacity))


def take(subscriber, limit: int) -> Iterator:
    """The samples a :func:`fifo_subscriber` holds, at most ``limit``, without waiting."""
    for _ in range(limit):
        sample = subscriber.try_recv()
        if sample is None:
            return
        yield sample
