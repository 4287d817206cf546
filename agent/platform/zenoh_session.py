"""Opening Zenoh sessions the project's way.

Every session the project opens goes through :func:`open_session`: multicast scouting is off
and every endpoint is explicit (``tcp/127.0.0.1:PORT`` in demos and tests), shared memory is
off (it is not available everywhere the agents run), and a client waits for a router that is
not up yet instead of failing at once.

Off a single host, sessions go over mutual TLS: ``root_ca``, ``certificate`` and
``private_key`` (made by :mod:`agent.security.certificates`) and ``tls/HOST:PORT`` endpoints; the
router's access control (:mod:`agent.security.access_control`) then knows each process by its
certificate. Plain ``tcp``/``udp`` to anything but loopback is refused unless ``allow_plain``.

Each session says in the log what its final config puts in force (:func:`describe`): its
endpoints and whether each is TLS or plain, mutual TLS, access control, multicast scouting and
how much of Zenoh's own log the process routes into its log (:mod:`agent.platform.zenoh_log`,
turned on here, at the process's first session).
"""

from __future__ import annotations

import ipaddress
import json
import logging
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from agent.platform import zenoh_log
from agent.platform.config import ConfigError, bounded, check_bounds
from agent.platform.process import in_user_mode_linux

DEFAULT_ROUTER = "tcp/127.0.0.1:7447"
LEASE_MS = 2000
"""How soon the others notice that a process hung, by default: 2 s."""
EMULATED_LEASE_MS = 10_000
"""The default lease in User-Mode Linux (:func:`~agent.platform.process.in_user_mode_linux`). There
the guest's one CPU serves every process of a run, each system call costs about 100 µs, and
keep-alives wait: with a 2 s lease the sessions of a CAN run (router, plant, four bridges,
four agents) expired and reconnected every few seconds, and the team halted; with 10 s it
ran through."""
_ENDPOINT = re.compile(r"^(tcp|udp|quic|tls)/[^:/\s]+:\d{1,5}$")
PLAIN = ("tcp", "udp")
"""Link protocols without encryption or authentication."""
TLS_FILES = ("root_ca", "certificate", "private_key")
"""The ``[zenoh]`` keys of mutual TLS: given all three, or none."""
log = logging.getLogger("heft.zenoh")


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
    are applied on top of it, so its mode, scouting and lease are never used. Its endpoints
    are, where it gives them, on the command line (:func:`file_endpoints`,
    :func:`agent.platform.cli_helpers.zenoh_settings`): ``--connect`` and ``--listen``
    replace them, and they replace ``connect`` and ``listen``."""
    root_ca: str | None = None
    """Mutual TLS: the team's CA certificate (PEM), which every certificate shown to this
    process must be signed by (``transport/link/tls/root_ca_certificate``). ``root_ca``,
    ``certificate`` and ``private_key`` go together (see :mod:`agent.security.certificates`)."""
    certificate: str | None = None
    """Mutual TLS: this process's certificate (PEM, signed by ``root_ca``); its Common Name
    is the identity the router's access control knows it by (``robot-3``, ``plant``, ...)."""
    private_key: str | None = None
    """Mutual TLS: the private key of ``certificate`` (PEM; keep it mode 0600)."""
    allow_plain: bool = False
    """Allow ``tcp``/``udp`` endpoints to addresses other than loopback: unencrypted, and
    anyone on the network can join. Off a single host, use ``tls`` endpoints instead."""

    def validate(self, where: str, names: dict[str, str] | None = None) -> None:
        """:class:`ConfigError` naming the key (``where.key``, or ``names[key]`` where given,
        e.g. a command-line option) unless the settings are usable."""
        names = names or {}

        def name(key: str) -> str:
            return names.get(key, f"{where}.{key}")

        if self.mode not in ("client", "peer", "router"):
            raise ConfigError(f"{name('mode')}: expected client, peer or router, got {self.mode!r}")
        for key in ("connect", "listen"):
            for i, endpoint in enumerate(getattr(self, key)):
                self.check_endpoint(endpoint, names.get(key, f"{where}.{key}[{i}]"))
        if self.mode == "client" and not self.connect:
            raise ConfigError(f"{name('connect')}: a client needs at least one router endpoint")
        if self.mode == "router" and not self.listen:
            raise ConfigError(f"{name('listen')}: a router needs at least one endpoint")
        check_bounds(self, where)
        if self.config_file is not None:
            self.check_config_file(self.config_file, name("config_file"))
        given = [key for key in TLS_FILES if getattr(self, key) is not None]
        if given and len(given) < len(TLS_FILES):
            missing = next(key for key in TLS_FILES if key not in given)
            raise ConfigError(
                f"{name(missing)}: missing: root_ca, certificate and private_key go together"
                f" (given: {', '.join(map(name, given))})"
            )
        for key in given:
            if key != "private_key":  # (see check_private_key)
                self.check_config_file(getattr(self, key), name(key))
        for key in ("connect", "listen"):
            for i, endpoint in enumerate(getattr(self, key)):
                at = names.get(key, f"{where}.{key}[{i}]")
                if not self.allow_plain:
                    self.check_plain(endpoint, at)
                if self.is_tls(endpoint) and not given and self.config_file is None:
                    raise ConfigError(
                        f"{at}: {endpoint}: a tls endpoint needs root_ca, certificate and"
                        " private_key (deploy/README.md)"
                    )

    def check_private_key(self, where: str) -> None:
        """:class:`ConfigError` naming ``where`` unless ``private_key`` (if any) is readable.

        Not part of :meth:`validate`: on robots the key is root's alone, and the service
        manager hands it to the process (systemd's ``LoadCredential``) at another path,
        given on the command line (``--tls-private-key``); the file's path is checked only
        once the command line has had its say (:func:`agent.platform.cli_helpers.zenoh_settings`,
        :func:`open_session`)."""
        if self.private_key is not None:
            self.check_config_file(self.private_key, where)

    @property
    def tls(self) -> bool:
        """Whether the settings give mutual TLS's three files."""
        return self.root_ca is not None

    @staticmethod
    def is_tls(endpoint: str) -> bool:
        return endpoint.split("/", 1)[0] in ("tls", "quic")

    @staticmethod
    def is_plain(endpoint: str) -> bool:
        """Whether ``endpoint`` is an unencrypted link (``tcp``, ``udp``)."""
        return endpoint.split("/", 1)[0] in PLAIN

    @staticmethod
    def is_loopback(endpoint: str) -> bool:
        """Whether ``endpoint``'s host is this machine's loopback (127.0.0.0/8, localhost,
        ::1)."""
        host = endpoint.split("/", 1)[-1].rsplit(":", 1)[0].strip("[]")
        if host.lower() == "localhost":
            return True
        try:
            return ipaddress.ip_address(host).is_loopback
        except ValueError:
            return False

    @staticmethod
    def check_plain(endpoint: str, where: str, allow: str = "set allow_plain = true") -> None:
        """:class:`ConfigError` naming ``where`` if ``endpoint`` is a plain link to an address
        other than loopback; ``allow`` says how to allow it anyway."""
        if ZenohSettings.is_plain(endpoint) and not ZenohSettings.is_loopback(endpoint):
            protocol = endpoint.split("/", 1)[0]
            raise ConfigError(
                f"{where}: {endpoint}: plain {protocol} to a non-loopback address: use"
                " tls/HOST:PORT with root_ca, certificate and private_key (deploy/README.md),"
                f" or {allow}"
            )

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
SEND_BUFFER_BYTES = 4 << 20
"""Each TCP or TLS link's socket send buffer (``so_sndbuf``; the kernel caps it at its
``net.core.wmem_max``). When a peer becomes unreachable (its link cut), what is sent to it
piles up in this buffer; once the buffer is full, a TLS link's writer waits, and while it
waits Zenoh cannot close the link when its lease expires: the router stalled, and the lost
robot was noticed only once its link came back (3.1 s after a 3 s cut). A buffer that holds
more than a lease's worth of a team's traffic lets the lease close the link: 1.6 s after the
cut, measured on namespace hosts (tests/multihost/test_multihost.py)."""


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
    for protocol in ("tcp", "tls"):
        config.insert_json5(f"transport/link/{protocol}/so_sndbuf", str(SEND_BUFFER_BYTES))
    if settings.mode == "client":
        config.insert_json5("connect/timeout_ms", str(settings.connect_timeout_ms))
        config.insert_json5(
            "connect/retry",
            '{"period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2}',
        )
    if settings.tls:
        for key, value in tls_keys(settings).items():
            config.insert_json5(key, json.dumps(value))
    return config


def tls_keys(settings: ZenohSettings) -> dict[str, object]:
    """Zenoh's keys for the settings' mutual TLS (none without it): the CA, the certificate
    and key shown when listening (a router, or any process with listen endpoints) and when
    connecting, and ``enable_mtls`` (the listener asks for the client's certificate)."""
    if not settings.tls:
        return {}
    prefix = "transport/link/tls/"
    keys: dict[str, object] = {f"{prefix}root_ca_certificate": settings.root_ca}
    if settings.mode == "router" or settings.listen:
        keys[f"{prefix}listen_certificate"] = settings.certificate
        keys[f"{prefix}listen_private_key"] = settings.private_key
    if settings.mode != "router" or settings.connect:
        keys[f"{prefix}connect_certificate"] = settings.certificate
        keys[f"{prefix}connect_private_key"] = settings.private_key
    keys[f"{prefix}enable_mtls"] = True
    return keys


def file_endpoints(path: str, mode: str) -> dict[str, tuple[str, ...]]:
    """The endpoints the Zenoh config file ``path`` gives a session of ``mode``: ``connect``
    and ``listen``, each only if the file gives some (a list, or a list for ``mode`` in a
    table by mode; not Zenoh's default, which a file without the key has). ``zenoh.ZError``
    if the file is not a valid Zenoh config."""
    import zenoh

    given, default = zenoh.Config.from_file(path), zenoh.Config()
    endpoints: dict[str, tuple[str, ...]] = {}
    for key in ("connect", "listen"):
        value = json.loads(given.get_json(f"{key}/endpoints"))
        if value == json.loads(default.get_json(f"{key}/endpoints")):
            continue
        if isinstance(value, dict):
            value = value.get(mode) or []
        if value:
            endpoints[key] = tuple(str(endpoint) for endpoint in value)
    return endpoints


def describe(config) -> str:
    """What the final Zenoh ``config`` of a session puts in force, as one line for the log:
    its mode and endpoints, plain links, TLS (whether client certificates are required: mutual
    TLS), access control (and its default permission), multicast scouting, and how much of
    Zenoh's own log this process routes (:func:`agent.platform.zenoh_log.in_force`), e.g.

    ``zenoh router: listen tls/192.168.10.1:7447; mutual TLS: clients must show a certificate
    signed by /etc/heft/tls/ca.pem; access control on: default deny, 7 subjects; multicast
    scouting off; zenoh log warn,zenoh=info (--zenoh-log info)``."""

    def get(key: str):
        return json.loads(config.get_json(key))

    mode = get("mode") or "peer"
    parts: list[str] = []
    endpoints: dict[str, list[str]] = {}
    for key in ("listen", "connect"):
        value = get(f"{key}/endpoints")
        if isinstance(value, dict):
            value = value.get(mode) or []
        endpoints[key] = [str(endpoint) for endpoint in value]
        if value:
            parts.append(f"{key} {', '.join(endpoints[key])}")
    every = endpoints["listen"] + endpoints["connect"]
    plain = [endpoint for endpoint in every if ZenohSettings.is_plain(endpoint)]
    if plain:
        protocols = "/".join(sorted({endpoint.split("/", 1)[0] for endpoint in plain}))
        where = "for loopback runs only"
        if not all(map(ZenohSettings.is_loopback, plain)):
            where = "anyone on the network can join"
        parts.append(f"plain {protocols}: no TLS, no certificates ({where})")
    tls = get("transport/link/tls") or {}
    if any(map(ZenohSettings.is_tls, endpoints["listen"])):
        if tls.get("enable_mtls"):
            parts.append(
                "mutual TLS: clients must show a certificate signed by"
                f" {tls.get('root_ca_certificate') or 'the system roots'}"
            )
        else:
            parts.append("TLS without client certificates: anyone can connect")
    if any(map(ZenohSettings.is_tls, endpoints["connect"])):
        shown = tls.get("connect_certificate")
        trusts = tls.get("root_ca_certificate") or "the system roots"
        if shown and tls.get("enable_mtls"):
            parts.append(f"mutual TLS: shows {shown}, trusts {trusts}")
        else:
            parts.append(f"TLS without a certificate of its own, trusts {trusts}")
    acl = get("access_control") or {}
    if acl.get("enabled"):
        subjects = len(acl.get("subjects") or [])
        parts.append(
            f"access control on: default {acl.get('default_permission')}, {subjects} subjects"
        )
    else:
        parts.append("access control off")
    parts.append(f"multicast scouting {'on' if get('scouting/multicast/enabled') else 'off'}")
    logged = zenoh_log.in_force()
    if logged is not None:
        parts.append(f"zenoh log {logged}")
    return f"zenoh {mode}: " + "; ".join(parts)


class SessionError(ConfigError):
    """Zenoh could not open the session: ``str()`` is one line naming the endpoint and why,
    e.g. ``listen tcp/127.0.0.1:7447: address already in use`` or ``connect
    tcp/127.0.0.1:7447: no answer within 15000 ms (connect_timeout_ms); is the router
    running?``."""


def open_session(settings: ZenohSettings):
    """Open a Zenoh session; close it with ``session.close()`` (or use it in ``with``). Once
    open, it says in the log what is in force (:func:`describe`). The first session of a
    process that asked for Zenoh's log (:func:`agent.platform.zenoh_log.request`) turns it on
    first. :class:`SessionError` if Zenoh cannot (it raises ``zenoh.ZError``: a busy or
    unusable port, no router within ``connect_timeout_ms``)."""
    import zenoh

    settings.check_private_key("zenoh.private_key")
    zenoh_log.start()
    config = zenoh_config(settings)
    in_force = describe(config)
    try:
        session = zenoh.open(config)
    except zenoh.ZError as err:
        raise SessionError(session_error(str(err), settings)) from None
    log.info("%s", in_force)
    return session


_LISTENER = re.compile(r"listener bound to (\w+/\S+?): \[.*?: (.+?) \(os error \d+\)", re.S)
_UNREACHABLE = re.compile(r"Unable to connect to any of \[(.*?)\]\s*(\. Timeout!|!)", re.S)


_LINK_OPTIONS = re.compile(r"#[\w=;.-]+")


def session_error(message: str, settings: ZenohSettings) -> str:
    """Zenoh's error on opening a session as one line naming the endpoint and the cause."""
    message = _LINK_OPTIONS.sub("", message)  # the link options zenoh_config adds (so_sndbuf)
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
        hint = "is the router running?"
        if any(map(ZenohSettings.is_tls, endpoints)):
            hint = (
                "is the router running, and are its certificate and this process's signed by"
                " the same CA (root_ca)?"
            )
        return f"connect {', '.join(endpoints)}: no answer {waited}; {hint}"
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
