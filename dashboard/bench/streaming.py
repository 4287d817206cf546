"""The dashboard's benchmark (``heft bench dashboard``).

Live: ``robots`` fake agents publish their estimates at ``rate_hz`` through a Zenoh router into
a ``heft dashboard`` process, with ``browsers`` headless Chromium pages connected. Measured:
the dashboard process's CPU (share of one core), the latency from each estimate's publication
to a page's receipt of the frame that first shows it (p50, p99), and how long the pages take
to redraw.

Memory: a synthetic recording of the same team (estimates at the agents' report rate, the
truth at 100 Hz) is replayed at ``replay_speed`` for ``replay_minutes`` into a ``heft
dashboard --replay`` process with one page connected; its resident memory is sampled and
compared with its level after the first quarter of the replay.

Its goals (:data:`GOALS`, measured by :meth:`BenchReport.figures`): the dashboard's CPU below
25 % of one core, the latency's p99 below 200 ms, the memory's growth below 10 %.

Every process is on this machine, on 127.0.0.1; the benchmark stops what it started.
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from agent.platform.goals import Goal, Sense
from agent.platform.protocol import Estimates, Keys, Phase, Truth, encode
from agent.platform.statistics import percentile
from agent.platform.zenoh_session import ZenohSettings, open_session

CHROMIUM = "/usr/bin/chromium"
"""The browser the benchmark's pages run in (Debian's ``chromium`` package)."""

BROWSER_ARGS = ["--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-sync"]
GOALS = (
    Goal("cpu_pct", "dashboard CPU, share of one core", 25.0, Sense.BELOW, "%"),
    Goal("latency_p99_ms", "publish -> browser latency p99", 200.0, Sense.BELOW, "ms"),
    Goal(
        "memory_growth_pct",
        "replay's memory growth after the first quarter",
        10.0,
        Sense.BELOW,
        "%",
    ),
)
"""What the benchmark checks, on the figures of :meth:`BenchReport.figures`."""
ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class BenchSettings:
    robots: int = 16
    rate_hz: float = 100.0
    browsers: int = 3
    seconds: float = 30.0
    """Length of the live measurement (after a 5 s warm-up)."""
    replay_minutes: float = 10.0
    replay_speed: float = 10.0
    report_hz: float = 20.0
    """The recording's estimates per robot per second (the agents report every 5 ticks)."""


@dataclass
class BenchReport:
    settings: BenchSettings
    cpu_pct: float = math.nan
    received_hz: float = math.nan
    """Messages the dashboard took in per second during the CPU measurement."""
    latency_ms: list[float] = field(default_factory=list)
    server_ms: list[float] = field(default_factory=list)
    """Of the latency, the part until the frame left the server."""
    chart_ms: list[float] = field(default_factory=list)
    scene_ms: list[float] = field(default_factory=list)
    rss_mb: list[float] = field(default_factory=list)

    @property
    def memory_growth_pct(self) -> float:
        """Growth after the first quarter of the replay (by then the charts' buffers are
        full: 3000 points per trace take 15 s at 10x), relative to its level then."""
        if len(self.rss_mb) < 4:
            return math.nan
        start = len(self.rss_mb) // 4
        base = self.rss_mb[start]
        return 100.0 * (max(self.rss_mb[start:]) - base) / base

    def figures(self) -> dict[str, float | None]:
        """The figures :data:`GOALS` bound (NaN: not measured)."""
        return {
            "cpu_pct": self.cpu_pct,
            "latency_p99_ms": _p(self.latency_ms, 99),
            "memory_growth_pct": self.memory_growth_pct,
        }

    def lines(self) -> list[str]:
        """The report (the goals' verdicts follow it: :data:`GOALS`)."""
        s = self.settings
        return [
            f"dashboard benchmark: {s.robots} robots' estimates at {s.rate_hz:g} Hz,"
            f" {s.browsers} browser(s), {s.seconds:g} s",
            f"  dashboard CPU: {self.cpu_pct:.1f} % of one core"
            f" for {self.received_hz:.0f} messages/s"
            f" ({1e4 * self.cpu_pct / self.received_hz:.0f} µs of CPU each)",
            f"  publish -> browser latency: p50 {_p(self.latency_ms, 50):.0f} ms,"
            f" p99 {_p(self.latency_ms, 99):.0f} ms over {len(self.latency_ms)} samples;"
            f" until the frame leaves the server p50 {_p(self.server_ms, 50):.0f} ms,"
            f" p99 {_p(self.server_ms, 99):.0f} ms",
            f"  page redraw: charts p50 {_p(self.chart_ms, 50):.1f} ms,"
            f" p99 {_p(self.chart_ms, 99):.1f} ms; top view, graph, timeline"
            f" and table p50 {_p(self.scene_ms, 50):.1f} ms,"
            f" p99 {_p(self.scene_ms, 99):.1f} ms",
            f"  replay of {s.replay_minutes * s.replay_speed:g} recorded minutes at"
            f" {s.replay_speed:g}x: resident memory {self._rss()}, growth after the first"
            f" quarter {self.memory_growth_pct:.1f} %",
        ]

    def _rss(self) -> str:
        if not self.rss_mb:
            return "not measured"
        return f"{min(self.rss_mb):.0f}-{max(self.rss_mb):.0f} MB ({len(self.rss_mb)} samples)"


def _p(values: list[float], q: float) -> float:
    """The ``q``-th percentile of ``values``; NaN (not measured) without any."""
    return percentile(values, q) if values else math.nan


# ------------------------------------------------------------------------------ processes
def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_dashboard(*args: str) -> tuple[subprocess.Popen, str]:
    """``heft dashboard ARGS --port 0`` and the URL it prints."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONUNBUFFERED="1")
    process = subprocess.Popen(
        [sys.executable, "-m", "agent", "dashboard", "--port", "0", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        env=env,
    )
    line = process.stdout.readline()
    match = re.match(r"dashboard: (\S+)", line)
    if not match:
        process.kill()
        raise RuntimeError(f"heft dashboard did not start: {line!r}")
    return process, match.group(1)


def stop(process: subprocess.Popen) -> None:
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return math.nan


def estimates(robot: int, n: int, tick: int) -> Estimates:
    """A plausible estimate of robot ``robot`` of a ring of ``n`` at ``tick``."""
    t = tick * 0.01
    left, right = (robot - 2) % n + 1, robot % n + 1
    return Estimates(
        robot=robot,
        tick=tick,
        phase=Phase.PUSH,
        phase_since=0,
        omega=0.3 + 0.01 * math.sin(t),
        relative_positions={left: (1.0 + 0.1 * math.exp(-t), 0.5), right: (-1.0, 0.2)},
        centroid_offset=(0.5, 0.5),
        w=2.0,
        moment=12.3 + math.exp(-t),
        com_offset=(0.1, -0.1),
        com_observer=(0.1, -0.1),
        com_velocity=(0.2, 0.0),
        mass=5.0 + math.exp(-t),
        contact_to_com=(1.0, 0.3),
        started={1: 0},
        settled={1: 10},
    )


def truth(n: int, tick: int) -> Truth:
    angle = 0.001 * tick
    contacts = tuple(
        (3 * math.cos(angle + 2 * math.pi * k / n), 3 * math.sin(angle + 2 * math.pi * k / n))
        for k in range(n)
    )
    return Truth(
        tick,
        tick * 0.01,
        (0.0, 0.0),
        angle,
        (0.0, 0.0),
        0.1,
        contacts,
        ((0.0, 0.0),) * n,
        tuple((-x, -y) for x, y in contacts),
        5.0,
        12.3,
    )


# ------------------------------------------------------------------------------ live
def measure_live(settings: BenchSettings, report: BenchReport, sync_playwright) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    keys = Keys(f"bench-{os.getpid()}")
    published: dict[int, float] = {}
    stop_event = threading.Event()
    with open_session(ZenohSettings(mode="router", connect=(), listen=(endpoint,))) as session:
        dashboard, url = start_dashboard("--team", keys.team, "--connect", endpoint)
        publishers = [
            session.declare_publisher(keys.estimate(i)) for i in range(1, 1 + settings.robots)
        ]

        def publish() -> None:
            period, tick, next_at = 1.0 / settings.rate_hz, 0, time.monotonic()
            while not stop_event.is_set():
                published[tick] = time.time() * 1000.0
                for i, publisher in enumerate(publishers, start=1):
                    publisher.put(encode(estimates(i, settings.robots, tick)))
                if tick % 10 == 0:
                    session.put(keys.truth(), encode(truth(settings.robots, tick)))
                published.pop(tick - 20_000, None)
                tick += 1
                next_at += period
                stop_event.wait(max(0.0, next_at - time.monotonic()))

        thread = threading.Thread(target=publish, daemon=True)
        try:
            with sync_playwright() as p:
                browser = p.chromium.launch(executable_path=CHROMIUM, args=BROWSER_ARGS)
                pages = []
                for _ in range(settings.browsers):
                    page = browser.new_context(viewport={"width": 1280, "height": 800}).new_page()
                    page.goto(url)
                    pages.append(page)
                thread.start()
                time.sleep(5.0)  # warm-up
                for page in pages:
                    page.evaluate("window.heft.receipts.length = 0")
                cpu0, wall0 = cpu_seconds(dashboard.pid), time.monotonic()
                received0 = received(url)
                time.sleep(settings.seconds)
                cpu1, wall1 = cpu_seconds(dashboard.pid), time.monotonic()
                received1 = received(url)
                report.cpu_pct = 100.0 * (cpu1 - cpu0) / (wall1 - wall0)
                report.received_hz = (received1 - received0) / (wall1 - wall0)
                for page in pages:
                    receipts = page.evaluate("window.heft.receipts")
                    report.chart_ms += page.evaluate("window.heft.chartMs")
                    report.scene_ms += page.evaluate("window.heft.sceneMs")
                    total, server = latencies(receipts, published)
                    report.latency_ms += total
                    report.server_ms += server
                browser.close()
        finally:
            stop_event.set()
            if thread.is_alive():
                thread.join()
            stop(dashboard)


def received(url: str) -> int:
    """How many messages the dashboard at ``url`` has taken in (``GET /api/snapshot``)."""
    import json
    import urllib.request

    with urllib.request.urlopen(f"{url.rstrip('/')}/api/snapshot", timeout=10) as response:
        return sum(json.load(response)["received"].values())


def latencies(receipts: list, published: dict[int, float]) -> tuple[list[float], list[float]]:
    """For each robot, the time from an estimate's publication to the first frame that
    shows it (or a newer one) reaching the page, and to that frame leaving the server."""
    total, server, shown = [], [], {}
    for at, sent, ticks in receipts:
        for robot, tick in (ticks or {}).items():
            if tick is None or tick <= shown.get(robot, -1):
                continue
            shown[robot] = tick
            published_at = published.get(tick)
            if published_at is not None:
                total.append(at - published_at)
                if sent is not None:
                    server.append(sent - published_at)
    return total, server


# ------------------------------------------------------------------------------ memory
def write_recording(path: Path, settings: BenchSettings, minutes: float) -> int:
    """A synthetic recording of ``minutes`` of the team: estimates at ``report_hz`` per robot,
    the truth at 100 Hz. Returns how many messages it holds."""
    from dashboard.recorder import Recorder

    keys = Keys("bench")
    ticks = round(minutes * 60 * 100)
    every = max(1, round(100 / settings.report_hz))
    count = 0
    with Recorder(path, keys.team) as recorder:
        for tick in range(ticks):
            stamp = 1_700_000_000_000_000_000 + tick * 10_000_000
            recorder.write(keys.truth(), truth(settings.robots, tick), stamp)
            count += 1
            if tick % every == 0:
                for i in range(1, settings.robots + 1):
                    recorder.write(keys.estimate(i), estimates(i, settings.robots, tick), stamp)
                    count += 1
    return count


def measure_memory(settings: BenchSettings, report: BenchReport, sync_playwright, folder: Path):
    path = folder / "bench.mcap"
    write_recording(path, settings, settings.replay_minutes * settings.replay_speed)
    dashboard, url = start_dashboard("--replay", str(path), "--speed", f"{settings.replay_speed:g}")
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=BROWSER_ARGS)
            page = browser.new_page(viewport={"width": 1280, "height": 800})
            page.goto(url)
            deadline = time.monotonic() + settings.replay_minutes * 60
            every = max(1.0, settings.replay_minutes * 60 / 60)
            while time.monotonic() < deadline and dashboard.poll() is None:
                report.rss_mb.append(rss_mb(dashboard.pid))
                time.sleep(every)
            browser.close()
    finally:
        stop(dashboard)


def run(settings: BenchSettings, folder: Path) -> BenchReport:
    from playwright.sync_api import sync_playwright

    report = BenchReport(settings)
    measure_live(settings, report, sync_playwright)
    if settings.replay_minutes > 0:
        measure_memory(settings, report, sync_playwright, folder)
    return report
