"""``heft bench``: accuracy, step durations and speed of in-process runs of a scenario.

The scenario (by default the paper's, ``simulator/scenarios/paper.toml``) is run ``repeat``
times in this process. The report gives the worst final errors (over robots and runs), the
simulated time each paper step took (from the results' ``phases``), how much faster than real
time the runs went (simulated time / wall-clock time: median, min and max over the runs) and the
process's peak resident memory.
"""

from __future__ import annotations

import resource
import statistics
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import simulator
from simulator.inprocess import RunOutcome, run_inprocess
from simulator.results import errors, step_times, team_phases
from simulator.scenario import Scenario

PAPER_SCENARIO = Path(simulator.__file__).resolve().parent / "scenarios" / "paper.toml"
"""The paper's Sec. VI scenario, shipped with the simulator package."""
DEFAULT_REPEAT = 3


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
    rows = (
        ("mass m", "mass_rel", 100.0, "%"),
        ("moment of inertia J", "moment_rel", 100.0, "%"),
        ("contact_to_com p_C - p_Ci", "contact_to_com_m", 1000.0, "mm"),
        ("relative positions z_ij", "relative_positions_m", 1000.0, "mm"),
    )
    lines = ["accuracy (worst over robots and runs, at the final instant):"]
    lines += [_error_line(label, _worst_over_runs(report, key), s, u) for label, key, s, u in rows]
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
    """The plain-text report of ``heft bench``."""
    converged = sum(o.converged for o in report.outcomes)
    total = len(report.outcomes)
    lines = [
        f"heft bench: scenario {report.scenario.name!r}, {report.scenario.n} robots,"
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


def run_generated(count: int, on_run: Callable[[int, RunOutcome], None] | None = None) -> list:
    """Run the generated scenarios of seeds ``0..count-1`` once each, in this process."""
    from simulator.generate import generate_scenario

    outcomes = []
    for seed in range(count):
        outcome = run_inprocess(generate_scenario(seed), record_every=1000)
        outcomes.append(outcome)
        if on_run is not None:
            on_run(seed, outcome)
    return outcomes


def format_generated(outcomes: list[RunOutcome]) -> str:
    """The generality report: per error and per duration, the median and the worst."""
    rows = (
        ("mass m", "mass_rel", 100.0, "%"),
        ("moment of inertia J", "moment_rel", 100.0, "%"),
        ("contact_to_com p_C - p_Ci", "contact_to_com_m", 1000.0, "mm"),
        ("relative positions z_ij", "relative_positions_m", 1000.0, "mm"),
    )
    found = [errors(o) for o in outcomes]
    converged = sum(o.converged for o in outcomes)
    lines = [
        f"heft bench --generated: seeds 0..{len(outcomes) - 1}, converged {converged}/"
        f"{len(outcomes)}",
        f"  {'':<34} {'median':>10} {'worst':>10}",
    ]
    for label, key, scale, unit in rows:
        values = [e[key] for e in found]
        if any(v is None for v in values):
            lines.append(f"  {label:<34} {'not estimated by every run':>21}")
            continue
        med, worst = statistics.median(values) * scale, max(values) * scale
        lines.append(f"  {label:<34} {med:8.4f} {unit:<2}{worst:8.4f} {unit}")
    sims = [o.sim_time_s for o in outcomes]
    speed = [o.sim_time_s / o.wall_s for o in outcomes if o.wall_s > 0]
    lines.append(
        f"  {'simulated time to finish':<34} {statistics.median(sims):8.2f} s {max(sims):8.2f} s"
    )
    if speed:
        lines.append(
            f"  {'faster than real time':<34} {statistics.median(speed):8.1f} x "
            f"{min(speed):8.1f} x (slowest)"
        )
    return "\n".join(lines)


DEFAULT_SIZES = (4, 8, 16)


@dataclass
class ZenohReport:
    """What :func:`run_zenoh_benchmark` measured."""

    lockstep: list[RunOutcome]
    realtime: RunOutcome


def run_zenoh_benchmark(
    sizes: Sequence[int] = DEFAULT_SIZES,
    on_run: Callable[[str, RunOutcome], None] | None = None,
) -> ZenohReport:
    """Lockstep runs of ring teams of each size, then the paper's scenario in real time, each
    with one process per robot over Zenoh on 127.0.0.1."""
    import io

    from simulator.generate import ring_scenario
    from simulator.launcher import run_zenoh
    from simulator.scenario import load_scenario

    lockstep = []
    for n in sizes:
        outcome = run_zenoh(ring_scenario(n), log_stream=io.StringIO())
        lockstep.append(outcome)
        if on_run is not None:
            on_run(f"lockstep, ring of {n}", outcome)
    realtime = run_zenoh(load_scenario(PAPER_SCENARIO), clock="realtime", log_stream=io.StringIO())
    if on_run is not None:
        on_run("real time, paper", realtime)
    return ZenohReport(lockstep, realtime)


def _agent_cpu(outcome: RunOutcome) -> tuple[float, float] | None:
    """Median CPU seconds of one agent process over the run, and per simulated second."""
    cpu = [v for k, v in outcome.transport.get("cpu_s", {}).items() if k.startswith("robot")]
    cpu = [v for v in cpu if v is not None]
    if not cpu:
        return None
    med = statistics.median(cpu)
    return med, med / outcome.sim_time_s


def format_zenoh_report(report: ZenohReport) -> str:
    """The plain-text report of ``heft bench --transport zenoh``."""
    lines = [
        "heft bench --transport zenoh: one process per robot, a router and the plant on",
        "127.0.0.1 (multicast scouting off)",
        "",
        "lockstep (ring teams): simulated time / wall-clock time while stepping",
        f"  {'robots':>6} {'converged':>9} {'simulated':>10} {'stepping':>9} {'ratio':>8}"
        f" {'CPU/agent':>10} {'CPU/agent/sim s':>16}",
    ]
    for o in report.lockstep:
        stepping = o.transport.get("stepping_wall_s")
        ratio = f"{o.sim_time_s / stepping:7.2f}x" if stepping else "      -"
        cpu = _agent_cpu(o)
        cpu_text = f"{cpu[0]:9.2f}s {cpu[1] * 100:14.1f} %" if cpu else f"{'-':>10} {'-':>16}"
        lines.append(
            f"  {o.scenario.n:>6} {'yes' if o.converged else 'NO':>9} {o.sim_time_s:9.2f}s"
            f" {stepping or 0:8.2f}s {ratio} {cpu_text}"
        )
    rt = report.realtime
    plant = rt.transport.get("plant") or {}
    cpu = _agent_cpu(rt)
    lines += [
        "",
        f"real time (paper, {rt.scenario.n} robots, {1 / rt.scenario.period_s:g} Hz):"
        f" {'converged' if rt.converged else 'NOT converged'} after {rt.sim_time_s:.2f} s",
        "  per-tick command latency (plant publishes a tick -> that tick's command arrives),"
        f" {plant.get('latency_samples', 0)} samples:",
        f"    p50 {_ms(plant.get('latency_ms_p50'))}   p99 {_ms(plant.get('latency_ms_p99'))}"
        f"   mean {_ms(plant.get('latency_ms_mean'))}",
        f"  late commands {plant.get('late_commands')}, missing {plant.get('missing_commands')},"
        f" plant overruns {plant.get('overruns')}",
    ]
    if cpu:
        lines.append(
            f"  CPU per agent process: {cpu[0]:.2f} s over the run,"
            f" {cpu[1] * 100:.1f} % of one core"
        )
    return "\n".join(lines)


def _ms(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f} ms"
