"""Opening Zenoh sessions the project's way.

Every session the project opens goes through :func:`open_session`: multicast scouting is off
and every endpoint is explicit (``tcp/127.0.0.1:PORT`` in demos and tests), shared memory is
off (it is not available everywhere the agents run), and a client waits for a router that is
not up yet instead of failing at once.
"""

from __future__ import annotations

import json
import queue
import re
from dataclasses import dataclass

from agent.config import ConfigError

DEFAULT_ROUTER = "tcp/127.0.0.1:7447"
_ENDPOINT = re.compile(r"^(tcp|udp|quic|tls)/[^:/\s]+:\d{1,5}$")


@dataclass(frozen=True)
class ZenohSettings:
    """Where a process's Zenoh session connects and listens (the ``[zenoh]`` table)."""

    mode: str = "client"
    """``client`` (through a router), ``peer`` or ``router``."""
    connect: tuple[str, ...] = (DEFAULT_ROUTER,)
    listen: tuple[str, ...] = ()
    lease_ms: int = 2000
    """How soon the others notice this process hung (``transport/link/tx/lease``)."""
    connect_timeout_ms: int = 15000
    """How long a client waits for its router at start-up."""

    def validate(self, where: str) -> None:
        if self.mode not in ("client", "peer", "router"):
            raise ConfigError(f"{where}.mode: expected client, peer or router, got {self.mode!r}")
        for key in ("connect", "listen"):
            for i, endpoint in enumerate(getattr(self, key)):
                if not _ENDPOINT.match(endpoint):
                    raise ConfigError(
                        f"{where}.{key}[{i}]: expected an explicit endpoint like "
                        f"tcp/127.0.0.1:7447, got {endpoint!r}"
                    )
        if self.mode == "client" and not self.connect:
            raise ConfigError(f"{where}.connect: a client needs at least one router endpoint")
        if self.mode == "router" and not self.listen:
            raise ConfigError(f"{where}.listen: a router needs at least one endpoint")
        if self.lease_ms < 100 or self.connect_timeout_ms < 0:
            raise ConfigError(f"{where}: lease_ms must be >= 100 and connect_timeout_ms >= 0")


def zenoh_config(settings: ZenohSettings):
    """The ``zenoh.Config`` for ``settings`` (multicast scouting always off)."""
    import zenoh

    config = zenoh.Config()
    config.insert_json5("mode", json.dumps(settings.mode))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("connect/endpoints", json.dumps(list(settings.connect)))
    config.insert_json5("listen/endpoints", json.dumps(list(settings.listen)))
    config.insert_json5("transport/shared_memory/enabled", "false")
    config.insert_json5("transport/link/tx/lease", str(settings.lease_ms))
    config.insert_json5("transport/link/tx/keep_alive", "4")
    if settings.mode == "client":
        config.insert_json5("connect/timeout_ms", str(settings.connect_timeout_ms))
        config.insert_json5(
            "connect/retry",
            '{"period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2}',
        )
    return config


def open_session(settings: ZenohSettings):
    """Open a Zenoh session; close it with ``session.close()`` (or use it in ``with``)."""
    import zenoh

    return zenoh.open(zenoh_config(settings))


def tick_publisher(session, key: str):
    """A publisher for a per-tick message (measurement, command, share): sent at once, not
    batched (``express``), and never dropped when queues fill (congestion control ``BLOCK``):
    a lockstep run waits for each of these."""
    import zenoh

    return session.declare_publisher(
        key, express=True, congestion_control=zenoh.CongestionControl.BLOCK
    )


class EventQueue:
    """Where a process's Zenoh callbacks leave what they receive, for its main thread.

    Callbacks run on Zenoh's threads and must stay tiny (a busy thread holding the GIL delays
    them by milliseconds): they only :meth:`put`; the main thread :meth:`drain`\\ s.
    """

    def __init__(self) -> None:
        self._queue: queue.SimpleQueue = queue.SimpleQueue()

    def put(self, event) -> None:
        self._queue.put(event)

    def drain(self, handle, timeout: float | None) -> None:
        """Wait up to ``timeout`` s for an event, then ``handle`` it and every other queued."""
        try:
            handle(self._queue.get(timeout=timeout))
            while True:
                handle(self._queue.get_nowait())
        except queue.Empty:
            pass
