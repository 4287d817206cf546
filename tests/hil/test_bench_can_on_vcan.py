"""``heft bench can`` for real: one short benchmark of a bridge on vcan (``make hil``, or
``heft vcan -- pytest tests/hil/test_bench_can_on_vcan.py``)."""

from __future__ import annotations

import math
import os

import pytest

from bridge.bench import can as benchmark
from bridge.bench.can import CanBenchSettings, format_can_report, run_can_benchmark


# ------------------------------------------------------------------------------ on vcan
@pytest.mark.hil
@pytest.mark.usefixtures("vcan")
def test_a_short_benchmark_of_a_bridge_on_vcan() -> None:
    """A few seconds at a slow period: every round trip measured, none lost, by kernel
    timestamps; the CPU shares real percentages; a clean forwarding rate.

    User-Mode Linux counts CPU time in whole 10 ms ticks, sampled at its timer, and a process
    woken by a 50 ms period works between two samples: a share over 3 s can read 0 there (seen
    in CI: the bridge, the router, the echo agent and the driver all at 0.0 % in the round-trip
    window, the bridge at 5.0 % in the 40 ticks/s step). So each share is a percentage, and
    the accounting is judged over every window of the run together."""
    settings = CanBenchSettings(
        seconds=3.0,
        period_s=0.05,
        step_seconds=1.0,
        min_step_ticks=20,
        start_rate=20.0,
        max_rate=40.0,
        refine=0,
    )
    report = run_can_benchmark(settings, say=print)
    print(format_can_report(report))
    trips = report.round_trips
    assert trips.sent == 60
    assert trips.count == trips.sent and trips.lost == 0 and trips.unmatched == 0
    p50, p99 = trips.p(50), trips.p(99)
    assert p50 is not None and p99 is not None
    assert 0 < p50 <= p99 <= trips.p(100) < math.inf  # figures, not goals: see heft bench
    shares = [*trips.cpu_percent.values(), *(step.bridge_cpu_percent for step in report.steps)]
    assert trips.bridge_cpu_percent is not None and len(trips.cpu_percent) == 4
    assert all(share is not None and 0 <= share < 100 for share in shares), shares
    assert sum(shares) > 0, shares
    assert [s.asked for s in report.steps] == [20.0, 40.0]
    fastest = report.fastest_clean
    assert fastest is not None and fastest.answered == fastest.ticks >= 20
    assert fastest.frames_read == fastest.frames_sent >= 3 * fastest.ticks
    if os.environ.get("HEFT_VCAN") == "1":  # inside heft vcan's guest
        assert report.where == benchmark.where_measured() == "in User-Mode Linux"
