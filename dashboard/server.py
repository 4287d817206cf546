"""Serving the dashboard's app with uvicorn on a thread, on a socket bound beforehand.

Binding first means a busy or foreign port fails at once with one clear line (before a run
starts), port 0 picks a free one, and the URL is known before the server runs.
"""

from __future__ import annotations

import ipaddress
import socket
import threading
import time

import uvicorn

LOOPBACK = "127.0.0.1"


class ServeError(OSError):
    """The server's address cannot be used (``str()`` is one line naming it)."""


def is_loopback(host: str) -> bool:
    """Whether ``host`` is a loopback address or ``localhost`` (no token needed there)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host:port``; :class:`ServeError` if it cannot be had."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((host, port))
        sock.listen(128)
    except OSError as err:
        sock.close()
        raise ServeError(f"listen {host}:{port}: {err.strerror or err}") from None
    sock.set_inheritable(False)
    return sock


class Server:
    """The app served on its own thread: :meth:`start`, :attr:`url`, :meth:`stop`."""

    def __init__(self, app, host: str = LOOPBACK, port: int = 0):
        self.sock = bind(host, port)
        self.host = host
        self.port = self.sock.getsockname()[1]
        config = uvicorn.Config(
            app,
            log_level="warning",
            lifespan="on",
            ws="websockets-sansio",
            ws_ping_interval=None,
            # Frames are small (about 12 kB for 16 robots) and many: compressing them cost
            # the server more than it saves on a LAN or an SSH tunnel.
            ws_per_message_deflate=False,
            timeout_graceful_shutdown=1,
        )
        self._server = uvicorn.Server(config)
        self._thread = threading.Thread(target=self._serve, name="dashboard-http", daemon=True)

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

    def _serve(self) -> None:
        self._server.run(sockets=[self.sock])

    def start(self, timeout_s: float = 10.0) -> Server:
        """Start serving; returns once requests are answered."""
        self._thread.start()
        deadline = time.monotonic() + timeout_s
        while not self._server.started:
            if not self._thread.is_alive() or time.monotonic() > deadline:
                raise ServeError(f"the dashboard at {self.url} did not start")
            time.sleep(0.01)
        return self

    def stop(self) -> None:
        self._server.should_exit = True
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
        self.sock.close()
