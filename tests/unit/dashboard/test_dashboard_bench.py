"""The dashboard benchmark's arithmetic (dashboard/bench/streaming.py): latency from publication to
the first frame that shows an estimate, and memory growth once the buffers are full."""

from __future__ import annotations

import math

from dashboard.bench.streaming import BenchReport, BenchSettings, estimates, latencies, truth
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
