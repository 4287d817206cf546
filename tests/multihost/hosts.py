"""Several network hosts on one machine, for the multi-host tests (``make multihost``).

Each host is a Linux network namespace with its own address on ``10.77.0.0/24`` (IPv4 only),
plugged by a veth pair into a Linux bridge that lives in a namespace of its own (the switch):
no interface of a test's network exists outside its namespaces, so all its traffic stays in
them. A process runs on a host through ``ip netns exec``. A host's link is cut and restored
with ``ip link set eth0 down|up`` in its namespace. Needs root (``HEFT_REQUIRE_NETNS=1`` makes a
machine without it a failure rather than a skip).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TextIO

from agent.platform.children import Child, stop_all
from tests.helpers.paths import ROOT

SUBNET = "10.77.0"


def netns_available() -> str | None:
    """Why network namespaces cannot be used here (``None`` if they can)."""
    if os.geteuid() != 0:
        return "network namespaces need root"
    if shutil.which("ip") is None:
        return "no ip command (iproute2)"
    probe = f"heft-probe-{os.getpid()}"
    made = subprocess.run(["ip", "netns", "add", probe], capture_output=True, text=True)
    if made.returncode != 0:
        return f"ip netns add failed: {made.stderr.strip()}"
    subprocess.run(["ip", "netns", "del", probe], capture_output=True)
    return None


def _ip(*args: str) -> None:
    done = subprocess.run(["ip", *args], capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)}: {done.stderr.strip()}")


class Hosts:
    """Named hosts (namespaces) on one switch; ``address(name)`` is the host's IPv4 address."""

    def __init__(self, names: Sequence[str], logs: Path):
        self.prefix = f"h{os.getpid() % 100000}-"
        self.names = list(names)
        self.logs = logs
        self._addresses = {name: f"{SUBNET}.{10 + i}" for i, name in enumerate(self.names)}
        self.children: list[Child] = []
        self._streams: list[TextIO] = []
        self._made: list[str] = []

    def ns(self, name: str) -> str:
        return self.prefix + name

    def address(self, name: str) -> str:
        return self._addresses[name]

    def __enter__(self) -> Hosts:
        try:
            switch = self.ns("switch")
            self._add(switch)
            _ip("-n", switch, "link", "add", "br0", "type", "bridge")
            _ip("-n", switch, "link", "set", "br0", "up")
            for i, name in enumerate(self.names):
                ns = self.ns(name)
                self._add(ns)
                port = f"p{i}"
                _ip(
                    "link",
                    "add",
                    "eth0",
                    "netns",
                    ns,
                    "type",
                    "veth",
                    "peer",
                    port,
                    "netns",
                    switch,
                )
                _ip("-n", ns, "addr", "add", f"{self.address(name)}/24", "dev", "eth0")
                _ip("-n", ns, "link", "set", "eth0", "up")
                _ip("-n", switch, "link", "set", port, "master", "br0")
                _ip("-n", switch, "link", "set", port, "up")
        except BaseException:
            self.close()
            raise
        return self

    def _add(self, ns: str) -> None:
        _ip("netns", "add", ns)
        self._made.append(ns)
        _ip("-n", ns, "link", "set", "lo", "up")
        for key in ("all", "default"):  # IPv4 only: nothing of IPv6's own chatter
            subprocess.run(
                ["ip", "netns", "exec", ns, "sysctl", "-qw", f"net.ipv6.conf.{key}.disable_ipv6=1"],
                capture_output=True,
            )

    def start(self, host: str, name: str, args: Sequence[str], module: str = "agent") -> Child:
        """``heft ARGS`` (or ``python -m MODULE ARGS``) as a process on ``host``; its output
        goes to ``logs/NAME.log``."""
        stream = open(self.logs / f"{name}.log", "a", buffering=1)  # noqa: SIM115
        self._streams.append(stream)
        env = dict(os.environ)
        env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
        env["PYTHONUNBUFFERED"] = "1"
        argv = ["ip", "netns", "exec", self.ns(host), sys.executable, "-m", module, *args]
        child = Child(name, argv, stream, env)
        self.children.append(child)
        return child

    def cut(self, host: str) -> None:
        _ip("-n", self.ns(host), "link", "set", "eth0", "down")

    def restore(self, host: str) -> None:
        _ip("-n", self.ns(host), "link", "set", "eth0", "up")

    def log(self, name: str) -> str:
        return (self.logs / f"{name}.log").read_text(encoding="utf-8", errors="replace")

    def close(self) -> None:
        stop_all(self.children[::-1])
        for stream in self._streams:
            stream.close()
        for ns in reversed(self._made):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)
        self._made.clear()

    def __exit__(self, *exc) -> None:
        self.close()
