"""A benchmark's goals as data, its verdict on each, and the exit status they give.

A benchmark that checks anything declares what as a module-level tuple of :class:`Goal` (e.g.
the CAN bridge's round trip p99 below 5 ms) and a function giving, from what it measured, the
figure each goal names by its :attr:`Goal.key`. :func:`judge` pairs each goal with its figure
in a :class:`Verdict`; its ``heft bench`` command prints them (:func:`format_verdicts`) after
its report and exits with :func:`exit_status`: 0 when every goal is met, 1 when any is not
(:func:`conclude` does the three). A figure that could not be measured (``None``, or NaN)
meets no goal.
"""

from __future__ import annotations

import enum
import math
import sys
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TextIO


class Sense(enum.StrEnum):
    """How a figure ``x`` must stand to its goal's bound ``b``."""

    AT_MOST = "at most"
    """``x ≤ b``."""
    AT_LEAST = "at least"
    """``x ≥ b``."""
    BELOW = "below"
    """``x < b``."""


@dataclass(frozen=True)
class Goal:
    """What is measured, the bound it must keep, in which sense, and the unit of both."""

    key: str
    """The name of the figure in the benchmark's figures (several goals may bound one)."""
    measured: str
    """What is measured, in words (the report's label)."""
    bound: float
    sense: Sense
    unit: str = ""

    def met_by(self, value: float | None) -> bool:
        """Whether ``value`` keeps the bound; never when it is None or NaN."""
        if value is None or math.isnan(value):
            return False
        if self.sense is Sense.AT_MOST:
            return value <= self.bound
        if self.sense is Sense.AT_LEAST:
            return value >= self.bound
        return value < self.bound

    def text(self) -> str:
        """The goal in words: ``below 5 ms``."""
        bound = f"{self.bound:g}"
        return f"{self.sense} {bound} {self.unit}" if self.unit else f"{self.sense} {bound}"


@dataclass(frozen=True)
class Verdict:
    """A goal and the figure measured for it."""

    goal: Goal
    value: float | None

    @property
    def met(self) -> bool:
        return self.goal.met_by(self.value)


def judge(goals: Iterable[Goal], figures: Mapping[str, float | None]) -> tuple[Verdict, ...]:
    """Each goal with its figure, ``figures[goal.key]`` (a goal the figures do not name is a
    ``KeyError``: a benchmark measures every goal it declares)."""
    return tuple(Verdict(goal, figures[goal.key]) for goal in goals)


def exit_status(verdicts: Iterable[Verdict]) -> int:
    """0 when every goal is met, 1 when any is not."""
    return 0 if all(verdict.met for verdict in verdicts) else 1


def format_verdicts(verdicts: Sequence[Verdict]) -> str:
    """One line per goal (what is measured, the figure, the goal, met or NOT met), then
    ``goals: met`` or ``goals: NOT met``."""
    width = max((len(v.goal.measured) for v in verdicts), default=0)
    figures = [_number(v.value, v.goal.unit) for v in verdicts]
    value_width = max((len(figure) for figure in figures), default=0)
    lines = ["goals:"]
    for verdict, figure in zip(verdicts, figures):
        lines.append(
            f"  {verdict.goal.measured:<{width}}  {figure:>{value_width}}"
            f"  ({verdict.goal.text()}): {_met(verdict.met)}"
        )
    lines.append(f"goals: {_met(exit_status(verdicts) == 0)}")
    return "\n".join(lines)


def conclude(
    goals: Iterable[Goal], figures: Mapping[str, float | None], stream: TextIO | None = None
) -> int:
    """The end of a benchmark's command: judge ``goals`` on ``figures``, print the verdicts
    (to ``stream``, standard output by default) and return the exit status."""
    verdicts = judge(goals, figures)
    print(format_verdicts(verdicts), file=stream or sys.stdout)
    return exit_status(verdicts)


def _met(met: bool) -> str:
    return "met" if met else "NOT met"


def _number(value: float | None, unit: str) -> str:
    """``value`` and its unit as the reports write figures: a whole number as one, else two
    decimals below 10, one below 100, none above; ``-`` for none."""
    if value is None or math.isnan(value):
        return "-"
    if math.isinf(value) or value == round(value):
        text = f"{value:.0f}"
    else:
        text = f"{value:.{2 if abs(value) < 10 else 1 if abs(value) < 100 else 0}f}"
    return f"{text} {unit}" if unit else text
