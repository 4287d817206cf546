"""The dashboard in a real browser during a live run: headless Chromium (Debian's, driven by
Playwright) opens the page while the paper's scenario runs over Zenoh (a router, the plant and
four agent processes, lockstep), and the page itself must show m̂ and Ĵ converging to the
truth, the top view moving and the phase timeline reaching "done". The run is recorded on the
way; replayed from the page, it shows the same final table as live. A robust run of the noisy
scenario, replayed, shows how sure each robot is: a 95 % band around each m̂ and ``±`` in the
table.

In CI (``CI`` set) a missing Chromium is a failure, never a skip."""

from __future__ import annotations

import contextlib
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from agent.platform.evaluation import SCALAR_95
from agent.platform.faults import FaultSettings
from agent.platform.protocol import Control, Keys, encode
from agent.platform.zenoh_session import ZenohSettings, open_session
from dashboard.companion import RunCompanion
from dashboard.display import Display
from simulator.launcher import robot_toml
from simulator.scenario import load_scenario
from tests.helpers.paths import PAPER, ROOT
from tests.helpers.recordings import record_run

pytestmark = pytest.mark.slow
CHROMIUM = "/usr/bin/chromium"
BROWSER_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
SCREENSHOT = ROOT / "out" / "dashboard.png"
NOISY = ROOT / "simulator" / "scenarios" / "paper-noisy.toml"


def chromium():
    """Playwright's Chromium, pointed at Debian's (skipped only outside CI when missing)."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        sync_playwright = None
    if sync_playwright is None or not Path(CHROMIUM).exists():
        if os.environ.get("CI"):
            pytest.fail(
                f"the browser test needs playwright and {CHROMIUM} (apt-get install chromium)"
            )
        pytest.skip(f"needs playwright and {CHROMIUM}")
    return sync_playwright


@contextlib.contextmanager
def browser_page(sync_playwright, url: str):
    """A headless Chromium page of 1280×800 opened on ``url``, and the errors it raises."""
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=BROWSER_ARGS)
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        errors: list[str] = []
        page.on("pageerror", lambda err: errors.append(str(err)))
        page.goto(url)
        yield page, errors
        browser.close()


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class PaperTeam:
    """The paper's team as processes: the plant and four agents, through a router."""

    def __init__(self, router: str, team: str, folder: Path):
        self.scenario = load_scenario(PAPER)
        env = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONUNBUFFERED="1")
        self.log = open(folder / "team.log", "w")  # noqa: SIM115 - closed in stop()
        self.processes = []
        heft = [sys.executable, "-m", "agent"]
        for i in range(1, self.scenario.n + 1):
            config = folder / f"robot-{i}.toml"
            text = robot_toml(i, self.scenario, team, "lockstep", router, FaultSettings())
            config.write_text(text, encoding="utf-8")
            self._start([*heft, "agent", "--config", str(config)], env)
        self._start(
            [*heft, "sim", str(PAPER), "--team", team, "--clock", "lockstep", "--connect", router],
            env,
        )

    def _start(self, args: list[str], env: dict) -> None:
        self.processes.append(
            subprocess.Popen(args, stdout=self.log, stderr=subprocess.STDOUT, env=env)
        )

    def stop(self) -> None:
        for process in self.processes:
            if process.poll() is None:
                process.terminate()
        for process in self.processes:
            try:
                process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        self.log.close()


TOP_SAMPLER = """() => {
  window.topSamples = [];
  setInterval(() => {
    const contact = window.heft.views.top.lines().find((t) => t.name === "contact 1");
    if (contact) window.topSamples.push([contact.x[0], contact.y[0]]);
  }, 100);
}"""
CHART_ENDS = """(name) => window.heft.charts[name].lines().map((t) => ({
  name: t.name, first: t.y[0], last: t.y[t.y.length - 1], count: t.y.length }))"""
CHART_DRAWN = """(name) => {
  const plot = window.heft.charts[name].plot;
  return plot ? [plot.series.length - 1, plot.data[0].length] : null;
}"""


BANDS = """(name) => window.heft.charts[name].bands().map((b) => ({
  name: b.name, count: b.x.length, lower: b.lower[b.lower.length - 1],
  upper: b.upper[b.upper.length - 1] }))"""
BAND_PIXELS = """(name) => {
  // the plot's pixels that change when uPlot's bands are hidden: those the bands painted
  const u = window.heft.charts[name].plot, { left, top, width, height } = u.bbox;
  const edges = u.bands.flatMap((b) => b.series);
  const pixels = () => u.ctx.getImageData(left, top, width, height).data;
  const shown = pixels();
  u.batch(() => edges.forEach((i) => u.setSeries(i, { show: false })));
  const hidden = pixels();
  u.batch(() => edges.forEach((i) => u.setSeries(i, { show: true })));
  let changed = 0;
  for (let k = 0; k < shown.length; k += 4) {
    if ([0, 1, 2, 3].some((c) => shown[k + c] !== hidden[k + c])) changed += 1;
  }
  return { bands: u.bands.length, changed, of: shown.length / 4 };
}"""


def wait_for(predicate, timeout_s: float, what: str, display=None) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}: {diagnosis(display)}"
        time.sleep(0.1)


def diagnosis(display) -> str:
    """What the dashboard knew, for a failure message."""
    if display is None:
        return ""
    state = display.hub.state
    robots = {
        i: (
            v.estimates and (v.estimates.tick, v.estimates.phase.label, v.estimates.phase_since),
            sorted(v.done_estimates)[:3],
        )
        for i, v in state.robots.items()
    }
    truths = (min(state.truths), max(state.truths)) if state.truths else None
    feed = display.feed
    alive = feed is not None and feed._thread.is_alive()
    return (
        f"robots {robots}, truths {truths}, done_instant {state.done_instant},"
        f" rejected {dict(state.rejected)}, received {dict(state.received)}, feed alive {alive}"
    )


def test_the_page_shows_a_live_run_converging_and_replays_it(tmp_path: Path) -> None:
    sync_playwright = chromium()
    router = f"tcp/127.0.0.1:{free_port()}"
    team = f"browser-{os.getpid()}"
    scenario = load_scenario(PAPER)
    # As heft demo does: the dashboard up before the run, then the recorder and the dashboard
    # subscribed once the run's router is up, before the plant and the agents start.
    companion = RunCompanion.open(tmp_path / "paper.mcap", dashboard=True, port=0)
    display = companion.display
    with open_session(ZenohSettings(mode="router", connect=(), listen=(router,))) as session:
        processes = None
        try:
            companion.on_ready(router, team)
            with browser_page(sync_playwright, display.url) as (page, errors):
                page.wait_for_function("window.heft && window.heft.frames > 0", timeout=20_000)
                page.evaluate(TOP_SAMPLER)
                started = time.monotonic()
                processes = PaperTeam(router, team, tmp_path)
                wait_for(lambda: display.hub.state.done, 120, "the team to be done", display)
                session.put(Keys(team).control(), encode(Control("stop")))  # as the launcher
                wait_for(lambda: display.hub.summary() is not None, 30, "the final table", display)
                print(f"live run: {time.monotonic() - started:.1f} s")
                page.wait_for_function(
                    "window.heft.scene && window.heft.scene.table.final", timeout=20_000
                )
                page.wait_for_timeout(600)  # the charts' last redraw
                live = display.hub.summary()

                # The charts hold m̂ and Ĵ converging to the truth (5 kg, 12.3795 kg m²).
                for chart, truth in (("mass", 5.0), ("moment", 12.3795)):
                    traces = {t["name"]: t for t in page.evaluate(CHART_ENDS, chart)}
                    drawn = page.evaluate(CHART_DRAWN, chart)  # uPlot holds every trace
                    assert drawn is not None and drawn[0] == len(traces) and drawn[1] > 20
                    robots = [t for name, t in traces.items() if "robot" in name]
                    assert len(robots) == 4, traces
                    truth_trace = next(t for name, t in traces.items() if "truth" in name)
                    assert truth_trace["last"] == truth
                    for trace in robots:
                        assert abs(trace["last"] - truth) / truth < 1e-3, trace
                edges = [t for t in page.evaluate(CHART_ENDS, "edge") if "robot" in t["name"]]
                assert len(edges) == 3
                contacts = scenario.contacts
                true_norms = [math.dist(contacts[i - 1], contacts[i]) for i in (1, 2, 3)]
                for trace, true_norm in zip(sorted(edges, key=lambda t: t["name"]), true_norms):
                    assert trace["count"] > 20
                    assert abs(trace["last"] - true_norm) < 1e-3
                    assert abs(trace["first"] - true_norm) > 10 * abs(trace["last"] - true_norm)
                # The top view moved with the load.
                samples = [s for s in page.evaluate("window.topSamples") if None not in s]
                assert len({tuple(s) for s in samples}) >= 3, samples
                assert math.dist(samples[0], samples[-1]) > 0.1
                # The phase timeline reached "done" for every robot.
                segments = page.evaluate("window.heft.views.timeline.lines().map((t) => t.name)")
                done = [name.removeprefix("done ") for name in segments if name.startswith("done ")]
                assert sorted(done) == [f"robot {i}" for i in range(1, 5)]
                assert page.inner_text("#table-title").startswith("final")
                SCREENSHOT.parent.mkdir(exist_ok=True)
                page.screenshot(path=str(SCREENSHOT))
                assert SCREENSHOT.stat().st_size > 20_000
                csv = page.evaluate("window.heft.csv()")
                assert csv.startswith("chart,trace,t_s,value,half_95\n") and "mass" in csv
                # The paper's estimators publish no uncertainty: no band, no ±.
                assert page.evaluate(BANDS, "mass") == [] and "±" not in page.inner_text("#table")

                # Replayed from the page, as fast as it goes: the same final table.
                started = time.monotonic()
                processes.stop()
                companion.run_over()
                print(f"stop: {time.monotonic() - started:.1f} s")
                page.select_option("#replay-speed", "0")
                page.click("#replay-restart")
                wait_for(lambda: display.hub.mode == "replay", 10, "the replay to start")
                started = time.monotonic()
                wait_for(lambda: display.hub.replayer.finished.is_set(), 60, "the replay")
                print(f"replay: {time.monotonic() - started:.1f} s")
                print(f"replay: {display.hub.replayer.recording.read_count} messages")
                assert display.hub.summary() == live
                page.wait_for_function(
                    "window.heft.source.mode === 'replay' && window.heft.scene.table.final",
                    timeout=20_000,
                )
                # The badge is drawn on the animation frame after the state arrives.
                page.wait_for_function(
                    "document.querySelector('#source').textContent.startsWith('REPLAY')",
                    timeout=5_000,
                )
                assert errors == []
        finally:
            if processes is not None:
                processes.stop()
            companion.close()


JUDGED = ("mass", "moment", "friction_torque", "coulomb", "contact_to_com", "relative_positions")
"""The table's error columns, after the robot, its phase and the four scalars' values."""
NOISY_INSIDE = ("mass", "moment", "contact_to_com", "relative_positions")
"""What every robot's 95 % intervals hold in the noisy scenario's run."""


def test_a_robust_runs_page_shows_how_sure_each_robot_is(tmp_path: Path) -> None:
    """The noisy scenario's robust run (in one process), recorded and replayed into the page:
    each m̂ has its 95 % band, painted by uPlot, as wide as ``±1.96 σ`` of what the robot
    published; the table gives ``±`` beside each value (the floor's friction ``τ̂_c`` and
    ``μ̂`` too) and whether the truth lies inside, as ``heft run``'s intervals say."""
    from simulator.inprocess import run_inprocess
    from simulator.results import intervals

    sync_playwright = chromium()
    scenario = load_scenario(NOISY)
    outcome = run_inprocess(scenario)
    assert outcome.converged
    path = tmp_path / "noisy.mcap"
    record_run(path, scenario, outcome, team="noisy")
    display = Display.open(None, port=0, recording=path)
    try:
        display.hub.replay(path, speed=0)
        with browser_page(sync_playwright, display.url) as (page, errors):
            page.wait_for_function(
                "window.heft.scene && window.heft.scene.table.final", timeout=20_000
            )
            page.wait_for_timeout(600)  # the charts' last redraw
            final = outcome.final.estimates
            bands = {band["name"]: band for band in page.evaluate(BANDS, "mass")}
            assert sorted(bands) == [f"m̂ robot {i}" for i in range(1, 5)]
            for i, est in final.items():
                band, half = bands[f"m̂ robot {i}"], SCALAR_95 * est.mass_std
                assert band["count"] > 20
                assert band["lower"] == pytest.approx(est.mass - half, abs=1e-8)
                assert band["upper"] == pytest.approx(est.mass + half, abs=1e-8)
            # (m̂ is published from Step 7's stage on, the last few seconds of the chart's time)
            painted = page.evaluate(BAND_PIXELS, "mass")
            assert painted["bands"] == 4 and painted["changed"] > 0.005 * painted["of"], painted
            # The table: "±" under each m̂, Ĵ, τ̂_c, μ̂, c and z; beside each error ✓ or ✗ as
            # heft run's intervals say (the truth of m, J, c and z inside each, as here).
            table = page.inner_text("#table")
            assert table.count("±") == 6 * 4 and table.count("✓") >= 4 * 4, table
            for i, est in final.items():
                cells = page.locator(f"#table tr:nth-child({i + 1}) td").all_inner_texts()
                assert cells[2].split() == [f"{est.mass:.4f}", f"±{SCALAR_95 * est.mass_std:.4f}"]
                half = SCALAR_95 * est.coulomb_std
                assert cells[5].split() == [f"{est.coulomb:.5f}", f"±{half:.5f}"]
                judged = intervals(outcome, i)
                for column, key in enumerate(JUDGED, start=6):
                    assert ("✓" if judged[key][1] else "✗") in cells[column], (key, cells)
                assert all(judged[key][1] for key in JUDGED if key in NOISY_INSIDE)
            page.screenshot(path=str(SCREENSHOT.with_name("dashboard-robust.png")))
            assert errors == []
    finally:
        display.close()
