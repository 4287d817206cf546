"""Benchmarks' goals as data (agent/platform/goals.py): each goal's verdict on a figure, the
verdicts printed, and the exit status computed from them."""

from __future__ import annotations

import io
import math

import pytest

from agent.platform.goals import (
    Goal,
    Sense,
    conclude,
    exit_status,
    format_verdicts,
    judge,
)

P99 = Goal("p99", "round trip p99", 5.0, Sense.BELOW, "ms")
RATIO = Goal("ratio", "robust / baseline", 1.5, Sense.AT_MOST)
DONE = Goal("done", "runs done", 100.0, Sense.AT_LEAST, "%")


@pytest.mark.parametrize(
    "goal, value, met",
    [
        (P99, 4.99, True),
        (P99, 5.0, False),  # below: strictly
        (RATIO, 1.5, True),  # at most: the bound itself
        (RATIO, 1.51, False),
        (DONE, 100.0, True),
        (DONE, 95.0, False),
        (DONE, None, False),  # not measured: no goal met
        (P99, math.nan, False),
        (RATIO, math.inf, False),
    ],
)
def test_a_goal_is_met_in_its_sense(goal: Goal, value: float | None, met: bool) -> None:
    assert goal.met_by(value) is met


def test_the_exit_status_is_computed_from_the_verdicts() -> None:
    assert exit_status(judge((P99, RATIO), {"p99": 1.0, "ratio": 1.2})) == 0
    assert exit_status(judge((P99, RATIO), {"p99": 1.0, "ratio": 1.7})) == 1
    assert exit_status(judge((P99,), {"p99": None})) == 1
    assert exit_status(()) == 0  # a benchmark without goals
    with pytest.raises(KeyError):  # every goal declared is measured
        judge((P99, RATIO), {"p99": 1.0})


def test_two_goals_may_bound_one_figure() -> None:
    low = Goal("inside", "truth inside", 90.0, Sense.AT_LEAST, "%")
    high = Goal("inside", "truth inside", 99.0, Sense.AT_MOST, "%")
    assert [v.met for v in judge((low, high), {"inside": 95.0})] == [True, True]
    assert [v.met for v in judge((low, high), {"inside": 100.0})] == [True, False]


def test_each_goal_is_printed_with_its_figure_and_verdict() -> None:
    verdicts = judge((P99, RATIO, DONE), {"p99": 0.8123, "ratio": 2.0, "done": None})
    assert format_verdicts(verdicts).splitlines() == [
        "goals:",
        "  round trip p99     0.81 ms  (below 5 ms): met",
        "  robust / baseline        2  (at most 1.5): NOT met",
        "  runs done                -  (at least 100 %): NOT met",
        "goals: NOT met",
    ]
    text = format_verdicts(judge((P99, RATIO, DONE), {"p99": 12.3, "ratio": 1.234, "done": 94.74}))
    assert " 12.3 ms  (below 5 ms): NOT met" in text and " 1.23  (at most 1.5)" in text
    assert " 94.7 %  (at least 100 %)" in text


def test_conclude_prints_the_verdicts_and_returns_the_status() -> None:
    stream = io.StringIO()
    assert conclude((P99,), {"p99": 1.0}, stream) == 0
    assert stream.getvalue().endswith("(below 5 ms): met\ngoals: met\n")
    stream = io.StringIO()
    assert conclude((P99,), {"p99": 7.0}, stream) == 1
    assert stream.getvalue().endswith("(below 5 ms): NOT met\ngoals: NOT met\n")
