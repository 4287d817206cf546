"""The one percentile (agent/platform/statistics.py), as the plant's command latencies and the
benchmarks' figures use it."""

from __future__ import annotations

import random
import statistics

import pytest

from agent.platform.statistics import percentile


def test_percentile_interpolates_between_the_closest_ranks() -> None:
    assert percentile([4.0, 1.0, 3.0, 2.0], 50) == 2.5
    assert percentile([4.0, 1.0, 3.0, 2.0], 0) == 1.0
    assert percentile([4.0, 1.0, 3.0, 2.0], 100) == 4.0
    assert percentile([7.0], 99) == 7.0
    assert percentile(range(1, 101), 99) == pytest.approx(99.01)
    values = [random.Random(3).expovariate(1.0) for _ in range(1000)]
    expected = statistics.quantiles(values, n=100, method="inclusive")
    assert percentile(values, 50) == pytest.approx(expected[49])
    assert percentile(values, 99) == pytest.approx(expected[98])


def test_percentile_refuses_no_values_and_a_bad_q() -> None:
    with pytest.raises(ValueError, match="no values"):
        percentile([], 50)
    with pytest.raises(ValueError, match="q must be"):
        percentile([1.0], 101)
    with pytest.raises(ValueError, match="q must be"):
        percentile([1.0], -1)
