"""The load-change benchmark (``heft bench changes``): does the team notice a changed
load, and estimate it again?

For each seed, the noise benchmark's noisy paper scenario (:func:`simulator.bench.noise.noisy`,
robust estimators) runs three times in this process:

- ``mass``: at :data:`CHANGE_AT_S` the load's mass grows by 20 %;
- ``com``: at :data:`CHANGE_AT_S` its COM moves by 10 cm along the load's x axis;
- ``none``: no change, and the run goes on to :data:`QUIET_UNTIL_S` (the team done long before:
  every probe then is a chance of a false alarm).

A change is *noticed* when the team restarts (:mod:`agent.algorithm.coordination`) after it; the
report gives how many were, within :data:`NOTICE_WITHIN_S` of the change, the delays, the errors
after the re-estimation against the changed load's truth, the false alarms, and the runs that kept
the floor. Beside the re-estimated load, the centralized reference (``heft baseline``'s batch
fit, :func:`simulator.bench.noise.baseline_fit`) on the same run's measurements from the
change to its end, which are all the changed load's, and the ratio of the two (reported, not
a goal). Its goals (:data:`GOALS`, measured by :func:`figures`): every change noticed within
:data:`NOTICE_WITHIN_S`, no false alarm, every run done and on its floor.
"""

from __future__ import annotations

import dataclasses
import statistics
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from agent.algorithm.tuning import Estimators
from agent.platform.goals import Goal, Sense
from agent.platform.protocol import Measurement
from simulator.bench.noise import NoiseSettings, baseline_errors, baseline_fit, noisy
from simulator.inprocess import run_inprocess
from simulator.results import errors, floor_check, load_changes
from simulator.scenario import LoadChange, Scenario

CHANGE_AT_S = 25.0
"""s: when the load changes (the paper's noisy scenario is done within 20 s)."""
HOLD_S = 12.0
"""s: how long a changed run goes on at least after the change."""
QUIET_UNTIL_S = 45.0
"""s: how long an unchanged run goes on."""
NOTICE_WITHIN_S = 5.0
"""s: the goal for noticing a change."""
CASES = ("mass", "com", "none")
GOALS = (
    Goal(
        "noticed",
        f"changes noticed within {NOTICE_WITHIN_S:g} s",
        100.0,
        Sense.AT_LEAST,
        "%",
    ),
    Goal("false alarms", "false alarms", 0.0, Sense.AT_MOST),
    Goal("done", "runs done", 100.0, Sense.AT_LEAST, "%"),
    Goal("on floor", "runs that kept the load on its floor", 100.0, Sense.AT_LEAST, "%"),
)
"""What the load-change benchmark checks, on the figures of :func:`figures`."""


@dataclass
class ChangeResult:
    """One run: the case, the restart delay (``None``: not noticed), false alarms, errors."""

    seed: int
    case: str
    latency_s: float | None
    false_alarms: int
    errors: dict[str, float | None]
    converged: bool
    on_floor: bool
    baseline: dict[str, float | None] = dataclasses.field(default_factory=dict)
    """The batch fit of the changed load (from the change on; empty for ``none``)."""


def changed(scenario: Scenario, case: str) -> Scenario:
    """``scenario`` with ``case``'s change (and hold)."""
    body = scenario.body
    if case == "none":
        return dataclasses.replace(
            scenario, run=dataclasses.replace(scenario.run, hold_s=QUIET_UNTIL_S)
        )
    if case == "mass":
        event = LoadChange(at_s=CHANGE_AT_S, mass=1.2 * body.mass)
    else:
        event = LoadChange(at_s=CHANGE_AT_S, com=(body.com[0] + 0.1, body.com[1]))
    return dataclasses.replace(
        scenario, events=(event,), run=dataclasses.replace(scenario.run, hold_s=HOLD_S)
    )


def run_case(scenario: Scenario, settings: NoiseSettings, seed: int, case: str) -> ChangeResult:
    """Seed ``seed`` of ``scenario`` (noisy, robust) with ``case``'s change."""
    base = noisy(scenario, settings, seed, Estimators.ROBUST)
    run = dataclasses.replace(base.run, max_time_s=max(base.run.max_time_s, 90.0))
    measured: list[list[Measurement]] = []
    outcome = run_inprocess(
        changed(dataclasses.replace(base, run=run), case),
        record_every=10,
        on_measure=measured.append,
    )
    found = load_changes(outcome)
    reference = {}
    if case != "none":
        since = round(CHANGE_AT_S / outcome.scenario.period_s)
        found = baseline_fit(outcome, measured, settings, since_tick=since)
        reference = baseline_errors(outcome, found)
    latency = found["changes"][0]["latency_s"] if found["changes"] else None
    return ChangeResult(
        seed=seed,
        case=case,
        latency_s=latency,
        false_alarms=found["false_alarms"],
        errors=errors(outcome),
        converged=outcome.converged,
        on_floor=floor_check(outcome)["within"],
        baseline=reference,
    )


def run_change_bench(
    scenario: Scenario,
    settings: NoiseSettings,
    on_result: Callable[[ChangeResult], None] | None = None,
) -> list[ChangeResult]:
    """Every case on the settings' seeds (:attr:`~simulator.bench.noise.NoiseSettings.
    first_seed` on)."""
    results = []
    for seed in range(settings.first_seed, settings.first_seed + settings.seeds):
        for case in CASES:
            result = run_case(scenario, settings, seed, case)
            results.append(result)
            if on_result is not None:
                on_result(result)
    return results


def _median(values: Sequence[float | None]) -> float | None:
    known = [v for v in values if v is not None]
    return statistics.median(known) if len(known) == len(values) and known else None


def _percent(count: int, total: int) -> float | None:
    """``count`` as a percentage of ``total``; None of none."""
    return 100 * count / total if total else None


def figures(results: Sequence[ChangeResult]) -> dict[str, float | None]:
    """The figures :data:`GOALS` bound: the share of the changes noticed within
    :data:`NOTICE_WITHIN_S` (%), the false alarms over every run, and the shares of runs done
    and on their floor (%)."""
    changes = [r for r in results if r.case != "none"]
    noticed = sum(r.latency_s is not None and r.latency_s <= NOTICE_WITHIN_S for r in changes)
    return {
        "noticed": _percent(noticed, len(changes)),
        "false alarms": sum(r.false_alarms for r in results),
        "done": _percent(sum(r.converged for r in results), len(results)),
        "on floor": _percent(sum(r.on_floor for r in results), len(results)),
    }


def format_change_report(results: Sequence[ChangeResult]) -> str:
    """The report: per case, noticed (within the goal), delays, errors, false alarms, floor
    (the goals' verdicts follow it: :data:`GOALS`)."""
    lines = [
        f"{'case':<6} {'runs':>4} {'noticed':>8} {'<=5 s':>6} {'delay med/max':>14}"
        f" {'m':>7} {'J':>7} {'ctc':>8} {'false':>6} {'floor':>6}",
    ]
    for case in CASES:
        rows = [r for r in results if r.case == case]
        if not rows:
            continue
        delays = [r.latency_s for r in rows if r.latency_s is not None]
        within = sum(d <= NOTICE_WITHIN_S for d in delays)
        delay = f"{statistics.median(delays):.2f}/{max(delays):.2f} s" if delays else "-"
        m = _median([r.errors.get("mass_rel") for r in rows])
        j = _median([r.errors.get("moment_rel") for r in rows])
        ctc = _median([r.errors.get("contact_to_com_m") for r in rows])
        noticed = f"{len(delays)}/{len(rows)}" if case != "none" else "-"
        alarms, floors = sum(r.false_alarms for r in rows), sum(r.on_floor for r in rows)
        lines.append(
            f"{case:<6} {len(rows):>4} {noticed:>8} {within if case != 'none' else '-':>6}"
            f" {delay:>14} {_pct(m):>7} {_pct(j):>7} {_mm(ctc):>8}"
            f" {alarms:>6} {floors:>3}/{len(rows)}"
        )
    lines.append("")
    lines.append(
        f"{'changed load':<13} {'m':>7} {'J':>7} {'ctc':>8}"
        f"   {'fit m':>7} {'fit J':>7} {'fit ctc':>8}   ratios m / J / ctc"
    )
    for case in CASES[:2]:
        rows = [r for r in results if r.case == case]
        if not rows:
            continue
        keys = ("mass_rel", "moment_rel", "contact_to_com_m")
        ours = [_median([r.errors.get(key) for r in rows]) for key in keys]
        fits = [_median([r.baseline.get(key) for r in rows]) for key in keys]
        ratios = " / ".join(
            "-" if a is None or not b else f"{a / b:.2f}" for a, b in zip(ours, fits)
        )
        lines.append(
            f"{case:<13} {_pct(ours[0]):>7} {_pct(ours[1]):>7} {_mm(ours[2]):>8}"
            f"   {_pct(fits[0]):>7} {_pct(fits[1]):>7} {_mm(fits[2]):>8}   {ratios}"
        )
    lines.append(
        "(median errors against the truth at the end, after any re-estimation; the fit: the"
        " centralized batch fit of the run's measurements from the change on)"
    )
    return "\n".join(lines)


def _pct(value: float | None) -> str:
    return "-" if value is None else f"{100 * value:.2f}%"


def _mm(value: float | None) -> str:
    return "-" if value is None else f"{1000 * value:.1f}mm"
