"""The dashboard benchmark's arithmetic (dashboard/bench/streaming.py): latency from publication to
the first frame that shows an estimate, memory growth once the buffers are full, and the goals
``heft bench dashboard`` exits on."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from agent.platform.goals import judge
from agent.platform.heft import main
from dashboard.bench import cli as bench_cli
from dashboard.bench import streaming
from dashboard.bench.streaming import (
    GOALS,
    BenchReport,
    BenchSettings,
    estimates,
    latencies,
    truth,
)
from dashboard.state import TeamState


def test_latency_counts_each_tick_once_at_the_first_frame_that_shows_it() -> None:
    published = {10: 1000.0, 11: 1010.0, 12: 1020.0}
    receipts = [
        [1050.0, 1040.0, {"1": 10, "2": 10}],
        [1100.0, 1090.0, {"1": 10, "2": 12}],  # robot 1 unchanged: not counted again
        [1150.0, 1140.0, {"1": 12, "2": 12}],
    ]
    total, server = latencies(receipts, published)
    assert total == [50.0, 50.0, 80.0, 130.0]
    assert server == [40.0, 40.0, 70.0, 120.0]


def test_memory_growth_is_measured_after_the_first_quarter() -> None:
    report = BenchReport(BenchSettings())
    report.rss_mb = [50.0, 80.0, 100.0, 100.0, 101.0, 100.0, 104.0, 102.0]
    assert math.isclose(report.memory_growth_pct, 4.0)
    assert any("growth after the first quarter 4.0 %" in line for line in report.lines())


def test_the_synthetic_team_is_valid_for_the_dashboard() -> None:
    state = TeamState("bench")
    for tick in range(0, 50, 5):
        state.ingest(truth(16, tick), tick * 0.01)
        for i in range(1, 17):
            assert state.ingest(estimates(i, 16, tick), tick * 0.01)
    assert state.n == 16 and not state.rejected
    assert len(state.edges()) == 16  # a ring


def measured(cpu_pct: float = 12.0, latency_ms: float = 40.0, rss_mb: float = 100.0):
    """A report as a run would fill it: ``latency_ms`` the slowest of 100 samples, the memory
    growing to ``rss_mb`` from 100 MB."""
    report = BenchReport(BenchSettings())
    report.cpu_pct, report.received_hz = cpu_pct, 1600.0
    report.latency_ms = [20.0] * 98 + [latency_ms] * 2
    report.server_ms = report.chart_ms = report.scene_ms = [1.0, 2.0]
    report.rss_mb = [50.0, 100.0, 100.0, 100.0, rss_mb]
    return report


def test_each_goal_is_judged_on_its_figure() -> None:
    def unmet(report: BenchReport) -> list[str]:
        return [v.goal.key for v in judge(GOALS, report.figures()) if not v.met]

    assert unmet(measured()) == []
    assert unmet(measured(cpu_pct=25.0)) == ["cpu_pct"]
    assert unmet(measured(latency_ms=250.0)) == ["latency_p99_ms"]
    assert unmet(measured(rss_mb=111.0)) == ["memory_growth_pct"]
    assert unmet(BenchReport(BenchSettings())) == [goal.key for goal in GOALS]  # not measured


@pytest.mark.parametrize("cpu_pct, status", [(12.0, 0), (31.0, 1)])
def test_bench_dashboard_exits_with_its_goals_verdict(monkeypatch, capsys, cpu_pct, status) -> None:
    def run(settings: BenchSettings, folder: Path) -> BenchReport:
        assert settings == BenchSettings() and folder.is_dir()
        return measured(cpu_pct=cpu_pct)

    monkeypatch.setattr(streaming, "run", run)
    monkeypatch.setattr(bench_cli, "missing_browser", lambda: None)
    assert main(["bench", "dashboard"]) == status
    out = capsys.readouterr().out
    assert out.startswith("dashboard benchmark: 16 robots' estimates at 100 Hz")
    assert f"dashboard CPU: {cpu_pct:.1f} % of one core for 1600 messages/s" in out
    verdict = "met" if status == 0 else "NOT met"
    assert f"(below 25 %): {verdict}" in out and out.endswith(f"goals: {verdict}\n")


def test_bench_dashboard_without_a_browser_says_what_is_missing(monkeypatch, capsys) -> None:
    def run(settings: BenchSettings, folder: Path) -> BenchReport:
        raise AssertionError("no benchmark without its browser")

    monkeypatch.setattr(streaming, "run", run)
    monkeypatch.setattr(streaming, "CHROMIUM", "/nonexistent/chromium")
    assert main(["bench", "dashboard"]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err == (
        "heft: error: bench dashboard needs Chromium at /nonexistent/chromium:"
        " apt-get install chromium\n"
    )
