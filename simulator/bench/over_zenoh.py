"""``heft bench zenoh``: the team as processes over Zenoh, one per robot plus a router and the
plant, all on 127.0.0.1.

First ring teams of each size (:func:`simulator.generate.ring_scenario`) in lockstep: how much
faster than real time they step, and each agent process's CPU; then the paper's scenario on
the wall clock: the latency from the plant publishing a tick to that tick's command arriving
(p50, p99, mean), late and missing commands, the plant's overruns, and each agent's CPU. It
reports figures and checks no goal.
"""

from __future__ import annotations

import io
import statistics
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from simulator.generate import ring_scenario
from simulator.inprocess import RunOutcome
from simulator.launcher import run_zenoh
from simulator.scenario import PAPER_SCENARIO, load_scenario

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
    """The plain-text report of ``heft bench zenoh``."""
    lines = [
        "heft bench zenoh: one process per robot, a router and the plant on",
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
