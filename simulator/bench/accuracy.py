"""``heft bench accuracy``: accuracy, step durations and speed of in-process runs of a scenario.

The scenario (by default the paper's, ``simulator/scenarios/paper.toml``) is run ``repeat``
times in this process. The report gives the worst final errors (over robots and runs), the
simulated time each paper step took (from the results' ``phases``), how much faster than real
time the runs went (simulated time / wall-clock time: median, min and max over the runs) and the
process's peak resident memory. It reports figures and checks no goal.
"""

from __future__ import annotations

import resource
import statistics
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from simulator.inprocess import RunOutcome, run_inprocess
from simulator.results import errors, step_times, team_phases
from simulator.scenario import Scenario

DEFAULT_REPEAT = 3
ERROR_ROWS = (
    ("mass m", "mass_rel", 100.0, "%"),
    ("moment of inertia J", "moment_rel", 100.0, "%"),
    ("contact_to_com p_C - p_Ci", "contact_to_com_m", 1000.0, "mm"),
    ("relative positions z_ij", "relative_positions_m", 1000.0, "mm"),
)
"""Label, key (:data:`~agent.platform.evaluation.ERROR_KEYS`), display scale and unit of each
error the in-process benchmarks report."""


@dataclass
class BenchReport:
    """What :func:`run_benchmark` measured."""

    scenario: Scenario
    source: str
    outcomes: list[RunOutcome]
    peak_rss_bytes: int

    @property
    def speedups(self) -> list[float]:
        """Simulated time / wall-clock time of each run."""
        return [o.sim_time_s / o.wall_s if o.wall_s > 0 else float("inf") for o in self.outcomes]


def peak_rss_bytes() -> int:
    """This process's peak resident set size (``getrusage``: KiB on Linux, bytes on macOS)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak if sys.platform == "darwin" else peak * 1024)


def run_benchmark(
    scenario: Scenario,
    repeat: int = DEFAULT_REPEAT,
    source: str = "",
    on_run: Callable[[int, RunOutcome], None] | None = None,
) -> BenchReport:
    """Run ``scenario`` ``repeat`` times in-process; ``on_run(k, outcome)`` after run ``k``."""
    if repeat < 1:
        raise ValueError(f"repeat must be at least 1, got {repeat}")
    outcomes = []
    for k in range(1, repeat + 1):
        outcome = run_inprocess(scenario)
        outcomes.append(outcome)
        if on_run is not None:
            on_run(k, outcome)
    return BenchReport(scenario, source or scenario.name, outcomes, peak_rss_bytes())


def _worst_over_runs(report: BenchReport, key: str) -> float | None:
    values = [errors(o)[key] for o in report.outcomes]
    return None if any(v is None for v in values) else max(values)  # type: ignore[type-var]


def _error_line(label: str, value: float | None, scale: float, unit: str) -> str:
    shown = "not estimated" if value is None else f"{value * scale:.4f} {unit}"
    return f"  {label:<34} {shown}"


def _accuracy_lines(report: BenchReport) -> list[str]:
    lines = ["accuracy (worst over robots and runs, at the final instant):"]
    lines += [
        _error_line(label, _worst_over_runs(report, key), s, u) for label, key, s, u in ERROR_ROWS
    ]
    return lines


def _seconds(value: float | None) -> str:
    return f"{'-':>7}" if value is None else f"{value:7.2f}"


def _step_lines(outcome: RunOutcome) -> list[str]:
    lines = [
        "paper steps (simulated seconds; end = the last robot's estimate settled):",
        f"  {'step':<32} {'start':>7} {'end':>7} {'took':>7}",
    ]
    for row in step_times(outcome):
        start, end = row["start_s"], row["end_s"]
        took = None if start is None or end is None else end - start
        label = f"{row['step']} {row['name']}"
        lines.append(f"  {label:<32} {_seconds(start)} {_seconds(end)} {_seconds(took)}")
    phases = sorted(team_phases(outcome).items(), key=lambda item: item[1])
    spans = [
        f"{name} {(phases[k + 1][1] if k + 1 < len(phases) else outcome.sim_time_s) - t:.2f} s"
        for k, (name, t) in enumerate(phases)
        if name != "done"
    ]
    lines.append(f"  team force regimes: {', '.join(spans) or '-'}")
    return lines


def _speed_lines(report: BenchReport) -> list[str]:
    speedups = report.speedups
    sim = statistics.median(o.sim_time_s for o in report.outcomes)
    wall = statistics.median(o.wall_s for o in report.outcomes)
    return [
        f"speed: {sim:.2f} s simulated in {wall:.3f} s wall (median of {len(speedups)} runs)",
        f"  {statistics.median(speedups):.1f}x faster than real time"
        f" (min {min(speedups):.1f}x, max {max(speedups):.1f}x)",
    ]


def _display_path(source: str) -> str:
    """``source`` relative to the working directory when it lies under it."""
    try:
        return str(Path(source).resolve().relative_to(Path.cwd()))
    except ValueError:
        return source


def format_report(report: BenchReport) -> str:
    """The plain-text report of ``heft bench accuracy``."""
    converged = sum(o.converged for o in report.outcomes)
    total = len(report.outcomes)
    lines = [
        f"heft bench accuracy: scenario {report.scenario.name!r}, {report.scenario.n} robots,"
        f" {total} in-process runs",
        f"scenario file: {_display_path(report.source)}",
        f"converged: {converged}/{total}",
        "",
        *_accuracy_lines(report),
        "",
        *_step_lines(report.outcomes[0]),
        "",
        *_speed_lines(report),
        f"peak RSS: {report.peak_rss_bytes / 2**20:.0f} MiB",
    ]
    return "\n".join(lines)
