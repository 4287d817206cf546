"""``heft bench generated``: generality, the generated scenarios of seeds ``0..N-1``
(:func:`simulator.generate.generate_scenario`: 3-8 robots, every graph and load shape) run once
each in this process.

The report gives, per error (the worst over robots at the final instant) and per duration, the
median and the worst over the scenarios. Its goal (:data:`GOALS`): every run converged.
"""

from __future__ import annotations

import statistics
from collections.abc import Callable, Sequence

from agent.platform.goals import Goal, Sense
from simulator.bench.accuracy import ERROR_ROWS
from simulator.generate import generate_scenario
from simulator.inprocess import RunOutcome, run_inprocess
from simulator.results import errors

DEFAULT_COUNT = 20
"""Scenarios run when ``heft bench generated`` is not told how many."""
GOALS = (Goal("converged_pct", "runs converged", 100.0, Sense.AT_LEAST, "%"),)


def figures(outcomes: Sequence[RunOutcome]) -> dict[str, float | None]:
    """The figures :data:`GOALS` bound: the share of runs that converged (%)."""
    converged = sum(o.converged for o in outcomes)
    return {"converged_pct": 100.0 * converged / len(outcomes) if outcomes else None}


def run_generated(
    count: int, on_run: Callable[[int, RunOutcome], None] | None = None
) -> list[RunOutcome]:
    """Run the generated scenarios of seeds ``0..count-1`` once each, in this process."""
    outcomes = []
    for seed in range(count):
        outcome = run_inprocess(generate_scenario(seed), record_every=1000)
        outcomes.append(outcome)
        if on_run is not None:
            on_run(seed, outcome)
    return outcomes


def format_generated(outcomes: Sequence[RunOutcome]) -> str:
    """The generality report: per error and per duration, the median and the worst."""
    found = [errors(o) for o in outcomes]
    converged = sum(o.converged for o in outcomes)
    lines = [
        f"heft bench generated: seeds 0..{len(outcomes) - 1}, converged {converged}/"
        f"{len(outcomes)}",
        f"  {'':<34} {'median':>10} {'worst':>10}",
    ]
    for label, key, scale, unit in ERROR_ROWS:
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
