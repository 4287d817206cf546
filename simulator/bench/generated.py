"""``heft bench generated``: generality of the default estimators without noise: the paper's
load (``simulator/scenarios/paper.toml``) and the loads of the generated scenarios of seeds
``0..N-1`` (:func:`simulator.generate.generate_scenario`: 3-8 robots, every graph and load
shape), each run once in this process with the default ``[agent]`` gains (:func:`by_default`;
the scenarios themselves run the paper's estimators, the reference).

The report gives the paper's load's errors (the worst over robots at the final instant), then,
per error and per duration over the generated loads, the median and the worst. Its goals
(:data:`GOALS`, measured by :func:`figures`): every run converged and kept its load on its floor;
on the paper's load m within 0.01 %, J within 0.05 %, ``contact_to_com`` within 1 mm; on the
generated loads the medians of m and J within 0.1 % and of ``contact_to_com`` within 2 mm.
"""

from __future__ import annotations

import dataclasses
import statistics
from collections.abc import Callable, Sequence

from agent.algorithm.tuning import AgentTuning
from agent.platform.goals import Goal, Sense
from simulator.bench.accuracy import ERROR_ROWS
from simulator.generate import generate_scenario
from simulator.inprocess import RunOutcome, run_inprocess
from simulator.results import errors, floor_check
from simulator.scenario import PAPER_SCENARIO, Scenario, load_scenario

DEFAULT_COUNT = 20
"""Scenarios run when ``heft bench generated`` is not told how many."""
ACCURACY = (
    ("mass_rel", "m", 100.0, "%", 0.01, 0.1),
    ("moment_rel", "J", 100.0, "%", 0.05, 0.1),
    ("contact_to_com_m", "contact_to_com", 1000.0, "mm", 1.0, 2.0),
)
"""Per error (:data:`~agent.platform.evaluation.ERROR_KEYS`): its name, display scale and unit,
and its goals, on the paper's load and for the generated loads' median."""
GOALS = (
    Goal("converged_pct", "runs converged", 100.0, Sense.AT_LEAST, "%"),
    Goal("on_floor_pct", "runs that kept the load on its floor", 100.0, Sense.AT_LEAST, "%"),
    *(
        Goal(f"paper {key}", f"the paper's load: {name} error", paper, Sense.AT_MOST, unit)
        for key, name, _, unit, paper, _ in ACCURACY
    ),
    *(
        Goal(f"median {key}", f"generated loads: median {name} error", median, Sense.AT_MOST, unit)
        for key, name, _, unit, _, median in ACCURACY
    ),
)
"""What the benchmark checks, on the figures of :func:`figures` (in the goals' units)."""


def by_default(scenario: Scenario) -> Scenario:
    """``scenario`` run with the default ``[agent]`` gains: the robust estimators."""
    return dataclasses.replace(scenario, agent=AgentTuning())


def figures(paper: RunOutcome, outcomes: Sequence[RunOutcome]) -> dict[str, float | None]:
    """The figures :data:`GOALS` bound: the shares of runs (the paper's load's among them)
    that converged and kept to their floor (%), the paper's load's errors and the generated
    loads' median errors (``None``: some run did not estimate it)."""
    runs = [paper, *outcomes]
    found: dict[str, float | None] = {
        "converged_pct": 100.0 * sum(o.converged for o in runs) / len(runs),
        "on_floor_pct": 100.0 * sum(floor_check(o)["within"] for o in runs) / len(runs),
    }
    mine = errors(paper)
    theirs = [errors(o) for o in outcomes]
    for key, _, scale, _, _, _ in ACCURACY:
        found[f"paper {key}"] = None if mine[key] is None else mine[key] * scale
        values = [e[key] for e in theirs]
        found[f"median {key}"] = (
            None if not values or None in values else statistics.median(values) * scale
        )
    return found


def run_paper() -> RunOutcome:
    """The paper's load, run once with the default gains, in this process."""
    return run_inprocess(by_default(load_scenario(PAPER_SCENARIO)), record_every=1000)


def run_generated(
    count: int, on_run: Callable[[int, RunOutcome], None] | None = None
) -> list[RunOutcome]:
    """The loads of the generated scenarios of seeds ``0..count-1``, run once each with the
    default gains, in this process."""
    outcomes = []
    for seed in range(count):
        outcome = run_inprocess(by_default(generate_scenario(seed)), record_every=1000)
        outcomes.append(outcome)
        if on_run is not None:
            on_run(seed, outcome)
    return outcomes


def format_generated(paper: RunOutcome, outcomes: Sequence[RunOutcome]) -> str:
    """The generality report: the paper's load's errors, then per error and per duration of
    the generated loads, the median and the worst."""
    found = [errors(o) for o in outcomes]
    converged = sum(o.converged for o in outcomes)
    floors = sum(floor_check(o)["within"] for o in outcomes)
    mine = errors(paper)
    state = "converged" if paper.converged else "NOT converged"
    lines = [
        "heft bench generated: the default estimators without noise",
        f"the paper's load: {state} at {paper.sim_time_s:.2f} s simulated",
    ]
    for label, key, scale, unit in ERROR_ROWS:
        shown = "not estimated" if mine[key] is None else f"{mine[key] * scale:.4f} {unit}"
        lines.append(f"  {label:<34} {shown}")
    lines += [
        f"generated loads: seeds 0..{len(outcomes) - 1}, converged {converged}/{len(outcomes)},"
        f" on their floor {floors}/{len(outcomes)}",
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
